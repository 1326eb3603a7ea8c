"""bench/gpu_check.py and bench/gpu_check.sh on the CPU: the runs resolved from the suite config, the artifact bundle
(events dropped, arrays unchanged, checksums), the eigs commands, the measurements read back from a run folder, the
JUnit and report JSON, and the scripts' argument errors. The GPU parts run only on a GPU machine (issue 34)."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from bench import gpu_check

REPO = Path(__file__).resolve().parents[1]
PLUS = {"pose_prior": True, "ade_zero_last": True, "blur_target": "discrete", "blur_weights": "trapezoid",
        "latent_weight": 0.5, "latent_dssim": True, "latent_weight_dark": 2.0}  # fmt: skip


def suite_config() -> dict:
    return yaml.safe_load((REPO / "config" / "config.yaml").read_text())


def test_runs_resolve_to_the_rules_config_json():
    runs = gpu_check.resolve_runs(suite_config(), ["eigs+", "edi-3dgs"])
    assert runs["eigs+"]["bins"] == runs["edi-3dgs"]["bins"] == 4
    assert json.loads(runs["eigs+"]["config"]) == {"method": "eigs", "steps": 1750, "schedule_steps": 3000,
                                                   "eval_every": 125, "method_options": PLUS}  # fmt: skip
    assert runs["edi-3dgs"]["config"] == '{"method":"edi-3dgs"}'
    # compact and key-sorted, as rules/common.smk train_config_json writes it
    assert runs["eigs+"]["config"].startswith('{"eval_every":125,"method":"eigs","method_options":{"ade_zero_last"')


def test_runs_argument_errors():
    with pytest.raises(gpu_check.CheckError, match="not a run of the config"):
        gpu_check.resolve_runs(suite_config(), ["eigs++"])
    with pytest.raises(gpu_check.CheckError, match="at least one"):
        gpu_check.parse_runs(" , ")
    with pytest.raises(gpu_check.CheckError, match="twice"):
        gpu_check.parse_runs("eigs+,edi-3dgs,eigs+")
    assert gpu_check.parse_runs(" eigs+ ,edi-3dgs") == ["eigs+", "edi-3dgs"]


def test_safe_name_keeps_device_file_names_plain():
    assert gpu_check.safe_name("eigs+") == "eigs-plus"
    assert gpu_check.safe_name("edi-3dgs") == "edi-3dgs"
    assert gpu_check.safe_name("a b/c") == "a_b_c"


def make_workflow(root: Path, big_events: int = 50_000) -> dict[str, np.ndarray]:
    """A workflow directory with chair's file layout (small synthetic contents); returns arrays to compare."""
    rng = np.random.default_rng(0)
    arrays = {"frames/blurry": rng.integers(0, 255, (4, 24, 32, 3), dtype=np.uint8),
              "camera/K": np.eye(3), "cum_counts": rng.integers(-5, 5, (4, 5, 24, 32), dtype=np.int32)}  # fmt: skip
    scene = root / "results" / "chair"
    (scene / "b4" / "sfm").mkdir(parents=True)
    with h5py.File(scene / "scene.h5", "w") as f:
        f.attrs["name"] = "chair"
        f.attrs["version"] = 3
        f["frames/blurry"] = arrays["frames/blurry"]
        f["frames/blurry"].attrs["note"] = "kept"
        f["camera/K"] = arrays["camera/K"]
        f["events/t"] = np.arange(big_events, dtype=np.int64)
        f["events/p"] = np.ones(big_events, dtype=np.int8)
    with h5py.File(scene / "b4" / "edi.h5", "w") as f:
        f["cum_counts"] = arrays["cum_counts"]
        f["method"] = "edi"  # a scalar string: copied exactly
    for name in ("poses.h5", "test_cameras.h5"):
        with h5py.File(scene / "b4" / "sfm" / name, "w") as f:
            f["c2w"] = np.tile(np.eye(4), (3, 1, 1))
    (scene / "b4" / "sfm" / "images.bin").write_bytes(b"\0" * 1000)  # not read by train/evaluate: left out
    (scene / "b4" / "init.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nend_header\n" + b"\1" * 100)
    lp = root / "resources" / "lpips"
    lp.mkdir(parents=True)
    (lp / "MANIFEST.json").write_text('{"files": {}}')
    (lp / "alex.pt").write_bytes(b"alex" * 100)
    (lp / "vgg.pt").write_bytes(b"vgg" * 1000)  # not needed (evaluation uses alex): left out
    return arrays


