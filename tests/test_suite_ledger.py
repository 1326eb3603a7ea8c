"""bench/suite_ledger.py on a hand-built workflow directory (two scenes, two runs, no training): `save` copies exactly
the finished jobs' small files, skips jobs already in the ledger unless --replace, `missing` lists exactly the
unfinished targets, the ledger reads as a run for bench/suite_report.py and `eigs tables`, and a malformed benchmark
file is a one-line error naming it."""

from __future__ import annotations

import csv
import json
import sys

import numpy as np
import pytest
import yaml

from bench import schedule, suite_ledger, suite_report
from eigs.evaluate.core import LPIPS_NET, SSIM_TABLE_MODE, per_image_csv
from eigs.tables.rows import configured_rows
from eigs.train.config import TrainConfig
from eigs.util.image import write_png

CONFIG = {
    "scenes": {"alpha": {"builtin": "chair"}, "beta": {"builtin": "tree"}},
    "threads": 1,
    "edi": {"bins": [4]},
    "runs": {"3dgs": {"method": "3dgs", "options": {"steps": 20}}, "eigs": {"method": "eigs"}},
}
HEADER = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
UPSTREAM = ["resources", "synth/alpha", "synth/beta", "edi/alpha_b4", "edi/beta_b4", "sfm/alpha_b4", "sfm/beta_b4",
            "init/alpha_b4", "init/beta_b4"]  # fmt: skip
TRAINED = [("alpha", "3dgs"), ("alpha", "eigs"), ("beta", "3dgs")]  # beta/eigs: still training (no outputs)
EVALUATED = [("alpha", "3dgs"), ("beta", "3dgs")]  # alpha/eigs: outputs but no benchmark file (not finished)
# novel-view PSNR at the held-out steps of each run's train_log.csv
CURVE = {("alpha", "3dgs"): [(0, 18.0), (10, 21.5), (20, 21.25)], ("alpha", "eigs"): [(0, 18.0), (10, 24.0)],
         ("beta", "3dgs"): [(0, 17.0), (10, 20.0), (20, 20.5)], ("beta", "eigs"): [(0, 17.0), (10, 23.0)]}  # fmt: skip
PSNR = {("alpha", "3dgs"): 21.0, ("beta", "3dgs"): 22.0, ("alpha", "eigs"): 25.0, ("beta", "eigs"): 24.0}


def benchmark(path, wall, cpu):
    path.parent.mkdir(parents=True, exist_ok=True)
    cpu_text = cpu if isinstance(cpu, str) else f"{cpu:.2f}"
    row = [f"{wall:.4f}", f"0:00:{int(wall):02d}", "812.3", "2100.5", "790.1", "795.0", "12.1", "3.4", "88.5", cpu_text]
    path.write_text(HEADER + "\t".join(row) + "\n")


def run_folder(d, scene, run):
    """A finished run folder as eigs.train.gaussian.trainer.write_run leaves it (model, config.json, train_log.csv)."""
    d.mkdir(parents=True)
    (d / "model.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nend_header\n" + bytes(4000))
    spec = CONFIG["runs"][run]
    train = TrainConfig.from_dict({"method": spec["method"], **spec.get("options", {})}).to_dict()
    inputs = {"scene": f"results/{scene}/scene.h5", "edi": f"results/{scene}/b4/edi.h5",
              "sfm": f"results/{scene}/b4/sfm", "init": f"results/{scene}/b4/init.ply"}  # fmt: skip
    facts = {"eigs_version": "0", "device": "cpu", "threads": 1, "method_options": {}, "scene": scene,
             "train_seconds": 100.0 + len(run), "n_gaussians": 900, "final": {}}  # fmt: skip
    (d / "config.json").write_text(json.dumps({"train": train, "inputs": inputs, "run": facts}, indent=2) + "\n")
    lines = ["step,wall_s,loss,n_gaussians,psnr_novel,psnr_blur"]
    for step, p in CURVE[(scene, run)]:
        lines += [f"{step},{step * 5.0},0.1,900,{p},{p + 1}", f"{step + 5},{step * 5.0 + 25},0.09,900,,"]
    (d / "train_log.csv").write_text("\n".join(lines) + "\n")


def eval_folder(d, scene, run):
    """metrics.json, per_image.csv and renders/ as eigs.evaluate.core.evaluate_run writes them (a scene with ground
    truth: blur views 0001, 0003 and novel view 0000)."""
    psnr = PSNR[(scene, run)]
    spec = CONFIG["runs"][run]
    steps = TrainConfig.from_dict({"method": spec["method"], **spec.get("options", {})}).steps
    rows = []
    rng = np.random.default_rng(len(scene) + len(run))
    for kind, image, view in (("blur", "0003.png", 3), ("blur", "0001.png", 1), ("novel", "0000.png", 0)):
        write_png(d / "renders" / kind / image, rng.integers(0, 256, (6, 8, 3), dtype=np.uint8))
        write_png(d / "renders" / f"gt_{kind}" / image, rng.integers(0, 256, (6, 8, 3), dtype=np.uint8))
        rows.append({"set": kind, "image": image, "view": view, "camera": "spline", "psnr": psnr, "ssim_3dgs": 0.8,
                     "lpips_alex": 0.2})  # fmt: skip
    group = {"n": 1, "psnr": psnr, "ssim_3dgs": 0.8, "ssim_skimage-gaussian": 0.79, "ssim_deblurnerf": 0.78,
             "ssim_skimage": 0.79, "lpips_alex": 0.2, "lpips_vgg": 0.25}  # fmt: skip
    doc = {"format": "eigs-metrics", "version": 1, "run_dir": f"results/{scene}/b4/{run}", "run": run,
           "method": CONFIG["runs"][run]["method"], "method_options": {}, "scene": scene, "bins": 4,
           "ground_truth": True, "ssim_table_mode": SSIM_TABLE_MODE, "lpips_net": LPIPS_NET,
           "metrics": {"blur": {**group, "n": 2}, "novel": group}, "train_seconds": 100.0 + len(run), "steps": steps,
           "n_gaussians": 900, "n_voxels": None, "fps": 40.0, "render_ms": 25.0, "frames_timed": 3, "device": "cpu",
           "width": 8, "height": 6, "test_cameras": {"spline": 3}, "path": None}  # fmt: skip
    (d / "per_image.csv").write_text(per_image_csv(rows))
    (d / "metrics.json").write_text(json.dumps(doc, indent=2) + "\n")


