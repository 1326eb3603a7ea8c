"""Camera refinement in training (issue 44): a learned SE(3) correction per training view, for every Gaussian method.

View v's cameras become ``P_v · exp(ξ_v)`` for its reference camera ``P_v`` (latent k = 0) and a camera-frame twist
``ξ_v = (ω, ν)`` (rotation vector in radians, then translation in scene units), zero at the start. Every render of
the view moves together: the rasterizer has no pose gradients, so the view's Gaussians (after whatever the method
moves them by: the ADE, a trajectory) are moved by ``W_v⁻¹`` with ``W_v = P_v · exp(ξ_v) · P_v⁻¹``, which renders
exactly what cameras ``W_v · P`` see (:mod:`eigs.render.rigid`): for the reference camera that is
``P_v · exp(ξ_v)``, and every latent camera of the view is moved by the same rigid ``W_v``.

Schedule and regulariser from published practice: Adam on the twists with learning rate ``lr_camera`` decaying
exponentially to ``lr_camera_final`` over the run's schedule and an L2 weight decay ``camera_reg`` on the twists —
BAD-Gaussians' camera optimiser (gsplat-based; its `pose_opt_lr` 1e-3, decayed by a factor 1e-3 over training,
`pose_opt_reg` 1e-6), the values our trajectory baselines' ``lr_pose`` already uses. gsplat's own example trainer uses
1e-5 for corrections refined over 30,000 steps, too slow for a few thousand (docs/training.md, "Camera refinement").
"""

from __future__ import annotations

import torch
from torch import Tensor

from eigs.render.rigid import gaussian_motion, se3_exp, transform_gaussians


class CameraRefinement:
    """The twists ``xi`` (V, 6), one per view of the scene (views training never draws keep zero), and the rigid
    motions of the Gaussians they imply. ``reference_c2w`` (V, 4, 4): each view's reference camera (held in
    float64); ``dtype``: the twists' (float32 in training, the Gaussians' dtype)."""

    NAME = "camera"  # the Adam param group's name

    def __init__(self, reference_c2w: Tensor, device: torch.device, dtype: torch.dtype = torch.float32):
        self.ref = reference_c2w.to(torch.float64)  # (V, 4, 4) on the CPU
        self.ref_inv = torch.linalg.inv(self.ref)
        self.xi = torch.zeros(self.ref.shape[0], 6, dtype=dtype, device=device, requires_grad=True)

    def param_group(self, lr: float, weight_decay: float) -> dict:
        return {"params": [self.xi], "lr": lr, "weight_decay": weight_decay, "name": self.NAME}

    def world_motion(self, v: int) -> Tensor:
        """(4, 4) float64 ``W_v⁻¹ = P_v · exp(−ξ_v) · P_v⁻¹``, the motion of view v's Gaussians (differentiable in
        ``xi``)."""
        dev = self.xi.device
        return gaussian_motion(self.ref[v].to(dev), self.xi[v].to(torch.float64), self.ref_inv[v].to(dev))

    def move(self, v: int, means: Tensor, quats: Tensor) -> tuple[Tensor, Tensor]:
        """View v's Gaussians, centres (N, 3) and rotations (N, 4), as its corrected cameras see them."""
        return transform_gaussians(means, quats, self.world_motion(v))

    @torch.no_grad()
    def corrected_c2w(self) -> Tensor:
        """(V, 4, 4) float64: every view's corrected reference camera ``P_v · exp(ξ_v)``."""
        return self.ref @ se3_exp(self.xi.detach().cpu().to(torch.float64))

    def state_dict(self) -> dict:
        return {"xi": self.xi.detach().cpu().clone()}

    def state_problem(self, state: object) -> str | None:
        """What makes a checkpoint's ``state`` (from :meth:`state_dict`) unusable here, or None."""
        xi = state.get("xi") if isinstance(state, dict) else None
        if not isinstance(xi, Tensor) or xi.shape != self.xi.shape or not bool(torch.isfinite(xi).all()):
            return "camera corrections missing or damaged"
        return None

    def load_state_dict(self, state: dict) -> None:
        problem = self.state_problem(state)
        if problem is not None:
            raise ValueError(problem)
        with torch.no_grad():
            self.xi.copy_(state["xi"].to(self.xi))
