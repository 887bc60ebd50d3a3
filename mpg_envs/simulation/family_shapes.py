"""The procedural shape families: how each draws its parameters from a seed and builds its parts.

Five families of graspable shapes, each a union of disjoint convex parts
(:mod:`mpg_envs.simulation.solids`), so none needs a convex decomposition:

* ``superquadrics`` -- one convex superquadric: ellipsoids, rounded boxes, cushions, diamonds;
* ``compounds`` -- a chain of two to four random convex parts along a line (bones,
  dumbbells, pears, knobbly bars);
* ``extrusions`` -- a random star-shaped polygon (five to ten corners) extruded;
* ``bent`` -- a square or round bar bent along a random polyline (L, V, Z, U shapes) or an arc;
* ``hollow`` -- tubes, round cups, square cups and flat rectangular frames.

Each family draws its parameters from a ``numpy`` generator (:func:`draw_shape`), rounded to
0.1 mm (or 0.01 for exponents and angles) so they are readable and an exact cache key, and
builds its parts from them alone (:func:`build_shape`); the parts are then scaled per axis by
:func:`~mpg_envs.simulation.solids.axis_fit_factors` into the gripper's range (every extent 2.5-10 cm,
the two smallest at most 6 cm), which leaves a shape drawn inside the range as it is.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from mpg_envs.simulation.assets import Part, convex_part
from mpg_envs.simulation.solids import (
    axis_fit_factors,
    box_part,
    extrude_pieces,
    parts_extents,
    regular_polygon,
    ring_pieces,
    scale_parts,
    star_polygon_pieces,
    superquadric_part,
    sweep_mitres,
    sweep_pieces,
)

FAMILY_NAMES: tuple[str, ...] = ("superquadrics", "compounds", "extrusions", "bent", "hollow")
"""The families, in the order the ``procedural`` mix cycles through them."""

FAMILY_CODES: dict[str, int] = {"superquadrics": 1, "compounds": 2, "extrusions": 3, "bent": 4, "hollow": 5}
"""A fixed number per family in its random stream's key, so families never share draws."""

FAMILY_LABELS: dict[str, str] = {
    "superquadrics": "superquadric",
    "compounds": "compound",
    "extrusions": "extrusion",
    "bent": "bent",
    "hollow": "hollow",
}
"""The prefix of each family's object names (``superquadric-03``)."""

ROUND_SECTIONS = 12
"""Facets around the round bars, tubes and cups."""

MAX_DRAWS = 50
"""Redraws of a bent path whose corners would make its pieces overlap."""


def _mm(x: float) -> float:
    """A length rounded to 0.1 mm."""
    return round(float(x), 4)


def _cm(rng: np.random.Generator, low: float, high: float) -> float:
    """A length drawn uniformly in ``[low, high]`` centimetres, in metres, rounded to 0.1 mm."""
    return _mm(rng.uniform(low, high) / 100.0)


# ------------------------------------------------------------------ superquadrics
def _draw_superquadric(rng: np.random.Generator) -> dict[str, Any]:
    long, mid = rng.uniform(4.0, 9.0), rng.uniform(3.0, 5.8)
    short = rng.uniform(2.6, min(mid, 5.0))
    extents = rng.permutation([long, mid, short])
    return {
        "semi_axes": [_mm(e / 200.0) for e in extents],
        # Exponents >= 1.6: convex, without the sharp edges of a diamond (1) that pads slip on.
        "exponents": [round(float(x), 2) for x in np.exp(rng.uniform(math.log(1.6), math.log(8.0), size=2))],
    }


def _build_superquadric(p: dict[str, Any]) -> list[Part]:
    return superquadric_part(p["semi_axes"], p["exponents"])


# ------------------------------------------------------------------ compounds
def _section(rng: np.random.Generator, low: float, high: float) -> dict[str, Any]:
    """A random convex cross-section (an n-gon on an ellipse) in the y-z plane."""
    return {
        "sides": int(rng.integers(5, 9)),
        "radii": [_cm(rng, low, high), _cm(rng, low, high)],
        "centre": [_cm(rng, -0.3, 0.3), _cm(rng, -0.3, 0.3)],
        "twist": round(float(rng.uniform(0.0, math.pi)), 2),
    }


