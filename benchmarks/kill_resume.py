"""Fault injection: a small training killed with SIGKILL at random moments, resumed each time.

``mpg-train --env MPG-Stage2-v0`` (a shallow net, a checkpoint every ``--checkpoint-every``
iterations) runs in a child process that is killed ``--kills`` times (``kill -9``) at random
moments (during start-up, iterations and saves alike), then left to finish. After every kill the
run folder must hold a loadable state and weights, and a log holding every iteration the state
counts; at the end the log must have its header and each iteration exactly once, and the state
must resume at the last iteration.

Then the exactness check: one run unkilled, and one killed right after each of its saves that
begin an episode (a resume restarts the episode a kill interrupted, from the same scene, so a
run killed at such saves retraces the unkilled one), must end with bitwise identical weights.

The last output line is one JSON object. Run it niced on a shared machine:

    nice python benchmarks/kill_resume.py [--kills 20] [--steps 50] [--exact-steps 16] [--seed 0]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mpg_agents.learning.train_log import CSV_COLUMNS  # noqa: E402

CONFIG = """batch_size = 1
replay_capacity = 64
target_update_every = 2
torch_threads = 1
[net_config]
trunk_depth = 2
"""


def start(out: Path, config: Path, steps: int) -> subprocess.Popen:
    """``mpg-train`` on ``out`` in a child process (its output to ``out/../<name>.log``)."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1", "MPG_NUM_THREADS": "1"}
    argv = [sys.executable, "-m", "mpg_agents.cli", "--env", "MPG-Stage2-v0", "--steps", str(steps), "--config", str(config), "--out", str(out)]
    log = open(out.parent / f"{out.name}.log", "a")
    return subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=str(out.parent))


def logged_iterations(out: Path) -> tuple[bool, list[int]]:
    """Whether ``progress.csv`` starts with its header, and the iterations of its complete rows."""
    path = out / "progress.csv"
    if not path.is_file():
        return False, []
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header = bool(rows) and rows[0] == CSV_COLUMNS
    return header, [int(r[0]) for r in rows if len(r) == len(CSV_COLUMNS) and r[0].isdigit()]


