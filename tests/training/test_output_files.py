"""Outputs written whole or not at all, output paths checked before any work, run folders that
are not ours left alone, and the inputs of mpg-plot and mpg-demo named when bad.

A full disk is a small tmpfs where this process may mount one (root); elsewhere the disk
"fills" by an injected ``ENOSPC`` at the swap of the written file."""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import mpg_agents.evaluation.eval_runner as eval_runner
from mpg_agents.cli import calibrate_main, eval_main, export_main, plot_main, train_main
from mpg_agents.cli_input import UsageError, check_output
from mpg_agents.demo import main as demo_main
from mpg_agents.evaluation.policy_zoo import shipped_checkpoint
from mpg_agents.learning.plotting import check_image_path, read_progress
from mpg_agents.learning.run_folder import LOCK_NAME, is_run_folder, prepare_run_folder
from mpg_agents.learning.train_log import CSV_COLUMNS
from mpg_envs.files import WriteFailed, check_folder_writable, check_writable, same_file, write_text_whole, written_whole

GRASP_NET = shipped_checkpoint().parent / "stage2_grasp_small.safetensors"
ENOSPC = os.strerror(errno.ENOSPC)  # "No space left on device"


def _mount_tmpfs(folder: Path, options: str) -> bool:
    """Mount a tmpfs at ``folder`` (made here); whether it worked (root, a mount command)."""
    folder.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    return subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)], capture_output=True).returncode == 0


def _unmount(folder: Path) -> None:
    subprocess.run(["umount", "-l", str(folder)], capture_output=True)


