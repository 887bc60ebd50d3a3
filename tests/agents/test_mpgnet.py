"""MPGNet: shapes, rotation bookkeeping, rough mask, gradient isolation, bad input."""

from __future__ import annotations


import numpy as np
import pytest
import torch

from mpg_agents.network.mpgnet import MPGNet
from mpg_agents.network.primitive_net import PLANES, QHead
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_agents.sb3 import MPGQNetwork
from mpg_envs.grid.actions import PixelActionSpace, encode_action

from .fake_env import observation_space, random_scene

ENV_PRIMITIVES = {
    "Stage1/Stage2": ("grasp",),
    "Stage3": ("move",),
    "Stage4": ("push", "grasp"),
    "Stage5/Occluded": ("move", "push", "grasp"),
}


def test_config_padding_and_dict_roundtrip():
    cfg = MPGNetConfig.small()
    assert cfg.padded_size == 320  # ceil(224 * sqrt 2) = 317 -> 320
    assert MPGNetConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError, match="unknown MPGNetConfig keys"):
        MPGNetConfig.from_dict({"varient": "small"})
    with pytest.raises(ValueError, match="primitives"):
        MPGNetConfig(primitives=("grasp", "push"))


@pytest.mark.parametrize("stage, primitives", list(ENV_PRIMITIVES.items()))
def test_output_shapes_for_every_env(stage, primitives, scene):
    torch.manual_seed(0)
    net = MPGNet(MPGNetConfig.small(primitives=primitives)).eval()
    assert tuple(net.branches) == primitives
    with torch.inference_mode():
        maps = net(scene)
    assert set(maps) == set(primitives)
    for q in maps.values():
        assert q.shape == (1, 16, 224, 224)
        assert torch.isfinite(q).all()
    # The SB3 Q-network flattens them in the env's action order.
    qnet = MPGQNetwork(observation_space(), PixelActionSpace(primitives), net.config, primitives)
    qnet.mpgnet.load_state_dict(net.state_dict())
    qnet.eval()
    with torch.inference_mode():
        flat = qnet({k: torch.as_tensor(v)[None] for k, v in scene.items()})
    assert flat.shape == (1, len(primitives) * 16 * 224 * 224)
    p, k, r, c = primitives[-1], 5, 100, 37
    assert torch.allclose(flat[0, encode_action(primitives, p, k, r, c)], maps[p][0, k, r, c], atol=1e-5)


def test_all_rotation_encoding_equals_one_rotation_at_a_time(small_net, rng):
    """The 16-rotation batch resamples a quarter of the rotations and turns them by exact 90
    degrees: every rotated plane and every mask feature equals the one-rotation path's."""
    batch = [random_scene(rng, occluded=False) for _ in range(2)]
    obs = {k: np.stack([b[k] for b in batch]) for k in batch[0]}
    with torch.inference_mode():
        prepared = small_net.prepare(obs)
        full = small_net.encode(prepared)
        assert full.planes.shape == (32, 5, 320, 320)
        assert full.rotations.tolist() == list(range(16)) * 2
        for b in range(2):
            single = small_net.prepare({key: v[b : b + 1] for key, v in obs.items()})
            for k in range(16):
                one = small_net.encode(single, rotations=torch.tensor([k]))
                torch.testing.assert_close(full.planes[16 * b + k], one.planes[0], rtol=0, atol=1e-6)
                torch.testing.assert_close(full.mask_features[16 * b + k], one.mask_features[0], rtol=1e-4, atol=1e-5)


