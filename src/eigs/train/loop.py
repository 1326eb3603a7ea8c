"""The run every trainer shares (Gaussian: :class:`eigs.train.gaussian.trainer.Trainer`, radiance field:
:class:`eigs.train.field.trainer.FieldTrainer`): one step's frame with the non-finite skip, checkpoints and resumption,
the step loop with its log and held-out scores (PSNR, sharpness), the result record and the run folder.

A trainer subclasses :class:`RunTrainer` and supplies the model's parts (its hooks): the loss of one step, the
optimisers' zero-grad and step, what follows the backward pass, its checkpoint state, its held-out render, its log
and ``config.json`` facts and its model file. :func:`fit` trains one to the end and writes the run folder.

Run folder (``RUN_DIR``): the model file (``model.ply`` or ``model.npz``), ``config.json`` (the resolved options,
the inputs and the run's facts), ``train_log.csv``. Checkpoints go to the sibling ``RUN_DIR.partial/`` (Snakemake
deletes a failed job's declared outputs, not this), which is removed once the run folder is complete.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import platform
import shutil
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from eigs import __version__
from eigs.artifacts import run as run_folder
from eigs.errors import EigsError
from eigs.metrics.pixel import psnr_torch
from eigs.metrics.sharpness import UndefinedSharpness, hf_scores
from eigs.train.config import TrainConfig
from eigs.train.data import HeldOut, TrainData
from eigs.util.atomic import atomic_path
from eigs.util.digest import files_digest
from eigs.util.progress import progress

CHECKPOINT_VERSION = 1
# the keys of every checkpoint beside a trainer's own (RunTrainer.model_state)
RUN_STATE = ("step", "torch_rng", "rows", "wall", "bad", "skipped")


@dataclass
class RunResult:
    """A finished (or stopped) run: the model and method as trained, the log rows, the training wall-clock seconds
    and the number of steps skipped for a non-finite loss or gradient."""

    model: Any  # eigs.train.gaussian.model.GaussianModel or eigs.train.field.model.FieldModel
    method: Any  # eigs.train.gaussian.methods.Method or eigs.train.field.methods.FieldMethod
    rows: list[dict[str, Any]]
    train_seconds: float
    skipped_steps: int


def finite_grads(params: list[torch.Tensor]) -> bool:
    """Whether every gradient of ``params`` is finite (parameters without one count as finite): a gradient's largest
    and smallest entries are both finite exactly when all its entries are (``amax`` and ``amin`` propagate NaN). Two
    vectorised passes: 1.2 ms on a field's 96³ × 4 grid gradient, where the infinity norm took 13–16 ms (one thread)."""
    grads = [p.grad for p in params if p.grad is not None and p.grad.numel() > 0]
    return all(bool(torch.stack((g.amax(), g.amin())).isfinite().all()) for g in grads)


# train_log.csv's held-out columns, written every ``eval_every`` steps (after the trainer's own fixed columns)
HELD_OUT_COLUMNS = ("psnr_novel", "psnr_blur", "sharpness_novel", "coherence_novel")


@torch.no_grad()
def held_out_scores(render: Callable[[int], torch.Tensor], held: HeldOut | None) -> dict[str, float]:
    """Scores of the 8-bit renders ``render(i)`` (H, W, C in [0, 1]) of the held-out images against their images:
    the mean per-image PSNR (dB) by kind, ``psnr_novel`` (novel views) and ``psnr_blur`` (blur views), and on the
    novel views the mean sharpness ratio and coherence (``sharpness_novel``, ``coherence_novel``:
    :func:`eigs.metrics.sharpness.hf_scores`, what ``eigs evaluate`` reports; a view whose image has no power in the
    band is left out, as there). NaN for a score without images."""
    out: dict[str, list[float]] = {k: [] for k in HELD_OUT_COLUMNS}
    for i in range(len(held) if held is not None else 0):
        img = (torch.round(render(i).clamp(0, 1) * 255.0) / 255.0).cpu()  # (H, W, C) on the 8-bit grid
        ref = held.images[i]  # type: ignore[union-attr]
        p = float(psnr_torch(img.permute(2, 0, 1), ref.permute(2, 0, 1)))
        novel = held.kind[i] == 1  # type: ignore[union-attr]
        out["psnr_novel" if novel else "psnr_blur"].append(p)
        if novel:
            try:
                ratio, coherence = hf_scores(img.double().numpy(), ref.double().numpy())
            except UndefinedSharpness:
                continue
            out["sharpness_novel"].append(ratio)
            out["coherence_novel"].append(coherence)
    return {k: (float(np.mean(v)) if v else math.nan) for k, v in out.items()}


