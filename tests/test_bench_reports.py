"""bench/render_compare.py and bench/camera_refine_report.py: the panels are the renders times the gain, clipped,
in the order given after the ground truth; the report names the machine of each row's two trainings."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from bench import camera_refine_report, render_compare  # noqa: E402


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
