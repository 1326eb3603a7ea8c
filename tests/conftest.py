"""Shared test fixtures.

Data that lives outside the repository (``../shared/data/real``) or comes from the package registry is
optional on a developer's machine but required in CI: :func:`require` skips with a reason locally and
fails under ``CI=true``, so no check vanishes silently.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
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


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):  # noqa: ANN001, ANN201 (pytest hook)
    """With ``EIGS_TEST_CPU_LOG=FILE``: one line per test appended to FILE (each xdist worker its own,
    ``FILE.<pid>``): node id, CPU seconds of the test process, of its finished child processes (Snakemake, its jobs,
    ``eigs`` subprocesses), and wall seconds, setup and teardown included. CPU time, unlike the wall time of
    ``--durations``, hardly changes when other work shares the cores (docs/development.md "Test suite time")."""
    path = os.environ.get("EIGS_TEST_CPU_LOG")
    if not path:
        yield
        return
    import resource
    import time

    def cpu(who: int) -> float:
        r = resource.getrusage(who)
        return r.ru_utime + r.ru_stime

    own, children, t0 = cpu(resource.RUSAGE_SELF), cpu(resource.RUSAGE_CHILDREN), time.perf_counter()
    yield
    own, children = cpu(resource.RUSAGE_SELF) - own, cpu(resource.RUSAGE_CHILDREN) - children
    with open(f"{path}.{os.getpid()}", "a") as f:
        f.write(f"{item.nodeid}\t{own:.2f}\t{children:.2f}\t{time.perf_counter() - t0:.2f}\n")


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


@dataclass
class ToyArtifacts:
    """The toy scene's upstream artifacts (synth → edi → sfm → init through the workflow), read-only to tests."""

    root: Path

    @property
    def scene(self) -> Path:
        return self.root / "results" / "toy" / "scene.h5"

    @property
    def edi(self) -> Path:
        return self.root / "results" / "toy" / "b4" / "edi.h5"

    @property
    def sfm(self) -> Path:
        return self.root / "results" / "toy" / "b4" / "sfm"

    @property
    def init(self) -> Path:
        return self.root / "results" / "toy" / "b4" / "init.ply"

    def paths(self) -> tuple[Path, Path, Path, Path]:
        return self.scene, self.edi, self.sfm, self.init


@pytest.fixture(scope="session")
def toy(tmp_path_factory) -> ToyArtifacts:
    """`snakemake all_sfm --configfile=config/toy.yaml` in a scratch directory, made once per test run: the
    pytest-xdist workers share it (the first one makes it under a file lock, the others wait and read it)."""
    from filelock import FileLock

    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # the run's folder, above each worker's own
    root = base / "toy_shared"
    with FileLock(str(base / "toy_shared.lock")):
        if not (root / "DONE").is_file():
            root.mkdir(exist_ok=True)
            proc = subprocess.run(
                [sys.executable, "-m", "snakemake", "all_sfm", "--cores", "2", "-s",
                 str(REPO / "workflow" / "Snakefile"), "--directory", str(root),
                 f"--configfile={REPO / 'config' / 'toy.yaml'}"],
                capture_output=True, text=True, check=False, timeout=900,
            )  # fmt: skip
            assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
            (root / "DONE").write_text("")
    return ToyArtifacts(root)