def _draw_compound(rng: np.random.Generator) -> dict[str, Any]:
    count = int(rng.integers(2, 5))
    fractions = rng.uniform(1.0, 2.0, size=count)
    cuts = np.concatenate([[0.0], np.cumsum(fractions)]) / fractions.sum() * rng.uniform(6.0, 9.5)
    return {
        "cuts": [_mm(c / 100.0) for c in cuts],
        # Interfaces (the first and last are the end caps) and one bulge inside each part.
        "interfaces": [_section(rng, 0.9, 2.0) for _ in range(count + 1)],
        "bulges": [_section(rng, 1.3, 2.7) for _ in range(count)],
        "bulge_at": [round(float(x), 2) for x in rng.uniform(0.3, 0.7, size=count)],
    }


def _section_points(section: dict[str, Any], x: float) -> np.ndarray:
    angles = np.linspace(0.0, 2 * math.pi, section["sides"], endpoint=False) + section["twist"]
    (ry, rz), (cy, cz) = section["radii"], section["centre"]
    return np.column_stack([np.full(len(angles), x), cy + ry * np.cos(angles), cz + rz * np.sin(angles)])


def _build_compound(p: dict[str, Any]) -> list[Part]:
    cuts, parts = p["cuts"], []
    for k, (bulge, at) in enumerate(zip(p["bulges"], p["bulge_at"])):
        # Part k lies between the planes x = cuts[k] and cuts[k + 1]; its faces there are the
        # interface polygons it shares with its neighbours, so the parts meet face to face.
        mid = cuts[k] + at * (cuts[k + 1] - cuts[k])
        points = [
            _section_points(p["interfaces"][k], cuts[k]),
            _section_points(bulge, mid),
            _section_points(p["interfaces"][k + 1], cuts[k + 1]),
        ]
        parts.append(convex_part(np.concatenate(points)))
    return parts


# ------------------------------------------------------------------ extrusions
def _draw_extrusion(rng: np.random.Generator) -> dict[str, Any]:
    corners = int(rng.integers(5, 11))
    gaps = rng.uniform(0.5, 1.5, size=corners)
    angles = np.cumsum(gaps) / gaps.sum() * 2 * math.pi + rng.uniform(0.0, 2 * math.pi)
    radii = rng.uniform(0.45, 1.0, size=corners)
    polygon = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
    span = polygon.max(axis=0) - polygon.min(axis=0)
    size = np.array([rng.uniform(5.0, 9.5), rng.uniform(3.0, 5.8)]) / 100.0
    polygon = polygon * (size / span)  # per axis: stays star-shaped about the origin
    return {"polygon": [[_mm(x), _mm(y)] for x, y in polygon], "height": _cm(rng, 2.6, 5.0)}


def _build_extrusion(p: dict[str, Any]) -> list[Part]:
    return extrude_pieces(star_polygon_pieces(np.array(p["polygon"])), p["height"])


# ------------------------------------------------------------------ bent bars
def _draw_bent(rng: np.random.Generator) -> dict[str, Any]:
    round_bar = bool(rng.uniform() < 0.4)
    width = rng.uniform(1.4, 2.5) / 100.0
    width = _mm(width)
    height = width if round_bar else _cm(rng, 1.4, 3.0)
    for _ in range(MAX_DRAWS):  # redraw a path whose corners would make the pieces overlap
        path = [[_mm(x), _mm(y)] for x, y in _bent_path(rng)]
        try:
            sweep_mitres(np.array(path), width / 2)
        except ValueError:
            continue
        return {"path": path, "round": round_bar, "width": width, "height": height}
    raise RuntimeError(f"no bent path fits a bar {width:.4f} m wide in {MAX_DRAWS} draws")


def _bent_path(rng: np.random.Generator) -> np.ndarray:
    """An arc of 90-240 degrees, or two or three straight segments turning either way."""
    if rng.uniform() < 0.25:
        arc, radius = rng.uniform(math.pi / 2, 4 * math.pi / 3), rng.uniform(2.0, 3.5) / 100.0
        angles = np.linspace(0.0, arc, 9)
        return np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
    heading, point, path = 0.0, np.zeros(2), [np.zeros(2)]
    for k in range(int(rng.integers(2, 4))):
        if k:
            heading += rng.choice([-1.0, 1.0]) * rng.uniform(math.radians(35), math.radians(115))
        point = point + rng.uniform(3.5, 6.5) / 100.0 * np.array([math.cos(heading), math.sin(heading)])
        path.append(point)
    return np.array(path)


def _build_bent(p: dict[str, Any]) -> list[Part]:
    w, h = p["width"], p["height"]
    if p["round"]:
        section = regular_polygon(0.5, ROUND_SECTIONS, (w, h)) + (0.0, h / 2)
    else:
        section = np.array([(-w / 2, 0.0), (w / 2, 0.0), (w / 2, h), (-w / 2, h)])
    return sweep_pieces(np.array(p["path"]), section)


