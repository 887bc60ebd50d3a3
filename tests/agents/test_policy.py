"""MPGNetPolicy with SB3: primitives, coordination, learning/saving/loading, safetensors weights."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3 import DQN

from mpg_agents import MPGDQN, MPGNetPolicy, PrioritizedHeightmapReplayBuffer
from mpg_agents.network.regions import region_max, target_region
from mpg_agents.acting.spaces import resolve_primitives
from mpg_envs.grid.actions import PixelActionSpace, decode_action

from .conftest import TINY, calibrate_bn
from .fake_env import FakeMPGEnv, observation_space, random_scene


@pytest.fixture(scope="module")
def make_policy(build_policy):
    """A policy on the fake env's spaces for ``primitives``."""
    return lambda primitives=("move", "push", "grasp"), **kwargs: build_policy(
        observation_space(), PixelActionSpace(primitives), **kwargs
    )


def test_resolve_primitives():
    assert resolve_primitives(PixelActionSpace(("push", "grasp"))) == ("push", "grasp")
    plain = spaces.Discrete(16 * 224 * 224)
    assert resolve_primitives(plain, ("move",)) == ("move",)
    assert resolve_primitives(spaces.Discrete(3 * 16 * 224 * 224)) == ("move", "push", "grasp")
    assert resolve_primitives(spaces.Discrete(2 * 16 * 224 * 224)) == ("push", "grasp")
    with pytest.raises(ValueError, match="pass primitives"):
        resolve_primitives(plain)
    with pytest.raises(ValueError, match=r"Discrete\(802817\) is not P \* 16 \* 224 \* 224 pixel actions"):
        resolve_primitives(spaces.Discrete(16 * 224 * 224 + 1))
    with pytest.raises(ValueError, match="contradicts"):
        resolve_primitives(PixelActionSpace(("grasp",)), ("move",))
    with pytest.raises(ValueError, match="does not match primitives"):
        MPGNetPolicy(observation_space(), spaces.Discrete(16 * 224 * 224), lambda _: 1e-4, primitives=("move", "grasp"))


def test_policy_rejects_bad_configuration(make_policy):
    with pytest.raises(ValueError, match="normalize_images=False"):
        make_policy(normalize_images=True)
    with pytest.raises(ValueError, match="coordination"):
        make_policy(coordination="vote")
    bad_space = observation_space()
    bad_space.spaces["depth"] = spaces.Box(0.0, 0.4, (112, 112), np.float32)
    with pytest.raises(ValueError, match="'depth' has shape"):
        MPGNetPolicy(bad_space, PixelActionSpace(("grasp",)), lambda _: 1e-4)


@pytest.fixture(scope="module")
def stage5_policy(make_policy) -> MPGNetPolicy:
    policy = make_policy()
    obs = {
        k: torch.as_tensor(np.stack([random_scene(np.random.default_rng(i), occluded=False)[k] for i in range(1)]))
        for k in ("color", "depth", "mask")
    }
    calibrate_bn(policy.q_net.mpgnet, obs)
    policy.q_net_target.load_state_dict(policy.q_net.state_dict())
    policy.set_training_mode(False)
    return policy


def test_workflow_coordination(stage5_policy, rng):
    policy = stage5_policy
    occluded = random_scene(rng, occluded=True)
    clear = random_scene(rng, occluded=False)
    try:
        # Occluded -> move, computing only the move branch.
        d = policy.decide(occluded)
        assert d.primitive == "move" and set(d.q_maps) == {"move"}
        # Graspable (any grasp Q >= Q*_g = -inf) -> grasp, push net not run.
        policy.set_q_star(-math.inf)
        d = policy.decide(clear)
        assert d.primitive == "grasp" and set(d.q_maps) == {"grasp"}
        assert d.grasp_score == pytest.approx(policy.discriminator()(clear), abs=1e-5)
        # Not graspable -> push.
        policy.set_q_star(math.inf)
        d = policy.decide(clear)
        assert d.primitive == "push" and set(d.q_maps) == {"grasp", "push"}
        # No Q*_g (None): the larger of the best grasp Q and the best push Q.
        policy.set_q_star(None)
        d = policy.decide(clear)
        best = {
            "grasp": float(region_max(d.q_maps["grasp"][None], _region(clear))[0]),
            "push": float(d.q_maps["push"].max()),
        }
        assert d.primitive == max(best, key=best.get)
        assert d.q_value == pytest.approx(max(best.values()), abs=1e-5)
        # The chosen move/grasp pixel lies in the target's bounding rectangle.
        policy.set_q_star(-math.inf)
        a = decode_action(("move", "push", "grasp"), policy.predict(clear, deterministic=True)[0])
        rows, cols = np.nonzero(clear["mask"])
        assert a.primitive == "grasp" and rows.min() <= a.row <= rows.max() and cols.min() <= a.col <= cols.max()
    finally:
        policy.set_q_star(None)


