"""bench/device_batch.py: the config merge, the job list, the scheduler (stages in order, failures, the deadline, the
benchmark files from wait4) and what the pack keeps; the jobs are stand-in commands, not training runs."""

from __future__ import annotations

import json
import sys
import tarfile
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import device_batch as db  # noqa: E402
from bench.gpu_check import CheckError  # noqa: E402
from bench.schedule import read_benchmark  # noqa: E402


def test_configs_merge_key_by_key_as_snakemake_merges_them(tmp_path):
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text("runs: {x: {method: 3dgs}, y: {method: eigs}}\nthreads: 1\n")
    b.write_text("runs: {z: {method: e2gs}, y: {method: oracle}}\n")
    cfg = db.merged_config([a, b])
    assert cfg == {"runs": {"x": {"method": "3dgs"}, "y": {"method": "oracle"}, "z": {"method": "e2gs"}}, "threads": 1}


def test_job_list_errors():
    assert db.parse_jobs("chair:eigs, tree:eigs+") == [("chair", "eigs"), ("tree", "eigs+")]
    for bad in ("chair", "chair:", ":eigs", "a:b,a:b"):
        with pytest.raises(CheckError):
            db.parse_jobs(bad)


def _script(code: str) -> list[str]:
    return [sys.executable, "-c", code]


def test_scheduler_runs_both_stages_records_failures_and_stops_at_the_deadline(tmp_path, monkeypatch):
    bundle = tmp_path / "bundle"
    bundle.mkdir()
    jobs = [{"scene": s, "run": r, "bins": 4, "config": "{}"} for s, r in
            (("a", "ok"), ("a", "fails"), ("b", "slow"), ("b", "late"))]  # fmt: skip
    (bundle / "MANIFEST.json").write_text(json.dumps({"format": db.FORMAT, "jobs": jobs}))
    busy = "import time\nt = time.process_time()\nwhile time.process_time() - t < 0.3: pass\n"

    def commands(_bundle, _res, work, job):
        out = work / "results" / job["scene"] / "b4" / job["run"]
        if job["run"] == "fails":
            return [_script("import time; time.sleep(0.3); raise SystemExit(3)"), _script("")]
        if job["run"] == "slow":
            return [_script("import time; time.sleep(60)"), _script("")]
        write = f"import pathlib; p = pathlib.Path({str(out)!r}); p.mkdir(parents=True, exist_ok=True); "
        return [_script(busy + write + "(p / 'config.json').write_text('{}')"),
                _script(write + "(p / 'stage2').write_text('done')")]  # fmt: skip

    monkeypatch.setattr(db, "job_commands", commands)
    rep = db.run_batch(bundle, tmp_path, tmp_path / "work", workers=3, start_until=0.1, deadline=6.0)
    status = {j["run"]: j["status"] for j in rep["jobs"]}
    assert status == {"ok": "ok", "fails": "train failed", "slow": "stopped at the deadline (train)",
                      "late": "not started"}  # fmt: skip
    work = tmp_path / "work"
    assert (work / "results" / "a" / "b4" / "ok" / "stage2").read_text() == "done"  # evaluate ran after train
    wall, cpu = read_benchmark(work / "benchmarks" / "train" / "a_b4_ok.tsv")  # the ledger's reader takes it
    assert cpu is not None and 0.25 <= cpu <= wall  # the child's own CPU time, from wait4
    assert not (work / "benchmarks" / "train" / "a_b4_fails.tsv").exists()
    assert rep["elapsed_s"] < 30  # the sleeping job was stopped, not waited for


def test_pack_keeps_the_small_outputs_and_one_grid_view(tmp_path):
    work = tmp_path / "w"
    ev = work / "results" / "s" / "b4" / "eval" / "r"
    for rel in ("renders/blur/0003.png", "renders/blur/0007.png", "renders/gt_blur/0003.png",
                "renders/gt_blur/0007.png", "renders/novel/0001.png", "metrics.json"):  # fmt: skip
        (ev / rel).parent.mkdir(parents=True, exist_ok=True)
        (ev / rel).write_bytes(b"x")
    run = work / "results" / "s" / "b4" / "r"
    run.mkdir(parents=True)
    for name in ("model.ply", "motion.npz", "config.json"):
        (run / name).write_bytes(b"x")
    db.pack(work, tmp_path / "p.tgz")
    with tarfile.open(tmp_path / "p.tgz") as tar:
        names = sorted(tar.getnames())
    assert names == ["results/s/b4/eval/r/metrics.json", "results/s/b4/eval/r/renders/blur/0003.png",
                     "results/s/b4/eval/r/renders/gt_blur/0003.png", "results/s/b4/r/config.json"]  # fmt: skip
