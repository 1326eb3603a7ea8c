"""The Gaussian trainer on the toy scene: learning, outputs, resumption, densification bookkeeping, NaN guard."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys

import numpy as np
import pytest
import torch

from eigs.artifacts.gaussians import read_gaussian_ply
from eigs.artifacts.run import partial_dir
from eigs.errors import EigsError
from eigs.train.catalog import method_class
from eigs.train.config import TrainConfig
from eigs.train.data import load_train_data
from eigs.train.gaussian.methods import StepOutput
from eigs.train.gaussian.trainer import Trainer, held_out_psnr, train


@pytest.fixture(scope="module")
def data(toy):
    return load_train_data(*toy.paths())


def _cfg(**kw) -> TrainConfig:
    base = {"steps": 300, "eval_every": 100, "log_every": 20, "refine_start": 60, "refine_every": 60}
    return TrainConfig.from_dict({**base, **kw})


def test_loss_falls_psnr_rises_outputs_reload(data, tmp_path):
    cfg = _cfg(method="3dgs")
    init_psnr = held_out_psnr(Trainer(data, cfg, torch.device("cpu")).model, data.held_out, data, 0,
                              torch.device("cpu"))["psnr_novel"]  # fmt: skip
    run = tmp_path / "run"
    res = train(data, cfg, run)
    rows = list(csv.DictReader((run / "train_log.csv").open()))
    losses = [float(r["loss"]) for r in rows]
    assert np.mean(losses[-3:]) < 0.7 * np.mean(losses[:3])
    psnrs = [float(r["psnr_novel"]) for r in rows if r["psnr_novel"]]
    assert len(psnrs) == 3 and psnrs[-1] > init_psnr + 3.0, (init_psnr, psnrs)
    assert {"step", "wall_s", "loss", "l1", "dssim", "n_gaussians", "psnr_novel", "psnr_blur", "sharpness_novel",
            "coherence_novel"} <= set(rows[0])
    sharp = [float(r["sharpness_novel"]) for r in rows if r["sharpness_novel"]]
    assert len(sharp) == 3 and all(0 < v < 2 for v in sharp)
    assert int(rows[-1]["step"]) == 300 and float(rows[-1]["wall_s"]) > 0
    cloud = read_gaussian_ply(run / "model.ply")
    assert len(cloud) == len(res.model) == int(rows[-1]["n_gaussians"])
    np.testing.assert_array_equal(cloud.means, res.model.params["means"].detach().numpy())
    doc = json.loads((run / "config.json").read_text())
    assert TrainConfig.from_dict(doc["train"]) == cfg
    assert doc["run"]["n_gaussians"] == len(cloud)
    assert doc["run"]["process_cpu_s"] > 0  # the job's own CPU seconds (bench/suite_ledger.py reads them)
    assert not partial_dir(run).exists()


def test_killed_run_resumes_to_the_same_parameters(data, tmp_path):
    cfg = _cfg(method="edi-3dgs", steps=200, checkpoint_every=50, reset_every=120)
    full = train(data, cfg, tmp_path / "full")
    part = train(data, cfg, tmp_path / "resumed", stop_after=130)  # "killed" after step 130 (checkpoint kept)
    assert len(part.rows) < len(full.rows)
    assert (partial_dir(tmp_path / "resumed") / "checkpoint.pt").exists()
    resumed = train(data, cfg, tmp_path / "resumed")
    for name, t in full.model.params.items():
        torch.testing.assert_close(resumed.model.params[name], t, rtol=0, atol=0, msg=name)
    a = list(csv.DictReader((tmp_path / "full" / "train_log.csv").open()))
    b = list(csv.DictReader((tmp_path / "resumed" / "train_log.csv").open()))
    assert [r["loss"] for r in a] == [r["loss"] for r in b]
    # the run says where its last process began (its process_cpu_s covers only the steps from there)
    facts = [json.loads((tmp_path / r / "config.json").read_text())["run"] for r in ("full", "resumed")]
    assert [f["resumed_at_step"] for f in facts] == [0, 130]


def test_run_stopped_part_way_through_a_longer_schedule(data, tmp_path):
    # steps=130 of a 200-step schedule (lr decay, densification window) is the first 130 steps of the 200-step run
    long = train(data, _cfg(method="3dgs", steps=200, reset_every=0), tmp_path / "long", stop_after=130)
    short_cfg = _cfg(method="3dgs", steps=130, schedule_steps=200)
    assert (short_cfg.horizon, short_cfg.refine_stop, _cfg(steps=130).refine_stop) == (200, 120, 78)
    short = train(data, short_cfg, tmp_path / "short")
    assert len(short.model) == len(long.model)
    for name, t in long.model.params.items():
        torch.testing.assert_close(short.model.params[name], t, rtol=0, atol=0, msg=name)
    with pytest.raises(EigsError, match="schedule_steps"):
        _cfg(schedule_steps=-1).validate()


def test_checkpoint_with_moments_adam_cannot_make_is_ignored(data, tmp_path, caplog):
    """A checkpoint whose Adam moments are finite but impossible (one exp_avg of 3e36: a damaged byte) would send a
    parameter to ±inf on the first step; it is ignored with a warning and the run starts over, finite."""
    cfg = _cfg(method="3dgs", steps=60)
    train(data, cfg, tmp_path / "run", stop_after=40)
    ckpt = partial_dir(tmp_path / "run") / "checkpoint.pt"
    state = torch.load(ckpt, weights_only=False)
    opt = state["optimizer"]
    index = next(g["params"][0] for g in opt["param_groups"] if g.get("name") == "opacities")
    opt["state"][index]["exp_avg"][0] = 3e36
    torch.save(state, ckpt)
    caplog.set_level("INFO")
    result = train(data, cfg, tmp_path / "run")
    assert "are inconsistent" in caplog.text and "resumed from" not in caplog.text
    assert all(bool(torch.isfinite(t).all()) for t in result.model.params.values())


def test_checkpoint_of_another_config_is_ignored(data, tmp_path, caplog):
    train(data, _cfg(method="3dgs", steps=100), tmp_path / "run", stop_after=50)
    caplog.set_level("INFO")
    train(data, _cfg(method="3dgs", steps=100, seed=1), tmp_path / "run")
    assert "written for another configuration" in caplog.text and "resumed from" not in caplog.text


def test_checkpoint_of_other_inputs_is_ignored(data, tmp_path, caplog):
    """A run killed part way, then rerun with the same options on changed input files (a rerun SfM, a new init
    cloud), starts over; on the same files it resumes."""
    init = tmp_path / "init.ply"
    init.write_bytes(b"cloud one")
    cfg = _cfg(method="3dgs", steps=60)
    for run in ("same", "changed"):
        train(data, cfg, tmp_path / run, inputs={"init": str(init)}, stop_after=40)
    caplog.set_level("INFO")
    train(data, cfg, tmp_path / "same", inputs={"init": str(init)})
    assert "resumed from" in caplog.text and "other input files" not in caplog.text
    caplog.clear()
    init.write_bytes(b"cloud two")
    train(data, cfg, tmp_path / "changed", inputs={"init": str(init)})
    assert "written from other input files" in caplog.text and "resumed from" not in caplog.text


def test_non_finite_steps_are_skipped_then_stop(data, tmp_path, monkeypatch):
    cls = method_class("3dgs")
    orig = cls.step

    def poisoned(self, model, sample, step, sh_degree):
        out = orig(self, model, sample, step, sh_degree)
        if step in (10, 11, 12):
            return StepOutput(out.loss * float("nan"), out.terms, out.infos)
        if step == 20:  # a finite loss whose gradient is not: NaN in one Gaussian's colour, this step only
            handle = []

            def once(g):
                handle[0].remove()
                return g.index_fill(0, torch.tensor([0]), float("nan"))

            handle.append(model.params["sh0"].register_hook(once))
        return out

    monkeypatch.setattr(cls, "step", poisoned)
    res = train(data, _cfg(method="3dgs", steps=60), tmp_path / "run")
    assert res.skipped_steps == 4
    for t in res.model.params.values():
        assert torch.isfinite(t).all()
    # K non-finite steps in a row stop the run with a clear message and keep a checkpoint
    monkeypatch.setattr(cls, "step", lambda self, m, s, k, d: StepOutput(orig(self, m, s, k, d).loss * math.inf, {}))
    with pytest.raises(EigsError, match="consecutive steps"):
        train(data, _cfg(method="3dgs", steps=60, max_bad_steps=5), tmp_path / "bad")
    assert (partial_dir(tmp_path / "bad") / "checkpoint.pt").exists()


def test_oracle_and_edi_methods_sample_what_they_should(data):
    dev = torch.device("cpu")
    v = data.n_views
    assert Trainer(data, _cfg(method="3dgs"), dev).method.n_samples() == int(data.valid[:, 0].sum()) == v
    assert Trainer(data, _cfg(method="edi-3dgs"), dev).method.n_samples() == int(data.valid.sum())
    oracle = Trainer(data, _cfg(method="oracle"), dev).method
    assert oracle.n_samples() == int(data.has_sharp_train.sum()) > 0
    torch.testing.assert_close(oracle.images[0], data.sharp_train[np.nonzero(data.has_sharp_train)[0][0]])


def test_config_errors_name_the_option():
    with pytest.raises(EigsError, match="unknown training option"):
        TrainConfig.from_dict({"stepz": 3})
    with pytest.raises(EigsError, match="steps must be int"):
        TrainConfig.from_dict({"steps": 1.5})
    with pytest.raises(EigsError, match="steps must be >= 1"):
        TrainConfig.from_dict({"steps": 0})
    with pytest.raises(EigsError, match="not valid JSON"):
        TrainConfig.from_json("{steps: 3}")
    assert TrainConfig.from_dict({"lr_means": 1}).lr_means == 1.0


def test_unknown_method_and_method_options(data):
    with pytest.raises(EigsError, match="unknown method"):
        Trainer(data, _cfg(method="nope"), torch.device("cpu"))
    with pytest.raises(EigsError, match="unknown option"):
        Trainer(data, _cfg(method="3dgs", method_options={"x": 1}), torch.device("cpu"))


def test_cli_train_and_render(toy, tmp_path):
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "eigs", "train", *map(str, toy.paths()), "-o", str(run), "--method", "3dgs",
           "--config", '{"steps": 40, "eval_every": 20}', "--threads", "1"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (run / "model.ply").exists()
    out = tmp_path / "renders"
    proc = subprocess.run(
        [sys.executable, "-m", "eigs", "render", str(run), str(toy.scene), str(toy.sfm), "--cameras", "orbit",
         "--frames", "6", "-o", str(out)],
        capture_output=True, text=True, check=False, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert len(list(out.glob("orbit_*.png"))) == 6
    assert json.loads((out / "render_report.json").read_text())["fps"] > 0
    bad = subprocess.run(cmd[:-4] + ["--config", '{"stepz": 1}'], capture_output=True, text=True, check=False)
    assert bad.returncode == 2 and "unknown training option(s) stepz" in bad.stderr
    assert "Traceback" not in bad.stderr


def test_cli_list_needs_no_inputs_and_missing_inputs_are_named():
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "eigs", "train", "--list"], capture_output=True, text=True)
    assert out.returncode == 0 and "bad-gaussians" in out.stdout and "eigs " in out.stdout
    bad = subprocess.run([sys.executable, "-m", "eigs", "train", "scene.h5"], capture_output=True, text=True)
    assert bad.returncode == 2 and "missing edi, sfm, init, output" in bad.stderr and "Traceback" not in bad.stderr