def test_bundle_copies_what_train_and_evaluate_read(tmp_path):
    arrays = make_workflow(tmp_path / "wf")
    out = tmp_path / "bundle"
    m = gpu_check.make_bundle(tmp_path / "wf", tmp_path / "wf" / "resources", suite_config(), "chair",
                              ["eigs+", "edi-3dgs"], out, max_mib=30)  # fmt: skip
    assert sorted(m["files"]) == ["chair/b4/edi.h5", "chair/b4/init.ply", "chair/b4/sfm/poses.h5",
                                  "chair/b4/sfm/test_cameras.h5", "chair/scene.h5", "resources/lpips/MANIFEST.json",
                                  "resources/lpips/alex.pt"]  # fmt: skip
    assert json.loads((out / "MANIFEST.json").read_text()) == m
    for rel, entry in m["files"].items():
        data = (out / rel).read_bytes()
        assert entry["sha256"] == hashlib.sha256(data).hexdigest() and entry["bytes"] == len(data)
    assert (out / "chair/b4/init.ply").read_bytes() == (tmp_path / "wf/results/chair/b4/init.ply").read_bytes()
    with h5py.File(out / "chair/scene.h5") as f:
        assert "events" not in f
        assert f.attrs["name"] == "chair" and f.attrs["version"] == 3
        assert np.array_equal(f["frames/blurry"][()], arrays["frames/blurry"])
        assert f["frames/blurry"].attrs["note"] == "kept"
        assert f["frames/blurry"].compression == "gzip"
        assert np.array_equal(f["camera/K"][()], arrays["camera/K"])
    with h5py.File(out / "chair/b4/edi.h5") as f:
        assert np.array_equal(f["cum_counts"][()], arrays["cum_counts"]) and f["cum_counts"].dtype == np.int32
        assert f["method"][()] == b"edi"
    assert gpu_check.verify_bundle(out)["scene"] == "chair"
    assert json.loads(m["runs"]["eigs+"]["config"])["steps"] == 1750


def test_bundle_refusals_and_a_tampered_bundle(tmp_path):
    make_workflow(tmp_path / "wf", big_events=1000)
    wf, res, cfg = tmp_path / "wf", tmp_path / "wf" / "resources", suite_config()
    with pytest.raises(gpu_check.CheckError, match="over --max-mib"):
        gpu_check.make_bundle(wf, res, cfg, "chair", ["edi-3dgs"], tmp_path / "b", max_mib=0.001)
    assert not (tmp_path / "b").exists() and not (tmp_path / ".b.tmp").exists()
    with pytest.raises(gpu_check.CheckError, match="not a scene"):
        gpu_check.make_bundle(wf, res, cfg, "teapot", ["edi-3dgs"], tmp_path / "b", max_mib=30)
    (wf / "results/chair/b4/init.ply").unlink()
    with pytest.raises(gpu_check.CheckError, match=r"missing artifact.*init\.ply"):
        gpu_check.make_bundle(wf, res, cfg, "chair", ["edi-3dgs"], tmp_path / "b", max_mib=30)
    (wf / "results/chair/b4/init.ply").write_bytes(b"ply")
    gpu_check.make_bundle(wf, res, cfg, "chair", ["edi-3dgs"], tmp_path / "b", max_mib=30)
    (tmp_path / "b/chair/b4/init.ply").write_bytes(b"plz")
    with pytest.raises(gpu_check.CheckError, match="checksum mismatch"):
        gpu_check.verify_bundle(tmp_path / "b")
    with pytest.raises(gpu_check.CheckError, match="no bundle manifest"):
        gpu_check.verify_bundle(tmp_path)