class RunTrainer(ABC):
    """One run's state, one step's frame and checkpoints; a subclass adds the model (the abstract hooks below;
    the others have defaults)."""

    log: logging.Logger  # the subclass module's logger (tests and users filter by it)
    inputs_digest: str | None = None  # eigs.util.digest.files_digest of the run's input files (set by fit)
    log_columns: tuple[str, ...]  # train_log.csv's fixed columns: step, wall_s, loss, the size, HELD_OUT_COLUMNS

    def _start(self, data: TrainData, cfg: TrainConfig, device: torch.device) -> None:
        """Set the run's state (step 0, no rows) and seed torch."""
        self.data, self.cfg, self.device = data, cfg, device
        torch.manual_seed(cfg.seed)
        self.step = 0
        self.rows: list[dict[str, Any]] = []
        self.wall = 0.0  # training seconds (wall clock)
        self.bad = 0  # non-finite steps in a row
        self.skipped = 0
        self.resumed_at = 0  # the step this process resumed at (0: it trained from the start)
        self._last: dict[str, float] = {}  # the last good step's loss and terms

    # ------------------------------------------------------------------ hooks
    @abstractmethod
    def forward(self) -> tuple[torch.Tensor, dict[str, float], Any]:
        """Prepare step ``self.step`` (schedules, learning rates) and return its loss, its logged terms and what
        :meth:`after_backward` needs."""

    @abstractmethod
    def zero_grad(self) -> None:
        """Clear the gradients of every optimiser."""

    @abstractmethod
    def trained_params(self) -> list[torch.Tensor]:
        """Every tensor the optimisers step (their gradients are checked for NaN/Inf)."""

    def after_backward(
        self, loss: torch.Tensor, terms: dict[str, float], aux: Any
    ) -> tuple[torch.Tensor, dict[str, float]]:
        """After a finite backward pass of step ``self.step``: the loss and terms to log."""
        return loss, terms

    @abstractmethod
    def optimizer_step(self) -> None:
        """Step the optimisers (``self.step`` already counts this step) and what follows them."""

    @abstractmethod
    def model_state(self) -> dict[str, Any]:
        """The checkpoint's model, optimiser, method and generator state (beside :data:`RUN_STATE`)."""

    def state_problem(self, state: dict) -> str | None:
        """What makes a checkpoint of this configuration unusable, or None."""
        missing = [k for k in RUN_STATE if k not in state]
        return f"missing {', '.join(missing)}" if missing else None

    @abstractmethod
    def restore_model(self, state: dict) -> None:
        """Load :meth:`model_state`'s part of ``state``."""

    @abstractmethod
    def held_out(self, step: int) -> dict[str, float]:
        """Held-out scores at ``step`` (:func:`held_out_scores`)."""

    @abstractmethod
    def size(self) -> dict[str, Any]:
        """The model-size columns of a log row."""

    @abstractmethod
    def describe(self, step: int, row: dict[str, Any]) -> str:
        """The log line of an evaluated step."""

    @abstractmethod
    def log_start(self) -> None:
        """Log the run's start (method, steps, model size, device)."""

    def before_steps(self) -> None:  # noqa: B027 (an optional hook: nothing by default)
        """Anything to do once before the first step of this process (after resuming)."""

    @abstractmethod
    def facts(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """``config.json``'s model facts: those before ``train_seconds`` and those after ``skipped_steps``."""

    @abstractmethod
    def write_model(self, folder: Path) -> None:
        """Write the model file (and any companion file) into ``folder``."""

    # ------------------------------------------------------------------ one step
    def train_step(self) -> bool:
        """Run step ``self.step``; False when it was skipped (non-finite loss or gradient)."""
        step = self.step
        loss, terms, aux = self.forward()
        self.zero_grad()
        ok = bool(torch.isfinite(loss))
        if ok:
            loss.backward()
            ok = finite_grads(self.trained_params())
        if ok:
            loss, terms = self.after_backward(loss, terms, aux)
        self.step += 1
        if not ok:
            self.zero_grad()
            self.bad += 1
            self.skipped += 1
            self.log.warning("step %d: non-finite loss or gradient, skipped (%d in a row)", step, self.bad)
            return False
        self.bad = 0
        self.optimizer_step()
        self._last = {"loss": loss.item(), **terms}
        return True

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        return {
            "version": CHECKPOINT_VERSION,
            "config": self.cfg.to_dict(),
            "inputs_digest": self.inputs_digest,
            "step": self.step,
            **self.model_state(),
            "torch_rng": torch.get_rng_state(),
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
        log = self.log
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
        if state.get("inputs_digest") != self.inputs_digest:
            # the same options on other data (a rerun SfM, a regenerated scene): resuming would mix the two
            log.warning("ignoring checkpoint %s: written from other input files", path)
            return False
        problem = self.state_problem(state)
        if problem is None:
            try:
                self.restore_model(state)
                torch.set_rng_state(state["torch_rng"])
                self.step, self.rows, self.wall = int(state["step"]), list(state["rows"]), float(state["wall"])
                self.bad, self.skipped = int(state["bad"]), int(state["skipped"])
            except Exception as err:  # damage the checks cannot see: rebuild and start over
                problem = f"{type(err).__name__}: {err}".splitlines()[0]
                self.__init__(self.data, self.cfg, self.device)  # type: ignore[misc]
        if problem is not None:
            log.warning("ignoring damaged checkpoint %s (%s)", path, problem)
            return False
        self.resumed_at = self.step
        log.info("resumed from %s at step %d", path, self.step)
        return True


def run_steps(tr: RunTrainer, ckpt: Path, run_dir: Path, stop_after: int | None) -> bool:
    """``tr.train_step()`` from ``tr.step`` to ``cfg.steps`` with the wall clock, the non-finite-streak stop, a log
    row every ``log_every`` steps (and held-out PSNR every ``eval_every``), checkpoints every ``checkpoint_every``.
    True when it left at ``stop_after`` (checkpoint written, no outputs)."""
    cfg = tr.cfg
    has_held_out = tr.data.held_out is not None
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
            row: dict[str, Any] = {"step": s, "wall_s": round(tr.wall, 4), **tr._last, **tr.size()}
            if evaluate:
                row.update(tr.held_out(s))
                tr.log.info("%s", tr.describe(s, row))
            tr.rows.append(row)
        if s % cfg.checkpoint_every == 0 and s < cfg.steps:
            tr.save_checkpoint(ckpt)
        if stop_after is not None and s >= stop_after:
            tr.save_checkpoint(ckpt)
            return True
    return False


def fit(
    tr: RunTrainer, run_dir: str | Path, *, inputs: dict[str, str] | None = None, stop_after: int | None = None
) -> RunResult:
    """Train ``tr`` to ``cfg.steps`` (resuming from ``RUN_DIR.partial/checkpoint.pt`` when there is one) and write
    the run folder. ``inputs`` (name → path): the run's input files, recorded in ``config.json``; a checkpoint
    resumes only on byte-identical inputs (their digest is in it). ``stop_after``: leave after this many steps
    (checkpoint written, no outputs) — for tests of resumption."""
    run_dir = Path(run_dir)
    ckpt = run_folder.partial_dir(run_dir) / run_folder.CHECKPOINT
    tr.inputs_digest = files_digest(inputs) if inputs else None
    if ckpt.exists():
        tr.load_checkpoint(ckpt)
    tr.log_start()
    tr.before_steps()
    if not run_steps(tr, ckpt, run_dir, stop_after):
        write_run(tr, run_dir, inputs or {})
        shutil.rmtree(run_folder.partial_dir(run_dir), ignore_errors=True)
    return RunResult(tr.model, tr.method, tr.rows, tr.wall, tr.skipped)  # type: ignore[attr-defined]


def log_csv(rows: list[dict[str, Any]], fixed: tuple[str, ...]) -> str:
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


def write_run(tr: RunTrainer, run_dir: Path, inputs: dict[str, str]) -> None:
    """Write the model file, ``config.json`` and ``train_log.csv`` together (atomic directory rename)."""
    head, tail = tr.facts()
    facts = {
        "eigs_version": __version__,
        "torch_version": torch.__version__,
        "device": str(tr.device),
        "threads": torch.get_num_threads(),
        "machine": platform.machine(),
        **head,
        "train_seconds": round(tr.wall, 3),
        # CPU seconds of this process so far (all threads: data loading, training, writing; a resumed run counts
        # its last process only): what the job costs alone on a shared machine (Snakemake's benchmark files
        # sample CPU time every ~30 s and miss up to that much of a job's end)
        "process_cpu_s": round(time.process_time(), 3),
        "resumed_at_step": tr.resumed_at,  # > 0: process_cpu_s covers only the steps from here
        "skipped_steps": tr.skipped,
        **tail,
        "final": tr.rows[-1] if tr.rows else {},
    }
    doc = {"train": tr.cfg.to_dict(), "inputs": inputs, "run": facts}
    with atomic_path(run_dir, directory=True) as tmp:
        tr.write_model(tmp)
        (tmp / run_folder.CONFIG).write_text(json.dumps(doc, indent=2, default=float) + "\n")
        (tmp / run_folder.LOG).write_text(log_csv(tr.rows, tr.log_columns))
