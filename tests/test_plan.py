"""eigs.plan, the run planning the workflow and bench/schedule.py share: its job list against Snakemake's dry runs (a
committed snapshot of every shipped config, taken before the planning moved there, and a live dry run of the toy
config), bench/schedule.py's DAG against it, and the per-method facts."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from bench.schedule import jobs_of, merge_configs
from eigs import plan

REPO = Path(__file__).resolve().parents[1]
SNAPSHOT = json.loads((REPO / "tests" / "data" / "plan_jobs.json").read_text())
CONFIGS = sorted(k for k in SNAPSHOT if k != "about")


def load(files: list[str]) -> dict:
    return merge_configs([yaml.safe_load((REPO / f).read_text()) for f in files])


def dry_run_jobs(stdout: str) -> list[str]:
    """The jobs of a dry run's output as ``rule k=v ...`` (rule all left out), sorted."""
    out = []
    for block in re.split(r"\n\[\w{3} \w{3} [^\]]*\]\n", stdout)[1:]:
        rule = re.search(r"^(?:local)?rule (\w+):$", block, re.M).group(1)
        wildcards = re.search(r"^\s+wildcards: (.*)$", block, re.M)
        if rule != "all":
            out.append(" ".join([rule, *(wildcards.group(1).split(", ") if wildcards else [])]))
    return sorted(out)


@pytest.mark.parametrize("name", CONFIGS)
def test_jobs_match_the_dry_run_snapshot(name):
    expected = SNAPSHOT[name]["jobs"]
    got = [str(j) for j in plan.jobs(load(SNAPSHOT[name]["configfiles"]))]
    assert len(got) == len(set(got))
    assert sorted(got) == expected


def test_jobs_match_a_live_dry_run(tmp_path):
    """The toy config's jobs as Snakemake plans them now, in an empty directory."""
    cmd = [sys.executable, "-m", "snakemake", "all", "-n", "--cores", "1", "-s", str(REPO / "workflow" / "Snakefile"),
           "--directory", str(tmp_path), f"--configfile={REPO / 'config' / 'toy.yaml'}"]  # fmt: skip
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, check=False, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert dry_run_jobs(proc.stdout) == sorted(str(j) for j in plan.jobs(load(["config/toy.yaml"])))


@pytest.mark.parametrize("name", CONFIGS)
def test_schedule_simulates_the_planned_jobs(name):
    """bench/schedule.py's DAG has the planned training, evaluation and video jobs, and one job per scene and per
    upstream stage, scene and B (a simulated scene's two preparation jobs count as one there)."""
    cfg = load(SNAPSHOT[name]["configfiles"])
    planned = plan.jobs(cfg)
    dag = jobs_of(cfg)
    for rule in ("train", "evaluate"):
        want = {(j.scene, j.run) for j in planned if j.rule in (rule, rule + "_field")}
        assert {tuple(k.split(":")[1:]) for k in dag if k.startswith(rule + ":")} == want
    assert {k.split(":")[1] for k in dag if k.startswith("video:")} == {j.scene for j in planned if j.rule == "video"}
    n_scenes, n_bins = len(cfg["scenes"]), len(plan.edi_bins(cfg))
    counts = {stage: sum(k.startswith(stage + ":") for k in dag) for stage in ("scene", "edi", "sfm", "init")}
    assert counts == {"scene": n_scenes, "edi": n_scenes * n_bins, "sfm": n_scenes * n_bins, "init": n_scenes * n_bins}


def test_method_facts():
    assert plan.needs_ground_truth("oracle") and not plan.needs_ground_truth("3dgs")
    assert plan.needs_events("eigs") and not plan.needs_events("3dgs")
    assert plan.is_field_method("nerf") and not plan.is_field_method("eigs")


