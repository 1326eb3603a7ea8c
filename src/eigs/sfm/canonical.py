"""The canonical frame shared by every mode: camera centres centred at the origin, RMS radius 1.

Later stages use absolute constants (λ_p = 1e-2, Huber δ = 0.1, near plane 0.01); in this frame they mean the
same thing for every scene. The transform is a similarity without rotation, x ↦ s · (x − mean); it is
recorded in ``report.json`` so results can be mapped back to the source frame.
"""

from __future__ import annotations

import logging

import numpy as np

from eigs.metrics.trajectory import Sim3

log = logging.getLogger(__name__)


def canonical_transform(centres: np.ndarray) -> Sim3:
    """Sim(3) (rotation I) taking camera ``centres`` (N, 3) to mean 0 and RMS distance 1 from the origin.

    When all centres coincide (RMS radius 0), only the translation is applied and a warning is logged.
    """
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    c = c[np.all(np.isfinite(c), axis=1)]
    if c.shape[0] == 0:
        raise ValueError("no finite camera centres to define the canonical frame")
    mean = c.mean(0)
    rms = float(np.sqrt(np.mean(np.sum((c - mean) ** 2, axis=1))))
    if not rms > 0:
        log.warning("all camera centres coincide: the canonical frame is only translated (scale 1)")
        rms = 1.0
    s = 1.0 / rms
    return Sim3(s, np.eye(3), -s * mean)


def describe(sim: Sim3) -> dict:
    """JSON form recorded in report.json: ``x_canonical = scale · R · x_source + t``."""
    return {
        "formula": "x_canonical = scale * R @ x_source + t",
        **sim.to_dict(),
        "source_mean": (-(sim.R.T @ sim.t) / sim.scale).tolist(),
        "source_rms_radius": 1.0 / sim.scale,
    }
