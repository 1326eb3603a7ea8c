"""Shared test fixtures.

Data that lives outside the repository (``../shared/data/real``) or comes from the package registry is
optional on a developer's machine but required in CI: :func:`require` skips with a reason locally and
fails under ``CI=true``, so no check vanishes silently.
"""

from __future__ import annotations

import os
from pathlib import Path

# Before anything loads OpenMP (torch): idle OpenMP threads sleep instead of spinning. pytest-xdist's workers and
# the Snakemake jobs of the workflow tests run torch side by side on few cores; with spinning threads each waits
# for cores that the other's idle threads burn (the toy DAG test: 328 s beside tests/train/test_train.py, 142 s
# with this; docs/development.md "Test suite time").
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import pytest  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
SHARED_REAL = SHARED / "data" / "real"


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


def require(condition: bool, reason: str) -> None:
    """Skip (locally) or fail (under CI=true) when ``condition`` is false."""
    if condition:
        return
    if in_ci():
        pytest.fail(f"required in CI but unavailable: {reason}")
    pytest.skip(reason)


@pytest.fixture(scope="session")
def shared_real() -> Path:
    """``../shared/data/real``: skips locally when absent, fails under CI=true."""
    require(SHARED_REAL.is_dir(), f"{SHARED_REAL} is absent")
    return SHARED_REAL


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO
