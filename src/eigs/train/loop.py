"""The training loop shared by every method: sample, render, loss, backward, guard, densify, Adam; a log of time
against held-out quality; checkpoints that make a killed run resume to the same result; atomic final outputs.

Run folder (``RUN_DIR``): ``model.ply`` (3DGS PLY), ``config.json`` (resolved options and run facts),
``train_log.csv``. Checkpoints go to the sibling ``RUN_DIR.partial/`` (Snakemake deletes a failed job's declared
outputs, not this), which is removed once the run folder is complete.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from eigs import __version__
from eigs.artifacts.gaussians import write_gaussian_ply
from eigs.artifacts.motion import FILE_NAME as MOTION_FILE
from eigs.artifacts.motion import RunMotion, sample_indices, write_motion
from eigs.errors import EigsError
from eigs.metrics.pixel import psnr_torch
from eigs.train.config import TrainConfig
from eigs.train.data import HeldOut, TrainData
from eigs.train.methods import Method
from eigs.train.model import PARAM_NAMES, GaussianModel, make_optimizer, means_lr, scene_extent
from eigs.train.plugins import make_method
from eigs.train.strategy import DensifyStrategy
from eigs.util.atomic import atomic_path
from eigs.util.progress import progress

log = logging.getLogger(__name__)

CHECKPOINT_VERSION = 1
ADAM_STATE = ("step", "exp_avg", "exp_avg_sq")  # what torch.optim.Adam keeps per parameter (amsgrad off)
LOG_COLUMNS = ("step", "wall_s", "loss", "n_gaussians", "psnr_novel", "psnr_blur")


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


@dataclass
class RunResult:
    model: GaussianModel
    method: Method
    rows: list[dict[str, Any]]
    train_seconds: float
    skipped_steps: int


def partial_dir_of(run_dir: str | Path) -> Path:
    run_dir = Path(run_dir)
    return run_dir.with_name(run_dir.name + ".partial")


@torch.no_grad()
def held_out_psnr(model: GaussianModel, held: HeldOut, data: TrainData, sh_degree: int, device: torch.device) -> dict:
    """Mean per-image PSNR (dB) of 8-bit renders on the held-out novel views and blur views (NaN when none)."""
    out: dict[str, list[float]] = {"psnr_novel": [], "psnr_blur": []}
    bg = data.background.to(device)
    for i in range(len(held)):
        img, _, _ = model.render(held.c2w[i], held.K[i].to(device), data.width, data.height, bg, sh_degree)
        img = torch.round(img.clamp(0, 1) * 255.0) / 255.0
        p = float(psnr_torch(img.permute(2, 0, 1).cpu(), held.images[i].permute(2, 0, 1)))
        out["psnr_novel" if held.kind[i] == 1 else "psnr_blur"].append(p)
    return {k: (float(np.mean(v)) if v else math.nan) for k, v in out.items()}


def _finite_grads(params: list[torch.Tensor]) -> bool:
    grads = [p.grad for p in params if p.grad is not None]
    if not grads:
        return True
    return bool(torch.stack([torch.isfinite(g).all() for g in grads]).all())


class Trainer:
    """One run: state, one step, checkpoints."""

    def __init__(self, data: TrainData, cfg: TrainConfig, device: torch.device):
        self.data, self.cfg, self.device = data, cfg, device
        torch.manual_seed(cfg.seed)
        self.model = GaussianModel.from_cloud(data.init, cfg.sh_degree, data.channels, device)
        centres = data.c2w[..., :3, 3].reshape(-1, 3).numpy()
        self.extent = scene_extent(centres)
        self.method = make_method(data, cfg, device)
        self.optimizer = make_optimizer(self.model, cfg, self.extent)
        for group in self.method.param_groups():
            self.optimizer.add_param_group(group)
        self.strategy = DensifyStrategy(cfg, self.extent, data.width, data.height, seed=cfg.seed)
        self.rng = np.random.default_rng(cfg.seed)
        self.order: list[int] = []
        self.step = 0
        self.rows: list[dict[str, Any]] = []
        self.wall = 0.0
        self.bad = 0
        self.skipped = 0

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        return {
            "version": CHECKPOINT_VERSION,
            "config": self.cfg.to_dict(),
            "step": self.step,
            "params": {n: t.detach().cpu() for n, t in self.model.params.items()},
            "optimizer": self.optimizer.state_dict(),
            "strategy": self.strategy.state_dict(),
            "method": self.method.state_dict(),
            "rng": self.rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "order": [int(i) for i in self.order],
            "rows": self.rows,
            "wall": self.wall,
            "bad": self.bad,
            "skipped": self.skipped,
        }

    def save_checkpoint(self, path: Path) -> None:
        with atomic_path(path) as tmp:
            torch.save(self.state_dict(), tmp)

    def load_checkpoint(self, path: Path) -> bool:
        """Resume from ``path``; False (and a warning naming it) when it belongs to another configuration or is
        unreadable or damaged, the trainer then as freshly built (a checkpoint is a cache: the run starts over)."""
        try:
            state = torch.load(path, map_location="cpu", weights_only=False)
        except Exception as err:  # a truncated or foreign file: start over rather than fail
            log.warning("ignoring unreadable checkpoint %s (%s)", path, str(err).splitlines()[0] if str(err) else err)
            return False
        if not isinstance(state, dict):
            log.warning("ignoring checkpoint %s: not a checkpoint", path)
            return False
        if state.get("version") != CHECKPOINT_VERSION or state.get("config") != self.cfg.to_dict():
            log.warning("ignoring checkpoint %s: written for another configuration", path)
            return False
        problem = self._checkpoint_problem(state)
        if problem is None:
            try:
                self._restore(state)
            except Exception as err:  # damage the checks above cannot see: rebuild and start over
                problem = f"{type(err).__name__}: {err}".splitlines()[0]
                self.__init__(self.data, self.cfg, self.device)
        if problem is not None:
            log.warning("ignoring damaged checkpoint %s (%s)", path, problem)
            return False
        log.info("resumed from %s at step %d", path, self.step)
        return True

    def _checkpoint_problem(self, state: dict) -> str | None:
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
        for group in opt.get("param_groups", []) if isinstance(opt.get("param_groups"), list) else []:
            if isinstance(group, dict) and group.get("name") in PARAM_NAMES and isinstance(group.get("params"), list):
                shape_of.update({i: params[group["name"]].shape for i in group["params"]})
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
        for group in opt.get("param_groups", []) if isinstance(opt.get("param_groups"), list) else []:
            if not isinstance(group, dict) or not _adam_hyperparameters_valid(group):
                return f"optimizer hyperparameters of group {group.get('name') if isinstance(group, dict) else '?'}"
        missing = [k for k in ("step", "strategy", "method", "rng", "torch_rng", "order", "rows", "wall", "bad",
                               "skipped") if k not in state]  # fmt: skip
        return f"missing {', '.join(missing)}" if missing else None

    def _restore(self, state: dict) -> None:
        for name in PARAM_NAMES:
            self.model.params[name] = state["params"][name].to(self.device).requires_grad_(True)
        self.optimizer = make_optimizer(self.model, self.cfg, self.extent)
        for group in self.method.param_groups():
            self.optimizer.add_param_group(group)
        self.method.load_state_dict(state["method"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.strategy.load_state_dict(state["strategy"])
        self.rng.bit_generator.state = state["rng"]
        torch.set_rng_state(state["torch_rng"])
        self.order = list(state["order"])
        self.step, self.rows, self.wall = int(state["step"]), list(state["rows"]), float(state["wall"])
        self.bad, self.skipped = int(state["bad"]), int(state["skipped"])

    # ------------------------------------------------------------------ one step
    @torch.no_grad()
    def warm_up(self) -> None:
        """One untimed render, so a first-use build of the rasterizer does not count as training time."""
        d = self.data
        c2w = d.c2w[int(d.reference_views()[0]), 0]
        self.model.render(c2w, d.K.to(self.device), d.width, d.height, d.background.to(self.device), 0)

    def sh_degree_at(self, step: int) -> int:
        return min(self.cfg.sh_degree, step // self.cfg.sh_degree_interval)

    def train_step(self) -> bool:
        """Run step ``self.step``; False when it was skipped (non-finite loss or gradient)."""
        cfg, step = self.cfg, self.step
        if not self.order:
            self.order = [int(i) for i in self.rng.permutation(self.method.n_samples())]
        sample = self.order.pop()
        for group in self.optimizer.param_groups:
            if group.get("name") == "means":
                group["lr"] = means_lr(cfg, self.extent, step)
        out = self.method.step(self.model, sample, step, self.sh_degree_at(step))
        self.optimizer.zero_grad(set_to_none=True)
        ok = bool(torch.isfinite(out.loss))
        if ok:
            out.loss.backward()
            params = [p for g in self.optimizer.param_groups for p in g["params"]]
            ok = _finite_grads(params)
        self.step += 1
        if not ok:
            self.optimizer.zero_grad(set_to_none=True)
            self.bad += 1
            self.skipped += 1
            log.warning("step %d: non-finite loss or gradient, skipped (%d in a row)", step, self.bad)
            return False
        self.bad = 0
        if self.strategy.active(step):
            self.strategy.after_backward(self.model, out.infos)
        self.optimizer.step()
        report = self.strategy.after_step(self.step, self.model, self.optimizer)
        if report is not None and (report.cloned or report.split or report.pruned):
            log.debug("step %d: cloned %d, split %d, pruned %d -> %d Gaussians", self.step, report.cloned,
                      report.split, report.pruned, len(self.model))  # fmt: skip
        self._last = {"loss": out.loss.item(), **out.terms}
        return True


def train(
    data: TrainData,
    cfg: TrainConfig,
    run_dir: str | Path,
    device: torch.device | None = None,
    *,
    inputs: dict[str, str] | None = None,
    stop_after: int | None = None,
) -> RunResult:
    """Train ``cfg.method`` on ``data`` and write the run folder. ``stop_after``: leave after this many steps
    (checkpoint written, no outputs) — for tests of resumption."""
    device = device or torch.device("cpu")
    run_dir = Path(run_dir)
    tr = Trainer(data, cfg, device)
    ckpt = resume_from_partial(tr, run_dir)
    log.info(
        "%s: %d steps, %d samples, %d Gaussians, extent %.3f, device %s",
        cfg.method, cfg.steps, tr.method.n_samples(), len(tr.model), tr.extent, device,
    )  # fmt: skip
    tr._last = {}
    tr.warm_up()
    stopped = run_steps(
        tr, cfg, ckpt, run_dir, stop_after,
        size=lambda: {"n_gaussians": len(tr.model)},
        held_out=lambda s: held_out_psnr(tr.model, data.held_out, data, tr.sh_degree_at(s), device),  # type: ignore[arg-type]
        describe=lambda s, row: f"step {s}  {tr.wall:.1f} s  {len(tr.model)} Gaussians  PSNR novel "
        f"{row['psnr_novel']:.2f} dB",
        has_held_out=data.held_out is not None,
    )  # fmt: skip
    if not stopped:
        complete_run(run_dir, lambda: write_run(tr, run_dir, inputs or {}))
    return RunResult(tr.model, tr.method, tr.rows, tr.wall, tr.skipped)


def resume_from_partial(tr: Any, run_dir: Path) -> Path:
    """The checkpoint path of ``run_dir`` (in its ``.partial`` sibling); ``tr`` resumes from it when it exists."""
    ckpt = partial_dir_of(run_dir) / "checkpoint.pt"
    if ckpt.exists():
        tr.load_checkpoint(ckpt)
    return ckpt


def complete_run(run_dir: Path, write: Callable[[], None]) -> None:
    """Write the run folder with ``write()``, then drop the ``.partial`` checkpoints it no longer needs."""
    write()
    shutil.rmtree(partial_dir_of(run_dir), ignore_errors=True)


def run_steps(
    tr: Any,
    cfg: TrainConfig,
    ckpt: Path,
    run_dir: Path,
    stop_after: int | None,
    *,
    size: Callable[[], dict[str, Any]],
    held_out: Callable[[int], dict[str, Any]],
    describe: Callable[[int, dict[str, Any]], str],
    has_held_out: bool,
) -> bool:
    """The step loop every trainer shares (Gaussian and field): ``tr.train_step()`` from ``tr.step`` to
    ``cfg.steps`` with the wall clock, the non-finite-streak stop, a log row every ``log_every`` steps (``size()``
    columns, and ``held_out(step)`` every ``eval_every``, logged as ``describe(step, row)``), checkpoints every
    ``checkpoint_every``. True when it left at ``stop_after`` (checkpoint written, no outputs)."""
    for _ in progress(range(tr.step, cfg.steps), desc=f"train {cfg.method}", total=cfg.steps - tr.step, unit="step"):
        t0 = time.perf_counter()
        tr.train_step()
        tr.wall += time.perf_counter() - t0
        if tr.bad >= cfg.max_bad_steps:
            tr.save_checkpoint(ckpt)
            raise EigsError(
                run_dir,
                f"{tr.bad} consecutive steps had a non-finite loss or gradient (last at step {tr.step}); the last "
                f"good state is in {ckpt}",
            )
        s = tr.step
        evaluate = has_held_out and cfg.eval_every and (s % cfg.eval_every == 0 or s == cfg.steps)
        if s % cfg.log_every == 0 or s == cfg.steps or evaluate:
            row: dict[str, Any] = {"step": s, "wall_s": round(tr.wall, 4), **tr._last, **size()}
            if evaluate:
                row.update(held_out(s))
                log.info("%s", describe(s, row))
            tr.rows.append(row)
        if s % cfg.checkpoint_every == 0 and s < cfg.steps:
            tr.save_checkpoint(ckpt)
        if stop_after is not None and s >= stop_after:
            tr.save_checkpoint(ckpt)
            return True
    return False


def log_csv(rows: list[dict[str, Any]], fixed: tuple[str, ...] = LOG_COLUMNS) -> str:
    """The rows as CSV: ``fixed`` columns (step, wall_s, loss, then the model size and held-out columns), each
    method's loss terms in first-seen order after the first three."""
    extra: list[str] = []
    for r in rows:
        for k in r:
            if k not in fixed and k not in extra:
                extra.append(k)
    columns = [*fixed[:3], *extra, *fixed[3:]]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, restval="", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()})
    return buf.getvalue()


