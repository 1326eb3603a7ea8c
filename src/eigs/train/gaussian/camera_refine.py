"""Camera refinement in training (issue 44): a learned SE(3) correction per training view, for every Gaussian method.

View v's cameras become ``P_v · exp(ξ_v)`` for its reference camera ``P_v`` (latent k = 0) and a camera-frame twist
``ξ_v = (ω, ν)`` (rotation vector in radians, then translation in scene units), zero at the start. Every render of
the view moves together: the rasterizer has no pose gradients, so the view's Gaussians (after whatever the method
moves them by: the ADE, a trajectory) are moved by ``W_v⁻¹`` with ``W_v = P_v · exp(ξ_v) · P_v⁻¹``, which renders
exactly what cameras ``W_v · P`` see (:mod:`eigs.render.rigid`): for the reference camera that is
``P_v · exp(ξ_v)``, and every latent camera of the view is moved by the same rigid ``W_v``.

The corrections are anchored to the SfM frame. Moving every camera by one rigid motion ``M`` and the Gaussians by
``M`` as well renders the same images, so the loss cannot see that motion (the gauge of the reconstruction); left
free, the trained cameras and the model drift together off the frame the test cameras were registered in, and
every test view is rendered off by that drift (measured on four 128×96 scenes, `edi-3dgs`: −4.5 to −5.7 dB on
today's protocol, docs/training.md "Camera refinement"). As bundle adjusters fix a gauge, the learned twists ``η_v``
(the parameters) are projected: in world coordinates the view's correction is ``ζ_v = Ad(P_v) η_v``
(``W_v = exp(ζ_v)``), and the twist used is ``ξ_v = η_v − Ad(P_v)⁻¹ ζ̄`` with ``ζ̄`` the mean of ``ζ_v`` over the views
with a pose, so the world corrections sum to zero: no common motion of all cameras is learned, the average camera
stays where SfM put it, and the Gaussians absorb a common error instead (as they must for the test cameras, which
share it). The projection is linear and idempotent; its gradient is its transpose (autograd).

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
        eye = torch.eye(4, dtype=torch.float64)
        safe = torch.where(posed[:, None, None], self.ref, eye)
        self.ad = se3_adjoint(safe).to(device)  # (V, 6, 6) camera-frame twist → world-frame twist
        self.ad_inv = se3_adjoint(torch.linalg.inv(safe)).to(device)  # (V, 6, 6) its inverse

    def twists(self) -> Tensor:
        """(V, 6) float64 anchored twists ``ξ_v = η_v − Ad(P_v)⁻¹ ζ̄`` (module docstring): their world corrections
        ``Ad(P_v) ξ_v`` sum to zero over the posed views (to rounding, ~1e-16 relative); views without a pose keep
        ``η_v``. Differentiable in ``xi``."""
        eta = self.xi.to(torch.float64)
        zeta = (self.ad @ eta[:, :, None])[:, :, 0]  # (V, 6) world-frame corrections
        mean = zeta[self.posed].mean(dim=0)  # (6,)
        shift = (self.ad_inv @ mean[None, :, None].expand(len(eta), 6, 1))[:, :, 0]  # (V, 6)
        return eta - torch.where(self.posed[:, None], shift, torch.zeros_like(shift))

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
