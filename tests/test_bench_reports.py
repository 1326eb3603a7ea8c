"""bench/render_compare.py, bench/camera_refine_report.py and bench/latent_dssim_report.py: the panels are the renders
times the gain, clipped, in the order given after the ground truth; the camera report names the machine of each row's
two trainings; the latent report's margins and means against eigs+ are those of hand-made metrics."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench import camera_refine_report, latent_dssim_report, render_compare  # noqa: E402


def test_a_panel_is_the_image_times_the_gain_clipped_under_its_label():
    img = np.array([[[10, 70, 0]], [[64, 200, 255]]], dtype=np.uint8)  # (2, 1, 3)
    out = render_compare.panel(img, "x", 4.0)
    assert out.shape == (2 + render_compare.LABEL_PX, 1, 3)
    assert out[render_compare.LABEL_PX:].tolist() == [[[40, 255, 0]], [[255, 255, 255]]]


def test_the_figure_puts_the_ground_truth_first_and_each_run_in_order(tmp_path):
    h, w = 8, 5
    for name, value in (("a", 10), ("b", 20)):
        for group, v in (("novel", value), ("gt_novel", 30)):
            d = tmp_path / name / "renders" / group
            d.mkdir(parents=True)
            Image.fromarray(np.full((h, w, 3), v, np.uint8)).save(d / "0003.png")
    out = tmp_path / "fig.png"
    subprocess.run([sys.executable, str(ROOT / "bench" / "render_compare.py"), "--view", "3", "--gain", "2",
                    "--out", str(out), f"A={tmp_path / 'a'}", f"B={tmp_path / 'b'}"], check=True)  # fmt: skip
    fig = np.asarray(Image.open(out))
    assert fig.shape == (h + render_compare.LABEL_PX, 3 * w, 3)
    assert [int(fig[-1, i * w, 0]) for i in range(3)] == [60, 20, 40]
    bad = subprocess.run([sys.executable, str(ROOT / "bench" / "render_compare.py"), "--view", "4", "--out",
                          str(out), f"A={tmp_path / 'a'}"], capture_output=True, text=True)  # fmt: skip
    assert bad.returncode != 0 and "0004.png: no such render" in bad.stderr


def test_the_report_names_the_machine_of_each_rows_two_trainings(tmp_path):
    jobs = tmp_path / "jobs.csv"
    jobs.write_text(
        "job,benchmark,wall_s,cpu_s,threads,machine,commit,date\n"
        'train:s:eigs+,x,1,1,1,"AMD EPYC, 2 cores",c,d\n'
        'train:s:eigs+-cam,x,1,1,1,"AMD EPYC, 2 cores",c,d\n'
        'train:s:oracle,x,1,1,1,"Intel(R) Xeon(R) Processor, 2 cores",c,d\n'
        'train:s:oracle-cam,x,1,1,1,"AMD EPYC, 2 cores",c,d\n'
        'evaluate:s:edi-3dgs,x,1,1,1,"Intel(R) Xeon(R) Processor, 2 cores",c,d\n'
    )
    seen = camera_refine_report.trainings([tmp_path, tmp_path / "no-ledger"])
    assert seen == {("s", "eigs+"): "AMD EPYC", ("s", "eigs+-cam"): "AMD EPYC", ("s", "oracle"): "Intel Xeon",
                    ("s", "oracle-cam"): "AMD EPYC"}  # fmt: skip
    assert camera_refine_report.machine_of(seen, "s", "eigs+") == "AMD EPYC"
    assert camera_refine_report.machine_of(seen, "s", "oracle") == "AMD EPYC / Intel Xeon"
    assert camera_refine_report.machine_of(seen, "s", "edi-3dgs") == "–"  # evaluated, never trained here


def _metrics(root: Path, scene: str, run: str, psnr: float, lpips: float, cpu: float | None) -> None:
    ev = root / scene / "b4" / "eval" / run
    ev.mkdir(parents=True)
    doc = {"metrics": {"novel": {"psnr": psnr, "ssim_3dgs": 0.9, "lpips_alex": lpips, "coherence": 0.5},
                       "all": {"brisque": 40.0}}, "n_gaussians": 1000, "train_seconds": 99.0}  # fmt: skip
    (ev / "metrics.json").write_text(json.dumps(doc))
    if cpu is not None:
        (root / scene / "b4" / run).mkdir(parents=True)
        (root / scene / "b4" / run / "config.json").write_text(json.dumps({"run": {"process_cpu_s": cpu}}))


def test_the_latent_report_closes_margins_and_averages_against_eigs_plus(tmp_path):
    for run, psnr, lpips, cpu in (("edi-3dgs", 30.0, 0.20, 10.0), ("oracle", 32.0, 0.10, 10.0),
                                  ("eigs+", 31.0, 0.25, 100.0), ("eigs+-ds", 31.5, 0.15, 150.0)):  # fmt: skip
        _metrics(tmp_path, "d346-x", run, psnr, lpips, cpu)
    for scene, base, cand in (("a", 28.0, 28.4), ("b", 30.0, 29.8)):
        _metrics(tmp_path, scene, "eigs+", base, 0.06, 100.0)
        _metrics(tmp_path, scene, "eigs+-ld", cand, 0.05, None)  # no run folder: no CPU seconds
    _metrics(tmp_path, "c", "eigs+-ld", 27.0, 0.05, None)  # no eigs+ on c: left out of the means
    text, data = latent_dssim_report.report(latent_dssim_report.read([tmp_path]))
    assert data["d346-x/eigs+"]["margin"] == 0.5 and data["d346-x/eigs+-ds"]["margin"] == 0.75
    assert data["d346-x/oracle"]["margin"] == 1.0
    assert abs(data["346×260/eigs+-ds-minus-eigs+"]["lpips_alex"] + 0.10) < 1e-12
    assert data["346×260/eigs+-ds-minus-eigs+"]["train_ratio"] == 1.5
    mean = data["128×96/eigs+-ld-minus-eigs+"]
    assert mean["scenes"] == 2 and abs(mean["psnr"] - 0.1) < 1e-12 and math.isnan(mean["train_ratio"])
    assert "| d346-x | `eigs+-ds` | 31.50 |" in text and "75 %" in text
    assert "resumed" not in text


def test_the_latent_report_leaves_out_the_cpu_of_a_resumed_run(tmp_path):
    _metrics(tmp_path, "d346-x", "eigs+-l2d", 31.0, 0.2, 50.0)
    cfg = tmp_path / "d346-x" / "b4" / "eigs+-l2d" / "config.json"
    cfg.write_text(json.dumps({"run": {"process_cpu_s": 50.0, "resumed_at_step": 1500}}))
    text, data = latent_dssim_report.report(latent_dssim_report.read([tmp_path]))
    assert math.isnan(data["d346-x/eigs+-l2d"]["cpu_s"])
    assert "d346-x `eigs+-l2d` resumed at step 1500" in text