def write_run(tr: Trainer, run_dir: Path, inputs: dict[str, str]) -> None:
    """Write ``model.ply``, ``config.json`` and ``train_log.csv`` together (atomic directory rename)."""
    import platform

    facts = {
        "eigs_version": __version__,
        "torch_version": torch.__version__,
        "device": str(tr.device),
        "threads": torch.get_num_threads(),
        "machine": platform.machine(),
        "method_description": tr.method.description,
        "method_options": tr.method.options,
        "scene": tr.data.scene.name,
        "n_samples": tr.method.n_samples(),
        "extent": tr.extent,
        "train_seconds": round(tr.wall, 3),
        # CPU seconds of this process so far (all threads: data loading, training, writing; a resumed run counts
        # its last process only): what the job costs alone on a shared machine (Snakemake's benchmark files
        # sample CPU time every ~30 s and miss up to that much of a job's end)
        "process_cpu_s": round(time.process_time(), 3),
        "skipped_steps": tr.skipped,
        "n_gaussians": len(tr.model),
        "final": tr.rows[-1] if tr.rows else {},
    }
    doc = {"train": tr.cfg.to_dict(), "inputs": inputs, "run": facts}
    with atomic_path(run_dir, directory=True) as tmp:
        write_gaussian_ply(tr.model.to_cloud(), tmp / "model.ply")
        (tmp / "config.json").write_text(json.dumps(doc, indent=2, default=float) + "\n")
        (tmp / "train_log.csv").write_text(log_csv(tr.rows))
        motion = run_motion(tr)
        if motion is not None:
            write_motion(motion, tmp / MOTION_FILE)


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
