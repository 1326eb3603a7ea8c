"""Learning-rate schedules shared by training and evaluation (no torch)."""

from __future__ import annotations

import math


def exp_decay(start: float, end: float, step: int, horizon: int) -> float:
    """Exponential decay from ``start`` at step 0 to ``end`` at ``horizon`` (constant after it); linear when either
    end is ≤ 0 (a logarithm needs both positive)."""
    t = min(max(step / max(horizon, 1), 0.0), 1.0)
    if start <= 0 or end <= 0:
        return start * (1 - t) + end * t
    return math.exp(math.log(start) * (1 - t) + math.log(end) * t)
