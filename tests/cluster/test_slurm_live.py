"""The workflow through Snakemake's SLURM executor on a live one-node SLURM cluster (opt-in: ``-m cluster``).

``tests/cluster/slurm.sh`` installs SLURM and munge from the distribution when they are missing, starts munged,
slurmctld and slurmd on this machine, and stops them afterwards. The toy DAG runs up to ``all_sfm``
(synth → edi → sfm → init) once locally and once with the SLURM workflow profile; the scheduler's job-completion
record must list every job, ``scontrol`` must show the profile's per-rule requests (CPUs, memory, time limit, a
GPU), and the outputs must equal the local run's. Needs root (it installs packages and starts daemons); without
root it skips, and under CI=true it fails instead. `.ci/run` runs it after `make test`.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from plyfile import PlyData

from tests.conftest import require

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "tests" / "cluster" / "slurm.sh"
PROFILE = REPO / "workflow" / "profiles" / "slurm" / "profile.yaml"
TOY = REPO / "config" / "toy.yaml"
# The toy scene has ground-truth poses, so its SfM stage is the given-mode rule (rules/sfm.smk); logs and
# benchmarks of both SfM rules go to the stage's directory "sfm".
RULES = ("synth", "edi", "sfm_given", "init")
STAGES = ("synth", "edi", "sfm", "init")

pytestmark = pytest.mark.cluster


def snakemake(workdir: Path, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    workdir.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "snakemake", "all_sfm", "-s", str(REPO / "workflow" / "Snakefile")]
    # two threads per job (config/toy.yaml has one), so the CPU request of a multi-threaded job shows below
    cmd += ["--directory", str(workdir), f"--configfile={TOY}", "--config", "threads=2", *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=1200, env=env)
    (workdir / "snakemake.out").write_text(proc.stdout + proc.stderr)
    return proc


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A running one-node cluster: yields the environment that points clients at it; stops it afterwards."""
    require(os.geteuid() == 0, "the live SLURM test installs packages and starts daemons: run it as root")
    require(
        shutil.which("sbatch") is not None or shutil.which("apt-get") is not None,
        "neither SLURM nor apt-get is available",
    )
    state = tmp_path_factory.mktemp("slurm")
    start = subprocess.run(["bash", str(SCRIPT), "start", str(state)], capture_output=True, text=True, timeout=600)
    env = {**os.environ, "SLURM_CONF": str(state / "slurm.conf")}
    try:
        assert start.returncode == 0, start.stdout + start.stderr
        yield state, env
    finally:
        stop = subprocess.run(["bash", str(SCRIPT), "stop", str(state)], capture_output=True, text=True, timeout=120)
        assert stop.returncode == 0, stop.stdout + stop.stderr
        for daemon in ("slurmctld", "slurmd"):
            assert not (state / f"{daemon}.pid").exists(), f"{daemon} was not stopped"


def h5_datasets(path: Path) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return out


def assert_same_h5(a: Path, b: Path) -> None:
    da, db = h5_datasets(a), h5_datasets(b)
    assert sorted(da) == sorted(db), f"{a.name}: datasets differ"
    for name in da:
        np.testing.assert_array_equal(da[name], db[name], err_msg=f"{a.name}:{name}")


def submitted_jobs(log: str) -> dict[str, str]:
    """{rule: SLURM job id} from the executor's "Job N has been submitted with SLURM jobid M" lines."""
    rules = dict(re.findall(r"\nrule (\w+):\n(?:.*\n)*?.*?jobid: (\d+)", log))  # rule -> snakemake job id
    slurm = dict(re.findall(r"Job (\d+) has been submitted with SLURM jobid (\d+)", log))
    return {rule: slurm[jid] for rule, jid in rules.items() if jid in slurm}


