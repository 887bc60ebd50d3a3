"""The short demo: build a scene, run a policy, print metrics, write pictures.

    python -m mpg_agents.demo [--policy shipped|oracle|random|CKPT] [--env MPG-OccludedHard-v0]
                              [--episodes 3] [--seed 500052] [--out demo_out]

Runs ``--episodes`` seeded episodes, prints each step and a summary (task success,
motions, grasp success), and writes ``scene.png`` (the first scene's colour heightmap with
the target outlined and its depth heightmap, beside ``env.render()``'s view when OpenGL is
available) and, for a network policy, ``qmaps_<k>.png`` for each motion ``k`` of the first
episode (every branch's Q map at that decision, the chosen action drawn and named).
By default it runs the shipped MPGNet on the hard track (``MPG-OccludedHard-v0``: the target
at most 30% visible, strict retrieval) from a held-out scene where the net first moves the
occluder aside, then grasps the target; ``--env MPG-Occluded-v0`` shows the paper's test scenes,
``--env MPG-OccludedHardNovel-v0 --seed 500001`` a scene of shapes no training used. On an
exemplar track (``--env MPG-OccludedHardExemplar-v0 --locator PATH``) the net acts through a
target locator, and ``scene.png`` adds the exemplar and the locator's map, the located target
outlined.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import cv2
import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the envs; picks EGL/OSMesa on headless Linux)
from mpg_agents.acting.device import DEVICES, resolve_device
from mpg_agents.cli_input import UsageError, check_checkpoint, check_env_id, fail
from mpg_agents.evaluation.policy_zoo import BUILTIN, is_builtin, make_policy
from mpg_envs.files import WriteFailed, check_folder_writable, write_bytes_whole
from mpg_envs.grid.primitive_specs import MOVE
from mpg_envs.perception.render import RenderUnavailableError
from mpg_envs.policies.registry import scripted_baseline_names
from mpg_envs.threads import set_torch_threads

DEMO_ENV = "MPG-OccludedHard-v0"
"""The demo's env: the hard track, where grasping alone mis-picks."""

DEMO_SEED = 500_052
"""The demo's first scene: a held-out hard-track test seed (training never uses it) where the
shipped MPGNet moves the occluder aside, then grasps the target."""

PANEL_PX = 448
TITLE_PX = 34


def titled(image: np.ndarray, title: str) -> np.ndarray:
    """``image`` (RGB) under a black title bar."""
    bar = np.zeros((TITLE_PX, image.shape[1], 3), np.uint8)
    cv2.putText(bar, title, (8, 23), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1, cv2.LINE_AA)
    return np.concatenate([bar, image], axis=0)


def heightmap_panels(obs: dict[str, np.ndarray], outline: np.ndarray | None = None) -> list[np.ndarray]:
    """The colour heightmap with the target outlined (``outline``, else the observation's
    mask; none in exemplar mode without it), and the depth heightmap, titled (RGB)."""
    size = (PANEL_PX, PANEL_PX)
    color = cv2.resize(obs["color"], size, interpolation=cv2.INTER_NEAREST)
    target = outline if outline is not None else obs.get("mask", np.zeros(obs["color"].shape[:2], np.uint8))
    mask = cv2.resize(np.asarray(target).astype(np.uint8), size, interpolation=cv2.INTER_NEAREST)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    cv2.drawContours(color, contours, -1, (255, 255, 255), 2)
    depth = np.asarray(obs["depth"], np.float32).reshape(obs["color"].shape[:2])
    top = max(float(depth.max()), 1e-6)
    depth_rgb = cv2.cvtColor(cv2.applyColorMap((depth / top * 255).astype(np.uint8), cv2.COLORMAP_VIRIDIS), cv2.COLOR_BGR2RGB)
    depth_rgb = cv2.resize(depth_rgb, size, interpolation=cv2.INTER_NEAREST)
    return [
        titled(color, "colour heightmap (target outlined in white)"),
        titled(depth_rgb, f"depth heightmap (dark: table, bright: {100 * top:.1f} cm)"),
    ]


