"""What a scene does not need is not scheduled (issue 20), checked on dry runs of small configs: ground-truth poses
skip COLMAP (an `sfm_given` job instead of `sfm`); a scene configured with `events: false` gets an `edi_frames` job
(`eigs edi --no-events`) instead of `edi` and no training or evaluation job of a method that needs events
(`needs_events` in eigs.train.catalog); upstream artifacts are one job per scene and B whatever the number of runs;
a run several tables use trains once; a config change that does not touch a stage does not rerun it (Snakemake's
params trigger, on outputs marked up to date with `--touch`).

Skips inside a job are tested where they happen: `--no-events` and a scene whose file has no events pass every view
through as sharp (tests/edi/test_cli.py, tests/edi/test_edi.py), as do views without motion
(tests/synth/test_still_views.py), and a sharp view trains on one render without event loss
(tests/train/test_deblur.py::test_sharp_views_use_one_render); scenes without ground truth are scored by BRISQUE only
and synthetic scenes by reference metrics only (tests/evaluate/test_evaluate.py)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from eigs.train.catalog import event_methods

REPO = Path(__file__).resolve().parents[1]
SNAKEFILE = REPO / "workflow" / "Snakefile"
# directory() outputs of the rules (the others are files)
DIRECTORY_OUTPUTS = re.compile(r"/(latent|sfm|renders)$")


def snakemake(workdir: Path, cfg: dict, *args: str, ok: bool = True) -> subprocess.CompletedProcess:
    path = workdir / "config.yaml"
    path.write_text(yaml.safe_dump(cfg))
    cmd = [sys.executable, "-m", "snakemake", *args, "--cores", "1", "-s", str(SNAKEFILE), "--directory",
           str(workdir), f"--configfile={path}"]  # fmt: skip
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, check=False, timeout=300)
    assert (proc.returncode == 0) == ok, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc


def job_counts(out: str) -> dict[str, int]:
    """The first ``Job stats`` table of a dry run as {rule: count} ({} when nothing is to be done)."""
    if "Job stats:" not in out:
        assert "Nothing to be done" in out, out[-2000:]
        return {}
    block = out.split("Job stats:", 1)[1].split("total", 1)[0]
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)\s+(\d+)$", block, re.M)}


def toy(**sections) -> dict:
    return {"scenes": {"toy": {"builtin": "toy"}}, "threads": 1, **sections}


RUNS = {"3dgs": {"method": "3dgs", "options": {"steps": 10}}, "eigs": {"method": "eigs", "options": {"steps": 10}}}


@pytest.mark.parametrize(
    ("sfm", "given"),
    [({}, True), ({"allow_given": True}, True), ({"mode": "given"}, True), ({"allow_given": False}, False),
     ({"mode": "colmap"}, False), ({"mode": "colmap", "allow_given": True}, False)],
)  # fmt: skip
def test_ground_truth_poses_schedule_no_colmap(tmp_path, sfm, given):
    """A built-in scene whose ground-truth poses are allowed (the default, `allow_given: true` under auto, or `mode:
    given`) gets an `sfm_given` job running `eigs sfm --mode given`; otherwise the COLMAP job `sfm`."""
    proc = snakemake(tmp_path, toy(sfm=sfm), "all_sfm", "-n", "-p", "--forceall")
    counts = job_counts(proc.stdout)
    assert (counts.get("sfm_given", 0), counts.get("sfm", 0)) == ((1, 0) if given else (0, 1)), proc.stdout
    commands = [ln for ln in proc.stdout.splitlines() if ln.startswith("Shell command: eigs sfm ")]
    assert len(commands) == 1 and ("--mode given" in commands[0]) == given


def test_ingested_scenes_keep_the_colmap_job(tmp_path):
    """Whether an ingested scene has ground-truth poses is in its file, not in the config: it keeps the `sfm` job
    (auto mode decides when it runs), beside a built-in scene's `sfm_given`."""
    src = tmp_path / "events.txt"
    src.write_text("0 1 1 1\n")
    cfg = {"scenes": {"toy": {"builtin": "toy"}, "mine": {"source": str(src), "format": "txt"}}, "threads": 1}
    counts = job_counts(snakemake(tmp_path, cfg, "all_sfm", "-n", "--forceall").stdout)
    assert counts["sfm_given"] == 1 and counts["sfm"] == 1


