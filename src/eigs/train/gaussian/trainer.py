"""The Gaussian methods' trainer (3DGS model, ``model.ply``) on the run shared with the radiance-field methods
(:mod:`eigs.train.loop`: steps, non-finite skip, log, checkpoints and resumption, run folder).

One step: draw the next training sample (a seeded permutation per epoch), set the means' decayed learning rate,
the method's loss on that sample, backward, densification statistics, Adam, densify and prune. The run folder holds
``model.ply`` (3DGS PLY), ``motion.npz`` for methods that model motion within the exposure, ``config.json`` and
``train_log.csv`` (column ``n_gaussians``).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

from eigs.artifacts.cameras import RefinedCameras, write_refined_cameras
from eigs.artifacts.gaussians import write_gaussian_ply
from eigs.artifacts.motion import RunMotion, sample_indices, write_motion
from eigs.artifacts.run import CAMERAS, MODEL_PLY, MOTION
from eigs.train.config import TrainConfig
from eigs.train.data import HeldOut, TrainData
from eigs.train.gaussian.camera_refine import CameraRefinement
from eigs.train.gaussian.methods import Method
from eigs.train.gaussian.model import PARAM_NAMES, GaussianModel, make_optimizer, means_lr, scene_extent
from eigs.train.gaussian.strategy import DensifyStrategy
from eigs.train.loop import HELD_OUT_COLUMNS, RunResult, RunTrainer, fit, held_out_scores
from eigs.train.optim import moments_consistent
from eigs.train.resolve import build_method
from eigs.util.options import Options
from eigs.util.schedule import exp_decay

log = logging.getLogger(__name__)

__all__ = ["LOG_COLUMNS", "RunResult", "Trainer", "held_out_psnr", "run_cameras", "run_motion", "train"]

ADAM_STATE = ("step", "exp_avg", "exp_avg_sq")  # what torch.optim.Adam keeps per parameter (amsgrad off)
LOG_COLUMNS = ("step", "wall_s", "loss", "n_gaussians", *HELD_OUT_COLUMNS)


def _adam_hyperparameters_valid(group: dict) -> bool:
    """Whether an Adam parameter group's saved hyperparameters are usable: lr finite ≥ 0, eps finite > 0, betas in
    [0, 1), weight_decay finite ≥ 0."""
    try:
        lr, eps, wd = float(group["lr"]), float(group["eps"]), float(group.get("weight_decay", 0.0))
        b1, b2 = (float(b) for b in group["betas"])
    except (KeyError, TypeError, ValueError):
        return False
    finite = all(math.isfinite(v) for v in (lr, eps, wd, b1, b2))
    return finite and lr >= 0 and eps > 0 and wd >= 0 and 0 <= b1 < 1 and 0 <= b2 < 1


def held_out_psnr(model: GaussianModel, held: HeldOut, data: TrainData, sh_degree: int, device: torch.device) -> dict:
    """Held-out scores of 8-bit renders (:func:`eigs.train.loop.held_out_scores`: PSNR by kind, the novel views'
    sharpness ratio and coherence; NaN when none)."""
    bg = data.background.to(device)
    return held_out_scores(
        lambda i: model.render(held.c2w[i], held.K[i].to(device), data.width, data.height, bg, sh_degree)[0], held
    )


class Trainer(RunTrainer):
    """One Gaussian run: the model, its Adam and densification, the method's sampling order."""

    log = log
    log_columns = LOG_COLUMNS

    def __init__(self, data: TrainData, cfg: TrainConfig, device: torch.device, options: Options | None = None):
        self._start(data, cfg, device)
        self.model = GaussianModel.from_cloud(data.init, cfg.sh_degree, data.channels, device)
        centres = data.c2w[..., :3, 3].reshape(-1, 3).numpy()
        self.extent = scene_extent(centres)
        self.method: Method = build_method(Method, data, cfg, device, options)
        self.optimizer = make_optimizer(self.model, cfg, self.extent)
        for group in self.method.all_param_groups():
            self.optimizer.add_param_group(group)
        self.strategy = DensifyStrategy(cfg, self.extent, data.width, data.height, seed=cfg.seed)
        self.rng = np.random.default_rng(cfg.seed)
        self.order: list[int] = []

    # ------------------------------------------------------------------ checkpoints
    def model_state(self) -> dict[str, Any]:
        return {
            "params": {n: t.detach().cpu() for n, t in self.model.params.items()},
            "optimizer": self.optimizer.state_dict(),
            "strategy": self.strategy.state_dict(),
            "method": self.method.state_dict(),
            "camera": self.method.camera.state_dict() if self.method.camera is not None else None,
            "rng": self.rng.bit_generator.state,
            "order": [int(i) for i in self.order],
        }

    def state_problem(self, state: dict) -> str | None:
        """What makes ``state`` unusable (missing parts; parameters or Adam moments of the wrong shape or not
        finite: torch's zip reader checks no CRC, so flipped bytes load silently), or None."""
        params = state.get("params")
        if not isinstance(params, dict) or any(not isinstance(params.get(n), torch.Tensor) for n in PARAM_NAMES):
            return "parameters missing"
        n = params["means"].shape[0] if params["means"].dim() else -1
        for name in PARAM_NAMES:
            t, ref = params[name], self.model.params[name]
            if t.dim() != ref.dim() or t.shape[0] != n or t.shape[1:] != ref.shape[1:] or t.dtype != ref.dtype:
                return f"parameter {name} has shape {tuple(t.shape)}"
            if not bool(torch.isfinite(t).all()):
                return f"parameter {name} has NaN/Inf values"
        opt = state.get("optimizer")
        if not isinstance(opt, dict) or not isinstance(opt.get("state"), dict):
            return "optimizer state missing"
        shape_of = {}  # Adam state index → the shape its moments must have (the Gaussian parameters' groups)
        group_of = {}  # Adam state index → its group (betas and eps for the moments' consistency)
        for group in opt.get("param_groups", []) if isinstance(opt.get("param_groups"), list) else []:
            if isinstance(group, dict) and group.get("name") in PARAM_NAMES and isinstance(group.get("params"), list):
                shape_of.update({i: params[group["name"]].shape for i in group["params"]})
            if isinstance(group, dict) and isinstance(group.get("params"), list) and _adam_hyperparameters_valid(group):
                group_of.update({i: group for i in group["params"] if isinstance(i, int)})
        for index, entry in opt["state"].items():
            if not isinstance(entry, dict) or any(not isinstance(entry.get(k), torch.Tensor) for k in ADAM_STATE):
                return f"optimizer state {index} lacks {', '.join(ADAM_STATE)}"
            if entry["exp_avg"].shape != entry["exp_avg_sq"].shape or (
                index in shape_of and entry["exp_avg"].shape != shape_of[index]
            ):
                return f"optimizer moments {index} have shape {tuple(entry['exp_avg'].shape)}"
            for key, t in entry.items():
                if isinstance(t, torch.Tensor) and t.is_floating_point() and not bool(torch.isfinite(t).all()):
                    return f"optimizer {key} has NaN/Inf values"
            # Adam divides by sqrt(exp_avg_sq) and by 1 - beta^step: a flipped sign bit or step byte gives NaN steps
            if entry["exp_avg_sq"].numel() and float(entry["exp_avg_sq"].min()) < 0:
                return f"optimizer exp_avg_sq {index} has negative values"
            if entry["step"].numel() != 1 or not float(entry["step"]) >= 1:
                return f"optimizer step {index} is {entry['step'].tolist()}"
            group = group_of.get(index)
            if group is not None and not moments_consistent(entry["exp_avg"], entry["exp_avg_sq"], group["betas"],
                                                            float(group["eps"])):  # fmt: skip
                return f"optimizer moments {index} are inconsistent (|exp_avg| beyond what exp_avg_sq allows)"
        for group in opt.get("param_groups", []) if isinstance(opt.get("param_groups"), list) else []:
            if not isinstance(group, dict) or not _adam_hyperparameters_valid(group):
                return f"optimizer hyperparameters of group {group.get('name') if isinstance(group, dict) else '?'}"
        if self.method.camera is not None and (problem := self.method.camera.state_problem(state.get("camera"))):
            return problem
        missing = [k for k in ("strategy", "method", "rng", "order") if k not in state]
        return f"missing {', '.join(missing)}" if missing else super().state_problem(state)

    def restore_model(self, state: dict) -> None:
        for name in PARAM_NAMES:
            self.model.params[name] = state["params"][name].to(self.device).requires_grad_(True)
        self.optimizer = make_optimizer(self.model, self.cfg, self.extent)
        for group in self.method.all_param_groups():
            self.optimizer.add_param_group(group)
        self.method.load_state_dict(state["method"])
        if self.method.camera is not None:
            self.method.camera.load_state_dict(state["camera"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.strategy.load_state_dict(state["strategy"])
        self.rng.bit_generator.state = state["rng"]
        self.order = list(state["order"])

    # ------------------------------------------------------------------ one step
    @torch.no_grad()
    def warm_up(self) -> None:
        """One untimed render, so a first-use build of the rasterizer does not count as training time."""
        d = self.data
        c2w = d.c2w[int(d.reference_views()[0]), 0]
        self.model.render(c2w, d.K.to(self.device), d.width, d.height, d.background.to(self.device), 0)

    def sh_degree_at(self, step: int) -> int:
        return min(self.cfg.sh_degree, step // self.cfg.sh_degree_interval)

    def forward(self) -> tuple[torch.Tensor, dict[str, float], Any]:
        cfg, step = self.cfg, self.step
        if not self.order:
            self.order = [int(i) for i in self.rng.permutation(self.method.n_samples())]
        sample = self.order.pop()
        for group in self.optimizer.param_groups:
            if group.get("name") == "means":
                group["lr"] = means_lr(cfg, self.extent, step)
            elif group.get("name") == CameraRefinement.NAME:
                group["lr"] = exp_decay(cfg.lr_camera, cfg.lr_camera_final, step, cfg.horizon)
        out = self.method.step(self.model, sample, step, self.sh_degree_at(step))
        return out.loss, out.terms, out.infos

    def zero_grad(self) -> None:
        self.optimizer.zero_grad(set_to_none=True)

    def trained_params(self) -> list[torch.Tensor]:
        return [p for g in self.optimizer.param_groups for p in g["params"]]

    def after_backward(
        self, loss: torch.Tensor, terms: dict[str, float], aux: Any
    ) -> tuple[torch.Tensor, dict[str, float]]:
        if self.strategy.active(self.step):
            self.strategy.after_backward(self.model, aux)
        return loss, terms

    def optimizer_step(self) -> None:
        self.optimizer.step()
        report = self.strategy.after_step(self.step, self.model, self.optimizer)
        if report is not None and (report.cloned or report.split or report.pruned):
            log.debug("step %d: cloned %d, split %d, pruned %d -> %d Gaussians", self.step, report.cloned,
                      report.split, report.pruned, len(self.model))  # fmt: skip

    # ------------------------------------------------------------------ log and run folder
    def held_out(self, step: int) -> dict[str, float]:
        return held_out_psnr(self.model, self.data.held_out, self.data, self.sh_degree_at(step), self.device)  # type: ignore[arg-type]

    def size(self) -> dict[str, Any]:
        return {"n_gaussians": len(self.model)}

    def describe(self, step: int, row: dict[str, Any]) -> str:
        return f"step {step}  {self.wall:.1f} s  {len(self.model)} Gaussians  PSNR novel {row['psnr_novel']:.2f} dB"

    def log_start(self) -> None:
        log.info(
            "%s: %d steps, %d samples, %d Gaussians, extent %.3f, device %s",
            self.cfg.method, self.cfg.steps, self.method.n_samples(), len(self.model), self.extent, self.device,
        )  # fmt: skip

    def before_steps(self) -> None:
        self.warm_up()

    def facts(self) -> tuple[dict[str, Any], dict[str, Any]]:
        head = {
            "method_description": self.method.description,
            "method_options": self.method.options,
            "scene": self.data.scene.name,
            "n_samples": self.method.n_samples(),
            "extent": self.extent,
        }
        return head, {"n_gaussians": len(self.model)}

    def write_model(self, folder: Path) -> None:
        write_gaussian_ply(self.model.to_cloud(), folder / MODEL_PLY)
        motion = run_motion(self)
        if motion is not None:
            write_motion(motion, folder / MOTION)
        cameras = run_cameras(self)
        if cameras is not None:
            write_refined_cameras(cameras, folder / CAMERAS)


def train(
    data: TrainData,
    cfg: TrainConfig,
    run_dir: str | Path,
    device: torch.device | None = None,
    *,
    inputs: dict[str, str] | None = None,
    stop_after: int | None = None,
) -> RunResult:
    """Train ``cfg.method`` on ``data`` and write the run folder (:func:`eigs.train.loop.fit`). ``stop_after``: leave
    after this many steps (checkpoint written, no outputs) — for tests of resumption."""
    tr = Trainer(data, cfg, device or torch.device("cpu"))
    return fit(tr, run_dir, inputs=inputs, stop_after=stop_after)


def run_motion(tr: Trainer) -> RunMotion | None:
    """The motion the trained method applies within the exposures, at a seeded sample of the final Gaussians'
    centres (:mod:`eigs.artifacts.motion`); None for methods that model none."""
    p = tr.model.params
    idx = torch.from_numpy(sample_indices(len(tr.model), tr.cfg.seed)).to(p["means"].device)
    means, quats = p["means"].detach()[idx], p["quats"].detach()[idx]
    m = tr.method.latent_motion(means, quats)
    if m is None:
        return None
    return RunMotion(
        method=tr.cfg.method,
        points=means.cpu().numpy(),
        displacement=m.displacement.cpu().numpy(),
        reference_c2w=m.reference_c2w.cpu().numpy(),
        views=m.views,
        camera_c2w=None if m.camera_c2w is None else m.camera_c2w.cpu().numpy(),
    )


def run_cameras(tr: Trainer) -> RefinedCameras | None:
    """The training cameras before and after camera refinement (:mod:`eigs.artifacts.cameras`); None when the run
    did not refine them."""
    cam = tr.method.camera
    if cam is None:
        return None
    views = np.zeros(cam.ref.shape[0], bool)
    views[tr.data.reference_views()] = True
    return RefinedCameras(method=tr.cfg.method, before=cam.ref.cpu().numpy(), after=cam.corrected_c2w().numpy(),
                          twist=cam.twists().detach().cpu().numpy(), views=views)  # fmt: skip