def exemplar_panels(obs: dict[str, np.ndarray], locator: Any = None) -> tuple[np.ndarray | None, list[np.ndarray]]:
    """Exemplar mode: the panel of the exemplar's colour heightmap, titled (RGB); with a
    ``locator`` also the target as it finds it (its mask, to outline; else ``None``) and the
    panel of its probability map."""
    size = (PANEL_PX, PANEL_PX)
    query = titled(cv2.resize(obs["query_color"], size, interpolation=cv2.INTER_NEAREST), "the exemplar (query_color)")
    if locator is None:
        return None, [query]
    location = locator.locate(obs)
    heat = cv2.applyColorMap((np.clip(location.probability, 0.0, 1.0) * 255).astype(np.uint8), cv2.COLORMAP_INFERNO)
    heat = cv2.resize(cv2.cvtColor(heat, cv2.COLOR_BGR2RGB), size, interpolation=cv2.INTER_NEAREST)
    seen = f"seen, p = {location.seen_probability:.2f}" if location.seen else f"not seen, p = {location.seen_probability:.2f}"
    return location.mask, [query, titled(heat, f"the locator's map ({seen})")]


def scene_picture(env: gym.Env, obs: dict[str, np.ndarray], locator: Any = None) -> np.ndarray:
    """The heightmap panels beside the rendered scene (``env.render()``) when OpenGL works; in
    exemplar mode also the exemplar and, with a ``locator``, its map, the located target
    outlined."""
    outline, extra = exemplar_panels(obs, locator) if "query_color" in obs else (None, [])
    panels = heightmap_panels(obs, outline) + extra
    try:
        view: Any = env.render()  # an RGB array (render_mode="rgb_array")
    except RenderUnavailableError as exc:
        print(f"(no rendered view in scene.png: {exc})")
    else:
        width = round(view.shape[1] * PANEL_PX / view.shape[0])
        view = cv2.resize(view, (width, PANEL_PX), interpolation=cv2.INTER_AREA)
        panels.append(titled(view, "the scene (env.render(), overview camera)"))
    return np.concatenate(panels, axis=1)


def step_outcome(info: dict) -> str:
    """What a motion did, for the demo's step line: a move lifts an object by design, so only a
    grasp's lift says which object it took."""
    if info["target_grasped"]:
        return "  grasped the target"
    if info["primitive"] == MOVE:
        return "  uncovered the target" if info["move_success"] else ""
    return "  grasped another object" if info["lifted"] else ""


class QMapsOfFirstEpisode:
    """A network policy that also writes ``qmaps_<k>.png`` (every branch's Q maps) before each
    motion ``k`` of the first episode; otherwise the policy itself. The evaluation resets a
    policy once at every episode's start, so the resets count the episodes."""

    def __init__(self, policy, out: Path):
        self.policy, self.out, self.name = policy, out, policy.name
        self.episodes, self.motion = 0, 0

    def reset(self) -> None:
        self.policy.reset()
        self.episodes, self.motion = self.episodes + 1, 0

    def act(self, obs: dict[str, np.ndarray]) -> int:
        self.motion += 1
        if self.episodes == 1:
            self.policy.save_qmaps(self.out / f"qmaps_{self.motion}.png", obs)
        return self.policy.act(obs)


def png_bytes(image: np.ndarray) -> bytes:
    """``image`` (RGB) as the bytes of a PNG file."""
    encoded, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not encoded:
        raise ValueError("could not encode the scene picture as PNG")
    return data.tobytes()


