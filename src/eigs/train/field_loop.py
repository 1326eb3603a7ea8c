"""The training loop of the radiance-field methods: the run-folder, log, checkpoint and resume contract of
:mod:`eigs.train.loop` for a voxel-grid field.

Run folder: ``model.npz`` (:mod:`eigs.artifacts.field`), ``config.json`` (the same sections as a Gaussian run;
``run.model`` = ``"field"``, ``run.n_voxels``), ``train_log.csv`` (``n_voxels`` and ``occupied`` instead of
``n_gaussians``). Checkpoints in the sibling ``RUN_DIR.partial/``; a killed run resumes to the same parameters.

One step: grow the grid when the schedule says so (a new Adam for the grid), refresh the occupancy mask, set the
decayed learning rate, draw and render the method's rays, MSE (+ the method's terms), skip the step when the loss
or a gradient is not finite, add the gradient of the total variation in place, Adam.
"""

from __future__ import annotations

import json
import logging
import math
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from eigs import __version__
from eigs.artifacts.field import FIELD_FILE, write_field
from eigs.artifacts.gaussians import sh_dc_to_rgb
from eigs.metrics.pixel import psnr_torch
from eigs.render.field import render_image
from eigs.train.config import TrainConfig
from eigs.train.data import TrainData
from eigs.train.field_methods import FieldMethod
from eigs.train.field_model import FieldModel, field_box, lr_factor, voxel_schedule
from eigs.train.loop import complete_run, log_csv, resume_from_partial, run_steps
from eigs.train.plugins import make_field_method
from eigs.util.atomic import atomic_path

log = logging.getLogger(__name__)

FIELD_CHECKPOINT_VERSION = 1
FIELD_LOG_COLUMNS = ("step", "wall_s", "loss", "n_voxels", "occupied", "psnr_novel", "psnr_blur")


@dataclass
class FieldRunResult:
    model: FieldModel
    method: FieldMethod
    rows: list[dict[str, Any]]
    train_seconds: float
    skipped_steps: int


@torch.no_grad()
def field_held_out_psnr(model: FieldModel, data: TrainData, device: torch.device) -> dict[str, float]:
    """Mean per-image PSNR (dB) of 8-bit renders at the held-out novel and blur views (NaN when none)."""
    held = data.held_out
    out: dict[str, list[float]] = {"psnr_novel": [], "psnr_blur": []}
    if held is None:
        return {k: math.nan for k in out}
    f = model.tensors()
    for i in range(len(held)):
        img = render_image(f, held.c2w[i], held.K[i].to(device), data.width, data.height, data.background)
        img = torch.round(img.clamp(0, 1) * 255.0) / 255.0
        p = float(psnr_torch(img.permute(2, 0, 1).cpu(), held.images[i].permute(2, 0, 1)))
        out["psnr_novel" if held.kind[i] == 1 else "psnr_blur"].append(p)
    return {k: (float(np.mean(v)) if v else math.nan) for k, v in out.items()}


