"""Digests of env episodes, to tell that a change left every registered id's episodes as they were.

``data/episode_digests.json`` holds the SHA-256 prefix of the reset observation and info of a few
seeds of each id registered before the target could be named other ways than by its mask
(``python tests/envs/episode_digests.py OUT`` writes them for the code checked out; ``data/episode_digests.json`` was
recorded on MuJoCo 3.x, ``data/episode_digests_mujoco4.json`` on 4.0.0).
"""

from __future__ import annotations

import hashlib
import json
import sys
from typing import Any

import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the ids)

RESET_CASES: tuple[tuple[str, int], ...] = (
    *((f"MPG-Stage{i}-v0", s) for i in range(1, 6) for s in (0, 1)),
    ("MPG-Occluded-v0", 500000),
    ("MPG-Occluded-v0", 500001),
    ("MPG-OccludedHard-v0", 500000),
    ("MPG-OccludedHard-v0", 500001),
    ("MPG-OccludedHardNovel-v0", 500000),
    ("MPG-OccludedHardCamera-v0", 500000),
)
"""``(env id, reset seed)`` pairs recorded: every stage on drawn scenes, the test-set ids on shipped scenes."""


def digest(value: Any) -> str:
    """A SHA-256 prefix of ``value``: dicts by sorted key, arrays by dtype, shape and bytes,
    sequences item by item, anything else by ``repr``."""
    h = hashlib.sha256()

    def feed(v: Any) -> None:
        if isinstance(v, dict):
            for k in sorted(v):
                h.update(repr(k).encode())
                feed(v[k])
        elif isinstance(v, np.ndarray):
            h.update(f"{v.dtype}{v.shape}".encode())
            h.update(np.ascontiguousarray(v).tobytes())
        elif isinstance(v, (list, tuple)):
            h.update(b"[")
            for x in v:
                feed(x)
            h.update(b"]")
        else:
            h.update(repr(v).encode())

    feed(value)
    return h.hexdigest()[:20]


def reset_digests(env_id: str, seed: int, **kwargs: Any) -> list[str]:
    """Digests of ``env_id``'s reset observation and info at ``seed`` (made with ``kwargs``)."""
    env = gym.make(env_id, **kwargs)
    try:
        obs, info = env.reset(seed=seed)
        return [digest(obs), digest(info)]
    finally:
        env.close()


def main(path: str) -> None:
    record = {f"{env_id}@{seed}": reset_digests(env_id, seed) for env_id, seed in RESET_CASES}
    with open(path, "w") as f:
        json.dump(record, f, indent=1, sort_keys=True)


if __name__ == "__main__":
    main(sys.argv[1])
