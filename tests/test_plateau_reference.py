"""bench/plateau_reference.py: the step count of a plateau reference (the rest of a run's longer schedule, else
twice its own steps) and its command-line errors."""

from __future__ import annotations

import sys

import pytest

from bench import plateau_reference


def test_reference_continues_a_longer_schedule():
    spec = {"method": "eigs", "options": {"steps": 1750, "schedule_steps": 3000, "eval_every": 125}}
    assert plateau_reference.reference_options(spec, None) == {"method": "eigs", "steps": 3000,
                                                               "schedule_steps": 3000, "eval_every": 125}  # fmt: skip
    assert spec["options"]["steps"] == 1750  # the config is not modified


def test_reference_of_an_own_schedule_doubles_it_and_drops_a_shorter_schedule():
    assert plateau_reference.reference_options({"method": "3dgs", "options": {"steps": 1000}}, None) == {
        "method": "3dgs", "steps": 2000}  # fmt: skip
    spec = {"method": "besplat", "options": {"steps": 500, "schedule_steps": 3000}}
    assert plateau_reference.reference_options(spec, 4000, eval_every=200) == {"method": "besplat", "steps": 4000,
                                                                               "eval_every": 200}  # fmt: skip


def test_reference_of_a_run_without_steps_needs_steps():
    with pytest.raises(ValueError, match="--steps"):
        plateau_reference.reference_options({"method": "e2nerf"}, None)
    assert plateau_reference.reference_options({"method": "e2nerf"}, 1600) == {"method": "e2nerf", "steps": 1600}


@pytest.mark.parametrize(
    ("argv", "message"),
    [(["--run", "nope"], "run 'nope' is not in"), (["--run", "e2nerf"], "pass --steps"),
     (["--run", "e2nerf", "--steps", "10"], "upstream not run in")],
)  # fmt: skip
def test_cli_errors_are_one_line(tmp_path, monkeypatch, capsys, argv, message):
    cfg = tmp_path / "config.yaml"
    cfg.write_text("runs:\n  e2nerf: {method: e2nerf}\n")
    monkeypatch.setattr(sys, "argv", ["plateau_reference.py", "--directory", str(tmp_path), "--scene", "chair",
                                      "--config", str(cfg), "--ledger", str(tmp_path / "ledger"), *argv])  # fmt: skip
    with pytest.raises(SystemExit, match=message):
        plateau_reference.main()
    assert not (tmp_path / "ledger").exists()