class FieldTrainer:
    """One field run: state, one step, checkpoints."""

    def __init__(self, data: TrainData, cfg: TrainConfig, device: torch.device):
        self.data, self.cfg, self.device = data, cfg, device
        torch.manual_seed(cfg.seed)
        self.method = make_field_method(data, cfg, device)
        self.opts = self.method.field_opts
        lo, hi = field_box(data.init.means, self.opts, cameras=data.c2w[data.valid][:, :3, 3].numpy())
        init = data.init
        rgb = np.clip(sh_dc_to_rgb(init.f_dc), 0.0, 1.0)
        rgb = rgb.mean(axis=1, keepdims=True) if data.channels == 1 else rgb
        self.model = FieldModel(lo, hi, data.channels, self.opts, device, points=init.means, colours=rgb)
        self.schedule = dict(voxel_schedule(self.opts, cfg.steps)[1:])
        self.vm_schedule = dict(voxel_schedule(self.opts, cfg.steps, vm=True)[1:])
        self.gen = torch.Generator().manual_seed(cfg.seed)
        self.grid_opt = self._grid_optimizer()
        params = self.method.parameters()
        self.method_opt = torch.optim.Adam(params, lr=self.method.lr()) if params else None
        self.step = 0
        self.rows: list[dict[str, Any]] = []
        self.wall = 0.0
        self.bad = 0
        self.skipped = 0
        self.occupied = 1.0
        self._last: dict[str, float] = {}

    def _grid_optimizer(self) -> torch.optim.Adam:
        return torch.optim.Adam(self.model.param_groups(), eps=1e-15)

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        return {
            "version": FIELD_CHECKPOINT_VERSION,
            "config": self.cfg.to_dict(),
            "step": self.step,
            "model": self.model.state_dict(),
            "grid_opt": self.grid_opt.state_dict(),
            "method_opt": self.method_opt.state_dict() if self.method_opt is not None else None,
            "method": self.method.state_dict(),
            "gen": self.gen.get_state(),
            "torch_rng": torch.get_rng_state(),
            "rows": self.rows,
            "wall": self.wall,
            "bad": self.bad,
            "skipped": self.skipped,
            "occupied": self.occupied,
        }

    def save_checkpoint(self, path: Path) -> None:
        with atomic_path(path) as tmp:
            torch.save(self.state_dict(), tmp)

    def load_checkpoint(self, path: Path) -> bool:
        """Resume from ``path``; False (and a warning) when it belongs to another configuration or is unreadable."""
        try:
            state = torch.load(path, map_location="cpu", weights_only=False)
        except Exception as err:  # a truncated or foreign file: start over rather than fail
            log.warning("ignoring unreadable checkpoint %s (%s)", path, err)
            return False
        if state.get("version") != FIELD_CHECKPOINT_VERSION or state.get("config") != self.cfg.to_dict():
            log.warning("ignoring checkpoint %s: written for another configuration", path)
            return False
        self.model.load_state_dict(state["model"])
        self.grid_opt = self._grid_optimizer()
        base = [g["base_lr"] for g in self.grid_opt.param_groups]  # from the options, not from the file
        try:
            self.grid_opt.load_state_dict(state["grid_opt"])
            self.method.load_state_dict(state["method"])
            if self.method_opt is not None:
                self.method_opt.load_state_dict(state["method_opt"])
        except (ValueError, KeyError, RuntimeError) as err:  # optimiser groups of another layout: start over
            log.warning("ignoring checkpoint %s: its optimiser state does not fit this run (%s)", path, err)
            return False
        # Adam's load_state_dict takes each group's hyperparameters from the file; a checkpoint written before the
        # learning-rate decay existed has no base_lr (it failed the first step after resuming)
        for group, b in zip(self.grid_opt.param_groups, base, strict=True):
            group["base_lr"] = b
        self.gen.set_state(state["gen"])
        torch.set_rng_state(state["torch_rng"])
        self.step, self.rows, self.wall = int(state["step"]), list(state["rows"]), float(state["wall"])
        self.bad, self.skipped = int(state["bad"]), int(state["skipped"])
        self.occupied = float(state["occupied"])
        log.info("resumed from %s at step %d", path, self.step)
        return True

    # ------------------------------------------------------------------ one step
    def train_step(self) -> bool:
        """Run step ``self.step``; False when it was skipped (non-finite loss or gradient)."""
        o, step = self.opts, self.step
        if step in self.schedule:
            self.model.grow(self.schedule[step], self.vm_schedule.get(step))
            self.grid_opt = self._grid_optimizer()
        if step >= o.occupancy_start and (step - o.occupancy_start) % o.occupancy_every == 0:
            self.occupied = self.model.update_occupancy()
        for group in self.grid_opt.param_groups:
            group["lr"] = group["base_lr"] * lr_factor(o, step, self.cfg.steps)
        out = self.method.step(self.model, step, self.gen)
        loss, terms = out.loss, dict(out.terms)
        dist = self.method.take_distortion()
        if o.distortion > 0 and dist is not None:
            loss = loss + o.distortion * dist
            terms["distortion"] = dist.item()
        self.grid_opt.zero_grad(set_to_none=True)
        if self.method_opt is not None:
            self.method_opt.zero_grad(set_to_none=True)
        ok = bool(torch.isfinite(loss))
        if ok:
            loss.backward()
            grads = [p.grad for p in [*self.model.leaves(), *self.method.parameters()] if p.grad is not None]
            ok = all(bool(torch.isfinite(g).all()) for g in grads)
        if ok and max(o.tv_density, o.tv_colour, o.vm_tv_colour) > 0:  # total variation: gradient added in place
            terms["tv"] = self.model.add_total_variation_grad(o.tv_density, o.tv_colour)
            loss = loss.detach() + terms["tv"]
        self.step += 1
        if not ok:
            self.bad += 1
            self.skipped += 1
            log.warning("step %d: non-finite loss or gradient, skipped (%d in a row)", step, self.bad)
            return False
        self.bad = 0
        self.grid_opt.step()
        if self.method_opt is not None:
            self.method_opt.step()
        self._last = {"loss": loss.item(), **terms}
        return True