def test_commands_are_the_rules_with_a_device(tmp_path):
    manifest = {"scene": "chair", "runs": {"eigs+": {"bins": 4, "config": '{"method":"eigs"}'}}}
    b, w = Path("/b"), Path("/w")
    cmds = gpu_check.commands(b, manifest, "eigs+", w, "cuda", 1)
    eigs = [sys.executable, "-m", "eigs.cli"]
    assert cmds["train"] == [*eigs, "train", "/b/chair/scene.h5", "/b/chair/b4/edi.h5", "/b/chair/b4/sfm",
                             "/b/chair/b4/init.ply", "-o", "/w/eigs-plus", "--config", '{"method":"eigs"}',
                             "--device", "cuda", "--threads", "1"]  # fmt: skip
    assert cmds["evaluate"] == [*eigs, "evaluate", "/w/eigs-plus", "/b/chair/scene.h5", "/b/chair/b4/sfm", "-o",
                                "/w/eval/eigs-plus/metrics.json", "--resources", "/b/resources", "--device", "cuda",
                                "--threads", "1"]  # fmt: skip


def write_run(run_dir: Path, metrics: Path, psnr: float, train_s: float, steps: int) -> None:
    run_dir.mkdir(parents=True)
    (run_dir / "config.json").write_text(json.dumps({"run": {"device": "cuda", "torch_version": "2.11.0+cu130"}}))
    (run_dir / "train_log.csv").write_text("step,wall_s,loss\n50,3.0,0.1\n100,4.0,0.1\n150,5.5,0.1\n")
    metrics.parent.mkdir(parents=True)
    metrics.write_text(json.dumps({
        "method": "eigs", "device": "cuda", "steps": steps, "train_seconds": train_s, "n_gaussians": 1000,
        "render_ms": 1.5, "ssim_table_mode": "skimage", "lpips_net": "alex",
        "metrics": {"novel": {"n": 12, "psnr": psnr, "ssim_skimage": 0.9, "ssim_other": 0.1, "lpips_alex": 0.05},
                    "blur": {"n": 24, "psnr": psnr + 1, "ssim_skimage": 0.8, "lpips_alex": 0.06}}}))  # fmt: skip


def test_summary_of_a_run_folder(tmp_path):
    write_run(tmp_path / "r", tmp_path / "e" / "metrics.json", 30.5, 70.0, 1750)
    s = gpu_check.summarize_run(tmp_path / "r", tmp_path / "e" / "metrics.json")
    assert s["novel_psnr"] == 30.5 and s["blur_psnr"] == 31.5
    assert s["novel_ssim"] == 0.9 and s["novel_lpips"] == 0.05 and s["blur_lpips"] == 0.06
    assert s["seconds_per_step"] == pytest.approx(0.04)
    assert s["steady_seconds_per_step"] == pytest.approx((5.5 - 3.0) / 100)
    assert s["train_device"] == "cuda" and s["torch"] == "2.11.0+cu130" and s["steps"] == 1750


JUNIT = """<?xml version="1.0" encoding="utf-8"?><testsuites><testsuite name="pytest" tests="3">
<testcase classname="tests.render.test_gsplat_conformance" name="test_gsplat_matches_cpu[0]" time="1.0"/>
<testcase classname="tests.render.test_gsplat_conformance" name="test_gsplat_matches_cpu[1]" time="1.0">{one}</testcase>
<testcase classname="tests.train.test_ade" name="test_fused_on_cuda_equals_cpu_reference" time="0.1">{two}</testcase>
</testsuite></testsuites>"""


@pytest.mark.parametrize(
    ("one", "two", "outcomes", "passed"),
    [
        ("", "", ["passed", "passed", "passed"], True),
        ('<failure message="x">x</failure>', "", ["passed", "failed", "passed"], False),
        ("", '<skipped message="needs a CUDA GPU"/>', ["passed", "passed", "skipped"], False),
        ('<error message="e"/>', "", ["passed", "error", "passed"], False),
    ],
)
def test_junit_outcomes(tmp_path, one, two, outcomes, passed):
    path = tmp_path / "junit.xml"
    path.write_text(JUNIT.format(one=one, two=two))
    res = gpu_check.parse_junit(path)
    assert list(res["cases"].values()) == outcomes and res["passed"] is passed
    assert "tests.train.test_ade::test_fused_on_cuda_equals_cpu_reference" in res["cases"]


