"""Thread counts from the cores actually free; overrides; passive OpenMP waiting; workers."""

from __future__ import annotations

import os

import pytest
import torch

from mpg_envs import threads
from mpg_envs.threads import THREADS_ENV, choose_threads, num_threads, requested_threads, worker_init


@pytest.mark.parametrize(
    ("cores", "load", "max_threads", "expected"),
    [
        (2, 0.0, None, 2),  # quiet 2-core machine: both cores
        (2, 0.4, None, 2),  # 1.6 free rounds to 2
        (2, 0.5, None, 2),  # 1.5 free: half rounds up
        (2, 0.6, None, 1),  # 1.4 free
        (2, 2.0, None, 1),  # two busy loops: never below one thread
        (2, 7.0, None, 1),  # overloaded
        (1, 0.0, None, 1),
        (16, 3.0, None, 13),
        (16, 0.0, 4, 4),  # capped
        (4, 0.0, 8, 4),  # the cap never exceeds the cores
    ],
)
def test_choose_threads(cores, load, max_threads, expected):
    assert choose_threads(cores, load, max_threads) == expected


@pytest.mark.parametrize(
    ("args", "match"),
    [((0, 0.0), "cores"), ((2, -1.0), "load"), ((2, float("nan")), "load"), ((2, 0.0, 0), "max_threads")],
)
def test_choose_threads_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        choose_threads(*args)


def test_requested_threads_reads_the_environment():
    assert requested_threads({}) is None
    assert requested_threads({THREADS_ENV: ""}) is None
    assert requested_threads({THREADS_ENV: " 3 "}) == 3
    for bad in ("0", "-2", "two", "1.5"):
        with pytest.raises(ValueError, match=f"{THREADS_ENV} must be a positive integer"):
            requested_threads({THREADS_ENV: bad})


def test_num_threads_precedence(monkeypatch):
    monkeypatch.setattr(threads, "available_cores", lambda: 2)
    monkeypatch.setattr(threads, "load_average", lambda: 2.3)
    monkeypatch.delenv(THREADS_ENV, raising=False)
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert num_threads() == 1  # automatic: the load leaves no core free
    monkeypatch.setattr(threads, "load_average", lambda: 0.2)
    assert num_threads() == 2
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert num_threads() == 3  # an explicit OpenMP setting (a worker's) is respected
    monkeypatch.setenv(THREADS_ENV, "5")
    assert num_threads() == 5  # and MPG_NUM_THREADS overrides it
    assert num_threads(3) == 3  # and an argument overrides the environment
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="num_threads must be a positive integer"):
            num_threads(bad)


def test_set_torch_threads(monkeypatch):
    monkeypatch.delenv(THREADS_ENV, raising=False)
    assert threads.set_torch_threads(1) == 1 and torch.get_num_threads() == 1
    monkeypatch.setenv(THREADS_ENV, "2")
    assert threads.set_torch_threads() == 2 and torch.get_num_threads() == 2


def test_passive_wait_is_set_on_import_and_respects_the_user(monkeypatch):
    import mpg_agents  # noqa: F401  (sets it before torch loads OpenMP)

    assert os.environ.get("OMP_WAIT_POLICY")  # PASSIVE unless the user chose one
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    threads.use_passive_openmp_wait()
    assert os.environ["OMP_WAIT_POLICY"] == "ACTIVE"
    monkeypatch.delenv("OMP_WAIT_POLICY")
    threads.use_passive_openmp_wait()
    assert os.environ["OMP_WAIT_POLICY"] == "PASSIVE"


def test_worker_init_gives_one_thread(monkeypatch):
    for name in ("OMP_NUM_THREADS", THREADS_ENV):
        monkeypatch.delenv(name, raising=False)  # restored after the test
    torch.set_num_threads(2)
    worker_init("ignored", 3)  # usable as a pool initializer with initargs
    assert torch.get_num_threads() == 1
    assert os.environ["OMP_NUM_THREADS"] == "1" and num_threads() == 1


def test_load_average_sees_the_machine():
    assert threads.load_average() >= 0
    now = threads.runnable_now(samples=2, interval_s=0.001)
    assert now is None or now >= 0  # None off Linux


def test_a_process_pinned_to_few_cores_counts_the_load_of_the_whole_machine():
    # pinned to 2 of 16 cores while 12 other threads run: 4 cores are free, use both of ours
    assert choose_threads(2, 12.0, machine_cores=16) == 2
    assert choose_threads(2, 14.6, machine_cores=16) == 1
    assert choose_threads(4, 13.0, machine_cores=16) == 3
    with pytest.raises(ValueError, match="machine_cores"):
        choose_threads(4, 0.0, machine_cores=2)


def test_one_thread_children_sets_the_worker_env_and_restores_it(monkeypatch):
    from mpg_envs.threads import WORKER_THREAD_ENV, one_thread_children

    monkeypatch.setenv("OMP_NUM_THREADS", "7")
    monkeypatch.delenv("MKL_NUM_THREADS", raising=False)
    with one_thread_children():
        assert {k: os.environ.get(k) for k in WORKER_THREAD_ENV} == WORKER_THREAD_ENV
    assert os.environ["OMP_NUM_THREADS"] == "7"
    assert "MKL_NUM_THREADS" not in os.environ
