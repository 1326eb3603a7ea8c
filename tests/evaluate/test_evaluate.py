"""eigs evaluate: what is rendered and saved, and that metrics.json agrees with `eigs metric` on the saved renders
and with a float64 PSNR computed here from the PNGs."""

from __future__ import annotations

import csv
import json

import cv2
import numpy as np
import pytest

from eigs.cli import main
from eigs.errors import EigsError
from eigs.evaluate.core import evaluate_run
from tests.evaluate.fixtures import make_case


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory, resources_dir):
    root = tmp_path_factory.mktemp("evalsyn")
    case = make_case(root)
    out = root / "eval" / "metrics.json"
    code = main(["evaluate", str(case["run"]), str(case["scene"]), str(case["sfm"]), "-o", str(out),
                 "--resources", str(resources_dir), "--threads", "1"])  # fmt: skip
    assert code == 0
    return case, out, json.loads(out.read_text())


def read_rgb(path):
    return cv2.imread(str(path), cv2.IMREAD_COLOR)[..., ::-1]


def cli_mean(capsys, *args) -> float:
    capsys.readouterr()
    assert main(["metric", *map(str, args)]) == 0
    return float(capsys.readouterr().out.strip().splitlines()[-1])


def test_layout_and_run_facts(synthetic):
    case, out, doc = synthetic
    renders = out.parent / "renders"
    assert sorted(p.name for p in (renders / "blur").iterdir()) == ["0000.png", "0001.png"]
    assert sorted(p.name for p in (renders / "novel").iterdir()) == ["0002.png", "0003.png"]
    assert doc["ground_truth"] is True and doc["metrics"]["blur"]["n"] == 2 and doc["metrics"]["novel"]["n"] == 2
    assert doc["n_gaussians"] == 300 and doc["train_seconds"] == 12.5 and doc["steps"] == 10
    assert doc["fps"] > 0 and doc["frames_timed"] == 4 and doc["test_cameras"]["given"] == 4
    assert doc["bins"] == 4 and doc["run"] == "run"
    # a scene with ground truth is scored by the reference metrics only: no BRISQUE (issue 20's skips)
    assert set(doc["metrics"]) == {"blur", "novel"} and not any("brisque" in g for g in doc["metrics"].values())
    # the ground truth saved beside the renders is the scene's, bit for bit
    from eigs.scene import read_scene

    sharp = read_scene(case["scene"], events=False).sharp
    for i in range(4):
        kind = "blur" if i < 2 else "novel"
        np.testing.assert_array_equal(read_rgb(renders / f"gt_{kind}" / f"{i:04d}.png"), sharp.images[i])


def test_psnr_matches_float64_from_the_pngs(synthetic):
    _, out, doc = synthetic
    renders = out.parent / "renders"
    for kind in ("blur", "novel"):
        vals = []
        for f in sorted((renders / kind).iterdir()):
            a = read_rgb(f).astype(np.float64) / 255
            b = read_rgb(renders / f"gt_{kind}" / f.name).astype(np.float64) / 255
            vals.append(10 * np.log10(1 / np.mean((a - b) ** 2)))
        assert doc["metrics"][kind]["psnr"] == pytest.approx(np.mean(vals), abs=1e-9)
        assert 3 < doc["metrics"][kind]["psnr"] < 40  # a real comparison, not identical images


def test_metrics_agree_with_eigs_metric_on_the_saved_renders(synthetic, capsys, resources_dir):
    _, out, doc = synthetic
    r = out.parent / "renders"
    for kind in ("blur", "novel"):
        m = doc["metrics"][kind]
        assert cli_mean(capsys, "psnr", r / kind, r / f"gt_{kind}") == pytest.approx(m["psnr"], abs=1e-4)
        for mode in ("3dgs", "skimage-gaussian", "deblurnerf"):
            got = cli_mean(capsys, "ssim", r / kind, r / f"gt_{kind}", "--mode", mode)
            assert got == pytest.approx(m[f"ssim_{mode}"], abs=1e-5)
        got = cli_mean(capsys, "lpips", r / kind, r / f"gt_{kind}", "--net", "alex", "--resources", resources_dir)
        assert got == pytest.approx(m["lpips_alex"], abs=1e-5)
        assert cli_mean(capsys, "sharpness", r / kind, r / f"gt_{kind}") == pytest.approx(m["sharpness"], rel=1e-6)
        assert m["sharpness_undefined"] == 0 and 0 < m["sharpness"]
        assert cli_mean(capsys, "coherence", r / kind, r / f"gt_{kind}") == pytest.approx(m["coherence"], rel=1e-6)
        # Cauchy-Schwarz: the detail kept cannot carry more power than the render has in the band
        assert m["coherence_undefined"] == 0 and m["coherence"] ** 2 <= m["sharpness"] + 1e-9


