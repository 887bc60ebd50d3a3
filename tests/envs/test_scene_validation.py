"""Scene files are checked on load: finite poses, unit quaternions, inside the workspace and not
above it, no interpenetration, a count the simulator holds, well-formed colours and positions,
and the mesh files they name unchanged since they were saved."""

import json
import warnings

import numpy as np
import pytest

from mpg_envs.scenes.scene_io import (
    MAX_OBJECTS, PENETRATION_TOLERANCE_M, SceneFile, SceneFileError, SceneObject, read_scene, save_scene,
)
from mpg_envs.scenes.scene_loading import load_scene, interpenetrations
from mpg_envs.grid.workspace import Workspace
from mpg_envs.simulation.world import World


@pytest.fixture(scope="module")
def scene_doc(tmp_path_factory):
    """A Stage II scene saved from the env (its JSON document) and the env to load edits with."""
    import gymnasium as gym

    import mpg_envs  # noqa: F401

    env = gym.make("MPG-Stage2-v0").unwrapped
    env.reset(seed=3)
    path = save_scene(env, tmp_path_factory.mktemp("scene") / "scene.json")
    yield json.loads(path.read_text()), env
    env.close()


def edited(doc, tmp_path, edit):
    doc = json.loads(json.dumps(doc))
    edit(doc)
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(doc))
    return str(path)


def load(env, path):
    return env.reset(options={"scene": path})


def set_obj(k, key, value):
    def edit(doc):
        doc["objects"][k][key] = value
    return edit


def test_the_saved_scene_loads_unchanged(scene_doc, tmp_path):
    doc, env = scene_doc
    _, info = load(env, edited(doc, tmp_path, lambda d: None))
    assert info["objects_left"] == len(doc["objects"])


@pytest.mark.parametrize("quat, message", [
    ([float("nan"), 0, 0, 1], r"object 1 \('\w+'\) is malformed: quat is \[nan, 0, 0, 1\]; valid: four numbers \[w, x, y, z\]"),
    ([0, 0, 0, 0], r"object 1 \('\w+'\) has orientation \[0\.0, 0\.0, 0\.0, 0\.0\] \(norm 0\); valid: a unit quaternion"),
    ([2, 0, 0, 0], r"object 1 \('\w+'\) has orientation \[2\.0, 0\.0, 0\.0, 0\.0\] \(norm 2\); valid: a unit quaternion \[w, x, y, z\], norm within 0\.001 of 1"),
])
def test_a_bad_quaternion_is_named(scene_doc, tmp_path, quat, message):
    doc, env = scene_doc
    with pytest.raises(SceneFileError, match=message):
        load(env, edited(doc, tmp_path, set_obj(1, "quat", quat)))


@pytest.mark.parametrize("key, value, message", [
    ("position", [0.5, 0.0], r"object 0 \('\w+'\) is malformed: position is \[0\.5, 0\.0\]; valid: three numbers \[x, y, z\] \(m\)"),
    ("position", [float("nan"), 0.0, 0.05], r"position is \[nan, 0\.0, 0\.05\]; valid: three numbers"),
    ("rgba", "red", r"object 0 \('\w+'\) is malformed: rgba is 'red'; valid: four numbers in \[0, 1\] \[red, green, blue, alpha\]"),
    ("rgba", [255, 0, 0, 1], r"rgba is \[255, 0, 0, 1\]; valid: four numbers in \[0, 1\]"),
    ("active", "no", r"object 0 \('\w+'\) is malformed: active is 'no'; valid: true or false"),
])
def test_a_malformed_object_is_named(scene_doc, tmp_path, key, value, message):
    doc, env = scene_doc
    with pytest.raises(SceneFileError, match=message):
        load(env, edited(doc, tmp_path, set_obj(0, key, value)))


def test_an_object_above_the_workspace_is_outside(scene_doc, tmp_path):
    doc, env = scene_doc

    def high(d):
        d["objects"][2]["position"][2] = 10.0

    with pytest.raises(SceneFileError, match=r"outside the workspace \(.*z in \[-0\.02, 0\.4\].*object 2 \('\w+'\) at \(.*, 10\.000\)"):
        load(env, edited(doc, tmp_path, high))


def test_interpenetrating_objects_are_named_with_the_depth(scene_doc, tmp_path):
    doc, env = scene_doc

    def overlap(shift):
        def edit(d):
            d["objects"][1]["position"] = list(np.add(d["objects"][0]["position"], (shift, 0.0, 0.0)))
            d["objects"][1]["quat"] = list(d["objects"][0]["quat"])
        return edit

    for shift in (0.0, 0.005):  # on each other (MuJoCo then finds no contact), or 5 mm apart
        with pytest.raises(SceneFileError, match=r"objects interpenetrate: object 0 \('\w+'\) and object 1 \('\w+'\) by \d+\.\d mm; at most 5 mm is valid"):
            load(env, edited(doc, tmp_path, overlap(shift)))


