"""Methods that explain a blurry frame by a learned camera trajectory within its exposure: BAD-Gaussians, BeSplat
and our reading of EvaGaussians (``docs/methods.md``).

One step on view v: the view's trajectory ``P(u) = P_ref · exp(ξ(u))`` (:mod:`eigs.train.gaussian.trajectory`) is
sampled at ``n_virtual`` evenly spaced times u_j = j / (n_virtual − 1); each virtual camera is rendered as the reference
camera looking at the Gaussians moved by ``P_ref · exp(−ξ(u_j)) · P_ref⁻¹`` (exact for a rigid motion, and
differentiable in ξ, which the rasterizer is not in the camera); the renders are averaged in linear intensity and
compared with the blurry frame (L1 + D-SSIM). Event losses compare renders at the latent times k / N, which are virtual
views when ``n_virtual − 1`` is a multiple of N.

Reference and start: ``P_ref`` is the view's latent pose k = 0 (as every method's). With ``init: latent`` the
control twists start at the least-squares fit to the relative latent poses ``P_0⁻¹ P_k`` from SfM (the paper's
protocol gives every method the EDI + COLMAP poses); with ``init: reference`` they start at zero plus N(0, 1e-5)
noise, as BAD-Gaussians starts from one COLMAP pose per image.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from eigs.errors import EigsError
from eigs.losses import photometric_loss
from eigs.losses.events import (
    event_integration_loss,
    from_linear,
    log_intensity,
    normalized_event_loss,
    to_linear,
)
from eigs.render.rigid import gaussian_motion, se3_exp, se3_log, transform_gaussians
from eigs.train.config import TrainConfig
from eigs.train.data import TrainData
from eigs.train.event_inputs import EventInputs
from eigs.train.gaussian.methods import LatentMotion, Method, StepOutput
from eigs.train.gaussian.model import GaussianModel
from eigs.train.gaussian.options import TrajectoryOptions
from eigs.train.gaussian.trajectory import curve_weights, fit_controls
from eigs.util.options import Options


class TrajectoryMethod(Method):
    """A per-view camera trajectory, ``n_virtual`` renders per step; the catalog's recipe of each method
    (``bad-gaussians``, ``besplat``, ``evagaussians``) sets its :class:`TrajectoryOptions`."""

    def __init__(self, data: TrainData, cfg: TrainConfig, opts: Options, device: torch.device):
        super().__init__(data, cfg, opts, device)
        assert isinstance(self.opts, TrajectoryOptions)
        o: TrajectoryOptions = self.opts
        self.o = o
        where = f"method {self.name}"
        mode, k_ctrl, n_virt = o.mode, o.n_control, o.n_virtual
        self.n_bins = data.n_latent - 1
        if o.event_loss != "none" and (n_virt - 1) % self.n_bins != 0:
            raise EigsError(where, f"event losses need n_virtual - 1 to be a multiple of the EDI bins {self.n_bins}")
        self.views = data.reference_views()
        if self.views.size == 0:
            raise EigsError(data.scene.name, f"method {self.name}: no view has a valid reference pose")
        self.mode, self.n_virtual = mode, n_virt
        u = torch.linspace(0.0, 1.0, n_virt, dtype=torch.float64)
        self.weights = curve_weights(mode, k_ctrl, u).float().to(device)  # (n_virtual, K)
        self.ref = data.c2w[:, 0].clone()  # (V, 4, 4) float64; NaN rows of invalid views are never used
        self.ref_f = self.ref.float().to(device)
        self.ref_inv_f = torch.linalg.inv(self._ref_or_identity()).float().to(device)
        controls = torch.zeros(data.n_views, k_ctrl, 6, dtype=torch.float64)
        if o.init == "latent":
            t_lat = torch.linspace(0.0, 1.0, data.n_latent, dtype=torch.float64)
            for v in self.views:
                ok = torch.from_numpy(data.valid[v])
                rel = torch.linalg.inv(self.ref[v]) @ data.c2w[v, ok]  # (M, 4, 4) camera-frame deltas P_0⁻¹ P_k
                controls[v] = fit_controls(mode, k_ctrl, t_lat[ok], se3_log(rel))
        else:
            gen = torch.Generator().manual_seed(cfg.seed)
            controls += 1e-5 * torch.randn(controls.shape, generator=gen, dtype=torch.float64)
        self.controls = controls.float().to(device).requires_grad_(True)  # (V, K, 6)
        self.blurry = data.blurry.to(device)
        self.response = data.camera_response
        self.events = EventInputs.from_edi(data.edi, device)

    def _ref_or_identity(self) -> Tensor:
        """(V, 4, 4) float64 reference poses with the identity in place of a view SfM did not register (NaN pose;
        such a view is never sampled), so that the batch inverse never meets a singular matrix."""
        ok = torch.isfinite(self.ref).all(dim=(1, 2))
        eye = torch.eye(4, dtype=self.ref.dtype).expand_as(self.ref)
        return torch.where(ok[:, None, None], self.ref, eye)

    # ------------------------------------------------------------------ registry hooks
    def n_samples(self) -> int:
        return int(self.views.size)

    def param_groups(self) -> list[dict]:
        return [{"params": [self.controls], "lr": self.o.lr_pose, "name": "trajectory"}]

    def state_dict(self) -> dict:
        return {"controls": self.controls.detach().cpu().clone()}

    def load_state_dict(self, state: dict) -> None:
        with torch.no_grad():  # in place: the optimiser holds this tensor
            self.controls.copy_(state["controls"].to(self.controls.device))

    @torch.no_grad()
    def latent_motion(self, means: Tensor, quats: Tensor) -> LatentMotion:
        """The trajectory at the latent times u = k / N, k = 1..N: camera poses ``P_ref · exp(ξ(u))`` and the
        scene motion that renders them from ``P_ref``, ``P_ref · exp(−ξ(u)) · P_ref⁻¹ x − x``."""
        u = torch.arange(1, self.n_bins + 1, dtype=torch.float64) / self.n_bins
        w = curve_weights(self.mode, self.controls.shape[1], u)  # (N, K)
        xi = torch.einsum("nk,vkd->vnd", w, self.controls.detach().cpu().double())  # (V, N, 6)
        ref = self._ref_or_identity()  # (V, 4, 4) float64
        cams = ref[:, None] @ se3_exp(xi)  # (V, N, 4, 4)
        moves = (ref[:, None] @ se3_exp(-xi) @ torch.linalg.inv(ref)[:, None]).float()
        x = means.detach().cpu().float()
        disp = torch.stack([torch.stack([transform_gaussians(x, quats.detach().cpu().float(), g)[0] - x for g in mv])
                            for mv in moves])  # fmt: skip
        views = np.zeros(self.data.n_views, bool)
        views[self.views] = True
        return LatentMotion(disp, self.ref.clone(), views, cams)

    # ------------------------------------------------------------------ one step
    def gaussian_motions(self, v: int) -> Tensor:
        """(n_virtual, 4, 4) rigid motions of the Gaussians that render view v's virtual cameras from P_ref."""
        xi = self.weights @ self.controls[v]  # (n_virtual, 6)
        return gaussian_motion(self.ref_f[v], xi, self.ref_inv_f[v])

    def step(self, model: GaussianModel, sample: int, step: int, sh_degree: int) -> StepOutput:
        o = self.o
        v = int(self.views[sample])
        p = model.params
        images, infos = [], []
        if o.sharp_one_render and bool(self.events.sharp[v]):  # no motion to model: one render, the frame as target
            return self.photometric_step(model, self.ref[v], self.blurry[v], sh_degree, v)
        for g in self.gaussian_motions(v):
            means, quats = transform_gaussians(p["means"], p["quats"], g)
            img, info = self.render_view(model, v, self.ref[v], sh_degree, means=means, quats=quats)
            images.append(img)
            infos.append(info)
        stack = torch.stack(images)  # (n_virtual, H, W, C)
        blur = from_linear(to_linear(stack, self.response).mean(dim=0), self.response)
        loss, l1, dssim = photometric_loss(blur, self.blurry[v], self.cfg.lambda_dssim, self.cfg.ssim_range)
        loss = o.lambda_blur * loss
        terms = {"l1": l1.item(), "dssim": dssim.item()}
        if o.event_loss != "none":
            stride = (self.n_virtual - 1) // self.n_bins
            logs = log_intensity(stack[::stride], self.response, self.events.mode)  # (L, H, W) at the latent times
            counts = self.events.counts[v]
            terms_ev = []
            for k in range(self.n_bins):
                e = counts[k + 1] - counts[k]
                if o.event_loss == "eigs":
                    c_pos, c_neg = self.events.thresholds(v)
                    terms_ev.append(event_integration_loss(logs[k], logs[k + 1], e, c_pos, c_neg, self.events.mask))
                else:
                    terms_ev.append(normalized_event_loss(logs[k], logs[k + 1], e, self.events.mask))
            ev = torch.stack(terms_ev).mean()
            loss = loss + o.lambda_event * ev
            terms["event"] = ev.item()
        return StepOutput(loss, terms, infos)
