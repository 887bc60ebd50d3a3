"""The README's demo command runs end to end and writes its pictures."""

from mpg_agents.baselines import shipped_checkpoint
from mpg_agents.demo import main


def test_shipped_checkpoint_is_small_and_loads():
    path = shipped_checkpoint()
    assert path.stat().st_size < 10 * 2**20
    from mpg_agents.mpgnet import read_checkpoint_header

    header = read_checkpoint_header(path)
    assert header["primitives"] == ["grasp"] and header["variant"] == "small"
    assert header["q_star"] is not None  # calibrated after Stage II


def test_demo_runs_the_shipped_policy(tmp_path, capsys):
    assert main(["--episodes", "1", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "task success" in out and "mean motions" in out
    for name in ("scene.png", "qmaps.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"
