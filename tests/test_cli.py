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


def test_scene_info_and_validate_read_the_events_by_chunks(tmp_path, capsys, monkeypatch):
    """`eigs scene` reads the raw events a chunk at a time: the summary equals the one of the scene in memory, and a
    damaged event in a late chunk is found and named."""
    import h5py

    from eigs.scene import EventFile, summarize, write_scene
    from tests.scene.test_scene_file import make_scene

    scene = make_scene()
    path = tmp_path / "s.h5"
    write_scene(scene, path)
    monkeypatch.setattr(EventFile, "READ_ROWS", 3)
    assert len(scene.events) > 6
    assert main(["scene", "info", str(path)]) == 0
    assert capsys.readouterr().out.strip() == summarize(scene).strip()
    with h5py.File(path, "a") as f:
        f["events/p"][len(scene.events) - 1] = 0
    for action in ("info", "validate"):
        assert main(["scene", action, str(path)]) == 2
        assert "events/p must be ±1" in capsys.readouterr().err