def saved_counters(out: Path) -> dict | None:
    """The counters of the run's saved state (``None``: nothing saved yet)."""
    from mpg_agents.learning.run_state import COUNTERS_FILE, state_folder

    for _ in range(50):  # the state folder is swapped by two renames: read again if caught between
        folder = state_folder(out)
        if folder is None:
            return None
        try:
            return json.loads((folder / COUNTERS_FILE).read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            time.sleep(0.01)
    raise RuntimeError(f"{out}: the saved state cannot be read")


def begins_episode(out: Path, counters: dict) -> bool:
    """Whether the saved state ``counters`` begins an episode: its last iteration ended one (its
    ``progress.csv`` row names an episode before the state's next one). The episode's own
    counters (``episode_motions``) are zeroed only when the next episode starts, so they cannot
    tell; the log's rows are on disk before the state that counts them."""
    iteration = counters["iteration"]
    with open(out / "progress.csv", newline="") as f:
        rows = [r for r in csv.reader(f) if len(r) == len(CSV_COLUMNS) and r[0] == str(iteration)]
    return bool(rows) and int(rows[-1][CSV_COLUMNS.index("episode")]) < counters["episode"]


def check_loadable(out: Path) -> int:
    """Load the saved state's online weights and ``weights.safetensors``; returns the state's iteration."""
    from mpg_agents.acting.weights import load_mpgnet
    from mpg_agents.learning.run_state import state_folder

    counters = saved_counters(out)
    if counters is None:
        return 0
    load_mpgnet(state_folder(out) / "online.safetensors")
    load_mpgnet(out / "weights.safetensors")
    return int(counters["iteration"])


def killed_at_random(root: Path, config: Path, args: argparse.Namespace, rng: random.Random) -> dict:
    """The random kills; returns what was seen."""
    out = root / "random"
    out.mkdir()
    # An unkilled start-up (to the first iteration's row) and the next iterations give the time
    # scale of the kill moments.
    t0 = time.monotonic()
    proc = start(out, config, args.steps)
    while not logged_iterations(out)[1] and proc.poll() is None:
        time.sleep(0.05)
    startup = time.monotonic() - t0
    while len(logged_iterations(out)[1]) < 4 and proc.poll() is None:
        time.sleep(0.05)
    per_iteration = (time.monotonic() - t0 - startup) / 3
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    kills, states, problems = 1, [check_loadable(out)], []
    while kills < args.kills:
        proc = start(out, config, args.steps)
        time.sleep(rng.uniform(0.3 * startup, startup + 3 * per_iteration))
        if proc.poll() is not None:  # it finished (or failed) before the kill
            if proc.returncode != 0:
                problems.append(f"a resume exited with status {proc.returncode} (see {out.name}.log)")
                break
            if check_loadable(out) >= args.steps:
                break
            continue
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        kills += 1
        iteration = check_loadable(out)
        logged = set(logged_iterations(out)[1])
        lost = [i for i in range(1, iteration + 1) if i not in logged]
        if lost:
            problems.append(f"kill {kills}: the state counts iterations {lost[:5]} the log lacks")
        states.append(iteration)
    if kills < args.kills:
        problems.append(f"the run finished after {kills} kills, fewer than {args.kills}: give more --steps")
    proc = start(out, config, args.steps)  # the last resume, left to finish
    if proc.wait() != 0:
        problems.append(f"the last resume exited with status {proc.returncode}")
    header, its = logged_iterations(out)
    if not header:
        problems.append("progress.csv has no header")
    if its != list(range(1, args.steps + 1)):
        problems.append(f"progress.csv iterations are not 1..{args.steps} once each: {its}")
    final = check_loadable(out)
    if final != args.steps:
        problems.append(f"the final state is at iteration {final}, not {args.steps}")
    resumed = resume_in_process(out, config, args.steps)
    if resumed != args.steps:
        problems.append(f"a learner resuming the final state starts at iteration {resumed}")
    return {"kills": kills, "state_iteration_after_each_kill": states, "startup_s": round(startup, 1),
            "iteration_s": round(per_iteration, 2), "log_rows": len(its), "problems": problems}


def resume_in_process(out: Path, config: Path, steps: int) -> int:
    """Resume the run's full state (weights, target, optimiser, replay, generators) in this process."""
    from mpg_agents.cli import training_settings
    from mpg_agents.learning.learner import Learner
    from dataclasses import replace

    base, _ = training_settings(str(config))
    learner = Learner(replace(base, steps=steps), "MPG-Stage2-v0", out, log=lambda s: None)
    learner.env.close()
    learner.lock.release()
    return learner.counters.iteration


def killed_at_episode_saves(root: Path, config: Path, args: argparse.Namespace) -> dict:
    """One run unkilled and one killed right after each save that begins an episode: same weights?"""
    steps = args.exact_steps
    ref = root / "unkilled"
    ref.mkdir()
    if start(ref, config, steps).wait() != 0:
        return {"problems": ["the unkilled run failed"]}
    out = root / "killed_at_saves"
    out.mkdir()
    kills, seen, problems = 0, set(), []
    while True:
        proc = start(out, config, steps)
        killed = False
        while proc.poll() is None:
            counters = saved_counters(out)
            if counters is not None and counters["iteration"] not in seen:
                seen.add(counters["iteration"])
                if 0 < counters["iteration"] < steps and begins_episode(out, counters):
                    proc.send_signal(signal.SIGKILL)
                    proc.wait()
                    kills, killed = kills + 1, True
                    if saved_counters(out) != counters:  # it saved again before the kill landed
                        problems.append(f"a kill meant for the save of iteration {counters['iteration']} came after the next save")
                    break
            time.sleep(0.01)
        if not killed:
            if proc.returncode != 0:
                problems.append(f"the run killed at its saves exited with status {proc.returncode}")
            break
    same = (ref / "weights.safetensors").read_bytes() == (out / "weights.safetensors").read_bytes()
    same_state = (ref / "state" / "online.safetensors").read_bytes() == (out / "state" / "online.safetensors").read_bytes()
    if not (same and same_state):
        problems.append("the run killed at its saves ends with other weights than the unkilled run")
    return {"kills_at_saves": kills, "weights_identical": same and same_state, "problems": problems}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=20)
    parser.add_argument("--steps", type=int, default=50, help="iterations of the randomly killed training")
    parser.add_argument("--exact-steps", type=int, default=16, help="iterations of the unkilled run and the one killed at its saves")
    parser.add_argument("--checkpoint-every", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0, help="picks the kill moments")
    parser.add_argument("--keep", help="keep the run folders here (default: a temporary folder)")
    args = parser.parse_args()
    rng = random.Random(args.seed)
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep) if args.keep else Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        config = root / "tiny.toml"
        config.write_text(f"checkpoint_every = {args.checkpoint_every}\n" + CONFIG)
        random_part = killed_at_random(root, config, args, rng)
        print(f"random kills: {json.dumps(random_part)}", flush=True)
        exact_part = killed_at_episode_saves(root, config, args)
        print(f"kills at episode-starting saves: {json.dumps(exact_part)}", flush=True)
    problems = random_part["problems"] + exact_part["problems"]
    result = {**{k: v for k, v in random_part.items() if k != "problems"}, **{k: v for k, v in exact_part.items() if k != "problems"},
              "steps": args.steps, "exact_steps": args.exact_steps, "checkpoint_every": args.checkpoint_every, "problems": problems, "ok": not problems,
              "wall_s": round(time.monotonic() - t0)}
    print(json.dumps(result))
    return 0 if not problems else 1


if __name__ == "__main__":
    sys.exit(main())