def test_checkpoint_architecture_loads_with_this_machines_execution_settings():
    """channels_last and trunk_batch say how to run, not what to compute: a file's values of
    them do not override the variant's defaults; its architecture fields do."""
    saved = MPGNetConfig.small(trunk_batch=None, channels_last=False, head_channels=32).to_dict()
    cfg = MPGNetConfig.from_checkpoint(saved)
    assert (cfg.trunk_batch, cfg.channels_last) == (MPGNetConfig.small().trunk_batch, True)
    assert (cfg.variant, cfg.head_channels, cfg.trunk_depth) == ("small", 32, MPGNetConfig.small().trunk_depth)
    assert MPGNetConfig.from_checkpoint(saved, trunk_batch=2).trunk_batch == 2
    with pytest.raises(ValueError, match="variant"):
        MPGNetConfig.from_checkpoint({"head_channels": 32})


def test_rotating_the_scene_by_90_degrees_shifts_rotations_by_4(small_net, scene):
    """np.rot90 turns content by -90 degrees (from +x toward -y), so Q_k(rotated scene) equals
    np.rot90 of Q_{k+4}(scene): a +90-degree action in the scene is a 0-degree one after."""
    rotated = {k: np.ascontiguousarray(np.rot90(v, 1, axes=(0, 1))) if v.ndim >= 2 else v for k, v in scene.items()}
    with torch.inference_mode():
        q = {p: m[0].numpy() for p, m in small_net(scene).items()}
        qr = {p: m[0].numpy() for p, m in small_net(rotated).items()}
    for p in q:
        spread = q[p].max() - q[p].min()
        assert spread > 1e-3, "Q maps are flat; the test would be vacuous"
        for k in range(16):
            expected = np.rot90(q[p][(k + 4) % 16], 1)
            assert np.abs(qr[p][k] - expected)[16:-16, 16:-16].max() < 1e-4 * max(1.0, spread), (p, k)
    # Not a symmetry of the maps themselves: k and k+4 differ in the unrotated frame.
    assert np.abs(q["push"][0] - q["push"][4]).max() > 1e-4


def test_rough_mask_zeroes_move_and_grasp_outside_rectangle(small_net, scene):
    rows, cols = np.nonzero(scene["mask"])
    inside = np.zeros((224, 224), bool)
    inside[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1] = True
    with torch.inference_mode():
        maps = small_net(scene)
    for p in ("move", "grasp"):
        q = maps[p][0].numpy()
        assert np.all(q[:, ~inside] == 0)
        assert np.count_nonzero(q[:, inside]) > 0.9 * q[:, inside].size
    assert np.count_nonzero(maps["push"][0].numpy()[:, ~inside]) > 0  # push is not restricted
    # Empty mask: nothing to localise, Q is left unrestricted.
    empty = dict(scene, mask=np.zeros_like(scene["mask"]))
    with torch.inference_mode():
        q = small_net(empty, ("grasp",))["grasp"][0].numpy()
    assert np.count_nonzero(q) > 0.99 * q.size


def test_loss_on_one_pixel_reaches_only_its_rotation(small_net, scene):
    """Full 16-rotation pass (eval BN): the gradient of Q[k, r, c] flows through rotation k only."""
    k, r, c = 5, 90, 120
    enc = small_net.encode(scene)
    enc.planes.requires_grad_(True)
    head_out = {}
    branch = small_net.branches["push"]

    def keep(module, inputs, output):
        output.retain_grad()
        head_out["q"] = output

    handle = branch.head.register_forward_hook(keep)
    try:
        q = small_net.maps_from(enc, ("push",))["push"]
        q[0, k, r, c].backward()
    finally:
        handle.remove()
    coarse_grad = head_out["q"].grad  # (16, 1, h, w) gradient at the head's output
    per_rotation = coarse_grad.abs().flatten(1).sum(1)
    assert per_rotation[k] > 0
    assert torch.all(per_rotation[torch.arange(16) != k] == 0)
    for name, channel in PLANES.items():
        if name == "mask":
            continue  # the mask trunk's features are shared; only colour and depth feed one branch
        g = enc.planes.grad[:, channel].abs().flatten(1).sum(1)
        assert g[k] > 0 and torch.all(g[torch.arange(16) != k] == 0), name