def test_junit_absent_or_broken_is_not_a_pass(tmp_path):
    assert gpu_check.parse_junit(tmp_path / "none.xml")["passed"] is False
    (tmp_path / "bad.xml").write_text("<testsuites>")
    assert gpu_check.parse_junit(tmp_path / "bad.xml")["passed"] is False


def test_report_and_comparison_with_a_baseline():
    runs = {"device": "cuda", "threads": 1, "scene": "chair", "runs": {
        "eigs+": {"novel_psnr": 30.70, "blur_psnr": 32.0, "seconds_per_step": 0.05, "train_wall_s": 100.0,
                  "evaluate_wall_s": 10.5, "steps": 1750, "train_cpu_s": 175.0},
        "edi-3dgs": {"novel_psnr": 29.9, "seconds_per_step": 0.01, "train_wall_s": 40.0, "evaluate_wall_s": 5.0},
        "broken": {"error": "train exited 1: boom", "train_wall_s": 2.0}}}  # fmt: skip
    baseline = {"device": "cpu", "environment": {"processor": "Xeon"}, "runs": {
        "eigs+": {"novel_psnr": 30.88, "blur_psnr": 32.5, "seconds_per_step": 0.15},
        "edi-3dgs": {"novel_psnr": 30.36, "seconds_per_step": 0.03}}}  # fmt: skip
    baseline["environment"]["eigs_code"] = "abc"
    env = {"gpu": "NVIDIA H100", "eigs_code": "abd"}
    doc = gpu_check.build_report(env, {"passed": True, "cases": {"t": "passed"}}, runs, gsplat_build_s=120.5,
                                 tests_rc=0, baseline=baseline, deviations=("a", "b"))  # fmt: skip
    assert doc["format"] == "eigs-gpu-check" and doc["environment"]["gpu"] == "NVIDIA H100"
    assert doc["conformance"] == {"passed": True, "cases": {"t": "passed"}, "pytest_rc": 0}
    assert doc["gsplat_build_s"] == 120.5 and doc["gsplat_deviations"] == ["a", "b"]
    assert doc["psnr"] == {"eigs+": 30.70, "edi-3dgs": 29.9, "broken": None}
    assert doc["run_wall_s"] == {"eigs+": 110.5, "edi-3dgs": 45.0, "broken": None}
    assert doc["runs"]["eigs+"]["cpu_seconds_per_step"] == pytest.approx(0.1)
    assert "cpu_seconds_per_step" not in doc["runs"]["edi-3dgs"] and doc["note"] is None
    assert doc["baseline"]["same_eigs_code"] is False and doc["baseline"]["processor"] == "Xeon"
    cmp = doc["baseline"]["comparison"]
    assert set(cmp) == {"eigs+", "edi-3dgs"}
    assert cmp["eigs+"]["novel_psnr_delta_db"] == pytest.approx(-0.18)
    assert cmp["eigs+"]["blur_psnr_delta_db"] == pytest.approx(-0.5)
    assert cmp["eigs+"]["within_tolerance"] is True and cmp["eigs+"]["step_speedup"] == pytest.approx(3.0)
    assert cmp["edi-3dgs"]["within_tolerance"] is False  # -0.46 dB
    json.dumps(doc)  # JSON-serialisable
    empty = gpu_check.build_report({}, {"passed": False, "cases": {}}, None)
    assert empty["runs"] == {} and empty["psnr"] == {} and "baseline" not in empty