@pytest.fixture()
def workflow(tmp_path):
    """(config path, workflow directory) of a session that ran part of the tiny config's DAG."""
    cfg = tmp_path / "config.yaml"
    cfg.write_text(yaml.safe_dump(CONFIG))
    d = tmp_path / "run"
    for i, name in enumerate(UPSTREAM):
        benchmark(d / "benchmarks" / f"{name}.tsv", 10.0 + i, 9.0 + i)
    for i, (scene, run) in enumerate(TRAINED):
        run_folder(d / "results" / scene / "b4" / run, scene, run)
        benchmark(d / "benchmarks" / "train" / f"{scene}_b4_{run}.tsv", 300.0 + i, 250.0 + i)
    (d / "results" / "beta" / "b4" / "eigs.partial").mkdir(parents=True)  # a checkpoint of the unfinished run
    (d / "results" / "beta" / "b4" / "eigs.partial" / "checkpoint.pt").write_bytes(bytes(100))
    for scene, run in [*EVALUATED, ("alpha", "eigs")]:
        eval_folder(d / "results" / scene / "b4" / "eval" / run, scene, run)
    for scene, run in EVALUATED:
        benchmark(d / "benchmarks" / "evaluate" / f"{scene}_b4_{run}.tsv", 4.0, "NA" if scene == "beta" else 3.5)
    (d / "logs").mkdir()
    return cfg, d


def files_under(root):
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


def ledger_main(*argv, capsys):
    code = suite_ledger.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(autouse=True)
def no_torch_machine(monkeypatch):
    """The machine line without importing torch (bench._report.machine does)."""
    monkeypatch.setattr(suite_ledger, "_machine", lambda: "Test CPU @ 1 GHz, 2 cores")
    monkeypatch.setattr(suite_report, "machine", lambda: "Test CPU @ 1 GHz, 2 cores")


def test_save_copies_exactly_the_finished_jobs(workflow, tmp_path, capsys):
    cfg, d = workflow
    ledger = tmp_path / "ledger"
    code, out, err = ledger_main("save", "--directory", d, "--config", cfg, "--ledger", ledger, "--commit", "abc123",
                                 capsys=capsys)  # fmt: skip
    assert code == 0, err
    expected = [f"benchmarks/{n}.tsv" for n in UPSTREAM]
    for scene, run in TRAINED:
        expected += [f"benchmarks/train/{scene}_b4_{run}.tsv", f"results/{scene}/b4/{run}/config.json",
                     f"results/{scene}/b4/{run}/train_log.csv"]  # fmt: skip
    for scene, run in EVALUATED:
        e = f"results/{scene}/b4/eval/{run}"
        # the grid's view: the first blur view by name (eigs.tables.figures.grid_view), rendered and ground truth
        expected += [f"benchmarks/evaluate/{scene}_b4_{run}.tsv", f"{e}/metrics.json", f"{e}/per_image.csv",
                     f"{e}/renders/blur/0001.png", f"{e}/renders/gt_blur/0001.png"]  # fmt: skip
    assert files_under(ledger) == sorted([*expected, "jobs.csv"])
    for f in expected:
        assert (ledger / f).read_bytes() == (d / f).read_bytes(), f
    rows = list(csv.DictReader((ledger / "jobs.csv").open()))
    assert [r["job"] for r in rows] == [
        "resources", "scene:alpha", "edi:alpha:4", "sfm:alpha:4", "init:alpha:4", "scene:beta", "edi:beta:4",
        "sfm:beta:4", "init:beta:4", "train:alpha:3dgs", "evaluate:alpha:3dgs", "train:beta:3dgs",
        "evaluate:beta:3dgs", "train:alpha:eigs"]  # fmt: skip
    by_job = {r["job"]: r for r in rows}
    assert by_job["train:alpha:eigs"] | {"date": ""} == {
        "job": "train:alpha:eigs", "benchmark": "train/alpha_b4_eigs", "wall_s": "301.00", "cpu_s": "251.00",
        "threads": "1", "machine": "Test CPU @ 1 GHz, 2 cores", "commit": "abc123", "date": ""}  # fmt: skip
    assert by_job["evaluate:beta:3dgs"]["cpu_s"] == ""  # Snakemake's NA: the job ended before its first sample
    assert by_job["resources"]["date"].endswith("Z")
    assert "saved train:alpha:eigs: 301 s wall, 251 s CPU, 3 files" in out.splitlines()
    # alpha/eigs's evaluation has outputs but no benchmark file: not saved, and said so with the file
    no_bench = d / "benchmarks/evaluate/alpha_b4_eigs.tsv"
    assert f"skipped evaluate:alpha:eigs: outputs but no benchmark file {no_bench}" in out.splitlines()
    assert out.splitlines()[-1] == f"{ledger}: saved 14 jobs, skipped 1"


