"""The radiance-field methods' trainer (voxel-grid field, ``model.npz``) on the run shared with the Gaussian methods
(:mod:`eigs.train.loop`: steps, non-finite skip, log, checkpoints and resumption, run folder).

Run folder: ``model.npz`` (:mod:`eigs.artifacts.field`), ``config.json`` (the same sections as a Gaussian run;
``run.model`` = ``"field"``, ``run.n_voxels``), ``train_log.csv`` (``n_voxels`` and ``occupied`` instead of
``n_gaussians``).

One step: grow the grid when the schedule says so (a new Adam for the grid), refresh the occupancy mask, set the
decayed learning rate, draw and render the method's rays, MSE (+ the method's terms), skip the step when the loss
or a gradient is not finite, add the gradient of the total variation in place, Adam.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
import torch

from eigs.artifacts.field import FIELD_FILE, write_field
from eigs.artifacts.gaussians import sh_dc_to_rgb
from eigs.render.field import render_image
from eigs.train.config import TrainConfig
from eigs.train.data import TrainData
from eigs.train.field.methods import FieldMethod
from eigs.train.field.model import FieldModel, field_box, lr_factor, voxel_schedule
from eigs.train.loop import HELD_OUT_COLUMNS, RunResult, RunTrainer, fit, held_out_scores
from eigs.train.optim import Optimizer, adam
from eigs.train.resolve import build_method
from eigs.util.options import Options

log = logging.getLogger(__name__)

FIELD_LOG_COLUMNS = ("step", "wall_s", "loss", "n_voxels", "occupied", *HELD_OUT_COLUMNS)
FIELD_STATE = ("model", "grid_opt", "method_opt", "method", "gen", "occupied")  # a field checkpoint's own keys


@torch.no_grad()
def field_held_out_psnr(model: FieldModel, data: TrainData, device: torch.device) -> dict[str, float]:
    """Held-out scores of 8-bit renders (:func:`eigs.train.loop.held_out_scores`; NaN when none)."""
    held = data.held_out
    f = model.tensors() if held is not None else None
    return held_out_scores(
        lambda i: render_image(f, held.c2w[i], held.K[i].to(device), data.width, data.height, data.background), held
    )


class FieldTrainer(RunTrainer):
    """One field run: the grid (and VM factors), their Adam, the method's own parameters and ray generator."""

    log = log
    log_columns = FIELD_LOG_COLUMNS

    def __init__(self, data: TrainData, cfg: TrainConfig, device: torch.device, options: Options | None = None):
        self._start(data, cfg, device)
        self.method: FieldMethod = build_method(FieldMethod, data, cfg, device, options)
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
        self.method_opt = adam(params, lr=self.method.lr()) if params else None
        self.occupied = 1.0  # fraction of the voxels the occupancy mask keeps

    def _grid_optimizer(self) -> Optimizer:
        return adam(self.model.param_groups(), eps=1e-15)

    # ------------------------------------------------------------------ checkpoints
    def model_state(self) -> dict[str, Any]:
        return {
            "model": self.model.state_dict(),
            "grid_opt": self.grid_opt.state_dict(),
            "method_opt": self.method_opt.state_dict() if self.method_opt is not None else None,
            "method": self.method.state_dict(),
            "gen": self.gen.get_state(),
            "occupied": self.occupied,
        }

    def state_problem(self, state: dict) -> str | None:
        missing = [k for k in FIELD_STATE if k not in state]
        return f"missing {', '.join(missing)}" if missing else super().state_problem(state)

    def restore_model(self, state: dict) -> None:
        self.model.load_state_dict(state["model"])
        self.grid_opt = self._grid_optimizer()
        base = [g["base_lr"] for g in self.grid_opt.param_groups]  # from the options, not from the file
        self.grid_opt.load_state_dict(state["grid_opt"])
        self.method.load_state_dict(state["method"])
        if self.method_opt is not None:
            self.method_opt.load_state_dict(state["method_opt"])
        # Adam's load_state_dict takes each group's hyperparameters from the file; a checkpoint written before the
        # learning-rate decay existed has no base_lr (it failed the first step after resuming)
        for group, b in zip(self.grid_opt.param_groups, base, strict=True):
            group["base_lr"] = b
        self.gen.set_state(state["gen"])
        self.occupied = float(state["occupied"])

    # ------------------------------------------------------------------ one step
    def forward(self) -> tuple[torch.Tensor, dict[str, float], Any]:
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
        return loss, terms, None

    def zero_grad(self) -> None:
        self.grid_opt.zero_grad(set_to_none=True)
        if self.method_opt is not None:
            self.method_opt.zero_grad(set_to_none=True)

    def trained_params(self) -> list[torch.Tensor]:
        return [*self.model.leaves(), *self.method.parameters()]

    def after_backward(
        self, loss: torch.Tensor, terms: dict[str, float], aux: Any
    ) -> tuple[torch.Tensor, dict[str, float]]:
        o = self.opts
        if max(o.tv_density, o.tv_colour, o.vm_tv_colour) > 0:  # total variation: gradient added in place
            terms["tv"] = self.model.add_total_variation_grad(o.tv_density, o.tv_colour)
            loss = loss.detach() + terms["tv"]
        return loss, terms

    def optimizer_step(self) -> None:
        self.grid_opt.step()
        if self.method_opt is not None:
            self.method_opt.step()

    # ------------------------------------------------------------------ log and run folder
    def held_out(self, step: int) -> dict[str, float]:
        return field_held_out_psnr(self.model, self.data, self.device)

    def size(self) -> dict[str, Any]:
        return {"n_voxels": self.model.n_voxels, "occupied": round(self.occupied, 4)}

    def describe(self, step: int, row: dict[str, Any]) -> str:
        return (
            f"step {step}  {self.wall:.1f} s  {self.model.n_voxels} voxels ({100 * self.occupied:.1f}% occupied)  "
            f"PSNR novel {row['psnr_novel']:.2f} dB"
        )

    def log_start(self) -> None:
        m = self.model
        log.info("%s: %d steps, box %s .. %s, %s field %s, device %s", self.cfg.method, self.cfg.steps,
                 np.round(m.lo_np, 3), np.round(m.hi_np, 3), self.opts.field, tuple(m.shape()),
                 self.device)  # fmt: skip

    def facts(self) -> tuple[dict[str, Any], dict[str, Any]]:
        head = {
            "model": "field",
            "method_description": self.method.description,
            "method_options": self.method.options,
            "scene": self.data.scene.name,
        }
        tail = {
            "n_voxels": self.model.n_voxels,
            "field": self.opts.field,
            "grid_shape": self.model.shape(),
            "vm_corners": None if self.model.vm is None else list(self.model.vm.dims),
            "occupied": self.occupied,
            "box": [self.model.lo_np.tolist(), self.model.hi_np.tolist()],
        }
        return head, tail

    def write_model(self, folder: Path) -> None:
        write_field(self.model.to_arrays(), folder / FIELD_FILE)


def train_field(
    data: TrainData,
    cfg: TrainConfig,
    run_dir: str | Path,
    device: torch.device | None = None,
    *,
    inputs: dict[str, str] | None = None,
    stop_after: int | None = None,
) -> RunResult:
    """Train the field method ``cfg.method`` on ``data`` and write the run folder (:func:`eigs.train.loop.fit`).
    ``stop_after``: leave after this many steps (checkpoint written, no outputs) — for tests of resumption."""
    tr = FieldTrainer(data, cfg, device or torch.device("cpu"))
    return fit(tr, run_dir, inputs=inputs, stop_after=stop_after)