def test_an_object_sunk_into_the_table_is_named_with_the_depth(scene_doc, tmp_path):
    doc, env = scene_doc

    def sink(d):
        d["objects"][2]["position"][2] -= 0.034

    with pytest.raises(SceneFileError, match=r"'.*edited\.json': objects sunk into the table \(its top is z = 0\): object 2 \('\w+'\) "
                                             r"by 3[34]\.\d mm; at most 5 mm is valid$"):
        load(env, edited(doc, tmp_path, sink))


def test_sunk_into_table_measures_the_depth(blocks):
    """A 'cube' block whose centre is 1 cm lower than its half height lies 1 cm in the table."""
    from mpg_envs.scenes.scene_loading import sunk_into_table

    cube = blocks["cube"] if "cube" in blocks else next(iter(blocks.values()))
    half = -float(np.concatenate([v for v, _ in cube.parts])[:, 2].min())
    world = World([cube, cube], robot_visual=False)
    world.set_object_pose(0, (0.5, 0.0, half - 0.01), (1, 0, 0, 0))
    world.set_object_pose(1, (0.6, 0.0, half), (1, 0, 0, 0))  # resting on the table
    world.forward()
    ((i, depth),) = sunk_into_table(world, PENETRATION_TOLERANCE_M)
    assert i == 0 and depth == pytest.approx(0.01, abs=1e-6)
    assert sunk_into_table(world, 0.011) == []


def set_doc(key, value):
    def edit(doc):
        doc[key] = value
    return edit


@pytest.mark.parametrize("edit, message", [
    (set_doc("target", True), r"target is true; valid: an object index 0\.\.\d+ \(an integer\), or null for no target"),
    (set_obj(0, "name", ["cube"]), r"object 0 \(\['cube'\]\) is malformed: name is \['cube'\]; valid: a string"),
    (set_obj(0, "source", 5), r"object 0 \('\w+'\) is malformed: source is 5; valid: a string"),
    (set_doc("object_set_seed", "abc"), r"object_set_seed is \"abc\"; valid: a non-negative integer"),
    (set_doc("object_set_seed", [1]), r"object_set_seed is \[1\]; valid: a non-negative integer"),
    (set_doc("object_set_seed", None), r"object_set_seed is null; valid: a non-negative integer"),
    (set_doc("object_set_seed", 1.7), r"object_set_seed is 1\.7; valid: a non-negative integer"),
    (set_doc("stage", 2), r"stage is 2; valid: a stage name \(a string\) or null"),
])
def test_a_field_of_the_wrong_type_is_named_with_the_valid_type(scene_doc, tmp_path, edit, message):
    doc, env = scene_doc
    with pytest.raises(SceneFileError, match=r"^scene file '.*edited\.json': " + message + "$"):
        load(env, edited(doc, tmp_path, edit))


@pytest.mark.parametrize("name, valid", [
    ("binary.txt", "a VPG test case or Grasping the Invisible preset, one object per line"),
    ("binary.json", "an mpg-scene JSON file"),
])
def test_a_binary_scene_file_is_named(scene_doc, tmp_path, name, valid):
    _, env = scene_doc
    path = tmp_path / name
    path.write_bytes(bytes(range(256)))
    with pytest.raises(SceneFileError, match=rf"^scene file '.*{name}' is not text \(byte 128 is not UTF-8\); valid: {valid}$"):
        load(env, str(path))


@pytest.mark.parametrize("options, message", [
    ({"scene": 123}, r"reset option 'scene' is 123; valid: a scene file's path \(str or Path\) or a SceneFile, or None"),
    ({"mesh_dir": 5}, r"reset option 'mesh_dir' is 5; valid: a folder's path \(str or Path\), or None"),
    ({"drop_outside": "no"}, r"reset option 'drop_outside' is 'no'; valid: True or False, or None"),
    ("scene.json", r"reset options are 'scene\.json'; valid: a dict with keys \['drop_outside', 'mesh_dir', 'num_objects', 'scene'\], or None"),
])
def test_a_reset_option_of_the_wrong_type_is_named(scene_doc, options, message):
    _, env = scene_doc
    with pytest.raises(ValueError, match=message):
        env.reset(options=options)
    with pytest.raises(SceneFileError, match=r"scene file 123 is not a path; valid: a \.json or \.txt scene file's path"):
        read_scene(123)