def check_arguments(args: argparse.Namespace) -> str:
    """The demo's arguments, checked before any work; returns the device to use.

    Raises:
        UsageError: a count or seed out of range, an unknown env id or policy (the valid ones
            named), or an ``--out`` that is a file or where no file can be written.
        ValueError: a device that is not there (CUDA asked for where there is none).
    """
    if args.episodes < 1:
        raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
    if args.seed < 0:
        raise UsageError(f"--seed must be >= 0, got {args.seed}")
    check_env_id(args.env)
    if not is_builtin(args.policy):
        if not Path(args.policy).exists():
            raise UsageError(
                f"unknown policy {args.policy!r}; valid: {', '.join(BUILTIN)} or the path of a .safetensors checkpoint"
            )
        check_checkpoint(args.policy)
    device = resolve_device(args.device)
    if Path(args.out).exists() and not Path(args.out).is_dir():
        raise UsageError(f"--out {args.out!r} is a file; give a folder (made if missing)")
    try:
        check_folder_writable(args.out)
    except WriteFailed as exc:
        raise UsageError(f"--out {args.out!r}: no picture can be written there ({exc.reason})") from None
    return str(device)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="MPG demo: a policy on a few seeded scenes.")
    scripted = ", ".join(scripted_baseline_names())
    parser.add_argument(
        "--policy", default="shipped", help=f"shipped (the trained checkpoint), {scripted} or a checkpoint path"
    )
    parser.add_argument(
        "--env",
        default=DEMO_ENV,
        help=f"a registered env id (default: {DEMO_ENV}, the hard track, "
        "15 objects; MPG-Occluded-v0: the paper's test scenes)",
    )
    parser.add_argument("--episodes", type=int, default=3, help="episodes to run (default 3)")
    # A held-out test seed (the shipped net trained on its own seeds), so the demo shows a
    # scene it never trained on.
    parser.add_argument(
        "--seed",
        type=int,
        default=DEMO_SEED,
        help=f"episode i is reset with seed + i (default {DEMO_SEED}, a held-out test seed)",
    )
    parser.add_argument(
        "--locator",
        metavar="PATH",
        help="exemplar tracks: the target locator's weights (mpg-train-locator's locator.safetensors)",
    )
    parser.add_argument("--out", default="demo_out", help="folder for scene.png and qmaps_<k>.png (default demo_out)")
    parser.add_argument(
        "--device",
        choices=DEVICES,
        default="auto",
        help="a network policy's device: auto (default: CUDA when available), cpu or cuda",
    )
    args = parser.parse_args(argv)
    try:
        device = check_arguments(args)
    except (UsageError, ValueError) as exc:
        return fail(exc)

    # Start-up time: argument errors are told before the evaluation (scipy) loads.
    from mpg_agents.evaluation.evaluate import evaluate  # noqa: PLC0415

    threads = set_torch_threads()  # the cores free now (MPG_NUM_THREADS overrides)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(args.env, render_mode="rgb_array")
    try:
        policy = make_policy(args.policy, env, device=str(device), **({"locator": args.locator} if args.locator else {}))
    except ValueError as exc:  # a checkpoint of another architecture or action space
        env.close()
        return fail(exc)
    print(
        f"policy {policy.name} on {args.env}, {args.episodes} episodes "
        f"from seed {args.seed}, {threads} torch threads, {device}"
    )

    locator = getattr(policy, "locator", None)  # a net on an exemplar env finds the target with one

    def on_reset(episode: int, obs: dict[str, np.ndarray]) -> None:
        if episode == 0:
            write_bytes_whole(out / "scene.png", png_bytes(scene_picture(env, obs, locator)))

    def on_step(episode: int, reward: float, info: dict) -> None:
        print(
            f"  episode {episode} motion {info['num_motions']}: {info['primitive']:5s} rot {info['rotation']:2d} "
            f"at {info['pixel']} reward {reward:+.1f}" + step_outcome(info)
        )

    if hasattr(policy, "save_qmaps"):
        policy = QMapsOfFirstEpisode(policy, out)
    try:
        result = evaluate(policy, env, args.episodes, args.seed, on_reset=on_reset, on_step=on_step)
    except WriteFailed as exc:  # a picture the disk refused: no "pictures in" over a folder without them
        env.close()
        return fail(exc)
    grasps = (
        "n/a" if result.grasp_success_rate is None else f"{100 * result.grasp_success_rate:.0f}% of {result.grasp_attempts}"
    )
    print(
        f"task success {round(result.task_success_rate * args.episodes)}/{args.episodes} "
        f"({100 * result.task_success_rate:.0f}%), mean motions {result.average_motions:.2f}, "
        f"target grasp success {grasps}, {result.seconds_per_motion:.2f} s per motion"
    )
    print(f"pictures in {out.resolve()}")
    env.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
