"""Stress suite (issue #20): property-based tests of the numerics and readers under extreme inputs.

Budget: ``tests/stress/budget.py`` (``EIGS_STRESS=ci`` by default, ``EIGS_STRESS=exhaustive`` for a long search).
"""

from __future__ import annotations

from tests.stress.budget import PROFILE


def pytest_report_header(config) -> str:
    return f"eigs stress profile: {PROFILE} (set EIGS_STRESS=exhaustive for the long search)"
