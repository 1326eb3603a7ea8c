"""eigs.util.atomic: a write that fails leaves nothing; a write that is killed leaves a temporary that the next write
of the same target removes (and no other target's)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from eigs.util.atomic import atomic_path, temporary_pattern

KILLED_WRITE = """
import os, signal, sys
from eigs.util.atomic import atomic_path
with atomic_path(sys.argv[1], directory=sys.argv[2] == "dir") as tmp:
    if sys.argv[2] == "dir":
        tmp.joinpath("half").write_bytes(b"x" * 1000)
    else:
        tmp.write_bytes(b"x" * 1000)
    os.kill(os.getpid(), signal.SIGKILL)
"""


def killed_write(target: Path, kind: str) -> None:
    proc = subprocess.run([sys.executable, "-c", KILLED_WRITE, str(target), kind], check=False)
    assert proc.returncode == -9


def test_failed_write_leaves_nothing(tmp_path):
    target = tmp_path / "a.h5"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("disk full")
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.h5"]


@pytest.mark.parametrize("kind", ["file", "dir"])
def test_killed_write_leaves_a_temporary_the_next_write_removes(tmp_path, kind):
    target = tmp_path / ("a.h5" if kind == "file" else "sfm")
    other = tmp_path / ("a.b.h5" if kind == "file" else "sfm2")  # a name that starts like the target's
    killed_write(target, kind)
    killed_write(other, kind)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert len(left) == 2 and not target.exists(), left
    pattern = temporary_pattern(target, directory=kind == "dir")
    assert sum(bool(pattern.fullmatch(n)) for n in left) == 1  # the target's, not the other's
    with atomic_path(target, directory=kind == "dir") as tmp:
        if kind == "dir":
            tmp.mkdir(exist_ok=True)
            (tmp / "whole").write_bytes(b"ok")
        else:
            tmp.write_bytes(b"ok")
    names = sorted(p.name for p in tmp_path.iterdir())
    assert target.name in names and len(names) == 2, names  # the target, and the other target's temporary
    assert not any(pattern.fullmatch(n) for n in names)
    assert any(temporary_pattern(other, directory=kind == "dir").fullmatch(n) for n in names)