def _region(scene):
    return target_region(torch.as_tensor(scene["mask"])[None])


def test_max_q_coordination(stage5_policy, rng):
    policy = stage5_policy
    scene = random_scene(rng, occluded=True)
    policy.set_coordination("max_q")
    try:
        action, _ = policy.predict(scene, deterministic=True)
        obs, _ = policy.obs_to_tensor(scene)
        with torch.inference_mode():
            expected = int(policy.q_net.greedy_actions(obs)[0])
        assert int(action) == expected
        assert set(policy.decide(scene).q_maps) == {"move", "push", "grasp"}
    finally:
        policy.set_coordination("workflow")


def test_predict_batches_and_rejects_bad_shapes(stage5_policy, rng):
    scenes = [random_scene(rng) for _ in range(2)]
    batch = {k: np.stack([s[k] for s in scenes]) for k in scenes[0]}
    actions, _ = stage5_policy.predict(batch, deterministic=True)
    assert actions.shape == (2,)
    for i, s in enumerate(scenes):
        assert stage5_policy.predict(s, deterministic=True)[0] == actions[i]
    with pytest.raises(ValueError, match="observation shape"):
        stage5_policy.predict(dict(scenes[0], depth=scenes[0]["depth"][:100]), deterministic=True)


def test_safetensors_weights_roundtrip_and_mismatch(tmp_path, stage5_policy, rng, make_policy):
    path = tmp_path / "stage5.safetensors"
    stage5_policy.set_q_star(1.85)
    try:
        stage5_policy.save_weights(path)
    finally:
        stage5_policy.set_q_star(None)
    other = make_policy()
    header = other.load_weights(path)
    assert other.q_star == 1.85 and header["primitives"] == ["move", "push", "grasp"]
    scene = random_scene(rng, occluded=False)
    other.set_training_mode(False)
    obs, _ = other.obs_to_tensor(scene)
    with torch.inference_mode():
        assert torch.equal(other.q_net(obs), stage5_policy.q_net(obs))  # same weights and BN statistics
    other.set_q_star(None)
    assert other.predict(scene, deterministic=True)[0] == stage5_policy.predict(scene, deterministic=True)[0]
    other.set_q_star(1.85)
    for a, b in zip(other.q_net_target.parameters(), other.q_net.parameters(), strict=True):
        assert torch.equal(a, b)
    # from_weights rebuilds from the header.
    rebuilt = MPGNetPolicy.from_weights(path, observation_space(), PixelActionSpace(("grasp",)))
    assert rebuilt.q_star == 1.85 and rebuilt.variant == "small"
    # Another architecture: clear error.
    large = MPGNetPolicy(observation_space(), PixelActionSpace(("grasp",)), lambda _: 1e-4, variant="large")
    with pytest.raises(ValueError, match="variant='small' but this network has variant='large'"):
        large.load_weights(path)


class _Exploit:
    def __reduce__(self):
        return (Path.touch, (Path("/tmp/mpg_agents_unpickled_marker"),))


def test_loading_weights_never_unpickles(tmp_path, stage5_policy):
    import pickle

    marker = Path("/tmp/mpg_agents_unpickled_marker")
    marker.unlink(missing_ok=True)
    evil = tmp_path / "weights.safetensors"
    evil.write_bytes(pickle.dumps(_Exploit()))
    with pytest.raises(ValueError, match="not a safetensors file"):
        stage5_policy.load_weights(evil)
    assert not marker.exists()