def test_run_scenes_follow_what_a_scene_has():
    cfg = {
        "scenes": {"toy": {"builtin": "toy"}, "mine": {"source": "x", "format": "txt", "events": False}},
        "runs": {"oracle": {"method": "oracle"}, "eigs": {"method": "eigs"}, "3dgs": {"method": "3dgs", "bins": 6},
                 "bad": {"method": "eigs", "scenes": ["mine"]}},
    }  # fmt: skip
    assert plan.run_scenes(cfg, "oracle") == ["toy"]
    assert plan.run_scenes(cfg, "eigs") == ["toy"]
    assert plan.run_scenes(cfg, "3dgs") == ["mine", "toy"]
    assert (plan.run_bins(cfg, "3dgs"), plan.run_bins(cfg, "eigs")) == (6, 4)
    assert [plan.sfm_rule(cfg, s) for s in ("mine", "toy")] == ["sfm", "sfm_given"]
    with pytest.raises(ValueError, match="run bad .* needs events"):
        plan.check(cfg)


def test_planning_needs_no_torch():
    code = ("import sys, yaml; from eigs import plan; plan.jobs(yaml.safe_load(open('config/config.yaml'))); "
            "assert 'torch' not in sys.modules")  # fmt: skip
    subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True, timeout=120)


@pytest.mark.parametrize(
    ("section", "words"),
    [
        ({"edi": {"mode": "exact"}}, ["config: edi: mode", "'exact' is not one of auto, estimated, e2nerf"]),
        ({"edi": {"treshold": 0.2}}, ["config: edi", "unknown option(s) treshold", "accepted: mode, bins"]),
        ({"sfm": {"matcher": "vocab"}}, ["config: sfm: matcher", "not one of auto, exhaustive, sequential"]),
        ({"init": {"points": 5}}, ["config: init", "unknown option(s) points", "accepted: min_points"]),
        ({"scenes": {"a": {"builtin": "toy", "sfm": {"mode": "glomap"}}}}, ["config: scene a: sfm: mode"]),
    ],
)
def test_stage_sections_fail_on_one_line_naming_the_key(section, words):
    from eigs.errors import EigsError

    with pytest.raises(EigsError) as err:
        plan.check_sections({"scenes": {"toy": {"builtin": "toy"}}, **section})
    msg = str(err.value)
    assert "\n" not in msg and all(w in msg for w in words), msg
    plan.check_sections(merge_configs([yaml.safe_load((REPO / "config" / "config.yaml").read_text())]))


@pytest.mark.parametrize(
    ("options", "line"),
    [
        (["--camera-response", "log"], "argument --camera-response: invalid choice: 'log'"),
        (["--time-window", "5,1"], "--time-window: END must be after START, got 5,1"),
        (["--groundtruth"], "argument --groundtruth: expected one argument"),
        (["--bogus", "1"], "not `eigs ingest` flags or their values: --bogus 1"),
        (["--views", "0:3", "extra.h5"], "not `eigs ingest` flags or their values: extra.h5"),
        ("--views 0:3", "expected a list of `eigs ingest` flags and values"),
    ],
)
def test_ingest_options_are_checked_when_planned(options, line):
    """A scene's `options:` go through `eigs ingest`'s own parser and option checks at planning, on one line naming
    the scene; the real configs' options pass."""
    cfg = {"scenes": {"rec": {"source": "rec.h5", "format": "h5", "options": options}}}
    with pytest.raises(ValueError) as err:
        plan.check(cfg)
    msg = str(err.value)
    assert msg.startswith("config: scene rec: options: ") and line in msg and "\n" not in msg, msg
    plan.check(yaml.safe_load((REPO / "config" / "davis346.yaml").read_text()))
    plan.check(yaml.safe_load((REPO / "config" / "real.yaml").read_text()))


def test_a_dry_run_names_a_bad_stage_option(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("scenes:\n  toy: {builtin: toy}\nsfm: {matcher: vocab}\n")
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "all", "-n", "--cores", "1", "-s", str(REPO / "workflow" / "Snakefile"),
         "--directory", str(tmp_path / "w"), f"--configfile={cfg}"],
        capture_output=True, text=True, check=False, timeout=300,
    )  # fmt: skip
    assert proc.returncode != 0
    assert "config: sfm: matcher: 'vocab' is not one of auto, exhaustive, sequential" in proc.stdout + proc.stderr