class FullDisk:
    """A folder whose disk fills up when :meth:`fill` is called: afterwards the write check's
    one-byte file still fits, an output file does not."""

    def __init__(self, folder: Path, tmpfs: bool, monkeypatch: pytest.MonkeyPatch) -> None:
        self.folder, self.tmpfs, self.monkeypatch = folder, tmpfs, monkeypatch

    def fill(self) -> None:
        if not self.tmpfs:
            def no_space(*args, **kwargs):
                raise OSError(errno.ENOSPC, ENOSPC)

            self.monkeypatch.setattr(os, "replace", no_space)
            return
        pad = self.folder / "pad"
        fd = os.open(pad, os.O_WRONLY | os.O_CREAT)
        try:
            while os.write(fd, b"\0" * 4096):
                pass
        except OSError:
            pass
        finally:
            os.close(fd)
        os.truncate(pad, max(0, pad.stat().st_size // 4096 * 4096 - 4096))  # one page left

    def names(self) -> list[str]:
        """What the folder holds (the pad aside): an output, never a temporary file."""
        return sorted(p.name for p in self.folder.iterdir() if p.name != "pad")


@pytest.fixture
def full_disk(tmp_path, monkeypatch):
    folder = tmp_path / "disk"
    tmpfs = _mount_tmpfs(folder, "size=64k")
    try:
        yield FullDisk(folder, tmpfs, monkeypatch)
    finally:
        if tmpfs:
            _unmount(folder)


@pytest.fixture
def read_only_folder(tmp_path):
    """A folder no file can be written in: a read-only tmpfs (root), else a folder without write
    permission (a user other than root)."""
    folder = tmp_path / "read-only"
    if _mount_tmpfs(folder, "ro,size=16k"):
        yield folder
        _unmount(folder)
    elif os.geteuid() != 0:
        folder.chmod(0o555)
        yield folder
        folder.chmod(0o755)
    else:
        pytest.skip("root may write any folder and cannot mount one read-only here")


class StubResult:
    """What an evaluation returns, without running one: a table and a large record."""

    failures: list = []

    def table(self) -> str:
        return "the table"

    def to_dict(self) -> dict:
        return {"records": [{"index": i, "note": "x" * 100} for i in range(200)]}


# ------------------------------------------------------------------------ the one writer
def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary_file(tmp_path):
    path = tmp_path / "out.json"
    path.write_text('{"old": true}')
    with pytest.raises(WriteFailed) as failed:
        with written_whole(path) as tmp:
            tmp.write_text("{half")
            raise OSError(errno.ENOSPC, ENOSPC)
    assert str(failed.value) == f"cannot write {str(path)!r}: {ENOSPC} (the old file is kept)"
    assert path.read_text() == '{"old": true}'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]
    with pytest.raises(WriteFailed, match=r"new.json': No space left on device \(nothing written\)$"):
        with written_whole(tmp_path / "new.json") as tmp:
            raise OSError(errno.ENOSPC, ENOSPC)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_a_written_file_replaces_the_old_one_keeping_its_mode_and_a_link(tmp_path):
    path = tmp_path / "out.json"
    path.write_text("old")
    path.chmod(0o640)
    link = tmp_path / "link.json"
    link.symlink_to(path)
    assert write_text_whole(link, "new") == link
    assert link.is_symlink() and path.read_text() == "new"
    assert path.stat().st_mode & 0o777 == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.json", "out.json"]


def test_check_writable_refuses_devices_proc_missing_folders_and_folders(tmp_path):
    with pytest.raises(WriteFailed, match=r"cannot write '/dev/full': it is a character device; give the path of a regular file"):
        check_writable("/dev/full")
    with pytest.raises(WriteFailed, match=r"cannot write '/proc/out.json': the folder '/proc' takes no new files"):
        check_writable("/proc/out.json")
    with pytest.raises(WriteFailed, match=r"the folder '.*missing' does not exist; create it first"):
        check_writable(tmp_path / "missing" / "out.json")
    with pytest.raises(WriteFailed, match="it is a folder; give a file path"):
        check_writable(tmp_path)
    check_writable(tmp_path / "out.json")
    assert list(tmp_path.iterdir()) == []  # the check leaves nothing behind
    with pytest.raises(WriteFailed, match=r"'/dev/full' is a file, not a folder"):
        check_folder_writable("/dev/full/pictures")
    check_folder_writable(tmp_path / "new" / "pictures")  # made later, where a folder above exists
    assert list(tmp_path.iterdir()) == []


def test_same_file_sees_through_links_and_spellings(tmp_path):
    a = tmp_path / "a.json"
    a.write_text("x")
    (tmp_path / "sub").mkdir()
    (tmp_path / "link").symlink_to(a)
    assert same_file(a, tmp_path / "sub" / ".." / "a.json") and same_file(tmp_path / "link", a)
    assert not same_file(a, tmp_path / "b.json") and not same_file(tmp_path / "b.json", tmp_path / "b.json")


def test_check_output_refuses_an_input_and_what_cannot_be_written(tmp_path):
    source = tmp_path / "v.safetensors"
    source.write_bytes(b"weights")
    with pytest.raises(UsageError, match=r"--json '.*v.safetensors' is the --policy checkpoint; write it to another file"):
        check_output(str(source), "--json", {"the --policy checkpoint": str(source)})
    with pytest.raises(UsageError, match=r"--json '/dev/full': it is a character device"):
        check_output("/dev/full", "--json")
    with pytest.raises(UsageError, match=r"--json '/proc/x.json': the folder '/proc' takes no new files"):
        check_output("/proc/x.json", "--json")
    check_output(str(tmp_path / "out.json"), "--json", {"the --policy checkpoint": str(source), "the --cases file": None})


# ------------------------------------------------------------------- 1. an output onto an input
def test_eval_and_calibrate_never_write_onto_the_checkpoint_they_read(tmp_path, capsys, monkeypatch):
    def no_episodes(*args, **kwargs):
        raise AssertionError("episodes ran before the output path was checked")

    monkeypatch.setattr(eval_runner, "evaluate_parallel", no_episodes)
    checkpoint = tmp_path / "v.safetensors"
    shutil.copy(GRASP_NET, checkpoint)
    before = checkpoint.read_bytes()
    link = tmp_path / "result.json"
    link.symlink_to(checkpoint)
    for out in (checkpoint, link, tmp_path / "." / "v.safetensors"):
        assert eval_main(["--policy", str(checkpoint), "--env", "MPG-Stage2-v0", "--episodes", "1", "--json", str(out)]) == 2
        assert capsys.readouterr().err == f"error: --json {str(out)!r} is the --policy checkpoint; write it to another file\n"
        assert calibrate_main(["--policy", str(checkpoint), "--env", "MPG-Stage2-v0", "--json", str(out)]) == 2
        assert "is the --policy checkpoint; write it to another file" in capsys.readouterr().err
    assert checkpoint.read_bytes() == before
    scene = tmp_path / "scene.json"
    scene.write_text("{}")
    assert eval_main(["--policy", "oracle", "--cases", str(scene), "--json", str(scene)]) == 2
    assert f"--json {str(scene)!r} is the --cases file" in capsys.readouterr().err
    assert scene.read_text() == "{}"


# --------------------------------------------------------------------- 2. a folder that is not ours
def test_train_refuses_a_folder_holding_no_run_of_ours_and_touches_nothing(tmp_path, capsys):
    out = tmp_path / "u"
    (out / "state").mkdir(parents=True)
    files = {"weights.safetensors": b"mine", "progress.csv": b"a,b\n1,2\n", "state/mine.txt": b"keep me"}
    for name, data in files.items():
        (out / name).write_bytes(data)
    for argv in (["--env", "MPG-Stage2-v0"], ["--pipeline"]):
        assert train_main([*argv, "--steps", "1", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err == (f"error: run folder {str(out)!r} is not empty and holds no run of this project (progress.csv, state/, "
                       "weights.safetensors); a run would overwrite them: give a new or empty folder, or an earlier run's folder to resume it\n")
    assert {name: (out / name).read_bytes() for name in files} == files
    assert sorted(p.name for p in out.iterdir()) == ["progress.csv", "state", "weights.safetensors"]


def test_a_run_folder_is_new_empty_or_one_of_ours(tmp_path):
    assert is_run_folder(tmp_path)  # empty
    (tmp_path / "train.log").write_text("mpg-train-runs writes its log before the run starts")
    assert is_run_folder(tmp_path)
    (tmp_path / "notes.txt").write_text("a user's")
    assert not is_run_folder(tmp_path)
    (tmp_path / LOCK_NAME).write_text("{}")  # a run started here
    assert is_run_folder(tmp_path)
    old = tmp_path / "old"
    (old / "state").mkdir(parents=True)
    (old / "weights.safetensors").write_bytes(b"w")
    assert not is_run_folder(old)
    (old / "state" / "FORMAT").write_text("mpg-train-state-v1")  # a run saved before the lock existed
    assert is_run_folder(old) and prepare_run_folder(old) == old
    foreign = tmp_path / "u"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("x")
    with pytest.raises(ValueError, match=r"holds no run of this project \(notes.txt\)"):
        prepare_run_folder(foreign)


# ------------------------------------------------------------------------------ 3. a full disk
def test_a_run_state_the_disk_refuses_keeps_the_previous_one(tmp_path):
    from mpg_agents.learning.run_state import STATE_FORMAT, state_folder, write_state

    write_state(tmp_path, lambda folder: write_text_whole(folder / "counters.json", '{"iteration": 4}'))

    def disk_full(folder: Path) -> None:
        write_text_whole(folder / "counters.json", '{"iteration": 6}')
        raise OSError(errno.ENOSPC, ENOSPC, str(folder / "replay.npz"))

    with pytest.raises(WriteFailed, match=f"cannot write '.*state.tmp': {ENOSPC}"):
        write_state(tmp_path, disk_full)
    assert state_folder(tmp_path) == tmp_path / "state" and (tmp_path / "state" / "FORMAT").read_text() == STATE_FORMAT
    assert (tmp_path / "state" / "counters.json").read_text() == '{"iteration": 4}'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state"]  # no state.tmp left


def test_eval_json_on_a_full_disk_keeps_the_old_file(full_disk, capsys, monkeypatch):
    out = full_disk.folder / "out.json"
    out.write_text('{"old": true}')

    def evaluate(*args, **kwargs):
        full_disk.fill()  # the disk fills while the episodes run
        return StubResult()

    monkeypatch.setattr(eval_runner, "evaluate_parallel", evaluate)
    assert eval_main(["--policy", "oracle", "--env", "MPG-Stage2-v0", "--episodes", "1", "--json", str(out)]) == 2
    captured = capsys.readouterr()
    assert "the table" in captured.out and "metrics written" not in captured.out
    assert captured.err == f"error: cannot write {str(out)!r}: {ENOSPC} (the old file is kept)\n"
    assert out.read_text() == '{"old": true}' and full_disk.names() == ["out.json"]


def test_a_full_disk_or_a_device_is_refused_before_the_evaluation(full_disk, capsys, monkeypatch):
    if not full_disk.tmpfs:
        pytest.skip("needs a real full disk (a tmpfs)")
    monkeypatch.setattr(eval_runner, "evaluate_parallel", lambda *a, **k: pytest.fail("the evaluation ran"))
    full_disk.fill()
    (full_disk.folder / "pad2").write_bytes(b"x" * 4096)  # the last page
    out = full_disk.folder / "out.json"
    assert eval_main(["--policy", "oracle", "--env", "MPG-Stage2-v0", "--json", str(out)]) == 2
    assert capsys.readouterr().err == f"error: --json {str(out)!r}: {ENOSPC}\n"


def test_plot_on_a_full_disk_writes_nothing(full_disk, tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "progress.csv").write_text(progress_csv(8))
    full_disk.fill()
    out = full_disk.folder / "curves.png"
    assert plot_main([str(run), "--out", str(out)]) == 2
    assert capsys.readouterr().err == f"error: cannot write {str(out)!r}: {ENOSPC} (nothing written)\n"
    assert full_disk.names() == []


def test_export_on_a_full_disk_names_the_file(full_disk, capsys):
    full_disk.fill()
    dst = full_disk.folder / "copy.safetensors"
    assert export_main([str(GRASP_NET), str(dst)]) == 2
    assert capsys.readouterr().err == f"error: cannot write {str(dst)!r}: {ENOSPC} (nothing written)\n"
    assert full_disk.names() == []


def test_a_demo_that_cannot_write_its_pictures_fails(full_disk, capsys, monkeypatch):
    import mpg_agents.demo as demo

    noise = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)  # a PNG of 12 kB: no room for it
    monkeypatch.setattr(demo, "scene_picture", lambda env, obs, locator=None: noise)  # and no rendering
    full_disk.fill()
    assert demo_main(["--policy", "random", "--env", "MPG-Stage1-v0", "--episodes", "1", "--out", str(full_disk.folder)]) == 2
    captured = capsys.readouterr()
    assert "pictures in" not in captured.out
    assert captured.err == f"error: cannot write {str(full_disk.folder / 'scene.png')!r}: {ENOSPC} (nothing written)\n"


# ------------------------------------------------------------------------ 10. mpg-plot's input
def progress_csv(rows: int) -> str:
    lines = [",".join(CSV_COLUMNS)]
    for it in range(1, rows + 1):
        lines.append(",".join([str(it), str(it // 3), "grasp", "greedy", "1.000", "0.50000", "0.5000", "1", str(it % 2), "0", "1",
                               "", "0.010", "0.020", "0.030"]))
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("damage, message", [
    (lambda text: text.replace("\n3,1,grasp", "\n3,1,gr\n4,1,grasp", 1), "line 4: 3 fields where the header has 15 (a truncated or damaged row)"),
    (lambda text: text.replace("\n2,0,", "\ntwo,0,", 1), "line 3: iteration is 'two', not a number"),
    (lambda text: text.replace("\n2,0,", "\n2.5,0,", 1), "line 3: iteration is '2.5', not a whole number >= 0"),
    (lambda text: text.replace("0.50000", "lots", 1), "line 2: loss is 'lots', not a number"),
    (lambda text: "iteration,episode\n1,0\n", "lacks the columns primitive, loss, epsilon, target_grasped, num_motions that the curves are drawn from"),
    (lambda text: text.split("\n")[0] + "\n", "has no iterations yet"),
    (lambda text: "", "is empty; mpg-train writes a header row first"),
    (lambda text: bytes(range(256)), "is not a text CSV file (binary data at byte 0)"),
    (lambda text: b"iteration\xff\xfe\n", "is not a text CSV file (byte 9 is not UTF-8)"),
])
def test_a_damaged_progress_file_is_named_with_what_is_wrong(tmp_path, capsys, damage, message):
    path = tmp_path / "progress.csv"
    text = damage(progress_csv(5))
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ValueError) as refused:
        read_progress(path)
    assert str(refused.value).startswith(str(path)) and message in str(refused.value)
    assert plot_main([str(tmp_path), "--out", str(tmp_path / "curves.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and not (tmp_path / "curves.png").exists()


def test_a_last_row_being_written_is_left_out_with_a_warning(tmp_path, capsys):
    path = tmp_path / "progress.csv"
    path.write_text(progress_csv(5) + "6,2,gra")
    with pytest.warns(UserWarning, match=r"line 7: the last row is cut short \(a training still writing it\?\); left out"):
        assert list(read_progress(path)["iteration"]) == [1, 2, 3, 4, 5]
    assert plot_main([str(tmp_path)]) == 0
    assert "warning: " in capsys.readouterr().err and (tmp_path / "curves.png").read_bytes()[:4] == b"\x89PNG"


def test_plot_writes_exactly_the_path_named_or_refuses_it(tmp_path, capsys):
    (tmp_path / "progress.csv").write_text(progress_csv(5))
    assert plot_main([str(tmp_path), "--out", str(tmp_path / "curves")]) == 2
    err = capsys.readouterr().err
    assert f"--out {str(tmp_path / 'curves')!r}: it has no suffix to name the picture's format; end it with one of .png, .pdf, .svg" in err
    assert plot_main([str(tmp_path), "--out", str(tmp_path / "curves.bmp")]) == 2
    assert "its suffix '.bmp' names no format the curves are written in" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["progress.csv"]
    assert plot_main([str(tmp_path), "--out", str(tmp_path / "curves.pdf")]) == 0
    assert capsys.readouterr().out == f"learning curves written to {tmp_path / 'curves.pdf'}\n"
    assert (tmp_path / "curves.pdf").read_bytes()[:4] == b"%PDF"
    check_image_path("x.PNG")


# ------------------------------------------------------------------------ 11. mpg-demo's input
@pytest.mark.parametrize("argv, message", [
    (["--episodes", "0"], "--episodes must be >= 1, got 0"),
    (["--episodes", "-1"], "--episodes must be >= 1, got -1"),
    (["--seed", "-1"], "--seed must be >= 0, got -1"),
    (["--policy", "nope"], "unknown policy 'nope'; valid: oracle, random, pixel-heuristic, matcher, shipped or the path of a .safetensors checkpoint"),
    (["--env", "MPG-Nope-v0"], "unknown env id 'MPG-Nope-v0'; valid: MPG-Stage1-v0, "),
])
def test_demo_names_a_bad_input_before_any_work(tmp_path, capsys, argv, message):
    out = tmp_path / "pictures"
    assert demo_main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {message}") and err.count("\n") == 1
    assert not out.exists()


def test_demo_refuses_an_out_where_no_picture_can_be_written(read_only_folder, capsys):
    for out in (read_only_folder, read_only_folder / "pictures"):
        assert demo_main(["--policy", "random", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"error: --out {str(out)!r}: no picture can be written there (") and err.count("\n") == 1