@pytest.mark.parametrize("algo", ["MPGDQN", "DQN"])
def test_dqn_learns_saves_loads_predicts(tmp_path, algo):
    env = FakeMPGEnv(("grasp",), horizon=3)
    # Exploration 1.0: collection takes random actions, so the time goes into the 50 learning
    # steps (greedy collection is covered by the predict checks below).
    common = dict(
        buffer_size=200,
        batch_size=1,
        train_freq=1,
        gradient_steps=1,
        seed=0,
        exploration_initial_eps=1.0,
        exploration_final_eps=1.0,
        policy_kwargs=dict(TINY),
    )
    if algo == "MPGDQN":
        # 50 learning steps on the prioritised compact buffer.
        model = MPGDQN(MPGNetPolicy, env, learning_starts=5, **common)
        steps = 55
    else:
        # Plain SB3 DQN (uniform DictReplayBuffer, full flat Q): a shorter run proves compatibility.
        model = DQN(MPGNetPolicy, env, learning_starts=5, **common)
        steps = 10
    before = [p.detach().clone() for p in model.q_net.parameters()]
    model.learn(total_timesteps=steps)
    assert model._n_updates == steps - 5
    assert any(not torch.equal(a, b) for a, b in zip(before, model.q_net.parameters(), strict=True))
    if algo == "MPGDQN":
        buffer = model.replay_buffer
        assert isinstance(buffer, PrioritizedHeightmapReplayBuffer)
        stored = buffer.priorities[: buffer.size()].reshape(-1)
        assert len(np.unique(stored)) > 10  # priorities were updated from the TD errors
    model.policy.set_q_star(0.75)
    path = tmp_path / "model.zip"
    model.save(path)
    loaded = type(model).load(path, env=env)
    assert loaded.policy.q_star == 0.75
    rng = np.random.default_rng(5)
    for _ in range(3):
        obs = random_scene(rng)
        a1, _ = model.predict(obs, deterministic=True)
        a2, _ = loaded.predict(obs, deterministic=True)
        assert a1 == a2


def test_imagenet_initialisation_reaches_every_trunk(tmp_path, make_policy):
    from mpg_agents.network.mobilenet import MobileNetV3Features

    torch.manual_seed(1)
    reference = MobileNetV3Features("small")
    for p in reference.parameters():
        torch.nn.init.normal_(p)
    state = {**reference.state_dict(), "classifier.0.weight": torch.zeros(1024, 576)}
    path = tmp_path / "mobilenet_v3_small.pth"
    torch.save(state, path)
    policy = make_policy(("push", "grasp"), imagenet_weights=str(path))
    stem = state["features.0.0.weight"]
    net = policy.q_net.mpgnet
    assert torch.equal(net.branches["push"].color_trunk.state_dict()["features.0.0.weight"], stem)
    assert torch.allclose(net.mask_trunk.state_dict()["features.0.0.weight"], stem.sum(1, keepdim=True))
    # The deepest convolution the (possibly cut) trunk keeps.
    last = [k for k in net.mask_trunk.state_dict() if k.endswith("weight") and k.startswith("features.")][-1]
    for trunk in (net.branches["grasp"].depth_trunk, policy.q_net_target.mpgnet.branches["grasp"].color_trunk):
        assert torch.equal(trunk.state_dict()[last], state[last])