def test_code_digest_follows_the_sources(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub" / "k.cpp").write_text("int k;\n")
    (tmp_path / "notes.txt").write_text("ignored")
    want = hashlib.sha256(b"a.py\0x = 1\n\0" + b"sub/k.cpp\0int k;\n\0").hexdigest()[:16]
    assert gpu_check.code_digest(tmp_path) == want
    (tmp_path / "notes.txt").write_text("still ignored")
    assert gpu_check.code_digest(tmp_path) == want
    (tmp_path / "sub" / "k.cpp").write_text("int k = 2;\n")
    assert gpu_check.code_digest(tmp_path) != want


def test_merge_runs_of_parallel_cpu_jobs(tmp_path):
    a, b, c = tmp_path / "a.json", tmp_path / "b.json", tmp_path / "c.json"
    a.write_text(json.dumps({"device": "cpu", "threads": 1, "scene": "chair", "runs": {"eigs+": {"x": 1}}}))
    b.write_text(json.dumps({"device": "cpu", "threads": 1, "scene": "chair", "runs": {"edi-3dgs": {"x": 2}}}))
    c.write_text(json.dumps({"device": "cuda", "threads": 1, "runs": {}}))
    merged = gpu_check.merge_runs([a, b, tmp_path / "absent.json"])
    assert merged == {"device": "cpu", "threads": 1, "scene": "chair",
                      "runs": {"eigs+": {"x": 1}, "edi-3dgs": {"x": 2}}}  # fmt: skip
    assert gpu_check.merge_runs([tmp_path / "absent.json"]) is None
    with pytest.raises(gpu_check.CheckError, match="differ"):
        gpu_check.merge_runs([a, c])


def test_cli_errors_are_one_line(tmp_path, capsys):
    assert gpu_check.main(["verify", "--bundle", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gpu_check.py verify: error:") and "\n" not in err
    assert gpu_check.main(["report", "--baseline", str(tmp_path / "no.json"), "-o", str(tmp_path / "r.json")]) == 2
    assert "--baseline" in capsys.readouterr().err


def run_sh(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "bench/gpu_check.sh", *args], cwd=REPO, capture_output=True, text=True,
                          env={**os.environ, **(env or {})}, timeout=120, check=False)  # fmt: skip


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((), "--bundle is required"),
        (("--bundle", "x"), "--out is required"),
        (("--bundle", "/nonexistent", "--out", "/tmp/o"), "MANIFEST.json does not exist"),
        (("--bundle",), "--bundle needs a folder"),
        (("--frobnicate",), "unknown argument '--frobnicate'"),
    ],
)
def test_shell_argument_errors(args, message):
    res = run_sh(*args)
    assert res.returncode == 2 and message in res.stderr


def test_shell_threads_must_be_positive(tmp_path):
    make_workflow(tmp_path / "wf", big_events=10)
    gpu_check.make_bundle(tmp_path / "wf", tmp_path / "wf" / "resources", suite_config(), "chair", ["edi-3dgs"],
                          tmp_path / "b", max_mib=30)  # fmt: skip
    res = run_sh("--bundle", str(tmp_path / "b"), "--out", str(tmp_path / "o"), "--threads", "0")
    assert res.returncode == 2 and "--threads must be a positive integer" in res.stderr


def test_shell_without_a_gpu_reports_what_it_could_measure(tmp_path):
    """The whole script on a CPU machine with tests and runs skipped: the bundle verifies, the gsplat build is
    reported as absent (no gsplat or CUDA here) and fails the exit status, and gpu_check.json and the log land in
    --out."""
    make_workflow(tmp_path / "wf", big_events=10)
    gpu_check.make_bundle(tmp_path / "wf", tmp_path / "wf" / "resources", suite_config(), "chair", ["edi-3dgs"],
                          tmp_path / "b", max_mib=30)  # fmt: skip
    (tmp_path / "wheels").mkdir()
    res = run_sh("--bundle", str(tmp_path / "b"), "--out", str(tmp_path / "o"), "--wheels", str(tmp_path / "wheels"),
                 "--skip-tests", "--skip-runs",
                 env={"PYTHON": sys.executable, "GPU_CHECK_WORK": str(tmp_path / "work")})  # fmt: skip
    assert res.returncode == 1, res.stdout + res.stderr  # the one phase that ran and failed: gsplat's build
    doc = json.loads((tmp_path / "o" / "gpu_check.json").read_text())
    assert doc["gsplat_build_s"] is None and doc["runs"] == {}
    assert doc["conformance"]["passed"] is False and doc["conformance"]["pytest_rc"] is None
    assert doc["environment"]["python"] == ".".join(map(str, sys.version_info[:3]))
    assert doc["gsplat_deviations"]  # eigs imported from src/ through PYTHONPATH
    log = (tmp_path / "o" / "gpu_check.log").read_text()
    assert "files verified" in log and "no wheels in" in log and "FAILED: gsplat-build" in log
