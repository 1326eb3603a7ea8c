"""bench/cost.py: the step-cost fit recovers known coefficients, the power law its exponent, shapes parse or fail
on one line, and resizing a run's inputs scales images, counts and intrinsics consistently."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import cost  # noqa: E402


def test_linear_fit_recovers_the_line_of_exact_data():
    P = np.array([0.0123, 0.049, 0.09, 0.64])  # noqa: N806
    a, b = cost.fit_linear(P, 0.015 + 1.4 * P)
    assert a == pytest.approx(0.015) and b == pytest.approx(1.4)


def test_thread_ratios_chain_the_small_size_and_the_target_size():
    d = [{"width": w, "height": h, "threads": t, "step_s": s}
         for (w, h, t, s) in ((346, 260, 2, 0.2), (346, 260, 4, 0.1), (800, 800, 4, 0.5), (800, 800, 8, 0.25),
                              (800, 800, 16, 0.2))]  # fmt: skip
    assert cost.thread_ratios(d, 2, 0.64) == {2: 1.0, 8: 4.0, 16: 5.0}
    assert cost.thread_ratios(d[:2], 2, 0.64) == {2: 1.0}  # nothing measured at the target size


def test_power_law_recovers_k_and_alpha():
    x = np.array([10.0, 40.0, 160.0])
    k, alpha = cost.power_law(x, 3.0 * x**1.7)
    assert k == pytest.approx(3.0) and alpha == pytest.approx(1.7)


def test_shapes_parse_or_fail_on_one_line():
    assert cost.parse_shape("346x260:30") == (346, 260, 30)
    assert cost.parse_size("800X800") == (800, 800)
    for bad in ("346x260", "346x260:1", "4x4:10", "axb:3"):
        with pytest.raises(SystemExit, match="cost.py: --"):
            cost.parse_shape(bad)


def test_resized_inputs_scale_images_counts_and_intrinsics():
    import dataclasses

    import torch

    from eigs.artifacts.edi import EdiResult

    v, lat, h, w = 2, 3, 6, 8
    counts = np.arange(v * lat * h * w, dtype=np.int32).reshape(v, lat, h, w)
    edi = EdiResult(latent=np.zeros((v, lat, h, w, 3), np.float32), timestamps_us=np.zeros((v, lat), np.int64),
                    cum_counts=counts, threshold=np.full(v, 0.3), sharp=np.zeros(v, bool),
                    event_count=np.zeros(v, np.int64), events_per_pixel=np.zeros(v), blur_extent_px=np.zeros(v),
                    mode="e2nerf", threshold_scope="given", event_mask=np.eye(h, w, dtype=bool))  # fmt: skip

    fields = {"K": torch.tensor([[10.0, 0, 4], [0, 10.0, 3], [0, 0, 1]]), "width": w, "height": h,
              "latent": torch.rand(v, lat, h, w, 3), "blurry": torch.full((v, h, w, 3), 0.25), "sharp_train": None,
              "edi": edi, "held_out": object()}  # the fields `resized` reads, as TrainData has them
    data = dataclasses.make_dataclass("Data", list(fields))(**fields)
    out = cost.resized(data, 2 * w, 2 * h)
    assert (out.width, out.height) == (16, 12) and out.held_out is None
    torch.testing.assert_close(out.K, torch.tensor([[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]]))
    assert out.blurry.shape == (v, 12, 16, 3) and torch.allclose(out.blurry, torch.full_like(out.blurry, 0.25))
    assert out.latent.shape == (v, lat, 12, 16, 3) and out.edi.latent.shape == (v, lat, 12, 16, 3)
    # nearest: each count is repeated on a 2×2 block, never interpolated
    np.testing.assert_array_equal(out.edi.cum_counts, counts.repeat(2, axis=2).repeat(2, axis=3))
    np.testing.assert_array_equal(out.edi.event_mask, np.eye(h, w, dtype=bool).repeat(2, 0).repeat(2, 1))


def test_model_writes_its_section_from_records(tmp_path):
    steps = tmp_path / "steps.jsonl"
    recs = [{"run": r, "width": w, "height": h, "gaussians": g, "threads": 2, "step_s": k * (0.002 + w * h / 4e6)}
            for r, k in (("3dgs", 1.0), ("eigs+", 5.0)) for w, h in ((128, 96), (346, 260), (800, 800))
            for g in (5_000, 20_000)]  # fmt: skip
    steps.write_text("".join(json.dumps(r) + "\n" for r in recs))
    dev = tmp_path / "dev.jsonl"
    rows = [{"run": "3dgs", "width": w, "height": h, "threads": t, "step_s": s, "machine": "X"}
            for (w, h, t, s) in ((346, 260, 2, 0.2), (346, 260, 4, 0.1), (800, 800, 4, 0.5), (800, 800, 8, 0.25),
                                 (800, 800, 16, 0.125))]  # fmt: skip
    dev.write_text("".join(json.dumps(r) + "\n" for r in rows))
    out = tmp_path / "out"
    cost.main(["model", "--steps", str(steps), "--scaling", str(dev), "--out", str(out)])
    data = json.loads((out / "cost.json").read_text())["data"]["runs"]
    assert data["3dgs"]["thread_speedup"] == {"2": 1.0, "8": 4.0, "16": 8.0}  # 2→4 ×2, then 4→8 ×2, 4→16 ×4
    assert data["eigs+"]["thread_speedup"] == {"2": 1.0}  # eigs+ was not timed on the many-core machine
    assert all(f["max_rel_err"] < 1e-6 for f in data["3dgs"]["fits"]) and len(data["3dgs"]["fits"]) == 2
    # the line through the exact points: 800×800 at 1× (3dgs) the 0.002 + P/4 s of the records
    assert data["3dgs"]["fits"][0]["target_ms"] == pytest.approx(1e3 * (0.002 + 0.64 / 4))
    md = (out / "cost.md").read_text()
    assert "800×800" in md and "| 3dgs | 1000 | 5,000 |" in md and (out / "bench_cost.png").is_file()


def test_step_at_interpolates_in_log_count_and_clamps_outside():
    lines = {5000: (0.010, 1.0), 20000: (0.030, 2.0)}  # at P = 0.5: 0.51 s and 1.03 s
    assert cost.step_at(lines, 5000, 0.5) == pytest.approx(0.51)
    assert cost.step_at(lines, 10000, 0.5) == pytest.approx(0.51 + 0.52 * np.log(2) / np.log(4))  # halfway in log
    assert cost.step_at(lines, 1000, 0.5) == pytest.approx(0.51)
    assert cost.step_at(lines, 90000, 0.5) == pytest.approx(1.03)


def test_train_log_intervals_leave_out_evaluations_and_plateau_is_first_within_tolerance():
    rows = [{"step": s, "wall_s": w, "n_gaussians": g, "psnr_novel": p} for s, w, g, p in (
        (50, 10.0, 100, ""), (100, 20.0, 120, ""), (150, 45.0, 150, "20.0"), (200, 55.0, 150, ""),
        (250, 80.0, 160, "21.8"), (300, 90.0, 170, ""), (350, 115.0, 170, "22.0"))]  # fmt: skip
    assert cost.step_intervals(rows) == [(50, 0.2, 100), (50, 0.2, 150), (50, 0.2, 160)]
    assert cost.plateau_step(rows) == (250, 21.8)
    assert cost.plateau_step(rows, tolerance_db=0.1) == (350, 22.0)
    assert cost.plateau_step(rows[:2]) is None


def test_measured_reads_a_workflow_directory(tmp_path, capsys):
    d = tmp_path / "run"
    (d / "benchmarks" / "edi").mkdir(parents=True)
    (d / "benchmarks" / "edi" / "s_b4.tsv").write_text("s\th:m:s\tmax_rss\tcpu_time\n120.0\t0:02:00\t2048\t200.0\n")
    log = d / "results" / "s" / "b4" / "eigs+" / "train_log.csv"
    log.parent.mkdir(parents=True)
    log.write_text("step,wall_s,n_gaussians,psnr_novel\n50,5,5000,\n100,10,5000,\n150,20,5000,25.0\n200,25,5000,\n")
    cfg = tmp_path / "c.yaml"
    cfg.write_text("scenes:\n  s: {builtin: chair, overrides: {width: 1000, height: 1000, n_train: 10}}\n")
    steps = tmp_path / "steps.jsonl"
    steps.write_text("".join(json.dumps({"run": "eigs+", "gaussians": 5000, "threads": 2, "width": w, "height": h,
                                         "step_s": 0.02 + 0.1 * w * h / 1e6}) + "\n"
                             for w, h in ((128, 96), (346, 260))))  # fmt: skip
    out = tmp_path / "m.json"
    cost.main(["measured", "--directory", str(d), "--config", str(cfg), "--scene", "s", "--runs", "eigs+",
               "--steps", str(steps), "--json", str(out)])  # fmt: skip
    m = json.loads(out.read_text())
    assert m["stages"]["edi"] == {"wall_s": 120.0, "cpu_s": 200.0, "max_rss_gb": 2.0}
    assert m["stages"]["sfm"] is None
    r = m["runs"]["eigs+"]
    assert r["step_ms_median"] == pytest.approx(100.0) and r["steps"] == 200 and r["gaussians_final"] == 5000
    assert r["model_over_measured"] == pytest.approx(1.2)  # the model's 0.12 s a step at 1 MP against 0.1 measured
    assert r["plateau"] == [150, 25.0]
    assert "| eigs+ | 200 |" in capsys.readouterr().out
    # a longer copy of the run, modelled by the configured run's records
    longer = d / "results" / "s" / "b4" / "eigs+long" / "train_log.csv"
    longer.parent.mkdir(parents=True)
    longer.write_text(log.read_text())
    cost.main(["measured", "--directory", str(d), "--config", str(cfg), "--scene", "s", "--runs", "eigs+long",
               "--steps", str(steps), "--json", str(out), "--alias", "eigs+long=eigs+"])  # fmt: skip
    assert json.loads(out.read_text())["runs"]["eigs+long"]["model_over_measured"] == pytest.approx(1.2)
    with pytest.raises(SystemExit, match="--alias"):
        cost.parse_alias("eigs+long")


def test_mean_pairs_counts_one_tile_per_tiny_gaussian_and_none_behind_the_camera():
    """Gaussians of 1/100 pixel at the centres of distinct 16×16 tiles, 1 unit in front of an identity camera, each
    make exactly one (Gaussian, tile) pair; the same Gaussians behind the camera make none."""
    import dataclasses

    import torch

    from eigs.artifacts.gaussians import GaussianCloud

    w, h, f = 64, 48, 100.0
    px = np.array([[8.0, 8.0], [24.0, 8.0], [40.0, 24.0], [56.0, 40.0], [8.0, 40.0]])  # tile centres
    n = len(px)
    means = np.stack([(px[:, 0] - w / 2) / f, (px[:, 1] - h / 2) / f, np.ones(n)], axis=1).astype(np.float32)
    cloud = GaussianCloud(means=means, f_dc=np.zeros((n, 3), np.float32), f_rest=np.zeros((n, 3, 0), np.float32),
                          opacity=np.full(n, 2.0, np.float32), log_scales=np.full((n, 3), np.log(1e-4), np.float32),
                          quats=np.tile(np.float32([1, 0, 0, 0]), (n, 1)))  # fmt: skip
    fields = {"init": cloud, "n_views": 2, "c2w": torch.eye(4, dtype=torch.float64).expand(2, 1, 4, 4),
              "K": torch.tensor([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1]]), "width": w, "height": h}
    data = dataclasses.make_dataclass("Data", list(fields))(**fields)
    assert cost.mean_pairs(data) == float(n)
    behind = dataclasses.replace(cloud, means=means * np.float32([1, 1, -1]))
    assert cost.mean_pairs(dataclasses.replace(data, init=behind)) == 0.0
