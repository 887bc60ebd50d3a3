"""Which quantile of the Q of greedy grasps that took the target becomes Q*_g.

The one default (:data:`CALIBRATION_QUANTILE`) and the one check (:func:`check_quantile`) of
every calibration quantile: :func:`~mpg_agents.acting.grasp_threshold.estimate_q_star`,
:func:`~mpg_agents.acting.grasp_threshold.calibrate_q_star`, a training stage's
``calibration_quantile`` and ``mpg-calibrate --quantile``. Pure and light (no torch): the
command lines and the stage table read it at start-up.
"""

from __future__ import annotations

from numbers import Real

CALIBRATION_QUANTILE = 0.5
"""The quantile unless one is asked for: the median, where the Q of successful grasps settles
(the paper's reading); a lower one lets the workflow take more of the grasps that do succeed."""


def check_quantile(value: float, what: str = "calibration quantile") -> float:
    """``value`` as a calibration quantile (a number in [0, 1]), else a ``ValueError`` naming
    ``what`` and the valid range."""
    if isinstance(value, bool) or not isinstance(value, Real) or not 0.0 <= value <= 1.0:
        raise ValueError(f"{what} must be in [0, 1], got {value!r}")
    return float(value)