def test_save_skips_jobs_in_the_ledger_and_replace_overwrites(workflow, tmp_path, capsys):
    cfg, d = workflow
    ledger = tmp_path / "ledger"
    common = ("--directory", d, "--config", cfg, "--ledger", ledger)
    assert ledger_main("save", *common, capsys=capsys)[0] == 0
    before = {f: (ledger / f).read_bytes() for f in files_under(ledger)}
    # a later session re-ran beta/3dgs (another time, another score) and finished beta/eigs
    bench_b3 = "benchmarks/train/beta_b4_3dgs.tsv"
    benchmark(d / bench_b3, 999.0, 900.0)
    m = d / "results/beta/b4/eval/3dgs/metrics.json"
    m.write_text(m.read_text().replace('"psnr": 22.0', '"psnr": 23.5'))
    run_folder(d / "results/beta/b4/eigs", "beta", "eigs")
    benchmark(d / "benchmarks/train/beta_b4_eigs.tsv", 500.0, 480.0)
    code, out, _ = ledger_main("save", *common, capsys=capsys)
    assert code == 0
    saved = [line for line in out.splitlines() if line.startswith("saved ")]
    assert saved == ["saved train:beta:eigs: 500 s wall, 480 s CPU, 3 files"]
    assert "skipped train:beta:3dgs: in the ledger already (--replace to take this run's)" in out
    assert all((ledger / f).read_bytes() == b for f, b in before.items() if f != "jobs.csv")
    code, out, _ = ledger_main("save", *common, "--replace", capsys=capsys)
    assert code == 0
    assert (ledger / bench_b3).read_bytes() == (d / bench_b3).read_bytes()
    doc = json.loads((ledger / "results/beta/b4/eval/3dgs/metrics.json").read_text())
    assert doc["metrics"]["blur"]["psnr"] == 23.5
    rows = list(csv.DictReader((ledger / "jobs.csv").open()))
    assert len(rows) == len({r["job"] for r in rows}) == 15  # one row per job, the replaced ones updated
    assert next(r for r in rows if r["job"] == "train:beta:3dgs")["wall_s"] == "999.00"
    assert not [f for f in files_under(ledger) if "model" in f or "partial" in f or "checkpoint" in f]


def test_save_only_takes_the_matching_jobs(workflow, tmp_path, capsys):
    cfg, d = workflow
    ledger = tmp_path / "ledger"
    common = ("--directory", d, "--config", cfg, "--ledger", ledger)
    assert ledger_main("save", *common, "--commit", "old", capsys=capsys)[0] == 0
    benchmark(d / "benchmarks/train/beta_b4_3dgs.tsv", 999.0, 900.0)  # the one job rerun at a new checkout
    code, out, _ = ledger_main("save", *common, "--replace", "--commit", "new", "--only", "*:beta:3dgs",
                               "--only", "sfm:beta:4", capsys=capsys)  # fmt: skip
    assert code == 0
    saved = {line.removeprefix("saved ").split(": ")[0] for line in out.splitlines() if line.startswith("saved ")}
    assert saved == {"train:beta:3dgs", "evaluate:beta:3dgs", "sfm:beta:4"}
    rows = {r["job"]: r for r in csv.DictReader((ledger / "jobs.csv").open())}
    assert {j for j, r in rows.items() if r["commit"] == "new"} == {"train:beta:3dgs", "evaluate:beta:3dgs",
                                                                    "sfm:beta:4"}  # fmt: skip
    assert rows["train:beta:3dgs"]["wall_s"] == "999.00"
    assert len(rows) == 14


