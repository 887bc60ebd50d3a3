"""Does a grasp net's Q tell the grasps that take the target from those that do not?

The command line of :mod:`mpg_agents.evaluation.grasp_outcomes`: runs a checkpoint greedily (its own
coordination and Q*_g) on ``--episodes`` scenes and prints, for every grasp it executed, how
its Q, the occlusion bit and its finger blocking relate to taking the target (counts, shares,
ROC AUCs), and what its moves and pushes did. ``--angle-trials`` also tries each grasp at the
other orientations at its pixel (undone); ``--grasp-fingers clear`` runs the net with its
finger mask (``MPGNetConfig.grasp_fingers``).

    python benchmarks/grasp_q_outcomes.py --policy mpg_agents/checkpoints/mpgnet_small.safetensors \
        --env MPG-Occluded-v0 --num-objects 15 --episodes 50 --seed 700000

Ends with one JSON line.
"""

from __future__ import annotations

import argparse
import json

from mpg_agents.evaluation.grasp_outcomes import grasp_records, summarise, summarise_motions
from mpg_envs.threads import set_torch_threads


def checkpoint_episodes_parser(description: str) -> argparse.ArgumentParser:
    """The options of a benchmark that runs an MPGNet checkpoint greedily on seeded episodes
    (also used by ``move_outcomes.py``); check ``--episodes`` with :func:`check_episodes`."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--policy", required=True, help="an MPGNet checkpoint, or 'shipped'")
    parser.add_argument("--env", default="MPG-Occluded-v0")
    parser.add_argument("--num-objects", type=int, default=15)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=700000, help="episode i is reset with seed + i (default: the tuning seeds)")
    return parser


def check_episodes(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    if args.episodes < 1:
        parser.error(f"--episodes must be >= 1, got {args.episodes}")


def main() -> None:
    parser = checkpoint_episodes_parser(__doc__.splitlines()[0])
    parser.add_argument("--angle-trials", action="store_true",
                        help="also try each grasp at the other orientations at its pixel (undone)")
    parser.add_argument("--grasp-fingers", choices=("any", "clear"), help="override the checkpoint's finger mask")
    args = parser.parse_args()
    check_episodes(parser, args)
    set_torch_threads(1)
    try:
        name, q_star, records, others = grasp_records(
            args.policy, args.env, args.num_objects, args.episodes, args.seed, args.angle_trials, args.grasp_fingers)
    except ValueError as exc:
        parser.error(str(exc))
    out = {"policy": name, "env": args.env, "num_objects": args.num_objects, "episodes": args.episodes,
           "seed": args.seed, **summarise(records, q_star), "motions": summarise_motions(others)}
    print(f"{name}: {out['grasps']} grasps in {args.episodes} episodes of {args.env} ({args.num_objects} objects)")
    print(f"  took the target {out['target']}, another object {out['wrong']}, nothing {sum(out['failures'].values())} {out['failures']}")
    print(f"  target share covered {out['target_share_covered']:.2f} (of {out['covered']}), "
          f"uncovered {out['target_share_uncovered']:.2f} (of {out['uncovered']})")
    edges = ", ".join(f"{e:.3f}" for e in out["q_quartile_edges"])
    shares = ", ".join(f"{s:.2f}" for s in out["target_share_per_q_quartile"])
    print(f"  per Q quartile (edges {edges}): {shares}")
    print(f"  ROC AUC of Q for a target grasp: {out['q_auc']:.3f}; Q*_g {q_star:.4f}: "
          f"{out['q_at_least_q_star']} grasps at or above it, target share {out['target_share_q_at_least_q_star']:.2f}")
    if "fingers_auc" in out:
        print(f"  fingers land free in {out['fingers_free']} grasps: target share free {out['target_share_fingers_free']:.2f}, "
              f"blocked {out['target_share_fingers_blocked']:.2f}; ROC AUC of minus the blocking {out['fingers_auc']:.3f}")
    if "missed_covered" in out:
        print(f"  missed the target: covered {out['missed_covered']} (another angle at the pixel takes it in "
              f"{out['missed_covered_other_angle_takes']}), uncovered {out['missed_uncovered']} "
              f"({out['missed_uncovered_other_angle_takes']})")
    moves, pushes = out["motions"]["move"], out["motions"]["push"]
    print(f"  moves: {moves['count']}, {moves['covered_before']} with the target covered, {moves['uncovered_it']} of those "
          f"left it uncovered, {moves['held_nothing']} lifted nothing")
    print(f"  pushes: {pushes['count']}, {pushes['covered_before']} with the target covered, {pushes['uncovered_it']} of those "
          "left it uncovered")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
