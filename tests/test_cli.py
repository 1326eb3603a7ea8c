"""The `eigs` entry point: help for every subcommand, one-line user errors, exit codes."""

from __future__ import annotations

import subprocess
import sys

import pytest

from eigs.cli import COMMANDS, main


def test_top_level_help_lists_every_subcommand(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_subcommand_help(name, capsys):
    with pytest.raises(SystemExit) as exc:
        main([name, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert f"usage: eigs {name}" in out
    assert "--threads" in out
    assert " ".join(out.split()).endswith(f"implemented in {COMMANDS[name]}")  # the subcommand → module map


def test_subcommand_modules_live_in_their_stage_package():
    """Each subcommand's module is a `cli` module of one package (`<package>.cli` or `<package>.<x>_cli`)."""
    import re

    for name, module in COMMANDS.items():
        assert re.fullmatch(r"eigs\.[a-z]+\.([a-z]+_)?cli", module), (name, module)


def test_no_subcommand_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "SUBCOMMAND" in capsys.readouterr().out


def test_user_error_is_one_line_without_traceback(tmp_path):
    missing = tmp_path / "missing.h5"
    proc = subprocess.run(
        [sys.executable, "-m", "eigs", "scene", "info", str(missing)], capture_output=True, text=True, check=False
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert lines == [f"eigs scene: error: {missing}: no such scene file"]
    assert "Traceback" not in proc.stderr


def test_scene_info_and_validate(tmp_path, capsys):
    from eigs.scene import write_scene
    from tests.scene.test_scene_file import make_scene

    path = tmp_path / "s.h5"
    write_scene(make_scene(), path)
    assert main(["scene", "info", str(path)]) == 0
    assert "scene 'unit'" in capsys.readouterr().out
    assert main(["scene", "validate", str(path)]) == 0
    assert "valid eigs scene" in capsys.readouterr().out