def test_missing_lists_exactly_the_unfinished_targets(workflow, tmp_path, capsys):
    cfg, d = workflow
    ledger = tmp_path / "ledger"
    code, out, _ = ledger_main("missing", "--config", cfg, "--ledger", ledger, capsys=capsys)
    assert code == 0
    everything = out.splitlines()
    assert everything == ["results/alpha/b4/3dgs/config.json", "results/alpha/b4/eval/3dgs/metrics.json",
                          "results/beta/b4/3dgs/config.json", "results/beta/b4/eval/3dgs/metrics.json",
                          "results/alpha/b4/eigs/config.json", "results/alpha/b4/eval/eigs/metrics.json",
                          "results/beta/b4/eigs/config.json", "results/beta/b4/eval/eigs/metrics.json"]  # fmt: skip
    ledger_main("save", "--directory", d, "--config", cfg, "--ledger", ledger, capsys=capsys)
    code, out, _ = ledger_main("missing", "--config", cfg, "--ledger", ledger, capsys=capsys)
    assert out.splitlines() == ["results/alpha/b4/eval/eigs/metrics.json", "results/beta/b4/eigs/config.json",
                                "results/beta/b4/eval/eigs/metrics.json"]  # fmt: skip
    _, out, _ = ledger_main("missing", "--config", cfg, "--ledger", ledger, "--rule", "train", capsys=capsys)
    assert out.splitlines() == ["results/beta/b4/eigs/config.json"]
    _, out, _ = ledger_main("missing", "--config", cfg, "--ledger", ledger, "--count", capsys=capsys)
    assert out.splitlines() == ["train: 3 done, 1 missing", "evaluate: 2 done, 2 missing",
                                "resources: 1 done, 0 missing", "scene: 2 done, 0 missing", "edi: 2 done, 0 missing",
                                "sfm: 2 done, 0 missing", "init: 2 done, 0 missing", "tables: 0 done, 1 missing",
                                "figures: 0 done, 1 missing", "video: 0 done, 2 missing"]  # fmt: skip
    # a job whose benchmark file is there but not its files (an interrupted copy) is missing
    (ledger / "results/alpha/b4/3dgs/train_log.csv").unlink()
    _, out, _ = ledger_main("missing", "--config", cfg, "--ledger", ledger, "--rule", "train", capsys=capsys)
    assert out.splitlines() == ["results/alpha/b4/3dgs/config.json", "results/beta/b4/eigs/config.json"]


def test_a_changed_budget_makes_the_runs_stale_until_pruned_and_rerun(workflow, tmp_path, capsys):
    cfg, d = workflow
    ledger = tmp_path / "ledger"
    common = ("--config", cfg, "--ledger", ledger)
    assert ledger_main("save", "--directory", d, *common, capsys=capsys)[0] == 0
    before = files_under(ledger)
    changed = yaml.safe_load(cfg.read_text())
    changed["runs"]["3dgs"]["options"]["steps"] = 30  # the ledger's 3dgs runs and evaluations have 20
    cfg.write_text(yaml.safe_dump(changed))
    stale = suite_ledger.stale_jobs(changed, ledger)
    assert stale == {f"{rule}:{scene}:3dgs": "steps 20 → 30" for rule in ("train", "evaluate")
                     for scene in ("alpha", "beta")}  # fmt: skip
    for command in ("missing", "tables", "save"):  # every command but prune refuses a ledger with stale jobs
        argv = (command, "--directory", d, *common) if command == "save" else (command, *common)
        code, _, err = ledger_main(*argv, capsys=capsys)
        assert code == 2 and "4 jobs were run with other options than the config" in err and "prune" in err
    assert files_under(ledger) == before
    code, out, _ = ledger_main("prune", *common, capsys=capsys)
    assert code == 0 and "removed 4 jobs" in out and "train:alpha:3dgs: removed (steps 20 → 30)" in out
    assert files_under(ledger) == sorted(f for f in before if "/3dgs/" not in f and "_3dgs" not in f)
    jobs = [r["job"] for r in csv.DictReader((ledger / "jobs.csv").open())]
    assert "train:alpha:eigs" in jobs and not [j for j in jobs if j.endswith(":3dgs")]
    _, out, _ = ledger_main("missing", *common, "--rule", "train", capsys=capsys)
    assert out.splitlines() == ["results/alpha/b4/3dgs/config.json", "results/beta/b4/3dgs/config.json",
                                "results/beta/b4/eigs/config.json"]  # fmt: skip
    # the workflow directory still holds the 20-step runs: save does not take them for the 30-step config
    code, out, _ = ledger_main("save", "--directory", d, *common, capsys=capsys)
    assert code == 0 and "skipped train:alpha:3dgs: trained with other options than the config (steps 20 → 30)" in out
    assert "skipped evaluate:beta:3dgs: trained with other options than the config (steps 20 → 30)" in out
    assert not (ledger / "results/alpha/b4/3dgs").exists()


def test_a_run_older_than_an_option_has_its_default_and_is_stale_only_when_the_config_sets_another(
    workflow, tmp_path, capsys
):
    """A run's config.json written before a TrainConfig key existed lacks it: the run had the default's behaviour."""
    cfg, d = workflow
    ledger = tmp_path / "ledger"
    assert ledger_main("save", "--directory", d, "--config", cfg, "--ledger", ledger, capsys=capsys)[0] == 0
    for config_json in (ledger / "results").glob("*/b4/*/config.json"):
        doc = json.loads(config_json.read_text())
        del doc["train"]["grow_grad2d_renders"]
        config_json.write_text(json.dumps(doc))
    changed = yaml.safe_load(cfg.read_text())
    assert suite_ledger.stale_jobs(changed, ledger) == {}
    changed["runs"]["3dgs"]["options"]["grow_grad2d_renders"] = "norm_sum"
    assert suite_ledger.stale_jobs(changed, ledger) == {
        f"{rule}:{scene}:3dgs": "grow_grad2d_renders vector_sum → norm_sum"
        for rule in ("train", "evaluate") for scene in ("alpha", "beta")
    }