def test_too_many_objects_are_refused(scene_doc, tmp_path):
    doc, env = scene_doc

    def many(d):
        d["objects"] = [d["objects"][0]] * (MAX_OBJECTS + 1)

    with pytest.raises(SceneFileError, match=rf"lists {MAX_OBJECTS + 1} objects; valid: a list of at most {MAX_OBJECTS} objects"):
        load(env, edited(doc, tmp_path, many))


def test_a_scene_file_object_is_checked_too(blocks):
    """A :class:`SceneFile` made in code goes through the same checks as a file."""
    cube = next(iter(blocks.values()))
    bad = SceneFile((SceneObject(cube, np.array([0.5, 0.0, 0.05]), np.zeros(4), label="object 0 ('x')"),), 0, "made")
    with pytest.raises(SceneFileError, match=r"'made': object 0 \('x'\) has orientation .*valid: a unit quaternion"):
        load_scene(lambda assets: World(assets, robot_visual=False), bad, Workspace(), drop_outside=False)
    many = SceneFile(tuple(SceneObject(cube, np.array([0.5, 0.0, 0.05]), np.array([1.0, 0, 0, 0])) for _ in range(MAX_OBJECTS + 1)), 0, "many")
    with pytest.raises(SceneFileError, match=rf"'many' has {MAX_OBJECTS + 1} objects; a scene holds at most {MAX_OBJECTS}"):
        load_scene(lambda assets: World(assets, robot_visual=False), many, Workspace(), drop_outside=False)


def test_interpenetrations_measures_the_overlap(blocks):
    """Two 'cube' blocks 1 cm apart along x overlap by their width less 1 cm."""
    cube = blocks["cube"] if "cube" in blocks else next(iter(blocks.values()))
    world = World([cube, cube], robot_visual=False)
    world.set_object_pose(0, (0.5, 0.0, 0.05), (1, 0, 0, 0))
    world.set_object_pose(1, (0.51, 0.0, 0.05), (1, 0, 0, 0))
    world.forward()
    (a, b, depth), *_ = interpenetrations(world, PENETRATION_TOLERANCE_M)
    width = np.ptp(np.concatenate([v for v, _ in cube.parts])[:, 0])
    assert (a, b) == (0, 1) and depth == pytest.approx(width - 0.01, abs=1e-3)
    world.set_object_pose(1, (0.5 + width + 0.01, 0.0, 0.05), (1, 0, 0, 0))
    world.forward()
    assert interpenetrations(world, 0.0) == []


# ------------------------------------------------------------------------------ mesh digests
def _box_folder(tmp_path, size=(0.04, 0.03, 0.02)):
    folder = tmp_path / "meshes"
    folder.mkdir(exist_ok=True)
    corners = [(x, y, z) for x in (0, size[0]) for y in (0, size[1]) for z in (0, size[2])]
    faces = [(1, 3, 4), (1, 4, 2), (5, 6, 8), (5, 8, 7), (1, 2, 6), (1, 6, 5),
             (3, 7, 8), (3, 8, 4), (1, 5, 7), (1, 7, 3), (2, 4, 8), (2, 8, 6)]  # fmt: skip
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in corners) + "".join(f"f {a} {b} {c}\n" for a, b, c in faces)
    (folder / "box.obj").write_text(text)
    return folder


def test_a_changed_mesh_under_a_saved_scene_is_named(tmp_path, monkeypatch):
    from mpg_envs.simulation.objects import load_mesh_folder

    monkeypatch.setenv("MPG_CACHE_DIR", str(tmp_path / "cache"))
    folder = _box_folder(tmp_path)
    (box,) = load_mesh_folder(folder)
    scene = SceneFile((SceneObject(box, np.array([0.5, 0.0, 0.01]), np.array([1.0, 0, 0, 0])),), 0)
    path = save_scene(scene, tmp_path / "box.json")
    doc = json.loads(path.read_text())
    assert len(doc["objects"][0]["sha256"]) == 64
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_scene(path).objects[0].asset.name == "box"

    _box_folder(tmp_path, size=(0.05, 0.03, 0.02))  # the mesh is replaced by a longer box
    with pytest.raises(SceneFileError, match=r"object 0 \('box'\)'s mesh '.*box\.obj' changed since the scene was saved \(sha256 .*"
                                             r"restore the mesh, or read_scene\(\.\.\., allow_changed_meshes=True\)"):
        read_scene(path)
    with pytest.warns(UserWarning, match=r"changed since the scene was saved .*loading the mesh as it is now"):
        read_scene(path, allow_changed_meshes=True)

    del doc["objects"][0]["sha256"]  # a file written before digests were recorded
    path.write_text(json.dumps(doc))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_scene(path).objects[0].asset.name == "box"
