"""The Adam every trainer uses: PyTorch's fused kernel (one pass over each parameter tensor for its moments and its
update) where the parameters' device has one, CPU and CUDA; the multi-tensor loop elsewhere.

Measured on the Xeon (2 threads, 2026-11-30): a Gaussian run's parameters (10,000 Gaussians with SH degree 3 and the
ADE's) 2.97 ms a step with ``foreach`` and 1.07 ms fused; a 4 × 96³ field grid 16.7 ms with PyTorch's default loop and
1.7 ms fused (20.2 and 2.8 ms on one thread). Same update up to float rounding (~1e-8 after ten steps).

The fused case is :class:`FusedAdam`, not ``torch.optim.Adam(fused=True)``: the same kernel call
(``torch._fused_adam_``), state and ``state_dict`` bit for bit, without ``torch.optim.Optimizer``, whose methods
import ``torch._dynamo`` (and sympy) on first use: seconds of every training process's start (docs/benchmarks.md,
"A training process's start").
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable
from copy import deepcopy
from typing import Any

import torch

FUSED_DEVICES = ("cpu", "cuda")  # where torch._fused_adam_ runs

# Options torch.optim.Adam writes into every parameter group; FusedAdam writes the same, so that either one's
# state_dict loads into the other (checkpoints written before FusedAdam resume).
_TORCH_ADAM_GROUP = {"amsgrad": False, "maximize": False, "foreach": None, "capturable": False,
                     "differentiable": False, "fused": True, "decoupled_weight_decay": False}  # fmt: skip


def _in_memory_order(ts: tuple[torch.Tensor, ...]) -> tuple[torch.Tensor, ...]:
    """Tensors of one shape and one dense layout (a field's channels-last grid, its gradient and moments) as 1-D
    views in memory order: Adam is elementwise, so the update is the same, and PyTorch's fused kernel runs its
    contiguous path (2.7× faster than on the strided tensors: 3.9 vs 10.6 ms on a 4 × 96³ grid, one thread). Other
    tensors as they are."""
    first = ts[0]
    if first.is_contiguous() or any(t.stride() != first.stride() or t.shape != first.shape for t in ts):
        return ts
    order = sorted(range(first.dim()), key=lambda d: -first.stride(d))
    if not first.permute(order).is_contiguous():  # not dense (a view with gaps): leave it to PyTorch
        return ts
    return tuple(t.permute(order).view(-1) for t in ts)


class FusedAdam:
    """Adam with bias correction (Kingma & Ba), no AMSGrad, no decoupled weight decay, on floating tensors of the
    CPU or CUDA: ``torch.optim.Adam(..., fused=True)``'s update, per-parameter state (``step`` a float32 scalar on
    the parameter's device, ``exp_avg``, ``exp_avg_sq``), ``param_groups`` and ``state_dict`` format, bit for bit
    (tests/train/test_optim.py). Groups are dicts with ``params`` and any extra keys (a ``name``, a ``base_lr``)."""

    def __init__(
        self,
        params: Iterable[Any],
        lr: float = 1e-3,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
        weight_decay: float = 0.0,
    ) -> None:
        self.defaults: dict[str, Any] = {"lr": lr, "betas": tuple(betas), "eps": eps, "weight_decay": weight_decay,
                                         **_TORCH_ADAM_GROUP}  # fmt: skip
        self.state: defaultdict[torch.Tensor, dict[str, Any]] = defaultdict(dict)
        self.param_groups: list[dict[str, Any]] = []
        groups = list(params)
        if not groups:
            raise ValueError("optimizer got an empty parameter list")
        for group in groups if isinstance(groups[0], dict) else [{"params": groups}]:
            self.add_param_group(group)

    def add_param_group(self, group: dict[str, Any]) -> None:
        group = dict(group)
        params = group["params"]
        group["params"] = [params] if isinstance(params, torch.Tensor) else list(params)
        for p in group["params"]:
            if not isinstance(p, torch.Tensor) or not p.is_floating_point() or p.device.type not in FUSED_DEVICES:
                raise TypeError(f"FusedAdam takes floating tensors on {' or '.join(FUSED_DEVICES)}, got {p!r:.60}")
        seen = {id(p) for g in self.param_groups for p in g["params"]}
        if len({id(p) for p in group["params"]} | seen) != len(seen) + len(group["params"]):
            raise ValueError("some parameters appear in more than one parameter group")
        for key, value in self.defaults.items():
            group.setdefault(key, value)
        self.param_groups.append(group)

    def zero_grad(self, set_to_none: bool = True) -> None:
        for group in self.param_groups:
            for p in group["params"]:
                if p.grad is None:
                    continue
                if set_to_none:
                    p.grad = None
                else:
                    p.grad.detach_().zero_()

    @torch.no_grad()
    def step(self) -> None:
        """One update of every parameter that has a gradient (its state created on its first)."""
        for group in self.param_groups:
            lists: dict[tuple[torch.device, torch.dtype], tuple[list[torch.Tensor], ...]] = {}
            for p in group["params"]:
                if p.grad is None:
                    continue
                state = self.state[p]
                if not state:
                    state["step"] = torch.zeros((), dtype=torch.float32, device=p.device)
                    state["exp_avg"] = torch.zeros_like(p, memory_format=torch.preserve_format)
                    state["exp_avg_sq"] = torch.zeros_like(p, memory_format=torch.preserve_format)
                bucket = lists.setdefault((p.device, p.dtype), ([], [], [], [], []))
                tensors = (*_in_memory_order((p, p.grad, state["exp_avg"], state["exp_avg_sq"])), state["step"])
                for lst, t in zip(bucket, tensors, strict=True):
                    lst.append(t)
            beta1, beta2 = group["betas"]
            for params, grads, exp_avgs, exp_avg_sqs, steps in lists.values():
                torch._foreach_add_(steps, 1)
                torch._fused_adam_(params, grads, exp_avgs, exp_avg_sqs, [], steps, amsgrad=False, lr=group["lr"],
                                   beta1=beta1, beta2=beta2, weight_decay=group["weight_decay"], eps=group["eps"],
                                   maximize=False, grad_scale=None, found_inf=None)  # fmt: skip

    def state_dict(self) -> dict[str, Any]:
        """``torch.optim.Optimizer.state_dict``'s format: parameters numbered in group order."""
        index: dict[int, int] = {}
        groups = []
        for group in self.param_groups:
            packed = {k: v for k, v in group.items() if k != "params"}
            packed["params"] = [index.setdefault(id(p), len(index)) for p in group["params"]]
            groups.append(packed)
        state = {index[id(p)]: s for p, s in self.state.items() if id(p) in index}
        return {"state": state, "param_groups": groups}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Load a :meth:`state_dict` (or ``torch.optim.Adam``'s): groups must match in number and sizes; each group's
        hyperparameters come from the file, its parameters are this optimizer's; moments cast to their parameter's
        dtype and device, ``step`` to a float32 scalar on it."""
        saved = deepcopy(state_dict["param_groups"])
        if len(saved) != len(self.param_groups):
            raise ValueError("loaded state dict has a different number of parameter groups")
        if any(len(g["params"]) != len(s["params"]) for g, s in zip(self.param_groups, saved, strict=True)):
            raise ValueError("loaded state dict has a parameter group of another size than the optimizer's")
        by_index = {}  # saved index → this optimizer's parameter
        for group, saved_group in zip(self.param_groups, saved, strict=True):
            by_index.update(zip(saved_group["params"], group["params"], strict=True))
        state: defaultdict[torch.Tensor, dict[str, Any]] = defaultdict(dict)
        for index, entry in state_dict["state"].items():
            if index not in by_index:
                continue
            p = by_index[index]
            state[p] = {
                key: (value.to(dtype=torch.float32, device=p.device) if key == "step"
                      else value.to(dtype=p.dtype, device=p.device)) if isinstance(value, torch.Tensor) else value
                for key, value in entry.items()
            }  # fmt: skip
        self.state = state
        self.param_groups = [{**s, "params": g["params"]} for g, s in zip(self.param_groups, saved, strict=True)]


Optimizer = FusedAdam | torch.optim.Optimizer  # what the trainers hold: adam()'s result


def adam(params: Iterable[Any], **kwargs: Any) -> Optimizer:
    """Adam over ``params`` (tensors or param-group dicts, as ``torch.optim.Adam`` takes them; ``lr``, ``betas``,
    ``eps``, ``weight_decay``): :class:`FusedAdam` when every parameter is a floating tensor on a device of
    :data:`FUSED_DEVICES`, else ``torch.optim.Adam`` with ``foreach``."""
    params = list(params)
    tensors = [p for g in params for p in (g["params"] if isinstance(g, dict) else [g])]
    fused = bool(tensors) and all(t.device.type in FUSED_DEVICES and t.is_floating_point() for t in tensors)
    return FusedAdam(params, **kwargs) if fused else torch.optim.Adam(params, foreach=True, **kwargs)


def moments_consistent(exp_avg: torch.Tensor, exp_avg_sq: torch.Tensor, betas: tuple[float, float], eps: float) -> bool:
    """Whether Adam moments could come from some gradient history: ``|m| ≤ C·√v`` entry by entry, with
    ``C = (1 − β1) / √((1 − β2)(1 − β1²/β2))`` (Cauchy–Schwarz on m = (1 − β1) Σ β1^k g_k against
    v = (1 − β2) Σ β2^k g_k²; needs β1² < β2, else no bound is checked), relaxed by 0.1 % for float32 rounding and by
    ``eps`` for squares that underflowed. A damaged checkpoint can hold finite moments that break it (an exp_avg of
    3e36 against a v of 1e-9), and Adam's first step from them overflows the parameter to ±inf."""
    b1, b2 = float(betas[0]), float(betas[1])
    if not b1 * b1 < b2:
        return True
    c = (1.0 - b1) / math.sqrt((1.0 - b2) * (1.0 - b1 * b1 / b2))
    m, v = exp_avg.detach().double(), exp_avg_sq.detach().double()
    return bool((m.abs() <= c * 1.001 * v.clamp_min(0).sqrt() + eps).all())
