"""Write the headline results into README.md and docs/index.md, and the track and finding tables
into docs/results.md, from the track table's and the finding table's files.

README.md and the docs home hold a block between ``<!-- headline:start -->`` and
``<!-- headline:end -->``: a sentence on the shipped MPGNet and one table (the shipped net, its
Grasping-Only control, the peers' baselines, the exemplar matcher and the oracle on each track at
15 and 30 objects, each track beside its exemplar version); the Results page a block between
``<!-- tracks:start -->`` and ``<!-- tracks:end -->`` (every row of the track table) and one
between ``<!-- finding:start -->`` and ``<!-- finding:end -->`` (every policy with the target
named by its mask, its visible pixels and an exemplar, and how each found it). Every figure is
read from ``benchmarks/results/tracks/tracks.json`` and ``benchmarks/results/finding/tracks.json``.
Run it after either table changes::

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
FINDING_JSON = ROOT / "benchmarks" / "results" / "finding" / "tracks.json"
PAGES = {
    ROOT / "README.md": ("headline",),
    ROOT / "docs" / "index.md": ("headline",),
    ROOT / "docs" / "results.md": ("tracks", "finding"),
}
"""Each page and the names of its blocks."""

TRACKS = {"hard": "blocks", "hard-novel": "unseen shapes", "hard-camera": "camera images"}
"""The track table's tracks, as the headline names them."""

ROWS = {
    "Oracle (reads the simulator)": "Oracle (reads the simulator, tries actions in a copy)",
    "**MPGNet (shipped)**": "MPGNet (shipped)",
    "Grasping-Only, trained as the shipped MPGNet": "Grasping-Only, trained as the shipped MPGNet (training seed 1)",
    "Grasping-Only, strict Stage V": "Grasping-Only, Stage V under strict retrieval (training seed 0)",
    "Push-grasp, strict Stage V": "Push-grasp, Stage V under strict retrieval (training seed 0)",
    "Target-Oriented VPG, strict Stage V": "Target-Oriented VPG, Stage V under strict retrieval (training seed 0)",
    "Exemplar matcher (colour and shape)": "Exemplar matcher (colour and shape)",
}
"""The headline's rows: the name shown, then the row's label in ``tracks.json``."""

SHIPPED, CONTROL = "MPGNet (shipped)", "Grasping-Only, trained as the shipped MPGNet (training seed 1)"
ORACLE, MATCHER = ROWS["Oracle (reads the simulator)"], "Exemplar matcher (colour and shape)"

EXEMPLAR = {"hard": "hard-exemplar", "hard-novel": "hard-novel-exemplar", "hard-camera": "hard-camera-exemplar"}
"""Each track's exemplar version (the same scenes, the target named by pictures of it): the headline's
column beside the track's."""

FAMILIES = {
    "blocks": ("hard", "hard-visible", "hard-exemplar"),
    "unseen shapes": ("hard-novel", "hard-novel-visible", "hard-novel-exemplar"),
    "camera images": ("hard-camera", "hard-camera-visible", "hard-camera-exemplar"),
}
"""The finding table's tracks by scenes: the target named by its mask, its visible pixels, an exemplar."""
SPECS = ("mask", "visible mask", "exemplar")


def percent(rate: float) -> str:
    """A rate as a whole percentage: ``0.985`` -> ``"98%"`` (half to even, as Python rounds)."""
    return f"{100 * rate:.0f}%"


def cell_text(cell: dict[str, Any]) -> str:
    """A cell as the track table writes it: success [95% interval] in mean motions."""
    lo, hi = cell["success_ci"]
    return f"{100 * cell['success']:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}] in {cell['motions']:.2f}"


def _cell(report: dict[str, Any], track: str, label: str, n: str) -> str:
    """A cell's text, ``-`` where the table has none."""
    cell = report["rows"].get(track, {}).get(label, {}).get(n)
    return "-" if cell is None else cell_text(cell)