def test_grasp_fingers_clear_keeps_grasps_where_the_fingers_land(make_policy):
    from mpg_agents.network.regions import least_blocked, target_pixels
    from mpg_envs.grid.grasp_geometry import fingers_blocked

    rng = np.random.default_rng(5)
    scene = random_scene(rng, occluded=False)
    depth = np.zeros((224, 224), np.float32)
    mask = np.zeros((224, 224), np.uint8)
    depth[100:130, 100:120] = 0.03
    mask[100:130, 100:120] = 1  # the target, 6 cm x 4 cm
    depth[95:135, 132:140] = 0.08  # a tall wall 2.4-4 cm to its right (+x)
    scene = dict(scene, depth=depth, mask=mask)
    clear = make_policy(net_config={**TINY["net_config"], "grasp_fingers": "clear", "grasp_region": "target"})
    calibrate_bn(clear.q_net.mpgnet, scene)
    clear.set_training_mode(False)
    blocked = torch.from_numpy(fingers_blocked(depth, 0.002, 0.04, 0.02))[None]
    on_target = target_pixels(torch.as_tensor(mask)[None], 2)
    expected = least_blocked(blocked, on_target, 0.005)[0] & on_target[0][None]
    assert expected.any() and (on_target[0][None] & ~expected).any(), "the wall must bar some grasps and not all"
    obs, _ = clear.obs_to_tensor(scene)
    with torch.inference_mode():
        enc = clear.q_net.mpgnet.encode(obs)
        assert torch.equal(clear.q_net.mpgnet.actable(enc, "grasp")[0], expected)
        assert torch.equal(clear.q_net.mpgnet.actable(enc, "move")[0, 0], enc.region[0])  # move keeps its region
    decision = clear.decide(scene, "grasp")
    assert expected[decision.rotation, decision.row, decision.col]
    assert decision.grasp_score == pytest.approx(decision.q_value)  # the score ranges over the same grasps
    # The greedy action of the flat Q (the TD target's argmax) obeys the mask as well.
    grasp_only = make_policy(("grasp",), net_config={**TINY["net_config"], "grasp_fingers": "clear", "grasp_region": "target"})
    grasp_only.q_net.load_state_dict({k: v for k, v in clear.q_net.state_dict().items() if "branches.move" not in k and "branches.push" not in k})
    grasp_only.set_training_mode(False)
    with torch.inference_mode():
        flat = int(grasp_only.q_net.greedy_actions(grasp_only.obs_to_tensor(scene)[0])[0])
    _, rot, row, col = decode_action(("grasp",), flat)
    assert expected[rot, row, col]
    with pytest.raises(ValueError, match="grasp_fingers"):
        make_policy(net_config={**TINY["net_config"], "grasp_fingers": "free"})


def test_move_fingers_clear_keeps_moves_where_the_fingers_land(make_policy):
    from mpg_agents.network.regions import least_blocked, target_region
    from mpg_envs.grid.grasp_geometry import fingers_blocked

    scene = random_scene(np.random.default_rng(6), occluded=True)
    depth = np.zeros((224, 224), np.float32)
    mask = np.zeros((224, 224), np.uint8)
    depth[100:130, 100:120] = 0.03
    mask[100:130, 100:120] = 1  # the target, 6 cm x 4 cm
    depth[110:120, 90:130] = 0.06  # an occluder lying across it
    depth[95:135, 132:140] = 0.10  # a tall wall to its right
    scene = dict(scene, depth=depth, mask=mask)
    policy = make_policy(net_config={**TINY["net_config"], "move_fingers": "clear"})
    calibrate_bn(policy.q_net.mpgnet, scene)
    policy.set_training_mode(False)
    blocked = torch.from_numpy(fingers_blocked(depth, 0.002, 0.04, 0.02))[None]
    region = target_region(torch.as_tensor(mask)[None])
    expected = least_blocked(blocked, region, 0.005)[0] & region[0][None]
    assert expected.any() and (region[0][None] & ~expected).any(), "some moves must be barred and not all"
    obs, _ = policy.obs_to_tensor(scene)
    with torch.inference_mode():
        enc = policy.q_net.mpgnet.encode(obs)
        assert torch.equal(policy.q_net.mpgnet.actable(enc, "move")[0], expected)
        assert torch.equal(policy.q_net.mpgnet.actable(enc, "grasp")[0, 0], enc.region_of("grasp")[0])  # grasp keeps its region
    decision = policy.decide(scene, "move")
    assert expected[decision.rotation, decision.row, decision.col]
    with pytest.raises(ValueError, match="move_fingers"):
        make_policy(net_config={**TINY["net_config"], "move_fingers": "free"})