# methods that train on the frames (or the ground truth) alone, beside every method that needs events
FRAMES_METHODS = ("3dgs", "oracle", "eigs-minus", "deblurring-gs", "bad-gaussians", "nerf", "deblur-nerf")


def test_scene_without_events_schedules_edi_frames_and_no_event_method(tmp_path):
    """Two scenes, one with `events: false`, at B = 4 and 6: per B one `edi` job (the evented scene) and one
    `edi_frames` job running `eigs edi --no-events` (the other); every method that needs events trains and is
    evaluated on the evented scene only, every other method on both; SfM and init stay one job per scene and B."""
    runs = {m: {"method": m, "options": {"steps": 10}} for m in (*sorted(event_methods()), *FRAMES_METHODS)}
    cfg = {"scenes": {"ev": {"builtin": "toy"}, "frames": {"builtin": "toy", "events": False}}, "threads": 1,
           "edi": {"bins": [4, 6]}, "runs": runs}  # fmt: skip
    proc = snakemake(tmp_path, cfg, "all", "-n", "-p", "--forceall")
    counts = job_counts(proc.stdout)
    assert counts["edi"] == counts["edi_frames"] == 2
    assert counts["sfm_given"] == counts["init"] == 2 * 2
    trained = set(re.findall(r"output: results/(\w+)/b4/([\w+-]+)/model\.(?:ply|npz)", proc.stdout))
    evaluated = set(re.findall(r"output: results/(\w+)/b4/eval/([\w+-]+)/metrics\.json", proc.stdout))
    expect = {("ev", m) for m in runs} | {("frames", m) for m in FRAMES_METHODS}
    assert trained == evaluated == expect
    assert counts.get("train", 0) + counts.get("train_field", 0) == counts["evaluate"] == len(expect)
    commands = [ln for ln in proc.stdout.splitlines() if ln.startswith("Shell command: eigs edi ")]
    frames = [c for c in commands if "logs/edi_frames/frames_b" in c]
    assert len(commands) == 4 and len(frames) == 2
    assert all(("--no-events" in c) == (c in frames) for c in commands)
    assert all("results/frames/" in c for c in frames)


def test_event_method_listing_a_scene_without_events_is_a_config_error(tmp_path):
    """A run's explicit `scenes:` naming an `events: false` scene for a method that needs events fails at parse time
    with a message naming the run and the scene, instead of silently dropping the scene; a frames-only method may."""
    scenes = {"ev": {"builtin": "toy"}, "frames": {"builtin": "toy", "events": False}}
    cfg = {"scenes": scenes, "runs": {"mine": {"method": "e2gs", "scenes": ["ev", "frames"]}}}
    proc = snakemake(tmp_path, cfg, "all", "-n", ok=False)
    assert re.search(r"run mine \(method e2gs.*\) lists scene\(s\) frames configured with `events: false`",
                     proc.stdout + proc.stderr)  # fmt: skip
    cfg["runs"]["mine"]["method"] = "3dgs"
    counts = job_counts(snakemake(tmp_path, cfg, "all", "-n", "--forceall").stdout)
    assert counts["train"] == 2 and counts["edi_frames"] == 1


def test_upstream_artifacts_once_per_scene_and_bins_whatever_the_runs(tmp_path):
    """Eight runs on two scenes, six of them at B = 4 and two at B = 6: EDI, SfM and init run once per (scene, B),
    synthesis once per scene; training once per (scene, run)."""
    methods = ["3dgs", "edi-3dgs", "eigs", "eigs-b", "eigs-minus", "e2gs"]
    runs = {m: {"method": m, "options": {"steps": 10}} for m in methods}
    runs |= {"eigs-b6": {"method": "eigs", "bins": 6}, "e2gs-b6": {"method": "e2gs", "bins": 6}}
    cfg = {"scenes": {"a": {"builtin": "toy"}, "b": {"builtin": "toy", "overrides": {"seed": 2}}}, "threads": 1,
           "edi": {"bins": [4, 6]}, "runs": runs}  # fmt: skip
    counts = job_counts(snakemake(tmp_path, cfg, "all", "-n", "--forceall").stdout)
    assert counts["synth"] == 2
    assert counts["edi"] == counts["sfm_given"] == counts["init"] == 2 * 2
    assert counts["train"] == counts["evaluate"] == 2 * len(runs)


