"""Confidence intervals for the paper's Table I metrics (pure functions over numbers).

- :func:`wilson_interval`: the Wilson score interval of a success rate (``k`` of ``n``
  episodes). Unlike the normal approximation it stays inside [0, 1] and is not empty at
  0/n or n/n, which 50-episode cells hit often.
- :func:`bootstrap_mean_interval`: a seeded percentile bootstrap of the mean (mean motions
  per episode), so one seed gives one interval.

Both delegate to SciPy (``binomtest(...).proportion_ci`` and ``stats.bootstrap``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import stats

DEFAULT_CONFIDENCE = 0.95
DEFAULT_RESAMPLES = 10_000


def _check_confidence(confidence: float) -> None:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")


def wilson_interval(successes: int, trials: int, confidence: float = DEFAULT_CONFIDENCE) -> tuple[float, float]:
    """The Wilson score interval (no continuity correction) of ``successes / trials``."""
    _check_confidence(confidence)
    if int(trials) != trials or trials < 1:
        raise ValueError(f"trials must be a positive integer, got {trials}")
    if int(successes) != successes or not 0 <= successes <= trials:
        raise ValueError(f"successes must be an integer in [0, trials={trials}], got {successes}")
    ci = stats.binomtest(int(successes), int(trials)).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def bootstrap_mean_interval(
    values: Sequence[float],
    confidence: float = DEFAULT_CONFIDENCE,
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
) -> tuple[float, float]:
    """A percentile-bootstrap interval of the mean of ``values`` (at least two), seeded.

    Constant values give the degenerate interval (v, v): every resample has the same mean.
    """
    _check_confidence(confidence)
    data = np.asarray(values, dtype=float)
    if data.ndim != 1 or data.size < 2:
        raise ValueError(f"a bootstrap needs a flat sequence of at least two values, got shape {data.shape}")
    if not np.isfinite(data).all():
        raise ValueError("values must be finite")
    if resamples < 1:
        raise ValueError(f"resamples must be >= 1, got {resamples}")
    if np.all(data == data[0]):
        return float(data[0]), float(data[0])
    result = stats.bootstrap(
        (data,),
        np.mean,
        confidence_level=confidence,
        n_resamples=int(resamples),
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)
