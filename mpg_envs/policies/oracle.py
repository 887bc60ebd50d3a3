"""The scripted reference policy, a :class:`~mpg_envs.policies.policy.Policy` that reads the simulator.

:class:`OraclePolicy` reads the simulator's state (object poses and shapes, which object is
the target, which object each heightmap pixel shows), never pixels alone, and, as a planner
with a perfect model of the physics, tries candidate actions in the env's simulation and undoes
them (``env.sim``: :meth:`~mpg_envs.tasks.episode_sim.EpisodeSim.try_primitive` and
:meth:`~mpg_envs.tasks.episode_sim.EpisodeSim.trial`) before taking one. It proves the suite is solvable
and is the upper baseline of evaluations. Each step it re-plans from the current state:

1. its best target grasps (across the short axis, where the open fingers come down on the
   freest space; through partial cover too) are tried in the copy, and the first that holds
   the target is taken;
2. otherwise its candidate preparations -- moves of the objects seen on the target (topmost
   first), moves of the objects in the fingers' way, pushes of those out along the closing
   direction -- are each tried and followed by grasp trials; the first after which a grasp
   holds is taken, else the one leaving the target least covered and least blocked.

Its plans by geometry (grasps at the 8 angles, finger-gap pushes) are
:mod:`mpg_envs.policies.grasp_plans`. With ``OracleConfig(verify_grasps=0)`` it plans by geometry
alone (no trials). It remembers every action it took or tried with the heightmap it was on and
never repeats one whose surroundings did not change (:class:`ActionMemory`), so a failed action
is never retried unchanged.

Diagnostics read the oracle's view through its public methods: :meth:`OraclePolicy.view`
(depth and which object each pixel shows), :meth:`OraclePolicy.occluders` and
:meth:`OraclePolicy.grasp_plans`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from mpg_envs.grid.grasp_geometry import JawGeometry, angle_to_rotation, footprint_rect
from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH
from mpg_envs.grid.workspace import NUM_ROTATIONS
from mpg_envs.policies.action_memory import ActionMemory, RepeatRule
from mpg_envs.policies.grasp_plans import GraspPlan, clip_pixel, plan_grasps, push_options
from mpg_envs.policies.policy import Policy

__all__ = ["ActionMemory", "GraspPlan", "OracleConfig", "OraclePolicy", "Policy", "angle_to_rotation", "footprint_rect"]


@dataclass(frozen=True)
class OracleConfig:
    """Geometry the oracle plans with (metres); the finger sizes are the 2F-85's."""

    max_grasp_width: float = 0.075  # wider than this across the fingers: not graspable
    # The 2F-85's open fingers (mpg_envs.grid.grasp_geometry.JawGeometry, shared with MPGNet's finger mask).
    finger_open_inner: float = JawGeometry.finger_open_inner  # an open finger's inner face, from the jaw's centre
    finger_thickness: float = JawGeometry.finger_thickness  # a finger's thickness along the closing direction, with a margin
    finger_half_width: float = JawGeometry.finger_half_width  # half a pad's width across the jaw, with a margin
    offset_step: float = 0.004  # the jaw slides along the closing direction in steps of this
    finger_margin: float = 0.004  # the swept strip starts this far off the object's side
    pad_below_tcp: float = JawGeometry.pad_below_tcp  # the pads' lower edge lies this far below the TCP
    finger_clearance: float = (
        JawGeometry.finger_clearance
    )  # a strip is free if nothing in it rises above the pads' lower edge + this
    # A grasp this little blocked is tried before any push (the pads push small things aside).
    grasp_tolerance: float = 0.02
    push_start_gap: float = 0.012  # a push starts this far outside the target's edge
    occluder_tolerance: float = 0.01  # as the env's occlusion test: higher than the target's top by this
    # When an action repeats a tried one (mpg_envs.policies.action_memory.RepeatRule's defaults).
    repeat_pixels: int = RepeatRule.repeat_pixels
    repeat_window: int = RepeatRule.repeat_window
    repeat_height_change: float = RepeatRule.repeat_height_change
    verify_grasps: int = 4  # target grasps tried in a copy of the simulation before acting (0: plan by geometry alone)
    verify_preparations: int = 5  # with trials: moves/pushes tried, each followed by verify_grasps grasp trials


