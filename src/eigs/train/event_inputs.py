"""What the event losses of a method read from the EDI artifact, moved to the training device once."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from eigs.artifacts.edi import EdiResult


@dataclass
class EventInputs:
    """``counts`` (V, L, H, W) int32 cumulative net counts; ``mask`` (H, W) bool or None (True: events ignored);
    ``c_maps`` per-pixel (C⁺, C⁻) (H, W) float32 or None; ``threshold`` (V,) float64 per-view threshold; ``mode``
    EDI's event model (``estimated`` or ``e2nerf``); ``sharp`` (V,) bool views EDI marked sharp."""

    counts: Tensor
    mask: Tensor | None
    c_maps: tuple[Tensor, Tensor] | None
    threshold: np.ndarray
    mode: str
    sharp: np.ndarray

    @classmethod
    def from_edi(cls, edi: EdiResult, device: torch.device) -> EventInputs:
        maps = None
        if edi.threshold_pos_map is not None and edi.threshold_neg_map is not None:
            maps = (
                torch.from_numpy(edi.threshold_pos_map).float().to(device),
                torch.from_numpy(edi.threshold_neg_map).float().to(device),
            )
        return cls(
            counts=torch.from_numpy(edi.cum_counts).to(device),
            mask=torch.from_numpy(edi.event_mask).to(device) if edi.event_mask is not None else None,
            c_maps=maps,
            threshold=np.asarray(edi.threshold, np.float64),
            mode=edi.mode,
            sharp=np.asarray(edi.sharp, bool),
        )

    def thresholds(self, v: int) -> tuple[Tensor | float, Tensor | float]:
        """(C⁺, C⁻) of view v: the per-pixel maps when EDI calibrated them, else the view's threshold twice."""
        if self.c_maps is not None:
            return self.c_maps
        c = float(self.threshold[v])
        return c, c