def train_field(
    data: TrainData,
    cfg: TrainConfig,
    run_dir: str | Path,
    device: torch.device | None = None,
    *,
    inputs: dict[str, str] | None = None,
    stop_after: int | None = None,
) -> FieldRunResult:
    """Train the field method ``cfg.method`` on ``data`` and write the run folder. ``stop_after``: leave after this
    many steps (checkpoint written, no outputs) — for tests of resumption."""
    device = device or torch.device("cpu")
    run_dir = Path(run_dir)
    tr = FieldTrainer(data, cfg, device)
    ckpt = resume_from_partial(tr, run_dir)
    m = tr.model
    log.info("%s: %d steps, box %s .. %s, %s field %s, device %s", cfg.method, cfg.steps, np.round(m.lo_np, 3),
             np.round(m.hi_np, 3), tr.opts.field, tuple(m.shape()), device)  # fmt: skip
    stopped = run_steps(
        tr, cfg, ckpt, run_dir, stop_after,
        size=lambda: {"n_voxels": tr.model.n_voxels, "occupied": round(tr.occupied, 4)},
        held_out=lambda s: field_held_out_psnr(tr.model, data, device),
        describe=lambda s, row: f"step {s}  {tr.wall:.1f} s  {tr.model.n_voxels} voxels "
        f"({100 * tr.occupied:.1f}% occupied)  PSNR novel {row['psnr_novel']:.2f} dB",
        has_held_out=data.held_out is not None,
    )  # fmt: skip
    if not stopped:
        complete_run(run_dir, lambda: write_field_run(tr, run_dir, inputs or {}))
    return FieldRunResult(tr.model, tr.method, tr.rows, tr.wall, tr.skipped)


def write_field_run(tr: FieldTrainer, run_dir: Path, inputs: dict[str, str]) -> None:
    """Write ``model.npz``, ``config.json`` and ``train_log.csv`` together (atomic directory rename)."""
    facts = {
        "eigs_version": __version__,
        "torch_version": torch.__version__,
        "device": str(tr.device),
        "threads": torch.get_num_threads(),
        "machine": platform.machine(),
        "model": "field",
        "method_description": tr.method.description,
        "method_options": tr.method.options,
        "scene": tr.data.scene.name,
        "train_seconds": round(tr.wall, 3),
        # CPU seconds of this process so far (all threads: data loading, training, writing; a resumed run counts
        # its last process only): what the job costs alone on a shared machine (Snakemake's benchmark files
        # sample CPU time every ~30 s and miss up to that much of a job's end)
        "process_cpu_s": round(time.process_time(), 3),
        "skipped_steps": tr.skipped,
        "n_voxels": tr.model.n_voxels,
        "field": tr.opts.field,
        "grid_shape": tr.model.shape(),
        "vm_corners": None if tr.model.vm is None else list(tr.model.vm.dims),
        "occupied": tr.occupied,
        "box": [tr.model.lo_np.tolist(), tr.model.hi_np.tolist()],
        "final": tr.rows[-1] if tr.rows else {},
    }
    doc = {"train": tr.cfg.to_dict(), "inputs": inputs, "run": facts}
    with atomic_path(run_dir, directory=True) as tmp:
        write_field(tr.model.to_arrays(), tmp / FIELD_FILE)
        (tmp / "config.json").write_text(json.dumps(doc, indent=2, default=float) + "\n")
        (tmp / "train_log.csv").write_text(log_csv(tr.rows, FIELD_LOG_COLUMNS))