def test_training_path_matches_full_pass_and_isolates_the_chosen_rotation(small_net, rng):
    """chosen_q runs only the chosen rotation per sample; in eval mode it equals the full maps."""
    primitives = ("move", "push", "grasp")
    batch = [random_scene(rng, occluded=False) for _ in range(3)]
    obs = {k: np.stack([b[k] for b in batch]) for k in batch[0]}
    prim = torch.tensor([1, 2, 0])
    rot = torch.tensor([3, 12, 7])
    with torch.inference_mode():
        full = small_net(obs)
        chosen = small_net.chosen_q(obs, primitives, prim, rot)
    for i in range(3):
        expected = full[primitives[int(prim[i])]][i, int(rot[i])]
        assert torch.allclose(chosen[i], expected, rtol=1e-4, atol=1e-4)
    # Train mode: each sample's loss has gradients only from its own branch.
    small_net.train()
    try:
        small_net.zero_grad()
        q = small_net.chosen_q(obs, primitives, torch.tensor([2, 2, 2]), rot)
        inside = [np.argwhere(b["mask"])[0] for b in batch]  # grasp Q is 0 outside the target box
        q[torch.arange(3), [int(p[0]) for p in inside], [int(p[1]) for p in inside]].sum().backward()
        grads = {
            p: sum(float(w.grad.abs().sum()) for w in b.parameters() if w.grad is not None)
            for p, b in small_net.branches.items()
        }
        assert grads["grasp"] > 0 and grads["move"] == 0 and grads["push"] == 0
    finally:
        small_net.zero_grad()
        small_net.eval()


@pytest.mark.parametrize("dilation", [0, 1, 3])
def test_head_dilation_reads_exactly_the_cells_that_far_away(dilation):
    """A head with dilation d: the Q of one cell depends on the features of the cells 0 and
    +-d rows/columns away (a 3 x 3 grid), and on no other; d = 0 is the paper's 1 x 1 head."""
    torch.manual_seed(0)
    head = QHead(6, 8, dilation).eval()
    features = torch.randn(1, 6, 15, 15, requires_grad=True)
    head(features)[0, 0, 7, 7].backward()
    reached = features.grad[0].abs().sum(0) > 0
    expected = torch.zeros(15, 15, dtype=torch.bool)
    offsets = sorted({-dilation, 0, dilation})
    for dr in offsets:
        for dc in offsets:
            expected[7 + dr, 7 + dc] = True
    assert torch.equal(reached, expected)
    assert head(features).shape == (1, 1, 15, 15)  # padding keeps the size


def test_head_dilation_setting_builds_the_wider_head_and_is_checked(scene):
    torch.manual_seed(0)
    net = MPGNet(MPGNetConfig.small(head_dilation=3)).eval()
    first = net.branches["grasp"].head[2]
    assert (first.kernel_size, first.dilation, first.padding) == ((3, 3), (3, 3), (3, 3))
    with torch.inference_mode():
        maps = net(scene)
    assert all(q.shape == (1, 16, 224, 224) and torch.isfinite(q).all() for q in maps.values())
    cfg = MPGNetConfig.from_checkpoint(MPGNetConfig.small(head_dilation=3).to_dict())
    assert cfg.head_dilation == 3
    assert MPGNetConfig.from_checkpoint({"variant": "small"}).head_dilation == 0  # older checkpoints
    with pytest.raises(ValueError, match="head_dilation must be >= 0"):
        MPGNetConfig.small(head_dilation=-1)