# ------------------------------------------------------------------ hollow shapes
HOLLOW_KINDS = ("tube", "cup", "square_cup", "frame")


def _draw_hollow(rng: np.random.Generator) -> dict[str, Any]:
    kind = HOLLOW_KINDS[int(rng.integers(len(HOLLOW_KINDS)))]
    wall = _cm(rng, 0.6, 1.0)
    if kind == "frame":  # a flat rectangular ring: the fingers take one side
        return {"kind": kind, "wall": _cm(rng, 0.9, 1.5), "size": [_cm(rng, 6.5, 9.5), _cm(rng, 4.5, 6.0), _cm(rng, 2.6, 4.0)]}
    if kind == "square_cup":
        return {
            "kind": kind,
            "wall": wall,
            "bottom": _cm(rng, 0.6, 1.0),
            "size": [_cm(rng, 4.0, 6.0), _cm(rng, 3.5, 6.0), _cm(rng, 3.5, 8.0)],
        }
    return {
        "kind": kind,
        "wall": wall,
        "bottom": _cm(rng, 0.6, 1.0) if kind == "cup" else 0.0,
        "diameter": _cm(rng, 3.6, 6.0),
        "length": _cm(rng, 3.5, 9.0),
    }


def _build_hollow(p: dict[str, Any]) -> list[Part]:
    kind, wall = p["kind"], p["wall"]
    if kind in ("tube", "cup"):
        outer, length, bottom = p["diameter"] / 2, p["length"], p["bottom"]
        # The outer radius is the polygon's circumradius: its flats lie at outer * cos(pi / n).
        parts = ring_pieces(outer - wall, outer, bottom, length, ROUND_SECTIONS)
        if bottom > 0:
            disc = regular_polygon(outer, ROUND_SECTIONS)
            parts += extrude_pieces([disc], bottom)
        return parts
    x, y, z = p["size"]
    if kind == "frame":
        # Two long bars the full length, two short ones between them.
        return [
            box_part((-x / 2, -y / 2, 0.0), (x / 2, -y / 2 + wall, z)),
            box_part((-x / 2, y / 2 - wall, 0.0), (x / 2, y / 2, z)),
            box_part((-x / 2, -y / 2 + wall, 0.0), (-x / 2 + wall, y / 2 - wall, z)),
            box_part((x / 2 - wall, -y / 2 + wall, 0.0), (x / 2, y / 2 - wall, z)),
        ]
    bottom = p["bottom"]
    return [
        box_part((-x / 2, -y / 2, 0.0), (x / 2, y / 2, bottom)),
        box_part((-x / 2, -y / 2, bottom), (x / 2, -y / 2 + wall, z)),
        box_part((-x / 2, y / 2 - wall, bottom), (x / 2, y / 2, z)),
        box_part((-x / 2, -y / 2 + wall, bottom), (-x / 2 + wall, y / 2 - wall, z)),
        box_part((x / 2 - wall, -y / 2 + wall, bottom), (x / 2, y / 2 - wall, z)),
    ]


_FAMILIES: dict[str, tuple[Callable[[np.random.Generator], dict[str, Any]], Callable[[dict[str, Any]], list[Part]]]] = {
    "superquadrics": (_draw_superquadric, _build_superquadric),
    "compounds": (_draw_compound, _build_compound),
    "extrusions": (_draw_extrusion, _build_extrusion),
    "bent": (_draw_bent, _build_bent),
    "hollow": (_draw_hollow, _build_hollow),
}


def check_family(family: str) -> str:
    """``family`` if it names a family; else ValueError listing the families."""
    if family not in _FAMILIES:
        raise ValueError(f"unknown shape family {family!r}; valid: {list(FAMILY_NAMES)}")
    return family


def draw_shape(family: str, seed: int, index: int) -> dict[str, Any]:
    """The parameters of shape ``index`` of ``family``'s set ``seed`` (deterministic: each
    shape has its own random stream, keyed ``[seed, family code, index]``)."""
    draw = _FAMILIES[check_family(family)][0]
    return draw(np.random.default_rng([seed, FAMILY_CODES[family], index]))


def build_shape(family: str, params: dict[str, Any]) -> list[Part]:
    """The convex parts of a shape from its parameters, fitted to the gripper's range."""
    parts = _FAMILIES[check_family(family)][1](params)
    factors = axis_fit_factors(parts_extents(parts))
    return parts if np.all(factors == 1.0) else scale_parts(parts, factors)
