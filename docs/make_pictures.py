"""Make the documentation's pictures (``docs/images/*.png``) from the code and the results files.

    MUJOCO_GL=egl python docs/make_pictures.py            # every picture (a minute or two on a CPU)
    MUJOCO_GL=egl python docs/make_pictures.py --only plot

Pictures:

* ``scene_<track>.png``: each benchmark track's first held-out scene (seed 500000, 15 objects):
  the colour heightmap with the target outlined, the depth heightmap and the rendered view
  (the demo's ``scene.png``; Environments page and docs home);
* ``qmaps.png``: the shipped MPGNet's Q maps for its first decision in that hard-track scene,
  the chosen action drawn (the demo's ``qmaps_0.png``; Agent page);
* ``demo.png``: the hard-track scene above its Q maps (README);
* ``results_tracks.png``: success and mean motions per track and object count for each policy
  of the track table, with 95% intervals, from ``benchmarks/results/tracks/tracks.json`` (Results page).

Each file is written as a palette PNG, scaled down until it is at most 200 kB.
"""

from __future__ import annotations

import argparse
import io
import json
import tempfile
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from PIL import Image

import mpg_envs
from mpg_agents.demo import scene_picture
from mpg_agents.evaluation.policy_zoo import make_policy

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "images"
TRACKS_JSON = ROOT / "benchmarks" / "results" / "tracks" / "tracks.json"
MAX_BYTES = 200_000
SEED = 500000
TRACK_ENVS = {
    "hard": "MPG-OccludedHard-v0",
    "hard-novel": "MPG-OccludedHardNovel-v0",
    "hard-camera": "MPG-OccludedHardCamera-v0",
}
TRACK_NAMES = {"hard": "blocks", "hard-novel": "unseen shapes", "hard-camera": "camera images of blocks"}


def save_small(image: Image.Image, path: Path, max_bytes: int = MAX_BYTES) -> int:
    """Write ``image`` as a palette PNG at most ``max_bytes`` long, scaling it down by steps of
    0.85 until it fits; returns the size written."""
    image = image.convert("RGB")
    while True:
        data = io.BytesIO()
        image.quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(data, format="PNG", optimize=True)
        if data.tell() <= max_bytes or min(image.size) < 64:
            break
        image = image.resize((round(image.width * 0.85), round(image.height * 0.85)), Image.Resampling.LANCZOS)
    path.write_bytes(data.getvalue())
    return data.tell()


def stacked(top: Image.Image, bottom: Image.Image) -> Image.Image:
    """``top`` above ``bottom``, the wider scaled to the narrower's width."""
    width = min(top.width, bottom.width)
    parts = [p.resize((width, round(p.height * width / p.width)), Image.Resampling.LANCZOS) for p in (top, bottom)]
    out = Image.new("RGB", (width, sum(p.height for p in parts)), "white")
    out.paste(parts[0], (0, 0))
    out.paste(parts[1], (0, parts[0].height))
    return out


def scenes_and_qmaps() -> None:
    """The tracks' scenes, the shipped net's Q maps and the README's picture."""
    hard_scene = None
    for track, env_id in TRACK_ENVS.items():
        env = mpg_envs.make(env_id, render_mode="rgb_array")
        try:
            obs, _ = env.reset(seed=SEED)
            scene = Image.fromarray(scene_picture(env, obs))
            print(track, save_small(scene, OUT / f"scene_{track}.png"))
            if track == "hard":
                hard_scene = scene
                policy = make_policy("shipped", env, seed=SEED)
                policy.reset()
                with tempfile.TemporaryDirectory() as tmp:
                    qpath = Path(tmp) / "qmaps.png"
                    policy.save_qmaps(qpath, obs)
                    qmaps = Image.open(qpath).convert("RGB")
                print("qmaps", save_small(qmaps, OUT / "qmaps.png"))
                print("demo", save_small(stacked(hard_scene, qmaps), OUT / "demo.png"))
        finally:
            env.close()


def interval_errors(value: float, interval: list[float]) -> list[float]:
    """Matplotlib's error-bar lengths (below, above) of ``value`` in ``interval``."""
    return [max(value - interval[0], 0.0), max(interval[1] - value, 0.0)]


def results_plot(report: dict[str, Any] | None = None) -> None:
    """Success and mean motions per track for each policy, with 95% intervals."""
    plt.switch_backend("Agg")
    report = report if report is not None else json.loads(TRACKS_JSON.read_text())
    tracks = list(report["rows"])
    objects = [str(n) for n in report["objects"]]
    labels = list(report["rows"][tracks[0]])
    fig, axes = plt.subplots(2, len(tracks), figsize=(4.2 * len(tracks), 7.5), sharey="row")
    width = 0.8 / len(labels)
    colours = plt.get_cmap("tab10")
    for col, track in enumerate(tracks):
        for row, (key, ci_key, scale, ylabel) in enumerate(
            [("success", "success_ci", 100.0, "success (%)"), ("motions", "motions_ci", 1.0, "mean motions")]
        ):
            ax = axes[row][col]
            for i, label in enumerate(labels):
                cells = [report["rows"][track][label][n] for n in objects]
                xs = np.arange(len(objects)) + (i - (len(labels) - 1) / 2) * width
                values = [scale * c[key] for c in cells]
                errors = np.array([interval_errors(scale * c[key], [scale * v for v in c[ci_key]]) for c in cells]).T
                ax.bar(
                    xs,
                    values,
                    width,
                    yerr=errors,
                    capsize=1.5,
                    color=colours(i % 10),
                    label=label if col == 0 and row == 0 else None,
                )
            ax.set_xticks(range(len(objects)), [f"{n} objects" for n in objects])
            if row == 0:
                ax.set_title(TRACK_NAMES.get(track, track))
            if col == 0:
                ax.set_ylabel(ylabel)
            ax.grid(axis="y", alpha=0.3)
    fig.legend(loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.17, 1, 1))
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    plt.close(fig)
    print("plot", save_small(Image.open(buffer), OUT / "results_tracks.png"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", choices=["scenes", "plot"], help="make only the scenes and Q maps, or only the plot")
    args = parser.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    if args.only in (None, "plot"):
        results_plot()
    if args.only in (None, "scenes"):
        scenes_and_qmaps()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
