"""Fixtures for ingestion tests: a quiet environment and helpers that run ``eigs ingest`` like a user."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from eigs.cli import main


@pytest.fixture(autouse=True)
def _no_progress(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("EIGS_PROGRESS", "0")


def run_ingest(fmt: str, source: Path | str, out: Path, *options: str) -> int:
    """``eigs ingest --format fmt source -o out options...`` in-process; returns the exit code."""
    return main(["ingest", "--format", fmt, str(source), "-o", str(out), *options])


def expect_failure(capsys: pytest.CaptureFixture, fmt: str, source: Path | str, out: Path, *options: str) -> str:
    """Run ingest expecting a user error: exit 2, one stderr line, no output file and no temporary left behind.
    Returns the message."""
    code = run_ingest(fmt, source, out, *options)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert err.startswith("eigs ingest: error: "), err
    assert "\n" not in err and "Traceback" not in err, err
    assert not out.exists()
    leftovers = [p for p in os.listdir(out.parent) if p.startswith(f".{out.stem}.")]
    assert not leftovers, leftovers
    return err