def test_a_flat_ground_truth_has_no_sharpness_and_is_counted(resources_dir, caplog):
    from eigs.evaluate.core import group_means, score_pair

    rng = np.random.default_rng(3)
    render = rng.integers(0, 256, (32, 40, 3), dtype=np.uint8)
    textured = score_pair(render, rng.integers(0, 256, (32, 40, 3), dtype=np.uint8), str(resources_dir))
    flat = score_pair(render, np.full((32, 40, 3), 40, dtype=np.uint8), str(resources_dir))
    assert np.isnan(flat["sharpness"]) and np.isfinite(flat["psnr"]) and textured["sharpness"] > 0
    assert np.isnan(flat["coherence"]) and np.isfinite(textured["coherence"])
    # the render is itself its ground truth: all of the detail, in phase
    assert score_pair(render, render, str(resources_dir))["coherence"] == pytest.approx(1.0, abs=1e-12)
    with caplog.at_level("WARNING", logger="eigs.evaluate"):
        g = group_means("novel", [textured, flat])
    assert g["n"] == 2 and g["sharpness_undefined"] == 1 and g["sharpness"] == textured["sharpness"]
    assert g["coherence_undefined"] == 1 and g["coherence"] == textured["coherence"]
    assert g["psnr"] == pytest.approx((textured["psnr"] + flat["psnr"]) / 2)
    assert "1 of 2 views have a flat ground truth; sharpness undefined" in caplog.text
    assert "1 of 2 views have a flat ground truth; coherence undefined" in caplog.text


def test_per_image_csv_rows(synthetic):
    _, out, doc = synthetic
    rows = list(csv.DictReader((out.parent / "per_image.csv").open()))
    assert [(r["set"], r["image"]) for r in rows] == [("blur", "0000.png"), ("blur", "0001.png"),
                                                     ("novel", "0002.png"), ("novel", "0003.png")]  # fmt: skip
    novel = [float(r["psnr"]) for r in rows if r["set"] == "novel"]
    assert np.mean(novel) == pytest.approx(doc["metrics"]["novel"]["psnr"], abs=1e-12)


def test_no_ground_truth_scores_brisque_on_training_views_and_a_path(tmp_path, capsys, resources_dir):
    case = make_case(tmp_path, ground_truth=False, seed=1)
    out = tmp_path / "eval" / "metrics.json"
    doc = evaluate_run(case["run"], case["scene"], case["sfm"], out, resources=str(resources_dir), path_frames=6)
    r = out.parent / "renders"
    assert doc["ground_truth"] is False
    assert sorted(p.name for p in (r / "train").iterdir()) == ["0000.png", "0001.png", "0002.png"]
    assert len(list((r / "path").iterdir())) == 6
    assert doc["path"] == {"kind": "ellipse", "frames": 6}  # these cameras all look along +z
    m = doc["metrics"]
    assert m["train"]["n"] == 3 and m["path"]["n"] == 6 and m["all"]["n"] == 9
    assert m["all"]["brisque_undefined"] == 0  # every render of this case has contrast
    assert cli_mean(capsys, "brisque", r / "train") == pytest.approx(m["train"]["brisque"], abs=1e-6)
    assert cli_mean(capsys, "brisque", r / "path") == pytest.approx(m["path"]["brisque"], abs=1e-6)
    assert m["all"]["brisque"] == pytest.approx((3 * m["train"]["brisque"] + 6 * m["path"]["brisque"]) / 9, abs=1e-9)
    assert "novel" not in m and "blur" not in m and doc["hidden_ground_truth"] is False


def test_hidden_ground_truth_scores_both_the_test_cameras_and_brisque(tmp_path, capsys, resources_dir):
    """A recording through the real-data path with its ground truth kept aside (config/davis346.yaml): the test
    cameras against the ground truth as for any synthetic scene, and BRISQUE as for a scene without one."""
    case = make_case(tmp_path)
    out = tmp_path / "eval" / "metrics.json"
    code = main(["evaluate", str(case["run"]), str(case["scene"]), str(case["sfm"]), "-o", str(out), "--resources",
                 str(resources_dir), "--path-frames", "6", "--hidden-ground-truth"])  # fmt: skip
    assert code == 0
    doc = json.loads(out.read_text())
    assert doc["ground_truth"] is True and doc["hidden_ground_truth"] is True
    m = doc["metrics"]
    assert set(m) == {"blur", "novel", "train", "path", "all"} and m["novel"]["n"] == 2 and m["all"]["n"] == 9
    assert doc["frames_timed"] == 4  # FPS over the test cameras, as for every scene with ground truth
    r = out.parent / "renders"
    assert cli_mean(capsys, "brisque", r / "path") == pytest.approx(m["path"]["brisque"], abs=1e-6)
    assert cli_mean(capsys, "psnr", r / "novel", r / "gt_novel") == pytest.approx(m["novel"]["psnr"], abs=1e-4)
    assert doc["path"] == {"kind": "ellipse", "frames": 6}
    sets = [row["set"] for row in csv.DictReader((out.parent / "per_image.csv").open())]
    assert sets == ["blur"] * 2 + ["novel"] * 2 + ["train"] * 3 + ["path"] * 6


def test_missing_run_config_is_a_clear_error(tmp_path):
    case = make_case(tmp_path)
    (case["run"] / "config.json").unlink()
    with pytest.raises(EigsError, match="config.json"):
        evaluate_run(case["run"], case["scene"], case["sfm"], tmp_path / "m.json")
