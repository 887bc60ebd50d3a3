"""Write the headline results into README.md and docs/index.md, and the track table into
docs/results.md, from the track table's file.

README.md and the docs home hold a block between ``<!-- headline:start -->`` and
``<!-- headline:end -->``: a sentence on the shipped MPGNet and one table (the shipped net, its
Grasping-Only control, the peers' baselines and the oracle on each track at 15 and 30 objects);
the Results page a block between ``<!-- tracks:start -->`` and ``<!-- tracks:end -->``: every
row of the track table. Every figure is read from ``benchmarks/results/tracks/tracks.json``.
Run it after the track table changes::

    python docs/make_headline.py            # rewrite the blocks
    python docs/make_headline.py --check    # exit 1 when a page's block differs from the file

``tests/test_headline_figures.py`` checks the pages against the file.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
TRACKS_JSON = ROOT / "benchmarks" / "results" / "tracks" / "tracks.json"
PAGES = {ROOT / "README.md": "headline", ROOT / "docs" / "index.md": "headline", ROOT / "docs" / "results.md": "tracks"}
"""Each page and the name of its block."""

TRACKS = {"hard": "blocks", "hard-novel": "unseen shapes", "hard-camera": "camera images"}
"""The track table's tracks, as the headline names them."""

ROWS = {
    "Oracle (reads the simulator)": "Oracle (reads the simulator, tries actions in a copy)",
    "**MPGNet (shipped)**": "MPGNet (shipped)",
    "Grasping-Only, trained as the shipped MPGNet": "Grasping-Only, trained as the shipped MPGNet (training seed 1)",
    "Grasping-Only, strict Stage V": "Grasping-Only, Stage V under strict retrieval (training seed 0)",
    "Push-grasp, strict Stage V": "Push-grasp, Stage V under strict retrieval (training seed 0)",
    "Target-Oriented VPG, strict Stage V": "Target-Oriented VPG, Stage V under strict retrieval (training seed 0)",
}
"""The headline's rows: the name shown, then the row's label in ``tracks.json``."""

SHIPPED, CONTROL = "MPGNet (shipped)", "Grasping-Only, trained as the shipped MPGNet (training seed 1)"


def percent(rate: float) -> str:
    """A rate as a whole percentage: ``0.985`` -> ``"98%"`` (half to even, as Python rounds)."""
    return f"{100 * rate:.0f}%"


def cell_text(cell: dict[str, Any]) -> str:
    """A cell as the track table writes it: success [95% interval] in mean motions."""
    lo, hi = cell["success_ci"]
    return f"{100 * cell['success']:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}] in {cell['motions']:.2f}"


def headline(report: dict[str, Any]) -> str:
    """The block between the markers, from the track table's report."""
    rows = report["rows"]
    objects = [str(n) for n in report["objects"]]
    for track in TRACKS:
        for label in ROWS.values():
            if label not in rows.get(track, {}):
                raise ValueError(f"{TRACKS_JSON.name} has no row {label!r} on track {track!r}")
    ship, control = rows["hard"][SHIPPED], rows["hard"][CONTROL]
    camera = rows["hard-camera"][SHIPPED]
    lines = [
        f"The shipped MPGNet, trained on 2 CPU cores, takes {percent(ship[objects[0]]['success'])} of the hard "
        f"track's held-out targets at {objects[0]} objects and {percent(ship[objects[1]]['success'])} at "
        f"{objects[1]}, where a Grasping-Only net trained the same way takes "
        f"{percent(control[objects[0]]['success'])} and {percent(control[objects[1]]['success'])}, and "
        f"{percent(camera[objects[0]]['success'])} and {percent(camera[objects[1]]['success'])} on rendered "
        "camera images. Success [95% interval] in mean motions, "
        f"{report['episodes']} held-out scenes per cell (seeds {report['seed']} on), from "
        "`benchmarks/results/tracks/tracks.json`:",
        "",
        "| Method | " + " | ".join(f"{name}, {n} obj." for name in TRACKS.values() for n in objects) + " |",
        "|---|" + "---:|" * (len(TRACKS) * len(objects)),
    ]
    for shown, label in ROWS.items():
        cells = [cell_text(rows[track][label][n]) for track in TRACKS for n in objects]
        lines.append(f"| {shown} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def track_table(report: dict[str, Any]) -> str:
    """Every row of the track table: success [95% interval] in mean motions per track and object count."""
    objects = [str(n) for n in report["objects"]]
    tracks = list(report["rows"])
    lines = [
        "| Method | " + " | ".join(f"{TRACKS.get(t, t)}, {n} obj." for t in tracks for n in objects) + " |",
        "|---|" + "---:|" * (len(tracks) * len(objects)),
    ]
    for label in report["rows"][tracks[0]]:
        cells = [
            cell_text(report["rows"][t][label][n]) if n in report["rows"][t].get(label, {}) else "-"
            for t in tracks
            for n in objects
        ]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def blocks(report: dict[str, Any]) -> dict[str, str]:
    """Each block's text by its name."""
    return {"headline": headline(report), "tracks": track_table(report)}


def markers(name: str) -> tuple[str, str]:
    """The start and end markers of the block ``name``."""
    return f"<!-- {name}:start -->", f"<!-- {name}:end -->"


def rewrite(text: str, block: str, page: str, name: str = "headline") -> str:
    """``text`` with the block ``name`` between its markers replaced by ``block``."""
    start, end = markers(name)
    if text.count(start) != 1 or text.count(end) != 1 or text.index(start) > text.index(end):
        raise ValueError(f"{page} needs one {start} ... {end} block")
    head, rest = text.split(start)
    _, tail = rest.split(end)
    return f"{head}{start}\n{block}\n{end}{tail}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="only report pages whose block differs from the file")
    args = parser.parse_args(argv)
    texts = blocks(json.loads(TRACKS_JSON.read_text()))
    stale = []
    for page, name in PAGES.items():
        text = page.read_text()
        new = rewrite(text, texts[name], page.name, name)
        if new != text:
            stale.append(page.name)
            if not args.check:
                page.write_text(new)
    if args.check and stale:
        print(f"headline figures differ from {TRACKS_JSON.name} in: {', '.join(stale)}", file=sys.stderr)
        return 1
    print("checked" if args.check else "written", ", ".join(p.name for p in PAGES))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
