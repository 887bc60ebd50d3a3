"""The documentation's pictures (``docs/images/``, made by ``docs/make_pictures.py``) stay small
and are each shown by a page."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
IMAGES = ROOT / "docs" / "images"
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


@pytest.fixture()
def pictures(docs_script):
    """``docs/make_pictures.py`` as a module."""
    return docs_script("make_pictures")


def test_each_picture_is_at_most_200_kb_and_all_at_most_2_mb():
    sizes = {p.name: p.stat().st_size for p in IMAGES.glob("*.png")}
    assert sizes, "docs/images/ holds no picture"
    assert all(size <= 200_000 for size in sizes.values()), sizes
    assert sum(sizes.values()) <= 2_000_000, sizes


def test_each_picture_is_shown_by_a_page():
    text = "\n".join(p.read_text() for p in PAGES)
    unshown = [p.name for p in IMAGES.glob("*.png") if f"images/{p.name}" not in text]
    assert not unshown, f"pictures no page shows: {unshown}"


def test_interval_errors_are_the_distances_to_the_interval_ends(pictures):
    assert pictures.interval_errors(0.99, [0.95, 1.0]) == pytest.approx([0.04, 0.01])
    assert pictures.interval_errors(3.0, [3.5, 4.0]) == [0.0, 1.0]  # a value outside its interval: no negative bar


def test_a_picture_is_scaled_down_until_it_fits(tmp_path, pictures):
    noise = Image.fromarray(np.random.default_rng(0).integers(0, 256, (400, 400, 3), dtype=np.uint8))
    size = pictures.save_small(noise, tmp_path / "n.png", max_bytes=40_000)
    written = Image.open(tmp_path / "n.png")
    assert size == (tmp_path / "n.png").stat().st_size <= 40_000 and written.width < 400
    flat = Image.new("RGB", (300, 200), "white")
    pictures.save_small(flat, tmp_path / "f.png", max_bytes=40_000)
    assert Image.open(tmp_path / "f.png").size == (300, 200)  # one that fits keeps its size
