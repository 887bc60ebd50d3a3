"""Record seeded episodes in full, or check that they replay identically.

For each policy and seed, the episode's every step is kept: the action, what the policy
decided it from (an MPGNet's primitive, Q value and grasp score; the oracle's plan), the
reward, the step's info, and a digest of every observation. A refactoring of the env or the
agent that must not change behaviour is checked by recording before and comparing after:

    python benchmarks/recorded_episodes.py --out before.json
    python benchmarks/recorded_episodes.py --check before.json

Defaults: ``shipped`` and ``oracle`` on ``MPG-OccludedHard-v0``, the test seeds
500000-500004 (shipped test-set scenes) and the dropped seeds 123 and 124.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPG_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import mpg_envs  # noqa: E402,F401
from mpg_agents.evaluation.evaluate import run_episode  # noqa: E402
from mpg_agents.evaluation.policy_zoo import NetworkPolicy, make_policy  # noqa: E402

SEEDS = (500000, 500001, 500002, 500003, 500004, 123, 124)


def obs_digest(obs: dict[str, np.ndarray]) -> str:
    """SHA-256 of every observation array (key, dtype, shape and bytes)."""
    h = hashlib.sha256()
    for key in sorted(obs):
        arr = np.ascontiguousarray(obs[key])
        h.update(f"{key}:{arr.dtype}:{arr.shape}".encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def plain(value: Any) -> Any:
    """``value`` as JSON can hold it exactly (floats by their repr, NaN as a string)."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if math.isfinite(value) else str(float(value))
    return value if value is None or isinstance(value, str) else repr(value)


class Recorder:
    """Acts as ``policy`` does and keeps what each decision was made from."""

    def __init__(self, policy) -> None:
        self.policy = policy
        self.steps: list[dict[str, Any]] = []

    def reset(self) -> None:
        self.policy.reset()

    def act(self, obs) -> int:
        entry: dict[str, Any] = {"obs": obs_digest(obs)}
        if isinstance(self.policy, NetworkPolicy) and self.policy.memory is None:
            d = self.policy.policy.decide(obs)
            action = int(d.action)
            entry.update(primitive=d.primitive, q_value=d.q_value, grasp_score=d.grasp_score)
        else:
            action = int(self.policy.act(obs))
            plan = getattr(self.policy, "last_plan", None)
            if plan is not None:
                entry["plan"] = plan
        entry["action"] = action
        self.steps.append(entry)
        return action


def record(policies: list[str], env_id: str, seeds: list[int]) -> dict[str, Any]:
    """Every step of every (policy, seed) episode."""
    out: dict[str, Any] = {"env_id": env_id, "episodes": {}}
    for name in policies:
        env = gym.make(env_id)
        recorder = Recorder(make_policy(name, env))
        for seed in seeds:
            recorder.steps = []
            start = time.perf_counter()
            resets: list[dict[str, Any]] = []
            steps: list[dict[str, Any]] = []
            run_episode(
                recorder, env, 0, seed,
                on_reset=lambda i, obs: resets.append({"obs": obs_digest(obs)}),
                on_step=lambda i, reward, info: steps.append({"reward": reward, "info": info}),
            )
            episode = [{**a, **s} for a, s in zip(recorder.steps, steps)]
            out["episodes"][f"{name}/{seed}"] = plain({"reset": resets[0], "steps": episode})
            print(f"{name} seed {seed}: {len(episode)} steps, {time.perf_counter() - start:.1f} s", flush=True)
        env.close()
    return out


def differences(before: dict[str, Any], after: dict[str, Any]) -> list[str]:
    """Where two recordings differ (empty: identical)."""
    diffs = []
    for key in sorted(set(before["episodes"]) | set(after["episodes"])):
        a, b = before["episodes"].get(key), after["episodes"].get(key)
        if a is None or b is None:
            diffs.append(f"{key}: only in {'after' if a is None else 'before'}")
            continue
        if a["reset"] != b["reset"]:
            diffs.append(f"{key}: reset observation differs")
        for k, (sa, sb) in enumerate(zip(a["steps"], b["steps"])):
            for field in sorted(set(sa) | set(sb)):
                va, vb = sa.get(field), sb.get(field)
                if field == "info":  # timings are not behaviour; keys added since are not a change
                    va = {x: y for x, y in (va or {}).items() if "seconds" not in x}
                    vb = {x: y for x, y in (vb or {}).items() if x in va}
                if va != vb:
                    diffs.append(f"{key} step {k}: {field} {va!r} != {vb!r}")
        if len(a["steps"]) != len(b["steps"]):
            diffs.append(f"{key}: {len(a['steps'])} steps before, {len(b['steps'])} after")
    return diffs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", nargs="+", default=["shipped", "oracle"])
    parser.add_argument("--env", default="MPG-OccludedHard-v0")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS))
    parser.add_argument("--out", help="write the recording here")
    parser.add_argument("--check", help="compare with this recording; exit 1 on any difference")
    args = parser.parse_args(argv)
    now = record(args.policies, args.env, args.seeds)
    if args.out:
        Path(args.out).write_text(json.dumps(now, indent=1, sort_keys=True))
    if args.check:
        diffs = differences(json.loads(Path(args.check).read_text()), now)
        for line in diffs[:50]:
            print(line)
        print(f"{len(now['episodes'])} episodes: " + ("identical" if not diffs else f"{len(diffs)} differences"))
        return 1 if diffs else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
