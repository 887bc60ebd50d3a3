"""Why does an MPGNet's move lift nothing? Where and at which angle its moves close.

The command line of :mod:`mpg_agents.evaluation.move_outcomes`: runs a checkpoint greedily on
``--episodes`` scenes, looks at each of its moves in a copy of the simulation before it is made
(what its pixel shows, its angle to the object's short axis, whether it, another angle at the
pixel, or the oracle's move of the top occluder lifts anything) and prints the counts.

    python benchmarks/move_outcomes.py --policy mpg_agents/checkpoints/mpgnet_small.safetensors \\
        --num-objects 15 --episodes 50 --seed 700000

Each trial costs a motion's simulation (about 0.3 s), ten per move. Ends with one JSON line.
"""

from __future__ import annotations

import json

from mpg_agents.evaluation.move_outcomes import ANGLE_LIMIT_DEG, ON_WHAT, move_records, summarise_moves
from mpg_envs.threads import set_torch_threads

# Run as a script, benchmarks/ is on the path: the options are grasp_q_outcomes.py's.
from grasp_q_outcomes import check_episodes, checkpoint_episodes_parser  # noqa: E402


def main() -> None:
    parser = checkpoint_episodes_parser(__doc__.splitlines()[0])
    parser.add_argument("--move-region", choices=("rectangle", "top"), help="override where the net's moves may act")
    parser.add_argument("--move-fingers", choices=("any", "clear"), help="override which moves may act (finger mask)")
    args = parser.parse_args()
    check_episodes(parser, args)
    set_torch_threads(1)
    try:
        name, records = move_records(args.policy, args.env, args.num_objects, args.episodes, args.seed, args.move_region, args.move_fingers)
    except ValueError as exc:
        parser.error(str(exc))
    out = {"policy": name, "env": args.env, "num_objects": args.num_objects, "episodes": args.episodes,
           "seed": args.seed, **summarise_moves(records)}
    print(f"{name}: {out['moves']} moves in {args.episodes} episodes of {args.env} ({args.num_objects} objects), "
          f"{out['lifted']} lifted an object")
    print("  on " + ", ".join(f"{k} {out['on'][k]} (lifted {out['lifted_on'][k]})" for k in ON_WHAT))
    print(f"  on an occluder within {ANGLE_LIMIT_DEG:g} deg of its short axis: {out['occluder_on_axis']} "
          f"(lifted {out['occluder_on_axis_lifted']}); further off: {out['occluder_off_axis']} (lifted {out['occluder_off_axis_lifted']})")
    print(f"  some angle at the same pixel lifts: {out['any_angle_lifts']} of {out['moves']}; "
          f"the oracle's move of the top occluder lifts it: {out['oracle_lifts']} of {out['oracle_tried']}")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