def headline(report: dict[str, Any], finding: dict[str, Any]) -> str:
    """The block between the markers, from the track table's and the finding table's reports."""
    rows = report["rows"]
    objects = [str(n) for n in report["objects"]]
    for track in TRACKS:
        for label in ROWS.values():
            if label != MATCHER and label not in rows.get(track, {}):
                raise ValueError(f"{TRACKS_JSON.name} has no row {label!r} on track {track!r}")
        if any(n not in finding["rows"].get(EXEMPLAR[track], {}).get(MATCHER, {}) for n in objects):
            raise ValueError(f"{FINDING_JSON} lacks {MATCHER!r} on {EXEMPLAR[track]!r}")
    ship, control = rows["hard"][SHIPPED], rows["hard"][CONTROL]
    camera = rows["hard-camera"][SHIPPED]
    matcher = finding["rows"]["hard-exemplar"][MATCHER]
    lines = [
        f"The shipped MPGNet, trained on 2 CPU cores, takes {percent(ship[objects[0]]['success'])} of the hard "
        f"track's held-out targets at {objects[0]} objects and {percent(ship[objects[1]]['success'])} at "
        f"{objects[1]}, where a Grasping-Only net trained the same way takes "
        f"{percent(control[objects[0]]['success'])} and {percent(control[objects[1]]['success'])}, and "
        f"{percent(camera[objects[0]]['success'])} and {percent(camera[objects[1]]['success'])} on rendered "
        "camera images. Named only by pictures of it (the exemplar columns: the same scenes, no mask), "
        f"the target is taken by a colour-and-shape matcher in {percent(matcher[objects[0]]['success'])} and "
        f"{percent(matcher[objects[1]]['success'])} of the blocks' scenes. Success [95% interval] in mean motions, "
        f"{report['episodes']} held-out scenes per cell (seeds {report['seed']} on), from "
        "`benchmarks/results/tracks/tracks.json` and `benchmarks/results/finding/tracks.json`; `-`: the method "
        "needs what the track does not give (the target's mask, or pictures of it), or its cell has not been run:",
        "",
        "| Method | "
        + " | ".join(f"{name}{extra}, {n} obj." for name in TRACKS.values() for extra in ("", ", exemplar") for n in objects)
        + " |",
        "|---|" + "---:|" * (2 * len(TRACKS) * len(objects)),
    ]
    for shown, label in ROWS.items():
        cells = []
        for track in TRACKS:
            cells += [_cell(report, track, label, n) for n in objects]
            cells += [_cell(finding, EXEMPLAR[track], label, n) for n in objects]
        lines.append(f"| {shown} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def finding_tables(finding: dict[str, Any]) -> str:
    """The finding table: per scenes, every policy with the target named by its mask, its visible
    pixels and an exemplar; then how each found the target (finding reported by its episodes)."""
    objects = [str(n) for n in finding["objects"]]
    labels = list(finding["policies"])
    lines = []
    for family, tracks in FAMILIES.items():
        lines += [
            f"**{family.capitalize()}**",
            "",
            "| Method | " + " | ".join(f"{spec}, {n} obj." for spec in SPECS for n in objects) + " |",
            "|---|" + "---:|" * (len(SPECS) * len(objects)),
        ]
        for label in labels:
            lines.append(f"| {label} | " + " | ".join(_cell(finding, t, label, n) for t in tracks for n in objects) + " |")
        lines.append("")
    lines += [
        "**How each found the target** (episodes where it showed at reset, where it showed at all, mean motions "
        "to first sight of those, look-alike grasps and other mis-picks per episode):",
        "",
        "| Scenes | Target named by | Method | objects | shown at reset | ever seen | motions to first sight "
        "| look-alike grasps/ep. | other mis-picks/ep. |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for family, tracks in FAMILIES.items():
        for spec, track in zip(SPECS, tracks):
            for label in labels:
                for n in objects:
                    cell = finding["rows"].get(track, {}).get(label, {}).get(n)
                    seen = (cell or {}).get("finding", {})
                    if not seen.get("episodes"):
                        continue
                    mean, looks = seen["motions_to_sight"], seen.get("lookalike_grasps_per_episode")
                    others = seen.get("other_mispicks_per_episode")
                    lines.append(
                        f"| {family} | {spec} | {label} | {n} | {seen['shown_at_reset']} of {seen['episodes']} | "
                        f"{seen['sighted']} of {seen['episodes']} | {'n/a' if mean is None else f'{mean:.2f}'} | "
                        f"{'n/a' if looks is None else f'{looks:.2f}'} | {'n/a' if others is None else f'{others:.2f}'} |"
                    )
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
        cells = [_cell(report, t, label, n) for t in tracks for n in objects]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def blocks(report: dict[str, Any], finding: dict[str, Any]) -> dict[str, str]:
    """Each block's text by its name."""
    return {"headline": headline(report, finding), "tracks": track_table(report), "finding": finding_tables(finding)}


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
    texts = blocks(json.loads(TRACKS_JSON.read_text()), json.loads(FINDING_JSON.read_text()))
    stale = []
    for page, names in PAGES.items():
        text = new = page.read_text()
        for name in names:
            new = rewrite(new, texts[name], page.name, name)
        if new != text:
            stale.append(page.name)
            if not args.check:
                page.write_text(new)
    if args.check and stale:
        print(f"headline figures differ from the results files in: {', '.join(stale)}", file=sys.stderr)
        return 1
    print("checked" if args.check else "written", ", ".join(p.name for p in PAGES))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
