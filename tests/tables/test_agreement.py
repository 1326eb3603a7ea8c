"""Rank correlations of eigs.tables.agreement against scipy and closed cases, and the BRISQUE/PSNR agreement table
from hand-made metrics.json files of hidden-ground-truth scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from eigs.tables.agreement import average_ranks, kendall_tau_b, spearman


def test_average_ranks_share_ties():
    assert average_ranks(np.array([3.0, 1.0, 3.0, 2.0])).tolist() == [3.5, 1.0, 3.5, 2.0]


@pytest.mark.parametrize("seed", range(20))
def test_against_scipy_with_ties(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 15))
    x = rng.integers(0, 4, n).astype(float)  # few distinct values: many ties
    y = rng.integers(0, 5, n).astype(float)
    if np.all(x == x[0]) or np.all(y == y[0]):
        return
    assert spearman(x, y)[0] == pytest.approx(stats.spearmanr(x, y).statistic, abs=1e-12)
    assert kendall_tau_b(x, y)[0] == pytest.approx(stats.kendalltau(x, y, variant="b").statistic, abs=1e-12)


def test_closed_cases():
    x = np.array([1.0, 2.0, 3.0, 4.0])
    assert spearman(x, 10 * x) == (1.0, "") and kendall_tau_b(x, 10 * x) == (1.0, "")
    assert spearman(x, -x) == (-1.0, "") and kendall_tau_b(x, -x) == (-1.0, "")
    # one swap of 3: rho = 1 - 6*2/(3*8) = 0.5, tau = (2 - 1)/3
    assert spearman(np.array([1.0, 2, 3]), np.array([2.0, 1, 3]))[0] == pytest.approx(0.5)
    assert kendall_tau_b(np.array([1.0, 2, 3]), np.array([2.0, 1, 3]))[0] == pytest.approx(1 / 3)


@pytest.mark.parametrize(("x", "y", "why"), [([], [], "0 method(s)"), ([1.0], [2.0], "1 method(s)"),
                                             ([1.0, 1.0, 1.0], [1.0, 2.0, 3.0], "all tied"),
                                             ([1.0, 2.0], [5.0, 5.0], "all tied")])  # fmt: skip
def test_undefined_is_nan_with_a_reason(x, y, why):
    for f in (spearman, kendall_tau_b):
        v, reason = f(np.array(x), np.array(y))
        assert math.isnan(v) and reason == why
