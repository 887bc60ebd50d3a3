"""The command-line options that override a checkpoint's network settings without touching its
weights (``--grasp-region``, ``--target-margin``, ``--move-region``, ``--grasp-fingers``,
``--move-fingers``), shared by ``mpg-eval`` and ``mpg-export``."""

from __future__ import annotations

import argparse
from typing import Any

from mpg_agents.cli_input import check_net_setting


def add_net_setting_arguments(parser: argparse.ArgumentParser, prefix: str) -> None:
    """The options that override a checkpoint's settings without weights (read by :func:`net_settings`);
    ``prefix`` starts each option's help text (e.g. ``"network policies: "``)."""
    parser.add_argument(
        "--grasp-region",
        choices=("rectangle", "target", "visible"),
        help=prefix + "where a grasp may act (override the checkpoint's: the target's "
        "rectangle, its footprint, or the part of it where the target shows)",
    )
    parser.add_argument(
        "--target-margin",
        type=int,
        help=prefix
        + "grow (> 0) or shrink (< 0) the target's pixels by this many pixels for grasp regions 'target' and 'visible'",
    )
    parser.add_argument(
        "--move-region",
        choices=("rectangle", "top"),
        help=prefix + "where a move may act (override the checkpoint's: the target's "
        "rectangle or the top of its footprint, the occluder)",
    )
    parser.add_argument(
        "--grasp-fingers",
        choices=("any", "clear"),
        help=prefix
        + "which grasps may act (override the checkpoint's): any, or only those whose open fingers land least blocked",
    )
    parser.add_argument(
        "--move-fingers",
        choices=("any", "clear"),
        help=prefix
        + "which moves may act (override the checkpoint's): any, or only those whose open fingers land least blocked",
    )


def net_settings(args: argparse.Namespace) -> dict[str, Any]:
    """``MPGNetConfig`` field -> value of the :func:`add_net_setting_arguments` options given (checked:
    a bad ``--target-margin`` is a ``UsageError``)."""
    check_net_setting("--target-margin", "target_margin_px", args.target_margin)
    given = (
        ("grasp_region", args.grasp_region),
        ("target_margin_px", args.target_margin),
        ("move_region", args.move_region),
        ("grasp_fingers", args.grasp_fingers),
        ("move_fingers", args.move_fingers),
    )
    return {name: value for name, value in given if value is not None}