def test_zero_head_init_answers_zero_until_trained_and_then_learns(scene):
    """head_init="zero": every Q is exactly 0 in training and evaluation mode before any
    step (He-normal's untrained maps are not), and one Adam step on the Q values (those
    inside the rough mask: the rest are 0 by construction) moves the last layer, after which
    the earlier layers get a gradient too."""
    torch.manual_seed(0)
    net = MPGNet(MPGNetConfig.small(head_init="zero", primitives=("grasp",)))
    for mode in (True, False):
        net.train(mode)
        with torch.no_grad():
            assert torch.count_nonzero(net(scene)["grasp"]) == 0
    torch.manual_seed(0)
    kaiming = MPGNet(MPGNetConfig.small(primitives=("grasp",))).train()
    with torch.no_grad():
        assert kaiming(scene)["grasp"].abs().max() > 1.0  # the random start zero removes
    net.train()
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-3)
    trunk_weight = next(net.branches["grasp"].color_trunk.parameters())
    for step in range(2):
        optimizer.zero_grad()
        (net(scene)["grasp"] - 1.0).pow(2).mean().backward()
        grad = trunk_weight.grad
        assert (grad is None or not grad.any()) if step == 0 else grad.abs().sum() > 0
        optimizer.step()
    with torch.no_grad():
        assert torch.count_nonzero(net(scene)["grasp"]) > 0
    assert MPGNetConfig.from_checkpoint({"variant": "small"}).head_init == "kaiming"  # older checkpoints
    with pytest.raises(ValueError, match="head_init must be one of"):
        MPGNetConfig.small(head_init="ones")


def test_bad_input_gives_clear_errors(small_net, scene):
    with pytest.raises(ValueError, match="'color' has shape"):
        small_net(dict(scene, color=scene["color"][:200]))
    with pytest.raises(ValueError, match="'depth' has shape"):
        small_net(dict(scene, depth=scene["depth"][None, None, None]))
    with pytest.raises(KeyError, match="mask"):
        small_net({"color": scene["color"], "depth": scene["depth"]})
    with pytest.raises(ValueError, match="NaN"):
        small_net(dict(scene, depth=np.full_like(scene["depth"], np.nan)))
    with pytest.raises(ValueError, match="batch sizes differ"):
        small_net(
            {"color": scene["color"][None].repeat(2, 0), "depth": scene["depth"][None], "mask": scene["mask"][None]}
        )
    with pytest.raises(ValueError, match="no 'push' branch"):
        MPGNet(MPGNetConfig.small(primitives=("grasp",)))(scene, ("push",))


def test_channels_first_colour_is_accepted(small_net, scene):
    chw = dict(scene, color=np.ascontiguousarray(scene["color"].transpose(2, 0, 1))[None])
    with torch.inference_mode():
        a = small_net(scene, ("grasp",))["grasp"]
        b = small_net({k: (v if k == "color" else v[None]) for k, v in chw.items()}, ("grasp",))["grasp"]
    assert torch.equal(a, b)


def test_a_colour_free_net_reads_depth_and_mask_only_and_round_trips(tmp_path, scene):
    from mpg_agents.acting.weights import load_mpgnet, save_mpgnet

    from .conftest import calibrate_bn

    torch.manual_seed(0)
    net = MPGNet(MPGNetConfig.small(color_input=False))
    calibrate_bn(net, scene)
    for branch in net.branches.values():
        assert branch.color_trunk is None and branch.trunks == (branch.depth_trunk,)
    assert not any("color_trunk" in key for key in net.state_dict())
    with torch.inference_mode():
        maps = net(scene)
        recoloured = net(dict(scene, color=255 - scene["color"]))
        deeper = net(dict(scene, depth=scene["depth"] + 0.01))
    for p in net.primitives:
        assert torch.equal(maps[p], recoloured[p])  # the colour reaches no Q
    assert not torch.equal(maps["push"], deeper["push"])  # the depth does
    path = tmp_path / "depth_only.safetensors"
    save_mpgnet(net, path)
    loaded, header = load_mpgnet(path)
    assert loaded.config.color_input is False and header["config"]["color_input"] is False
    loaded.eval()
    with torch.inference_mode():
        assert torch.equal(loaded(scene)["grasp"], maps["grasp"])
    with pytest.raises(ValueError, match="color_input must be True or False"):
        MPGNetConfig.small(color_input="no")