def test_toy_dag_through_slurm_equals_local_run(cluster, tmp_path):
    state, env = cluster
    # The profile as shipped, plus one GPU for the cheap `init` job, so a GPU request travels the real path
    # (Snakemake resources -> sbatch --gpus -> the node's gres) without running training in CI.
    profile = yaml.safe_load(PROFILE.read_text())
    profile["set-resources"]["init"]["gpu"] = 1
    (tmp_path / "profile").mkdir()
    (tmp_path / "profile" / "profile.yaml").write_text(yaml.safe_dump(profile))

    local = tmp_path / "local"
    proc = snakemake(local, "--cores", "2")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]

    remote = tmp_path / "slurm"
    # squeue for status (the test cluster has no accounting database for sacct); poll soon after submitting.
    proc = snakemake(
        remote,
        "--workflow-profile",
        str(tmp_path / "profile"),
        "--slurm-status-command",
        "squeue",
        "--slurm-init-seconds-before-status-checks",
        "2",
        env=env,
    )
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-5000:]

    # Every stage was submitted to SLURM, and the scheduler's completion record lists each job as completed
    # in the run's working directory.
    jobs = submitted_jobs(log)
    assert sorted(jobs) == sorted(RULES), log[-3000:]
    records = {}
    for line in (state / "jobcomp.log").read_text().splitlines():
        fields = dict(re.findall(r"(\w+)=(\S*)", line))
        records[fields["JobId"]] = fields
    for rule, jobid in jobs.items():
        rec = records.get(jobid)
        assert rec is not None, f"{rule}: SLURM job {jobid} missing from the completion record"
        assert (rec["JobState"], rec["ExitCode"]) == ("COMPLETED", "0:0"), rec
        assert Path(rec["WorkDir"]).resolve() == remote.resolve(), rec

    # The profile's requests reached the scheduler: CPUs = threads (2 as set above, init: 1), --mem = mem_mb,
    # --time = runtime (minutes), and init's GPU.
    expect = {"synth": (2, 4000, 60), "edi": (2, 4000, 60), "sfm_given": (2, 6000, 60), "init": (1, 2000, 30)}
    for rule, (cpus, mem, minutes) in expect.items():
        show = subprocess.run(
            ["scontrol", "show", "job", jobs[rule]], capture_output=True, text=True, env=env, check=True
        ).stdout
        assert f"TRES=cpu={cpus},mem={mem}M" in show, show
        assert f"TimeLimit={minutes // 60:02d}:{minutes % 60:02d}:00" in show, show
        assert ("gres:gpu:1" in show) == (rule == "init"), show

    # Same outputs as the local run. Deterministic stages: equal bytes / equal HDF5 datasets.
    a, b = local / "results" / "toy", remote / "results" / "toy"
    assert_same_h5(a / "scene.h5", b / "scene.h5")
    assert_same_h5(a / "b4" / "edi.h5", b / "b4" / "edi.h5")
    for rel in ("contact_sheet.png", "b4/sfm/cameras.bin"):
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    pngs = sorted(p.name for p in (a / "b4" / "latent").glob("*.png"))
    assert len(pngs) == 8 * 5 and pngs == sorted(p.name for p in (b / "b4" / "latent").glob("*.png"))
    for name in pngs:
        assert (a / "b4" / "latent" / name).read_bytes() == (b / "b4" / "latent" / name).read_bytes(), name
    for name in ("poses.h5", "test_cameras.h5"):
        assert_same_h5(a / "b4" / "sfm" / name, b / "b4" / "sfm" / name)
    # SfM's triangulated points differ by a few points between any two runs (also two local ones: threaded
    # feature matching), so the point cloud and the init PLY built from it are compared by their structure.
    ra, rb = (json.loads((d / "b4" / "sfm" / "report.json").read_text()) for d in (a, b))
    for key in set(ra) - {"points", "timings_s"}:
        assert ra[key] == rb[key], key
    na, nb = ra["points"]["count"], rb["points"]["count"]
    assert abs(na - nb) <= 0.05 * na, (na, nb)
    va, vb = (PlyData.read(str(d / "b4" / "init.ply"))["vertex"] for d in (a, b))
    assert va.data.dtype == vb.data.dtype
    assert len(va.data) - na == len(vb.data) - nb, "init adds the same number of random points"

    for stage in STAGES:
        assert any((remote / "logs" / stage).iterdir()), f"no log for {stage}"
        assert any((remote / "benchmarks" / stage).iterdir()), f"no benchmark for {stage}"
