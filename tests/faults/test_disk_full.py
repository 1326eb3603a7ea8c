"""Each writing stage into a filesystem that fills up: one line naming the path and the stage, nothing partial left,
and the same command completes once space is freed.

A small tmpfs is mounted by the test (root; skipped with its reason where mounting is not allowed, a failure under
CI=true), the stage's outputs go there and its inputs come from elsewhere (the shared toy artifacts, or the
hand-built evaluation case). The tmpfs is then grown (``mount -o remount,size=…``, the user freeing space) and the
same command is run again.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import require
from tests.evaluate.fixtures import make_case
from tests.faults.harness import check_file
from tests.metrics.conftest import resources_dir  # noqa: F401  (the LPIPS/BRISQUE model files fixture)

SMALL = "64k"
ROOMY = "256m"


class SmallFs:
    """A tmpfs at ``root`` of ``size``; :meth:`grow` frees space as a user would."""

    def __init__(self, root: Path):
        self.root = root

    def grow(self) -> None:
        subprocess.run(["mount", "-o", f"remount,size={ROOMY}", str(self.root)], check=True)

    def files(self) -> list[str]:
        return sorted(str(p.relative_to(self.root)) for p in self.root.rglob("*") if not p.is_dir())


@pytest.fixture
def small_fs(tmp_path, request):
    """A tmpfs of :data:`SMALL` (or the size a test's ``fs_size`` mark gives: the hand-built evaluation case and its
    video are smaller than 64 KiB)."""
    mark = request.node.get_closest_marker("fs_size")
    size = mark.args[0] if mark else SMALL
    root = tmp_path / "fs"
    root.mkdir()
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(root)], capture_output=True,
                          text=True, check=False)  # fmt: skip
    require(proc.returncode == 0, f"cannot mount a tmpfs (root and mount permission needed): {proc.stderr.strip()}")
    try:
        yield SmallFs(root)
    finally:
        subprocess.run(["umount", "-l", str(root)], check=False)


def eigs(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "EIGS_PROGRESS": "0", "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "eigs.cli", *args], capture_output=True, text=True, timeout=600,
                          env=env, check=False)  # fmt: skip


def assert_full_then_rerun(fs: SmallFs, stage: str, args: list[str], named: Path, outputs: list[Path]) -> None:
    """``eigs stage args`` fails on the full tmpfs with one error line naming ``named``; no file is left on it; after
    :meth:`SmallFs.grow` the same command succeeds and every output file reads back whole."""
    proc = eigs(stage, *args)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr[-3000:]
    errors = [ln for ln in lines if ln.startswith(f"eigs {stage}: error: ")]
    assert errors == [lines[-1]], proc.stderr[-3000:]
    assert lines[-1].startswith(f"eigs {stage}: error: {named}: no space left on its filesystem"), lines[-1]
    assert fs.files() == [], f"left on the full filesystem: {fs.files()}"
    fs.grow()
    proc = eigs(stage, *args)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for out in outputs:
        for f in [out] if out.is_file() else sorted(p for p in out.rglob("*") if p.is_file()):
            assert check_file(f) is None, (f, check_file(f))
    assert outputs and all(o.exists() for o in outputs)


def test_edi(small_fs, toy):
    edi, latent = small_fs.root / "edi.h5", small_fs.root / "latent"
    args = [str(toy.scene), "-o", str(edi), "--latent-dir", str(latent), "--bins", "4"]
    assert_full_then_rerun(small_fs, "edi", args, edi, [edi, latent])


def test_sfm(small_fs, toy):
    out = small_fs.root / "sfm"
    args = [str(toy.scene), str(toy.edi), "--latent-dir", str(toy.edi.parent / "latent"), "-o", str(out),
            "--threads", "1"]  # fmt: skip
    assert_full_then_rerun(small_fs, "sfm", args, out, [out])


def test_init(small_fs, toy):
    out = small_fs.root / "init.ply"
    assert_full_then_rerun(small_fs, "init", [str(toy.sfm), "-o", str(out)], out, [out])


@pytest.mark.parametrize("what", ["checkpoint", "model"])
def test_train(small_fs, toy, what):
    """The checkpoint written at step 20 (``checkpoint``), or with no checkpoint the run folder at the end."""
    run = small_fs.root / "run"
    config = {"method": "3dgs", "steps": 40, "eval_every": 40, "checkpoint_every": 20 if what == "checkpoint" else 100}
    args = [*map(str, toy.paths()), "-o", str(run), "--config", json.dumps(config), "--threads", "1"]
    named = run.with_name("run.partial") / "checkpoint.pt" if what == "checkpoint" else run
    assert_full_then_rerun(small_fs, "train", args, named, [run])
    assert (run / "model.ply").is_file() and not run.with_name("run.partial").exists()


@pytest.mark.fs_size("4k")
def test_evaluate(small_fs, tmp_path, resources_dir):  # noqa: F811
    case = make_case(tmp_path / "case")
    out = small_fs.root / "eval" / "metrics.json"
    args = [str(case["run"]), str(case["scene"]), str(case["sfm"]), "-o", str(out), "--resources", str(resources_dir),
            "--threads", "1"]  # fmt: skip
    assert_full_then_rerun(small_fs, "evaluate", args, out.parent / "renders", [out.parent])


@pytest.mark.fs_size("4k")
def test_video(small_fs, tmp_path):
    case = make_case(tmp_path / "case")
    out = small_fs.root / "orbit.mp4"
    args = [str(case["run"]), "--scene", str(case["scene"]), "-o", str(out), "--frames", "200", "--threads", "1"]
    assert_full_then_rerun(small_fs, "video", args, out, [out])