class OraclePolicy:
    """The scripted reference policy for any MPG env (a :class:`Policy`); also SB3's ``predict``."""

    name = "oracle"

    def __init__(self, env: gym.Env, config: OracleConfig = OracleConfig()):
        self.env = env
        self.config = config
        self.memory = ActionMemory(config)
        self.last_plan: dict[str, Any] | None = None  # what the last act() decided and why
        self._episode_motions = -1
        self._obs: dict[str, np.ndarray] = {}  # the observation of the last act()
        self._ids_model: Any = None  # the mujoco.MjModel the caster below was made for
        self._ids_caster: Any = None  # its RaycastHeightmapper (made on first use)

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style: ``(action, state)`` for the env's current state."""
        return self.act(obs), state

    def reset(self) -> None:
        """Forget the actions tried in the last episode."""
        self.memory.clear()
        self.last_plan = None

    def act(self, obs: Any = None) -> int:
        """The flat action index the oracle chooses now, for the env's current observation
        ``obs`` (``None``: the env's last one) and the simulator state behind it."""
        env: Any = self.env.unwrapped  # an MPG env (gym.Env does not declare its attributes)
        if env.num_motions == 0 and self._episode_motions != 0:
            self.reset()  # a new episode even if the caller did not say so
        self._episode_motions = env.num_motions
        self._obs = env.last_observation if obs is None else obs
        if getattr(env, "target_spec", "mask") != "mask":  # the policy is shown less: plan on the simulator's view
            self._obs = self._simulator_view(env, self._obs)
        depth = np.asarray(self._obs["depth"])
        primitive, rotation, row, col, plan = self._choose(env, depth)
        self.memory.record(primitive, rotation, row, col, depth)
        self.last_plan = plan
        return env.action_space.encode(primitive, rotation, row, col)

    # ------------------------------------------------------------ planning
    def _choose(self, env, depth: np.ndarray):
        world, allowed, target = env.world, env.primitives, env.target
        ids = self.view(world)[1]
        if target is None or env.stage.mask_all_objects or not world.active[target]:
            inside = set(world.active_objects().tolist()) - set(world.objects_outside_workspace().tolist())
            for i in sorted(inside, key=lambda i: -world.object_top(i)):
                step = self._first_new(GRASP, self.grasp_plans(env, i, depth, ids), depth)
                if step:
                    return (*step, {"kind": "grasp_any"})
            return self._last_resort(env, depth, GRASP)
        verify = GRASP in allowed and self.config.verify_grasps > 0
        if verify:
            step = self._verified_grasp(env, target, depth, ids)
            if step:
                return (*step, {"kind": "grasp_verified"})
        plans = self.grasp_plans(env, target, depth, ids) if GRASP in allowed else []
        if not verify:
            occluded = bool(self._obs["occluded"][0])
            if MOVE in allowed and (occluded or GRASP not in allowed):
                moves = list(self._moves(env, target, depth, ids, plans, blockers=False))[
                    : max(1, self.config.verify_preparations)
                ]
                step = self._tried_move(env, target, depth, ids, moves)
                if step:
                    return step
            good = [p for p in plans if p.blocked <= self.config.grasp_tolerance]
            step = self._first_new(GRASP, good, depth)
            if step:
                return (
                    *step,
                    {"kind": "grasp_free" if good[0].free else "grasp_tolerated", "blocked": round(good[0].blocked, 4)},
                )
            step = next(self._pushes(env, target, depth, plans), None)
            if step:
                return step
        else:
            step = self._look_ahead(env, target, depth, ids, plans)
            if step:
                return step
        step = self._first_new(GRASP, plans, depth)
        if step:
            return (*step, {"kind": "grasp_blocked", "no_free_grasp": True})
        return self._last_resort(env, depth, GRASP if GRASP in allowed else allowed[0])

    def _tried_move(self, env, target: int, depth: np.ndarray, ids: np.ndarray, moves: list):
        """With trials (Stage III, no grasp to verify), the first move, over the movers' angles
        (up to ``2 * verify_grasps`` trials), that lifts the object it aims at and leaves the
        target in place (going 4 cm below a thin occluder's top can pinch the target under it);
        without trials, or if none does, the first move."""
        budget = 2 * self.config.verify_grasps
        for move in moves:
            j = move[4]["object"]
            for p in self.grasp_plans(env, j, depth, ids, require_fit=False):
                if budget <= 0:
                    return moves[0]
                if self.memory.repeats(MOVE, p.rotation, p.row, p.col, depth):
                    continue
                budget -= 1
                result = env.sim.try_primitive(MOVE, p.rotation, p.row, p.col, depth, target)
                if result.lifted and result.grasped_object == j and not result.target_moved:
                    return MOVE, p.rotation, p.row, p.col, move[4]
        return moves[0] if moves else None

    def _moves(self, env, target: int, depth: np.ndarray, ids: np.ndarray, plans: list[GraspPlan], blockers: bool = True):
        """Untried moves, in order: the objects seen on the target (topmost first); with no
        grasp allowed and none on top, the nearest neighbours; with ``blockers``, then the
        objects in the open fingers' way of the least blocked target grasps."""
        world, allowed = env.world, env.primitives
        if MOVE not in allowed:
            return
        movers = self.occluders(world, target, depth, ids, self._obs["mask"])
        if not movers and GRASP not in allowed:  # Stage III, nothing on top: clear the nearest
            movers = self._neighbours(world, target)
        kinds = {j: "move_occluder" for j in movers}
        if blockers:
            for p in sorted(plans, key=lambda p: p.blocked):
                for _, j in p.blockers:
                    if j not in kinds:
                        movers.append(j)
                        kinds[j] = "move_blocker"
        for j in movers:
            step = self._first_new(MOVE, self.grasp_plans(env, j, depth, ids, require_fit=False), depth)
            if step:
                yield (*step, {"kind": kinds[j], "object": j})

    def _pushes(self, env, target: int, depth: np.ndarray, plans: list[GraspPlan]):
        """Untried pushes that open a finger gap (:func:`~mpg_envs.policies.grasp_plans.push_options`)."""
        if PUSH not in env.primitives or not plans:
            return
        seen = set()
        for _, start, rotation in push_options(env.world, target, plans, self.config):
            r, c = clip_pixel(env.world.workspace, start)
            if (rotation, r, c) not in seen and not self.memory.repeats(PUSH, rotation, r, c, depth):
                seen.add((rotation, r, c))
                yield PUSH, rotation, r, c, {"kind": PUSH, "no_free_grasp": True}

    def _look_ahead(self, env, target: int, depth: np.ndarray, ids: np.ndarray, plans: list[GraspPlan]):
        """Of the first ``verify_preparations`` untried moves and pushes, the first after which
        a target grasp holds in the simulation; else the one leaving the target least covered
        and its fingers least blocked; ``None`` when there is none."""
        c = self.config
        candidates = list(self._moves(env, target, depth, ids, plans))[: c.verify_preparations]
        candidates += list(self._pushes(env, target, depth, plans))[: max(0, c.verify_preparations - len(candidates))]
        best, best_score = None, None
        sim = env.sim
        for cand in candidates:
            primitive, rotation, row, col, info = cand
            with sim.trial():
                sim.executor.execute(primitive, rotation, row, col, depth, target)
                if not sim.world.active[target] or target in set(sim.world.objects_outside_workspace().tolist()):
                    continue
                after, ids_after = self.view(sim.world)
                mask, _ = sim.target_view(after, target)
                plans_after = self.grasp_plans(env, target, after, ids_after)
                for p in plans_after[: c.verify_grasps]:
                    result = sim.try_primitive(GRASP, p.rotation, p.row, p.col, after, target)
                    if result.lifted and result.grasped_object == target:
                        return primitive, rotation, row, col, {**info, "verified_next": True}
                occluders = self.occluders(sim.world, target, after, ids_after, mask)
                score = (len(occluders), min((p.blocked for p in plans_after), default=1.0))
                if best_score is None or score < best_score:
                    best, best_score = cand, score
        return best

    def _verified_grasp(self, env, target: int, depth: np.ndarray, ids: np.ndarray):
        """The first of the best ``verify_grasps`` untried target grasps that holds the target
        when tried in a copy of the simulation; the ones that did not are remembered as tried."""
        tried = 0
        for p in self.grasp_plans(env, target, depth, ids):
            if tried >= self.config.verify_grasps:
                break
            if self.memory.repeats(GRASP, p.rotation, p.row, p.col, depth):
                continue
            tried += 1
            result = env.sim.try_primitive(GRASP, p.rotation, p.row, p.col, depth, target)
            if result.lifted and result.grasped_object == target:
                return GRASP, p.rotation, p.row, p.col
            self.memory.record(GRASP, p.rotation, p.row, p.col, depth)
        return None

    def _first_new(self, primitive: str, plans: list[GraspPlan], depth: np.ndarray):
        """The first plan (with small pixel shifts) that does not repeat a tried action."""
        for p in plans:
            for dr, dc in ((0, 0), (3, 0), (0, 3), (-3, 0), (0, -3)):
                r = int(np.clip(p.row + dr, 0, depth.shape[0] - 1))
                c = int(np.clip(p.col + dc, 0, depth.shape[1] - 1))
                if not self.memory.repeats(primitive, p.rotation, r, c, depth):
                    return primitive, p.rotation, r, c
        return None

    def _last_resort(self, env, depth: np.ndarray, primitive: str):
        """Nothing new left to try at the planned spots: the first untried angle at the target."""
        world = env.world
        i = env.target if env.target is not None and world.active[env.target] else int(world.active_objects()[0])
        centre, _, _ = footprint_rect(world.object_vertices(i)[:, :2])
        r, c = clip_pixel(world.workspace, centre)
        for k in range(NUM_ROTATIONS):
            if not self.memory.repeats(primitive, k, r, c, depth):
                return primitive, k, r, c, {"kind": "last_resort", "no_free_grasp": True}
        return primitive, 0, r, c, {"kind": "last_resort", "no_free_grasp": True}

    # ------------------------------------------------------------ pieces
    def grasp_plans(self, env, i: int, depth: np.ndarray, ids: np.ndarray, require_fit: bool = True) -> list[GraspPlan]:
        """Grasps of object ``i`` at the 8 angles, best first: free ones nearest the short
        axis, then the least blocked. At each angle the jaw slides along the closing
        direction (the open fingers span 85 mm) to where both fingers come down on free space
        (:func:`~mpg_envs.policies.grasp_plans.plan_grasps`)."""
        pc = env.config.primitives
        return plan_grasps(env.world, i, depth, ids, self.config, pc.grasp_depth, pc.grasp_min_height, require_fit)

    def occluders(self, world, target: int, depth: np.ndarray, ids: np.ndarray, mask: np.ndarray) -> list[int]:
        """Objects seen over the target's footprint ``mask`` (``depth``, ``ids``: a :meth:`view`)
        higher than the target's top, topmost first."""
        mask = np.asarray(mask) > 0
        over = mask & (depth > world.object_top(target) + self.config.occluder_tolerance)
        found = {int(j): float(depth[over & (ids == j)].max()) for j in np.unique(ids[over]) if j >= 0 and j != target}
        return sorted(found, key=lambda j: -found[j])

    def _neighbours(self, world, target: int) -> list[int]:
        t = world.object_position(target)[:2]
        others = [int(j) for j in world.active_objects() if j != target]
        return sorted(others, key=lambda j: float(np.linalg.norm(world.object_position(j)[:2] - t)))

    def view(self, world) -> tuple[np.ndarray, np.ndarray]:
        """The oracle's own ray-cast view of ``world``'s current state: the depth heightmap and
        which object each pixel shows (-1: the table; its own caster, so trials never touch
        the env's cameras or generator)."""
        if self._ids_model is not world.model:
            # Start-up time: the caster loads mujoco, which this module does not.
            from mpg_envs.perception.heightmap import RaycastHeightmapper  # noqa: PLC0415

            if self._ids_caster is not None:
                self._ids_caster.close()
            self._ids_caster = RaycastHeightmapper(world.model, world.workspace, num_threads=1)
            self._ids_model = world.model
        hm = self._ids_caster.heightmaps(world.data)
        return hm.depth.astype(np.float32), world.object_of_geom(hm.geom_id)

    def _simulator_view(self, env, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``obs`` with the target's whole footprint and cover flag as ``target_spec="mask"``
        shows them (judged on the oracle's own clean view of the simulator)."""
        mask, occluded = env.sim.target_view(self.view(env.world)[0], env.target)
        return {**obs, "mask": mask, "occluded": np.array([int(occluded)], dtype=np.int8)}
