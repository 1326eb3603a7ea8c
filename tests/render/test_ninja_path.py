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