def test_ledger_is_a_run_for_suite_report_and_eigs_tables(workflow, tmp_path, capsys, monkeypatch):
    cfg, d = workflow
    ledger = tmp_path / "ledger"
    ledger_main("save", "--directory", d, "--config", cfg, "--ledger", ledger, capsys=capsys)
    # suite_report's readers: the held-out curve and the job times, as from the workflow directory
    for scene, run in TRAINED:
        assert suite_report.curve(ledger, scene, 4, run) == CURVE[(scene, run)]
        assert suite_report.curve(ledger, scene, 4, run) == suite_report.curve(d, scene, 4, run)
    assert suite_report.job_time(ledger, "train/alpha_b4_eigs", 1) == (301.0, 251.0)
    assert schedule.job_time(ledger, "sfm/beta_b4", 2) == (16.0, 7.5)  # bench/schedule.py reads it unchanged
    assert suite_report.job_time(ledger, "evaluate/beta_b4_3dgs", 1) == (4.0, 4.0)  # NA CPU: the wall time
    assert suite_report.job_time(ledger, "train/beta_b4_eigs", 1) is None
    # Tables I-V with the workflow's row mapping (eigs.tables.rows.configured_rows, which rule tables passes)
    mapping = configured_rows(None, yaml.safe_load(cfg.read_text())["runs"])
    assert mapping["table1"]["3dgs"] == "3dgs" and mapping["table1"]["eigs"] == "eigs"
    assert mapping["table1"]["e2gs"] is None and mapping["table3"]["4"] is None  # eigs+ is not configured
    assert mapping["table2"]["ours"] == "eigs" and "ladder" not in mapping  # no ladder run: no ladder table
    code, out, err = ledger_main("tables", "--config", cfg, "--ledger", ledger, capsys=capsys)
    assert code == 0, err
    per_scene = list(csv.DictReader((ledger / "tables" / "per_scene.csv").open()))
    assert sorted((r["run"], r["scene"], float(r["psnr"])) for r in per_scene) == [("3dgs", "alpha", 21.0),
                                                                                   ("3dgs", "beta", 22.0)]  # fmt: skip
    t1 = list(csv.DictReader((ledger / "tables" / "table1.csv").open()))
    row = next(r for r in t1 if r["row"] == "3dgs")
    assert float(row["psnr"]) == pytest.approx(21.5) and row["run"] == "3dgs"
    assert "results/{alpha,beta}/b4/3dgs" in (ledger / "tables" / "table1.md").read_text()
    assert (ledger / "figures" / "curves.png").stat().st_size > 0 and (ledger / "figures" / "pareto.png").exists()
    assert "no qualitative grids" in out
    # suite_report on the ledger: the training runs' times and plateau check, and the ledger's tables
    report = tmp_path / "suite.md"
    monkeypatch.setattr(sys, "argv", ["suite_report.py", "--directory", str(ledger), "--config", str(cfg),
                                      "--out", str(report)])  # fmt: skip
    suite_report.main()
    text = report.read_text()
    assert "14 of 21 jobs have run" in text
    # 3dgs: CPU s mean (250, 252), wall (300, 302), final PSNR (21.25, 20.5), largest gap 0.25 (alpha)
    assert "| 3dgs | 3dgs | 20 | 2 | 251 | 301 | 20.88 | 0.25 | yes |" in text
    assert "## Tables" in text and "## Schedule" not in text and "## Plateau references" not in text
    # plateau references (bench/plateau_reference.py): the suite run's final PSNR against the longer run's best
    for scene, ref in (("alpha", [(0, 18.0), (20, 21.0), (40, 21.7), (60, 21.6)]), ("beta", [(20, 20.6), (40, 20.1)])):
        log = ledger / "plateau" / f"{scene}_b4_3dgs" / "train_log.csv"
        log.parent.mkdir(parents=True)
        log.write_text("step,loss,psnr_novel\n" + "".join(f"{st},0.1,{p}\n{st + 5},0.1,\n" for st, p in ref))
    assert suite_report.reference_curve(ledger, "beta", 4, "3dgs") == [(20, 20.6), (40, 20.1)]
    suite_report.main()
    text = report.read_text()
    # alpha: final 21.25, reference best 21.7 at step 40: short by 0.45; beta: final 20.5, best 20.6: 0.10
    assert "| 3dgs | alpha | 20 | 21.25 | 60 | 21.70 (40) | 21.60 | +0.45 | **no** |" in text
    assert "| 3dgs | beta | 20 | 20.50 | 40 | 20.60 (20) | 20.10 | +0.10 | yes |" in text


def test_report_spliced_into_a_readme_block():
    doc = "# Project\n\nintro\n<!-- suite-report:begin -->\nold report\n<!-- suite-report:end -->\n\n## After\n"
    report = "# The default suite, measured\n\nWritten by x.\n\n## Time per stage\n\n| a |\n|---|\n"
    out = suite_report.splice(doc, report)
    assert out == ("# Project\n\nintro\n<!-- suite-report:begin -->\n\nWritten by x.\n\n### Time per stage\n\n| a |\n"
                   "|---|\n\n<!-- suite-report:end -->\n\n## After\n")  # fmt: skip
    assert suite_report.splice(out, report) == out  # idempotent
    with pytest.raises(ValueError, match="NOTES.md: no `<!-- suite-report:begin -->`"):
        suite_report.splice("# Project\n", report, "NOTES.md")


