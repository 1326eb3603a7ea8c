"""bench/step_ab.py's children: the command line and environment each revision's child runs with."""

from __future__ import annotations

import argparse
from pathlib import Path

from bench.step_ab import child_command


def args(**kw) -> argparse.Namespace:  # noqa: ANN003
    base = {"own_config": False, "omp_wait_policy": "inherit", "threads": 1, "steps": 10, "warm": 3,
            "lockstep": False}  # fmt: skip
    return argparse.Namespace(**{**base, **kw})


def test_the_wait_policy_is_the_environments_unless_asked(monkeypatch):
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    src = Path("/tmp/rev-abc/src")
    cmd, env = child_command(src, "results/chair:config/config.yaml:eigs+:0", args())
    assert "OMP_WAIT_POLICY" not in env and env["PYTHONPATH"] == str(src)
    assert cmd[cmd.index("--threads") + 1] == "1" and "--lockstep" not in cmd
    _, env = child_command(src, "results/chair:config/config.yaml:eigs+:0", args(omp_wait_policy="passive"))
    assert env["OMP_WAIT_POLICY"] == "PASSIVE"


def test_own_config_reads_the_revisions_copy_and_lockstep_is_passed_on():
    src = Path("/tmp/rev-abc/src")
    cmd, _ = child_command(src, "results/chair:config/config.yaml:eigs+:10000", args(own_config=True, lockstep=True))
    assert cmd[cmd.index("--case") + 1] == "results/chair:/tmp/rev-abc/config/config.yaml:eigs+:10000"
    assert "--lockstep" in cmd
