"""The event-integration loss over a view's renders as one fused CPU kernel with its own backward
(``csrc/event_loss.cpp``).

:func:`event_loss_over_renders` computes what :func:`eigs.losses.events.event_integration_loss` computes from the
slices ``logs[:-1]``, ``logs[1:]`` and the count differences of consecutive renders: one pass forward and one
backward instead of some twenty whole-image tensor ops. The gradient is the same float32 arithmetic as that graph's
autograd (tests/losses/test_events.py checks it bit for bit); the loss value is summed in float64. Used on float32
CPU tensors without the dead zone; elsewhere the tensor ops run.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import torch
from torch import Tensor
from torch.autograd.function import once_differentiable

from eigs.losses.events import event_integration_loss
from eigs.util.extension import load_extension

CSRC = Path(__file__).resolve().parent / "csrc"
SOURCES = ("event_loss.cpp",)


def load() -> ModuleType:
    """The compiled kernel (built on first use, cached)."""
    return load_extension("eigs_event_loss", CSRC, SOURCES, (), "the fused event loss")


class _EventLoss(torch.autograd.Function):
    """Mean event-integration term of ``logs`` (L, H, W) against cumulative counts ``cum`` (L, H, W) int32 over the
    pixels ``keep`` (H, W) (``masked``: a mask chose them, and no pixel left gives 0 as the tensor ops' clamped
    count; else every pixel, and none gives NaN as their mean); the gradient flows to ``logs`` only."""

    @staticmethod
    def forward(ctx, logs: Tensor, cum: Tensor, c_pos: Tensor, c_neg: Tensor, keep: Tensor, masked: bool) -> Tensor:  # type: ignore[override]
        ctx.masked = masked
        (out,) = load().event_loss_fwd(logs, cum, c_pos, c_neg, keep)
        total, n = float(out[0]), int(out[1])
        ctx.save_for_backward(logs, cum, c_pos, c_neg, keep)
        ctx.n = n
        # as the tensor ops: a mask keeps at least one term in the denominator; without one, a mean over nothing is NaN
        mean = total / max(n, 1) if ctx.masked else (total / n if n else float("nan"))
        return torch.tensor(mean, dtype=logs.dtype)

    @staticmethod
    @once_differentiable
    def backward(ctx, v_loss: Tensor) -> tuple[Tensor | None, None, None, None, None, None]:  # type: ignore[override]
        logs, cum, c_pos, c_neg, keep = ctx.saved_tensors
        v_logs = load().event_loss_bwd(logs, cum, c_pos, c_neg, keep, float(v_loss), ctx.n)
        return v_logs, None, None, None, None, None


def _threshold_map(c: Tensor | float, shape: torch.Size) -> Tensor:
    """A threshold (one value or an (H, W) map) as the (H, W) float32 map the kernel reads."""
    return torch.as_tensor(c, dtype=torch.float32).expand(shape).contiguous()


def event_loss_over_renders(
    logs: Tensor, cum_counts: Tensor, c_pos: Tensor | float, c_neg: Tensor | float, mask: Tensor | None = None,
    deadzone: float = 0.0, mismatch: float = 0.0,
) -> Tensor:
    """Eq. 9–10 over the L − 1 intervals of consecutive renders: ``logs`` (L, H, W) log intensities in time order,
    ``cum_counts`` (L, H, W) cumulative net counts at the renders' times; thresholds and mask as
    :func:`event_integration_loss`, which gives the same loss (the mean of the intervals' losses)."""
    fused = (logs.device.type == "cpu" and logs.dtype == torch.float32 and cum_counts.dtype == torch.int32
             and deadzone == 0 and mismatch == 0 and logs.dim() == 3 and logs.shape[0] >= 2
             and cum_counts.shape == logs.shape)  # fmt: skip
    if not fused:
        return event_integration_loss(logs[:-1], logs[1:], cum_counts[1:] - cum_counts[:-1], c_pos, c_neg, mask,
                                      deadzone=deadzone, mismatch=mismatch)  # fmt: skip
    shape = logs.shape[1:]
    keep = torch.ones(shape, dtype=torch.bool) if mask is None else (~mask).contiguous()
    return _EventLoss.apply(logs.contiguous(), cum_counts.contiguous(), _threshold_map(c_pos, shape),
                            _threshold_map(c_neg, shape), keep, mask is not None)  # fmt: skip
