"""The rasterizer's JIT build finds the ninja of the package's own environment without an activated venv."""

from __future__ import annotations

import os
import sys

import pytest

from eigs.render._backend import ninja_on_path


def test_the_venv_ninja_is_put_on_path_when_path_has_none(monkeypatch, tmp_path):
    scripts = os.path.dirname(sys.executable)
    if not os.path.isfile(os.path.join(scripts, "ninja")):
        pytest.skip("this interpreter's environment has no ninja script (installed outside a venv)")
    monkeypatch.setenv("PATH", str(tmp_path))  # an empty folder: no ninja anywhere on PATH
    ninja_on_path()
    assert os.environ["PATH"].split(os.pathsep)[0] == scripts
    ninja_on_path()  # found now: PATH is left as it is
    assert os.environ["PATH"].count(scripts) == 1


def test_the_venv_ninja_goes_before_another_ninja_on_path(monkeypatch, tmp_path):
    """A system ninja first on PATH (Debian's 1.11.1 on our machines) is passed over for the pinned one: two versions
    hash the build commands differently and each switch between them rebuilt the extension."""
    import shutil

    scripts = os.path.dirname(sys.executable)
    own = os.path.join(scripts, "ninja")
    if not os.path.isfile(own):
        pytest.skip("this interpreter's environment has no ninja script (installed outside a venv)")
    other = tmp_path / "ninja"
    other.write_text("#!/bin/sh\nexit 1\n")
    other.chmod(0o755)
    monkeypatch.setenv("PATH", str(tmp_path))
    assert shutil.which("ninja") == str(other)
    ninja_on_path()
    assert shutil.which("ninja") == own
    ninja_on_path()
    assert os.environ["PATH"].count(scripts) == 1
