"""Pure-PyTorch float64 reference of the volume rendering of one ray (tests only): the contract of
:mod:`eigs.render.volume` written literally, sample by sample, with the transmittance as a running product
T_{i+1} = T_i (1 − α_i) instead of the batched exponential of a cumulative sum."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from eigs.render.volume import TAU_MAX


def composite_ray(sigmas: Tensor, colours: Tensor, deltas: Tensor, background: Tensor) -> tuple[Tensor, Tensor]:
    """One ray: ``sigmas`` (S,), ``colours`` (S, C), ``deltas`` (S,), ``background`` (C,) → colour (C,) and
    opacity (scalar), in float64. Non-finite densities follow the contract (NaN → 0, +inf → saturated)."""
    sigmas, colours = sigmas.double(), colours.double()
    deltas, background = deltas.double(), background.double()
    trans = torch.ones((), dtype=torch.float64)
    rgb = torch.zeros_like(background)
    for i in range(sigmas.shape[0]):
        s = float(sigmas[i].detach())
        if math.isnan(s) or s < 0.0:
            tau = torch.zeros((), dtype=torch.float64)
        elif math.isinf(s):
            tau = torch.full((), TAU_MAX, dtype=torch.float64)
        else:
            tau = torch.clamp(sigmas[i] * deltas[i], 0.0, TAU_MAX)
        alpha = 1.0 - torch.exp(-tau)
        rgb = rgb + trans * alpha * colours[i]
        trans = trans * (1.0 - alpha)
    return rgb + trans * background, 1.0 - trans
