"""Case sets: the peers' text files (Grasping the Invisible's presets, VPG's test cases with
Efficient Push-Grasping's goals), their faithful loading, run jitter and the shipped
challenge set."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from mpg_envs.scenes.cases import (
    EPG_CASES,
    EPG_SHIFT,
    GTI_PRESETS,
    INDEX_FILE,
    JITTER_DEG,
    JITTER_M,
    Case,
    CaseSet,
    challenge_dir,
    jitter_scene,
    load_cases,
)
from mpg_envs.scenes.scene_io import SceneFileError, objects_outside, read_scene
from mpg_envs.scenes.scene_loading import LOAD_TOLERANCE_DEG, LOAD_TOLERANCE_M, pose_errors
from mpg_envs.scenes.vpg_scenes import GTI_COLOURS
from mpg_envs.grid.workspace import Workspace

from conftest import peers_or_stop


@pytest.fixture(scope="module")
def env():
    import gymnasium as gym

    import mpg_envs  # noqa: F401

    made = gym.make("MPG-Occluded-v0")
    yield made.unwrapped
    made.close()


def gti_file(folder: Path, *lines: str) -> Path:
    path = folder / "preset.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


def rotation(quat: np.ndarray) -> np.ndarray:
    w, x, y, z = quat
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


# ------------------------------------------------------------------------ reading GTI
def test_gti_preset_target_is_the_coloured_line_and_blocks_are_grey(tmp_path):
    # No mesh folder beside it: VPG's meshes map onto the blocks set.
    path = gti_file(tmp_path, "# a comment", "block 4.obj -0.6 0.0 0.026 0 0 0", "", "red 4.obj -0.5 0.1 0.026 0 0 0")
    scene = read_scene(path)
    assert scene.target == 1 and not scene.target_is_first_kept and scene.settle
    assert scene.objects[1].asset.rgba == (1.0, 0.0, 0.0, 1.0)
    assert scene.objects[0].asset.rgba[:3] == pytest.approx(GTI_COLOURS["block"])
    assert scene.objects[1].label == "object 1 (red 4.obj, line 4)"
    # VPG (x, y) -> (-x, -y). Zero angles: the shape frame is VPG's world, ours turned 180
    # degrees about z; the cube's frame is the shape frame with x and z swapped (y flipped):
    # R = Rz(180) [[0, 0, 1], [0, -1, 0], [1, 0, 0]] = [[0, 0, -1], [0, 1, 0], [1, 0, 0]],
    # a turn of -90 degrees about y: q = (cos 45, 0, -sin 45, 0).
    np.testing.assert_allclose(scene.objects[1].position, [0.5, -0.1, 0.026], atol=1e-9)
    np.testing.assert_allclose(scene.objects[1].quat, [math.sqrt(0.5), 0.0, -math.sqrt(0.5), 0.0], atol=1e-9)


def test_gti_pose_is_the_shape_frame_of_vpg_meshes(peers_dir, tmp_path):
    # VPG's long box 3.obj (100 x 50 x 25 mm along the OBJ's x, y, z) with zero angles stands
    # on end: CoppeliaSim's shape frame has the OBJ's x as its z, z as its x.
    path = gti_file(tmp_path, "green 3.obj -0.45 -0.05 0.0505 0 0 0")
    scene = read_scene(path, mesh_dir=peers_dir / "vpg" / "blocks")
    obj = scene.objects[0]
    world = obj.position + obj.asset.vertices @ rotation(obj.quat).T
    np.testing.assert_allclose(world.max(axis=0) - world.min(axis=0), [0.025, 0.05, 0.1], atol=2e-4)
    np.testing.assert_allclose((world.max(axis=0) + world.min(axis=0)) / 2, [0.45, 0.05, 0.0505], atol=1e-6)


def test_gti_object_posed_inside_the_table_is_raised_onto_it_with_a_warning(tmp_path):
    path = gti_file(tmp_path, "blue 4.obj -0.5 0 0.0135 0 0 0")  # a 51 mm cube centred 13.5 mm up
    with pytest.warns(UserWarning, match=r"raised onto the table.*object 0 \(blue 4.obj, line 1\) by 12\.2 mm"):
        scene = read_scene(path)
    obj = scene.objects[0]
    bottom = obj.position[2] + (obj.asset.vertices @ rotation(obj.quat).T)[:, 2].min()
    assert bottom == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize(
    "lines, message",
    [
        (["purple 4.obj -0.5 0 0.026 0 0 0"], r"preset.txt:1: unknown name 'purple'; valid: block, red, orange"),
        (["red 4.obj -0.5 0 0.026 0 0"], r"preset.txt:1: expected Grasping the Invisible's 'name mesh x y z rx ry rz', got 7"),
        (["block 4.obj -0.5 0 0.026 0 0 0"], r"no line names a target colour \(red, orange, .*violet\); exactly one must"),
        (["red 4.obj -0.5 0 0.026 0 0 0", "blue 4.obj -0.6 0 0.026 0 0 0"], r"2 lines \(object 0 \(red 4.obj, line 1\), object 1"),
        (["red 4.obj -0.5 zero 0.026 0 0 0"], r"preset.txt:1: could not convert string to float: 'zero'"),
        (["red 5.obj -0.5 0 0.026 0 0 0"], r"preset.txt:1: unknown mesh '5.obj', not in the blocks set"),
    ],
)
def test_malformed_gti_presets_raise_naming_the_line(tmp_path, lines, message):
    with pytest.raises(SceneFileError, match=message):
        read_scene(gti_file(tmp_path, *lines))


# --------------------------------------------------------------------- faithful loading
def test_every_peer_file_loads_within_tolerance_of_its_poses(peers_dir, env):
    """VPG's test cases and GTI's presets: stacks stand, nothing leaves the table."""
    files = sorted((peers_dir / "vpg" / "test-cases").glob("test-10-obj-*.txt")) + sorted((peers_dir / "gti").glob("*.txt"))
    assert len(files) >= 10 + len(GTI_PRESETS)
    worst = {}
    for path in files:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # VPG's objects beyond the workspace; GTI's blocks inside the table
            scene = read_scene(path)
            env.reset(options={"scene": scene, "drop_outside": True})
        outside = set(objects_outside(scene, env.config.workspace))
        kept = [i for i in range(len(scene.objects)) if i not in outside]
        assert kept and all(env.world.active[kept]), f"{path.name}: an object left the table or the workspace while settling"
        distance, angle = pose_errors(env.world, scene)
        worst[path.stem] = (np.nanmax(distance), np.nanmax(angle))
    bad = {name: (round(1000 * d, 1), round(a, 1)) for name, (d, a) in worst.items() if d > LOAD_TOLERANCE_M or a > LOAD_TOLERANCE_DEG}
    assert not bad, f"objects off their file pose (mm, degrees): {bad}"


def test_epg_cases_load_with_their_goal_as_target(peers_dir, env):
    cases = load_cases("epg", peers_dir)
    assert [c.name for c in cases] == [f"epg-{k:02d}" for k in range(10)]
    for case, (stem, goal) in zip(cases, EPG_CASES):
        vpg = read_scene(peers_dir / "vpg" / "test-cases" / f"{stem}.txt")
        scene = case.scene_file(env.config.workspace)
        assert scene.target == goal and scene.objects[goal].active and scene.objects[goal].asset.name == vpg.objects[goal].asset.name
        moved = np.array([o.position - v.position for o, v in zip(scene.objects, vpg.objects)])
        expected = np.tile([0.0, -EPG_SHIFT, 0.0], (len(moved), 1))
        if case.name == "epg-00":
            expected[1, 1] += 0.02  # its object 1 sits 2 cm nearer VPG's y = 0 than in VPG's file
        np.testing.assert_allclose(moved, expected, atol=1e-12)
        _, info = env.reset(options={"scene": scene})
        assert info["target"] == goal
        distance, angle = pose_errors(env.world, scene)
        assert np.nanmax(distance) <= LOAD_TOLERANCE_M and np.nanmax(angle) <= LOAD_TOLERANCE_DEG, case.name
    # EPG's case 6 is VPG's test-10-obj-07 (it skipped VPG's 06): its goal, object 1, is VPG's 4.obj.
    assert EPG_CASES[6] == ("test-10-obj-07", 1)


def test_gti_set_has_the_twelve_presets(peers_dir):
    cases = load_cases("gti", peers_dir)
    assert [c.name for c in cases] == list(GTI_PRESETS) and len(cases) == 12
    assert load_cases("gti", peers_dir / "gti").cases == cases.cases  # the set's own folder works too


# ------------------------------------------------------------------------------ jitter
def scene_of_cubes(positions: list[tuple[float, float]]):
    from mpg_envs.simulation.objects import blocks_object_set
    from mpg_envs.scenes.scene_io import SceneFile, SceneObject

    cube = next(a for a in blocks_object_set() if a.name == "cube")
    objects = tuple(SceneObject(cube, np.array([x, y, 0.0257]), np.array([1.0, 0.0, 0.0, 0.0]), True, f"object {k}") for k, (x, y) in enumerate(positions))
    return SceneFile(objects, 0, "cubes")


def test_jitter_is_rigid_small_deterministic_and_run_0_is_the_case():
    scene = scene_of_cubes([(0.45, 0.0), (0.55, 0.05), (0.5, -0.1)])
    assert jitter_scene(scene, 0, "a") is scene
    xy = np.array([o.position[:2] for o in scene.objects])
    centre = (xy.min(axis=0) + xy.max(axis=0)) / 2
    turns, shifts = [], []
    for run in range(1, 40):
        moved = jitter_scene(scene, run, "a")
        assert all(np.array_equal(a.position, b.position) for a, b in zip(moved.objects, jitter_scene(scene, run, "a").objects))
        new = np.array([o.position[:2] for o in moved.objects])
        # Rigid: the same distances; the turn is the yaw each quaternion gained.
        assert np.allclose(np.linalg.norm(new[1:] - new[0], axis=1), np.linalg.norm(xy[1:] - xy[0], axis=1), atol=1e-12)
        yaw = math.degrees(2 * math.atan2(moved.objects[0].quat[3], moved.objects[0].quat[0]))
        c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
        shift = new[0] - (centre + np.array([[c, -s], [s, c]]) @ (xy[0] - centre))
        turns.append(yaw)
        shifts.append(shift)
        assert [o.position[2] for o in moved.objects] == [o.position[2] for o in scene.objects]
    assert max(abs(t) for t in turns) <= JITTER_DEG and np.abs(shifts).max() <= JITTER_M + 1e-12
    assert max(abs(t) for t in turns) > JITTER_DEG / 2 and np.abs(shifts).max() > JITTER_M / 2  # it does move
    other = jitter_scene(scene, 1, "b")
    assert not np.array_equal(other.objects[0].position, jitter_scene(scene, 1, "a").objects[0].position)


def test_jitter_never_takes_an_object_out_of_the_workspace():
    ws = Workspace()
    # One centre 1 mm inside the far corner, the scene wide enough that a turn alone moves it 10 mm.
    scene = scene_of_cubes([(ws.x_max - 0.001, ws.y_max - 0.001), (ws.x_min + 0.05, ws.y_min + 0.05)])
    for run in range(1, 60):
        assert objects_outside(jitter_scene(scene, run, "edge", ws), ws) == []
    with pytest.raises(ValueError, match="run must be a non-negative integer"):
        jitter_scene(scene, -1)


def test_jitter_leaves_objects_out_of_the_scene_where_they_are():
    import dataclasses

    scene = scene_of_cubes([(0.5, 0.0), (0.9, 0.0)])
    scene = dataclasses.replace(scene, objects=(scene.objects[0], dataclasses.replace(scene.objects[1], active=False)))
    moved = jitter_scene(scene, 3, "x")
    assert np.array_equal(moved.objects[1].position, scene.objects[1].position)
    assert not np.array_equal(moved.objects[0].position, scene.objects[0].position)


# --------------------------------------------------------------------------- case sets
def test_challenge_set_is_shipped_and_every_case_loads_at_rest(env):
    cases = load_cases("challenge")
    assert len(cases) >= 12 and all(c.note for c in cases)
    index = json.loads((challenge_dir() / INDEX_FILE).read_text())
    assert sorted(p.stem for p in challenge_dir().glob("*.json") if p.name != INDEX_FILE) == sorted(e["name"] for e in index)
    for case in cases:
        scene = case.scene_file(env.config.workspace)
        assert not scene.settle and scene.target is not None and objects_outside(scene, env.config.workspace) == []
        obs, info = env.reset(options={"scene": scene})
        assert info["target"] == scene.target and info["objects_left"] == len(scene.objects), case.name
        assert env.world.objects_at_rest() and obs["mask"].any(), case.name
        distance, _ = pose_errors(env.world, scene)
        assert np.nanmax(distance) == 0.0, case.name  # saved at rest: placed exactly


def test_a_scene_file_or_folder_is_a_case_set(tmp_path):
    folder = challenge_dir()
    one = load_cases(folder / "tower.json")
    assert isinstance(one, CaseSet) and [c.name for c in one] == ["tower"]
    assert {c.name for c in load_cases(folder)} == {c.name for c in load_cases("challenge")}
    with pytest.raises(ValueError, match=r"holds no .json or .txt scene files"):
        load_cases(tmp_path)


@pytest.mark.parametrize(
    "name, peers, message",
    [
        ("nope", None, r"unknown case set 'nope': valid are challenge, epg, gti, or the path of a scene file or a folder"),
        ("epg", None, r"case set 'epg' is read from the peers' files: name the folder"),
        ("gti", "/nonexistent", r"case set 'gti': Grasping the Invisible's presets not found \(looked for exploration-00.txt"),
    ],
)
def test_load_cases_errors_name_what_is_valid(name, peers, message):
    with pytest.raises(ValueError, match=message):
        load_cases(name, peers)


def test_case_target_override_is_checked():
    scene = scene_of_cubes([(0.5, 0.0), (0.6, 0.0)])
    assert Case("c", scene, target=1).scene_file().target == 1
    with pytest.raises(SceneFileError, match=r"case 'c': target 2 is not an object index 0..1"):
        Case("c", scene, target=2).scene_file()


@pytest.mark.slow
def test_the_oracle_solves_every_challenge_case_in_strict_retrieval():
    import gymnasium as gym

    from mpg_envs.policies.oracle import OraclePolicy

    env = gym.make("MPG-Occluded-v0", wrong_grasp="fail")
    oracle = OraclePolicy(env)
    failed = []
    for case in load_cases("challenge"):
        obs, _ = env.reset(seed=0, options={"scene": case.scene_file()})
        oracle.reset()
        done, info = False, {}
        while not done:
            obs, _, terminated, truncated, info = env.step(oracle.act(obs))
            done = terminated or truncated
        if not info["is_success"]:
            failed.append((case.name, info.get("end_reason")))
    env.close()
    assert not failed


def test_the_peers_folder_skips_when_absent_and_fails_under_ci(tmp_path):
    with pytest.raises(pytest.fail.Exception, match="vpg/test-cases, vpg/blocks, gti"):
        peers_or_stop(tmp_path, ci=True)
    with pytest.raises(pytest.skip.Exception, match="MPG_PEERS_DIR"):
        peers_or_stop(tmp_path, ci=False)