def test_a_run_in_several_tables_trains_once(tmp_path):
    """The default row mappings (eigs.tables.rows) put the run `eigs+` in four tables (Table I's row of that name,
    Table III's B = 4, Table IV's width 256, Table V's depth 3; Table II ablates `eigs`): one training job and one
    evaluation per scene, read by the one tables job."""
    runs = {"3dgs": RUNS["3dgs"], "eigs+": {"method": "eigs", "options": {"steps": 10}}}
    proc = snakemake(tmp_path, toy(runs=runs), "all", "-n", "-p", "--forceall")
    counts = job_counts(proc.stdout)
    assert counts["train"] == counts["evaluate"] == len(runs) and counts["tables"] == 1
    assert proc.stdout.count("output: results/toy/b4/eigs+/model.ply") == 1
    for row in ('"eigs+":"eigs+"', '"4":"eigs+"', '"256":"eigs+"', '"3":"eigs+"'):
        assert row in proc.stdout, row


def mark_all_up_to_date(workdir: Path, cfg: dict) -> None:
    """Create every output of the `all` DAG of ``cfg`` (empty files and folders) and mark them up to date with their
    provenance (`--touch` records each job's params and code, as a real run does)."""
    out = snakemake(workdir, cfg, "all", "-n", "--forceall").stdout
    for line in out.splitlines():
        line = line.strip()
        if line.startswith("output: "):
            for p in line.removeprefix("output: ").split(", "):
                target = workdir / p
                if DIRECTORY_OUTPUTS.search(p):
                    target.mkdir(parents=True, exist_ok=True)
                else:
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.touch()
    snakemake(workdir, cfg, "all", "--touch", "--forceall")
    assert job_counts(snakemake(workdir, cfg, "all", "-n").stdout) == {}


def test_a_config_change_reruns_only_the_stages_it_touches(tmp_path):
    """After a complete run (outputs marked up to date with their provenance), a dry run plans only the jobs whose
    params a config change touches, and what depends on them."""
    base = toy(runs=RUNS, evaluate={"path_frames": 8})
    mark_all_up_to_date(tmp_path, base)

    def planned(cfg: dict) -> dict[str, int]:
        return job_counts(snakemake(tmp_path, cfg, "all", "-n", "--rerun-triggers", "mtime", "params", "code").stdout)

    # threads are no stage's params: nothing reruns
    assert planned({**base, "threads": 2}) == {}
    # one run's training options: that run's train and evaluate, then the tables and figures
    runs = {**RUNS, "eigs": {"method": "eigs", "options": {"steps": 20}}}
    # (the orbit video shows eigs: it is rendered again)
    assert planned({**base, "runs": runs}) == {"train": 1, "evaluate": 1, "tables": 1, "figures": 1, "video": 1,
                                               "all": 1}  # fmt: skip
    # a new run: its own jobs only; upstream artifacts are reused (the video shows edi-3dgs too: made again)
    runs = {**RUNS, "edi-3dgs": {"method": "edi-3dgs", "options": {"steps": 10}}}
    assert planned({**base, "runs": runs}) == {"train": 1, "evaluate": 1, "tables": 1, "figures": 1, "video": 1,
                                               "all": 1}  # fmt: skip
    # init options: init and everything trained from it, not synth, EDI or SfM
    changed = planned({**base, "init": {"random": 500}})
    assert changed == {"init": 1, "train": 2, "evaluate": 2, "tables": 1, "figures": 1, "video": 1, "all": 1}
    # EDI options: EDI and downstream, not the scene
    changed = planned({**base, "edi": {"mask_top": 0.02}})
    assert "synth" not in changed and changed["edi"] == changed["sfm_given"] == 1 and changed["train"] == 2
    # the scene itself: everything but the downloaded model files
    changed = planned({**base, "scenes": {"toy": {"builtin": "toy", "overrides": {"seed": 3}}}})
    assert changed["synth"] == 1 and changed["train"] == 2 and "resources" not in changed