def complete_ledger(workflow, tmp_path, capsys):
    """The hand-built workflow with its last training and evaluations added, saved as a ledger: (config, ledger)."""
    cfg, d = workflow
    run_folder(d / "results/beta/b4/eigs", "beta", "eigs")
    benchmark(d / "benchmarks/train/beta_b4_eigs.tsv", 500.0, 480.0)
    eval_folder(d / "results/beta/b4/eval/eigs", "beta", "eigs")
    for scene in ("alpha", "beta"):
        benchmark(d / "benchmarks" / "evaluate" / f"{scene}_b4_eigs.tsv", 5.0, 4.0)
    ledger = tmp_path / "ledger"
    ledger_main("save", "--directory", d, "--config", cfg, "--ledger", ledger, capsys=capsys)
    return cfg, ledger


def test_schedule_of_a_complete_ledger_without_tables_and_figures_jobs(workflow, tmp_path, capsys, monkeypatch):
    cfg, ledger = complete_ledger(workflow, tmp_path, capsys)
    _, out, _ = ledger_main("missing", "--config", cfg, "--ledger", ledger, capsys=capsys)
    assert out == ""
    report = tmp_path / "suite.md"
    monkeypatch.setattr(sys, "argv", ["suite_report.py", "--directory", str(ledger), "--config", str(cfg),
                                      "--out", str(report)])  # fmt: skip
    suite_report.main()
    text = report.read_text()
    assert "## Schedule" in text and "the figures and tables and video jobs not measured, counted as 0 s" in text


def test_speedups_scale_only_the_listed_runs_trainings(tmp_path):
    times = {"train:a:eigs+": 100.0, "train:b:eigs+": 50.0, "train:a:3dgs": 10.0, "evaluate:a:eigs+": 4.0,
             "sfm:a:4": 30.0}  # fmt: skip
    got = schedule.sped_up(times, {"eigs+": 0.5, "nerf": 2.0})
    assert got == {"train:a:eigs+": 50.0, "train:b:eigs+": 25.0, "train:a:3dgs": 10.0, "evaluate:a:eigs+": 4.0,
                   "sfm:a:4": 30.0}  # fmt: skip
    # one core runs everything one after the other: the makespan is the sum of the job times
    jobs = {j: (j, [], 1) for j in times}
    assert schedule.simulate(jobs, got, 1) == pytest.approx(sum(got.values()))
    good = tmp_path / "s.json"
    good.write_text(json.dumps({"factors": {"eigs+": 0.7}}))
    assert schedule.load_speedups(good) == {"eigs+": 0.7}
    for doc in ({"eigs+": 0.7}, {"factors": {"eigs+": -1}}, {"factors": {"eigs+": "nan"}}, "x"):
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps(doc))
        with pytest.raises(schedule.LedgerError, match="bad.json"):
            schedule.load_speedups(bad)


