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

    def commands(_bundle, _res, work, job, edi_here=False, threads=1):
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


def test_prepared_scenes_are_made_first_and_their_jobs_read_them(tmp_path, monkeypatch):
    config = {"scenes": {"c": {"builtin": "chair", "overrides": {"shake": 2.5}}, "d": {"builtin": "dish"}},
              "edi": {"bins": [4], "threshold": "auto"}, "sfm": {"allow_given": False}, "init": {"max_points": 9},
              "runs": {"r": {"method": "eigs", "options": {"steps": 5}}}}  # fmt: skip
    m = db.make_bundle(tmp_path, config, [("c", "r"), ("d", "r")], tmp_path / "bundle", prepare=("c", "d"))
    assert m["files"] == {}  # nothing local is read for a prepared scene
    spec = m["prepare"]["c"]
    assert spec == {"builtin": "chair", "overrides": '{"shake":2.5}', "bins": [4], "edi": '{"threshold":"auto"}',
                    "sfm": '{"allow_given":false}', "init": '{"max_points":9}'}  # fmt: skip
    with pytest.raises(CheckError, match="no job"):
        db.make_bundle(tmp_path, config, [("c", "r")], tmp_path / "b2", prepare=("d",))
    with pytest.raises(CheckError, match="COLMAP"):
        db.prepare_spec({**config, "sfm": {"allow_given": True}}, "c", [4])

    work = tmp_path / "work"
    cmds = {t["stage"]: t["cmd"] for t in db.batch_tasks(tmp_path / "bundle", tmp_path, work, m) if t["scene"] == "c"}
    assert cmds["synth"][-6:] == ["-o", str(work / "results/c/scene.h5"), "--contact-sheet",
                                  str(work / "results/c/contact_sheet.png"), "--threads", "1"]  # fmt: skip
    assert str(work / "results/c/b4/init.ply") in cmds["train"]  # the job reads the prepared scene

    # the scheduler: scene d's synth fails, so its edi, sfm, init and job are skipped; scene c's chain runs in order
    order = tmp_path / "order.txt"

    def prepare(_work, scene, _spec):
        stages = ("synth", "edi", "sfm", "init")
        code = "raise SystemExit(1)" if scene == "d" else ""
        return [(st, scene, _script(f"open({str(order)!r}, 'a').write('{scene}:{st}\\n'); " + (code if st == "synth"
                                    else ""))) for st in stages]  # fmt: skip

    def commands(_bundle, _res, _work, job, edi_here=False, threads=1):
        return [_script(f"open({str(order)!r}, 'a').write('{job['scene']}:train\\n')"), _script("")]

    monkeypatch.setattr(db, "prepare_commands", prepare)
    monkeypatch.setattr(db, "job_commands", commands)
    rep = db.run_batch(tmp_path / "bundle", tmp_path, work, workers=4, start_until=60, deadline=60)
    assert [x for x in order.read_text().split() if x.startswith("c:")] == ["c:synth", "c:edi", "c:sfm", "c:init",
                                                                              "c:train"]  # fmt: skip
    assert "d:edi" not in order.read_text() and "d:train" not in order.read_text()
    assert rep["prepared"] == {"c": "ok", "d": "synth failed"}
    assert {j["scene"]: j["status"] for j in rep["jobs"]} == {"c": "ok", "d": "skipped: its scene was not prepared"}
    assert (work / "benchmarks" / "sfm" / "c.tsv").is_file()


def test_edi_on_machine_carries_the_events_and_runs_edi_before_the_jobs(tmp_path):
    """A scene whose EDI is made on the machine: its scene file keeps its events, no edi.h5 is carried, one `eigs
    edi` per B runs first with the rules' --config, the jobs read its output; a hidden-ground-truth scene is
    evaluated with --hidden-ground-truth as rules/common_tables.smk asks."""
    import h5py
    import numpy as np

    src = tmp_path / "results" / "s"
    (src / "b4" / "sfm").mkdir(parents=True)
    with h5py.File(src / "scene.h5", "w") as f:
        f["events/binned"] = np.arange(4096, dtype=np.int32).reshape(64, 64)
        f["frames/blurry"] = np.zeros((2, 8, 8, 3), np.uint8)
    for name in ("sfm/poses.h5", "sfm/test_cameras.h5"):
        with h5py.File(src / "b4" / name, "w") as f:
            f["x"] = np.ones(3)
    (src / "b4" / "init.ply").write_bytes(b"ply")
    config = {"scenes": {"s": {"source": "x", "format": "e2nerf-real", "simulate": {"builtin": "chair"},
                               "options": ["--groundtruth", "g.h5"]}},
              "edi": {"bins": [4], "threshold": 0.3}, "evaluate": {"path_frames": 7},
              "runs": {"r": {"method": "eigs", "options": {"steps": 5}}, "q": {"method": "3dgs"}}}  # fmt: skip
    m = db.make_bundle(tmp_path, config, [("s", "r"), ("s", "q")], tmp_path / "bundle", edi_on_machine=("s",))
    assert "s/b4/edi.h5" not in m["files"] and "s/b4/init.ply" in m["files"]
    assert m["edi"] == {"s": {"bins": [4], "edi": '{"threshold":0.3}'}}
    with h5py.File(tmp_path / "bundle" / "s" / "scene.h5") as f:
        assert np.array_equal(f["events/binned"][()], np.arange(4096).reshape(64, 64))  # kept, losslessly
    with pytest.raises(CheckError, match="both"):
        db.make_bundle(tmp_path, config, [("s", "r")], tmp_path / "b2", prepare=("s",), edi_on_machine=("s",))
    with pytest.raises(CheckError, match="no job"):
        db.make_bundle(tmp_path, config, [("s", "r")], tmp_path / "b3", edi_on_machine=("t",))

    work = tmp_path / "work"
    tasks = db.batch_tasks(tmp_path / "bundle", tmp_path, work, m)
    assert [t["stage"] for t in tasks] == ["edi", "train", "evaluate", "train", "evaluate"]
    edi = tasks[0]["cmd"]
    assert edi[edi.index("edi") + 1] == str(tmp_path / "bundle/s/scene.h5")
    assert edi[edi.index("--config") + 1] == '{"threshold":0.3}' and edi[edi.index("--bins") + 1] == "4"
    assert tasks[1]["after"] == 0 and tasks[3]["after"] == 0  # both jobs wait for the EDI file
    train, evaluate = tasks[1]["cmd"], tasks[2]["cmd"]
    assert str(work / "results/s/b4/edi.h5") in train and str(tmp_path / "bundle/s/b4/init.ply") in train
    assert evaluate[evaluate.index("-o") + 2: evaluate.index("--resources")] == ["--path-frames", "7",
                                                                                 "--hidden-ground-truth"]  # fmt: skip
    two = db.batch_tasks(tmp_path / "bundle", tmp_path, work, m, threads=2)
    for t in two:
        assert t["cmd"][t["cmd"].index("--threads") + 1] == "2"
