"""Camera refinement in training (issue 44): a learned SE(3) correction per training view, for every Gaussian method.

View v's cameras become ``P_v · exp(ξ_v)`` for its reference camera ``P_v`` (latent k = 0) and a camera-frame twist
``ξ_v = (ω, ν)`` (rotation vector in radians, then translation in scene units), zero at the start. Every render of
the view moves together: the rasterizer has no pose gradients, so the view's Gaussians (after whatever the method
moves them by: the ADE, a trajectory) are moved by ``W_v⁻¹`` with ``W_v = P_v · exp(ξ_v) · P_v⁻¹``, which renders
exactly what cameras ``W_v · P`` see (:mod:`eigs.render.rigid`): for the reference camera that is
``P_v · exp(ξ_v)``, and every latent camera of the view is moved by the same rigid ``W_v``.

The corrections are anchored to the SfM frame: the learned parameters ``η`` (V, 6) are projected, and the twists
used are ``ξ = η − G·G⁺·η`` (over the views with a pose; ``G⁺`` the pseudo-inverse), ``G`` spanning 13 directions in
which the corrections move the reconstruction as a whole and the loss cannot, or can hardly, see them:
- every camera moved by one world motion ``exp(ζ)`` (6; ``η_v = Ad(P_v)⁻¹ ζ``): with the Gaussians moved alike it
  renders the same images (the gauge of a reconstruction);
- the cameras scaled about their centroid (1; world translations ``∝ c_v − c̄``): the same with the Gaussians scaled;
- one camera-frame twist for every view (6; ``η_v = ξ``): for cameras around an object at similar distances a common
  tilt equals a translation of the model, so it is nearly invisible to the loss.
Left free, training walks along them: measured on 128×96 scenes with `edi-3dgs` (docs/training.md "Camera
refinement"), unanchored corrections shared a 0.27–0.33° tilt about the cameras' x axes (spread 0.05–0.08° between
views), the model followed, and every test camera SfM registered was off by it (−4.9 to −5.6 dB under today's
protocol, +0.1 to +0.3 dB with the test cameras refined); removing the world motion alone left the tilt (−2 dB). The
projection is linear and idempotent; its gradient is its transpose (autograd). A common error of the SfM along these
directions is left to the Gaussians, as for the test cameras, which share it. With one or two posed views nothing is
left to learn (the 13 directions span their corrections).

Schedule and regulariser from published practice: Adam on the twists with learning rate ``lr_camera`` decaying
exponentially to ``lr_camera_final`` over the run's schedule and an L2 weight decay ``camera_reg`` on the twists —
BAD-Gaussians' camera optimiser (gsplat-based; its `pose_opt_lr` 1e-3, decayed by a factor 1e-3 over training,
`pose_opt_reg` 1e-6), the values our trajectory baselines' ``lr_pose`` already uses. gsplat's own example trainer uses
1e-5 for corrections refined over 30,000 steps, too slow for a few thousand (docs/training.md, "Camera refinement").
"""

from __future__ import annotations

import torch
from torch import Tensor

from eigs.render.rigid import gaussian_motion, se3_adjoint, se3_exp, transform_gaussians


def gauge_basis(c2w: Tensor) -> Tensor:
    """(6 V, 13) float64: the directions of the stacked camera-frame twists (V views, ``c2w`` (V, 4, 4) float64) along
    which the corrections move the reconstruction as a whole (module docstring): a common world twist (6 columns), a
    scaling about the cameras' centroid (1), a common camera-frame twist (6)."""
    v = c2w.shape[0]
    # (V, 6, 6) world-frame twist → camera-frame twist: column j holds the camera twists of world twist e_j
    world = se3_adjoint(torch.linalg.inv(c2w))
    centres = c2w[:, :3, 3]
    spread = torch.cat([torch.zeros_like(centres), centres - centres.mean(dim=0)], dim=1)  # (V, 6) world twists
    scale = world @ spread[:, :, None]  # (V, 6, 1)
    common = torch.eye(6, dtype=c2w.dtype).expand(v, 6, 6)
    return torch.cat([world, scale, common], dim=2).reshape(6 * v, 13)


class CameraRefinement:
    """The learned twists ``xi`` (V, 6), one per view of the scene (views training never draws keep zero), their
    anchored form (:meth:`twists`) and the rigid motions of the Gaussians they imply. ``reference_c2w`` (V, 4, 4):
    each view's reference camera (held in float64; a view without a pose has non-finite entries and takes no part in
    the anchoring); ``dtype``: the parameters' (float32 in training, the Gaussians' dtype)."""

    NAME = "camera"  # the Adam param group's name

    def __init__(self, reference_c2w: Tensor, device: torch.device, dtype: torch.dtype = torch.float32):
        self.ref = reference_c2w.to(torch.float64)  # (V, 4, 4) on the CPU
        self.ref_inv = torch.linalg.inv(self.ref)
        self.xi = torch.zeros(self.ref.shape[0], 6, dtype=dtype, device=device, requires_grad=True)
        posed = torch.isfinite(self.ref).all(dim=(1, 2))  # (V,)
        if not bool(posed.any()):
            raise ValueError("camera refinement needs at least one view with a pose")
        self.posed = posed.to(device)
        g = gauge_basis(self.ref[posed])  # (6 Vp, 13)
        self.gauge = g.to(device)
        self.gauge_pinv = torch.linalg.pinv(g, rtol=1e-10).to(device)  # (13, 6 Vp)

    def twists(self) -> Tensor:
        """(V, 6) float64 anchored twists ``ξ = η − G·G⁺·η`` (module docstring): orthogonal to every gauge direction
        (to rounding, ~1e-15 relative); views without a pose keep ``η_v``. Differentiable in ``xi``."""
        eta = self.xi.to(torch.float64)
        flat = eta[self.posed].reshape(-1)  # (6 Vp,)
        anchored = flat - self.gauge @ (self.gauge_pinv @ flat)
        return eta.masked_scatter(self.posed[:, None].expand_as(eta), anchored)

    def param_group(self, lr: float, weight_decay: float) -> dict:
        return {"params": [self.xi], "lr": lr, "weight_decay": weight_decay, "name": self.NAME}

    def world_motion(self, v: int) -> Tensor:
        """(4, 4) float64 ``W_v⁻¹ = P_v · exp(−ξ_v) · P_v⁻¹`` (``ξ_v`` anchored, :meth:`twists`), the motion of
        view v's Gaussians (differentiable in ``xi``)."""
        dev = self.xi.device
        return gaussian_motion(self.ref[v].to(dev), self.twists()[v], self.ref_inv[v].to(dev))

    def move(self, v: int, means: Tensor, quats: Tensor) -> tuple[Tensor, Tensor]:
        """View v's Gaussians, centres (N, 3) and rotations (N, 4), as its corrected cameras see them."""
        return transform_gaussians(means, quats, self.world_motion(v))

    @torch.no_grad()
    def corrected_c2w(self) -> Tensor:
        """(V, 4, 4) float64: every view's corrected reference camera ``P_v · exp(ξ_v)`` (anchored twists)."""
        return self.ref @ se3_exp(self.twists().detach().cpu())

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