def test_speedups_skip_the_jobs_trained_at_or_after_their_measurement(tmp_path):
    """A factor (now / then, "now" measured at commit M, "then" at the run's ``against``) scales the jobs trained
    before M only: jobs recorded at M or at a descendant of it are already today's, and jobs recorded after the
    commit the factor was measured against are left as recorded too (a scratch git repository: A <- M <- B)."""
    import subprocess

    repo = tmp_path / "repo"
    repo.mkdir()

    def git(*a: str) -> str:
        return subprocess.run(["git", "-C", str(repo), *a], check=True, capture_output=True, text=True).stdout.strip()

    git("init", "-q")
    commits = []
    for name in ("a", "m", "b"):
        git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "--allow-empty", "-m", name)
        commits.append(git("rev-parse", "HEAD"))
    a, m, b = commits
    ledger = tmp_path / "ledger"
    ledger.mkdir()
    with (ledger / "jobs.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["job", "benchmark", "wall_s", "cpu_s", "threads", "machine", "commit", "date"])
        for job, c in (("train:x:nerf", a), ("train:y:nerf", m[:7]), ("train:z:nerf", b), ("sfm:x:4", b),
                       ("train:w:nerf", "0" * 40)):  # fmt: skip
            w.writerow([job, "", 1, 1, 1, "pc, 2 cores", c, "2026-12-01"])
    current = schedule.jobs_trained_since(ledger, m[:7], repo=repo)
    assert current == {"train:y:nerf", "train:z:nerf"}  # A before M, an unknown commit counts as older
    times = {"train:x:nerf": 10.0, "train:y:nerf": 10.0, "train:z:nerf": 10.0, "train:w:nerf": 10.0}
    got = schedule.sped_up(times, {"nerf": 0.5}, current)
    assert got == {"train:x:nerf": 5.0, "train:y:nerf": 10.0, "train:z:nerf": 10.0, "train:w:nerf": 5.0}
    assert schedule.jobs_trained_since(tmp_path, m) == set()  # no jobs.csv
    doc = tmp_path / "s.json"
    doc.write_text(json.dumps({"factors": {"nerf": 0.5}, "measured_at": m[:7]}))
    assert schedule.speedups_measured_at(doc) == m[:7]
    doc.write_text(json.dumps({"factors": {"nerf": 0.5}}))
    assert schedule.speedups_measured_at(doc) is None
    # a factor measured against A scales the jobs trained at A or before it only: train:y (at M) and train:z (at B)
    # were retrained after A; an unknown commit counts as older
    assert schedule.jobs_past_their_factor(ledger, {"nerf": a[:7]}, repo=repo) == {"train:y:nerf", "train:z:nerf"}
    assert schedule.jobs_past_their_factor(ledger, {"nerf": b}, repo=repo) == set()
    assert schedule.jobs_past_their_factor(ledger, {"eigs": a}, repo=repo) == set()  # another run's factor
    doc.write_text(json.dumps({"factors": {"nerf": 0.5}, "measured_at": b, "against": {"nerf": a}}))
    assert schedule.speedups_against(doc) == {"nerf": a}
    assert schedule.unscaled_jobs(ledger, doc, repo=repo) == ({"train:y:nerf", "train:z:nerf"}, b)


def test_suite_report_adds_the_schedule_with_the_speedups(workflow, tmp_path, capsys, monkeypatch):
    cfg, ledger = complete_ledger(workflow, tmp_path, capsys)
    speed = tmp_path / "speed.json"
    speed.write_text(json.dumps({"factors": {"eigs": 0.5}}))
    report = tmp_path / "suite.md"
    monkeypatch.setattr(sys, "argv", ["suite_report.py", "--directory", str(ledger), "--config", str(cfg),
                                      "--out", str(report), "--speedups", str(speed)])  # fmt: skip
    suite_report.main()
    rows = [ln for ln in report.read_text().split("## Schedule")[1].splitlines() if ln.startswith("| 1 |")]
    hours, scaled = (float(v) for v in rows[0].strip("| ").split(" | ")[1:3])
    assert scaled < hours and "`eigs` 0.50" in report.read_text()


@pytest.mark.parametrize(
    "content",
    [
        "",
        "garbage without tabs\n",
        HEADER.replace("cpu_time", "cpu") + "1\t0:00:01\t1\t1\t1\t1\t1\t1\t1\t1\n",
        HEADER + "soon\t0:00:01\t1\t1\t1\t1\t1\t1\t1\t1\n",
    ],
    ids=["empty", "not-tsv", "no-cpu-column", "not-a-number"],
)
def test_malformed_benchmark_is_a_one_line_error_naming_it(workflow, tmp_path, capsys, monkeypatch, content):
    cfg, d = workflow
    bad = d / "benchmarks" / "sfm" / "beta_b4.tsv"
    bad.write_text(content)
    ledger = tmp_path / "ledger"
    code, out, err = ledger_main("save", "--directory", d, "--config", cfg, "--ledger", ledger, capsys=capsys)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and err.startswith(f"suite_ledger.py save: error: {bad}: ")
    assert "Traceback" not in err and not ledger.exists()  # checked before anything is written
    # suite_report on a directory with the same file: one line naming it, not a traceback
    monkeypatch.setattr(sys, "argv", ["suite_report.py", "--directory", str(d), "--config", str(cfg), "--out",
                                      str(tmp_path / "suite.md")])  # fmt: skip
    with pytest.raises(SystemExit) as exc:
        suite_report.main()
    msg = str(exc.value)
    assert msg.startswith(f"suite_report.py: error: {bad}: ") and "\n" not in msg


def test_unreadable_config_and_metrics_are_one_line_errors(workflow, tmp_path, capsys):
    cfg, d = workflow
    code, _, err = ledger_main("missing", "--config", tmp_path / "nope.yaml", capsys=capsys)
    assert code == 2 and err.startswith(f"suite_ledger.py missing: error: {tmp_path / 'nope.yaml'}: ")
    m = d / "results/beta/b4/eval/3dgs/metrics.json"
    m.write_text("{")
    code, _, err = ledger_main("save", "--directory", d, "--config", cfg, "--ledger", tmp_path / "l", capsys=capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and str(m) in err
    code, _, err = ledger_main("tables", "--config", cfg, "--ledger", tmp_path / "empty", capsys=capsys)
    assert code == 2 and "no evaluated run in the ledger" in err


def test_read_benchmark_na_cpu_and_missing_file(tmp_path):
    p = tmp_path / "benchmarks" / "tables.tsv"
    benchmark(p, 0.41, "NA")  # a job that ended before Snakemake's first sample
    assert schedule.read_benchmark(p) == (0.41, None)
    assert schedule.job_time(tmp_path, "tables", 1) == (0.41, 0.41)
    assert schedule.job_time(tmp_path, "figures", 1) is None  # not run
    with pytest.raises(suite_ledger.LedgerError) as exc:
        schedule.read_benchmark(tmp_path / "nope.tsv")
    assert str(exc.value).startswith(f"{tmp_path / 'nope.tsv'}: cannot read the benchmark file")


def test_job_time_prefers_a_training_runs_own_cpu_seconds(tmp_path):
    """A run that recorded ``process_cpu_s`` gives its CPU seconds (the benchmark file's sampled CPU time misses up to
    30 s of a job's end); without it, a damaged config or for other rules, the benchmark file's; per thread both."""
    benchmark(tmp_path / "benchmarks" / "train" / "my_scene_b6_eigs+.tsv", 300.0, 250.0)
    benchmark(tmp_path / "benchmarks" / "sfm" / "my_scene_b6.tsv", 50.0, 40.0)
    run = tmp_path / "results" / "my_scene" / "b6" / "eigs+"
    run.mkdir(parents=True)
    assert schedule.job_time(tmp_path, "train/my_scene_b6_eigs+", 1) == (300.0, 250.0)
    (run / "config.json").write_text(json.dumps({"run": {"process_cpu_s": 280.5}}))
    assert schedule.job_time(tmp_path, "train/my_scene_b6_eigs+", 2) == (300.0, 140.25)
    assert schedule.job_time(tmp_path, "train/my_scene_b6_eigs+", 1) == (300.0, 280.5)
    assert schedule.job_time(tmp_path, "sfm/my_scene_b6", 2) == (50.0, 20.0)
    (run / "config.json").write_text('{"run": {"process_cpu_s": NaN}}')
    assert schedule.job_time(tmp_path, "train/my_scene_b6_eigs+", 1) == (300.0, 250.0)
    (run / "config.json").write_text("{trunc")
    assert schedule.job_time(tmp_path, "train/my_scene_b6_eigs+", 1) == (300.0, 250.0)
    # resumed from a checkpoint at step 1500: its process and benchmark saw only the rest; its training seconds stand
    (run / "config.json").write_text(json.dumps({"run": {"process_cpu_s": 49.5, "train_seconds": 277.6,
                                                         "resumed_at_step": 1500}}))  # fmt: skip
    assert schedule.job_time(tmp_path, "train/my_scene_b6_eigs+", 1) == (300.0, 277.6)
    (run / "config.json").write_text(json.dumps({"run": {"process_cpu_s": 49.5, "resumed_at_step": 0}}))
    assert schedule.job_time(tmp_path, "train/my_scene_b6_eigs+", 1) == (300.0, 49.5)


def test_a_device_batch_directory_names_the_machine_it_ran_on(tmp_path):
    from bench.suite_ledger import LedgerError, batch_machine

    assert batch_machine(tmp_path) is None  # a workflow directory of this machine
    (tmp_path / "batch.json").write_text('{"cpu": "Intel(R) Xeon(R) Processor", "cores": 16, "workers": 14}')
    assert batch_machine(tmp_path) == "Intel(R) Xeon(R) Processor, 16 cores, device_batch: 14 one-thread jobs at a time"
    (tmp_path / "batch.json").write_text('{"cpu": "X", "cores": 16, "workers": 8, "threads_per_job": 2}')
    assert batch_machine(tmp_path) == "X, 16 cores, device_batch: 8 jobs of 2 threads at a time"
    (tmp_path / "batch.json").write_text('{"cpu": "x"}')
    with pytest.raises(LedgerError, match="batch.json"):
        batch_machine(tmp_path)


def test_merge_moves_a_second_ledgers_jobs_with_their_provenance(workflow, tmp_path, capsys):
    cfg, d = workflow
    ledger, retrained = tmp_path / "ledger", tmp_path / "retrained"
    assert ledger_main("save", "--directory", d, "--config", cfg, "--ledger", ledger, "--commit", "old",
                       capsys=capsys)[0] == 0  # fmt: skip
    # the 3dgs budget changes: the ledger's 3dgs jobs are stale; beta's is retrained into a second ledger
    changed = yaml.safe_load(cfg.read_text())
    changed["runs"]["3dgs"]["options"]["steps"] = 30
    cfg.write_text(yaml.safe_dump(changed))
    for rel in ("results/beta/b4/3dgs/config.json", "results/beta/b4/eval/3dgs/metrics.json"):
        doc = json.loads((d / rel).read_text())
        if "train" in doc:
            doc["train"]["steps"] = 30
        else:
            doc["steps"] = 30
        (d / rel).write_text(json.dumps(doc))
    benchmark(d / "benchmarks/train/beta_b4_3dgs.tsv", 777.0, 700.0)
    code, out, err = ledger_main("save", "--directory", d, "--config", cfg, "--ledger", retrained, "--commit", "new",
                                 "--only", "*:beta:3dgs", capsys=capsys)  # fmt: skip
    assert code == 0, err
    before = files_under(ledger)
    code, out, err = ledger_main("merge", "--source", retrained, "--config", cfg, "--ledger", ledger, capsys=capsys)
    assert code == 0, err
    assert out.splitlines()[-1] == f"{ledger}: moved 2 jobs from {retrained}"
    assert files_under(ledger) == before  # the same files, beta's 3dgs now the retrained one
    for f in files_under(retrained):
        if f != "jobs.csv":
            assert (ledger / f).read_bytes() == (retrained / f).read_bytes(), f
    rows = {r["job"]: r for r in csv.DictReader((ledger / "jobs.csv").open())}
    assert rows["train:beta:3dgs"]["commit"] == "new" and rows["train:beta:3dgs"]["wall_s"] == "777.00"
    assert rows["train:alpha:3dgs"]["commit"] == "old"
    # alpha's 3dgs is still stale: prune takes it out, and then the ledger is current
    assert set(suite_ledger.stale_jobs(changed, ledger)) == {"train:alpha:3dgs", "evaluate:alpha:3dgs"}
    assert ledger_main("prune", "--config", cfg, "--ledger", ledger, capsys=capsys)[0] == 0
    assert suite_ledger.stale_jobs(changed, ledger) == {}
    # a source that is itself stale is refused before anything is written
    changed["runs"]["3dgs"]["options"]["steps"] = 40
    cfg.write_text(yaml.safe_dump(changed))
    now = {f: (ledger / f).read_bytes() for f in files_under(ledger)}
    code, _, err = ledger_main("merge", "--source", retrained, "--config", cfg, "--ledger", ledger, capsys=capsys)
    assert code == 2 and "2 jobs were run with other options than the config" in err
    assert {f: (ledger / f).read_bytes() for f in files_under(ledger)} == now
