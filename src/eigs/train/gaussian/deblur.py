"""Methods that explain a blurry frame by N+1 sharp renders: EiGS (ADE + blur + event + consistency), its
ablations, Deblurring-GS(+), and E2GS (fixed latent poses). ``docs/methods.md`` lists each method's recipe.

One step on view v: render k = 0 with the Gaussians as they are and k = 1..N with them moved (ADE) — or, for the
fixed-pose methods, render every latent pose P_k — from the view's reference camera; average the renders in linear
intensity (Eq. 2/7) and compare with the blurry frame (Eq. 8); add the event loss on consecutive renders
(Eq. 9–10) and the motion-consistency loss on the displacements (Eq. 3–6), Eq. 11.
"""

from __future__ import annotations

import logging

import numpy as np
import torch
from torch import Tensor

from eigs.errors import EigsError
from eigs.losses import photometric_loss
from eigs.losses.consistency import motion_consistency_loss
from eigs.losses.events import (
    e2nerf_event_loss,
    from_linear,
    lin_log,
    log_intensity,
    luma,
    to_linear,
)
from eigs.losses.fused_events import event_loss_over_renders
from eigs.metrics.texture import DARK_TEXTURE, ssim_texture_visibility
from eigs.render.rigid import rotation_product_matrix, transform_gaussians
from eigs.train.config import TrainConfig
from eigs.train.data import TrainData
from eigs.train.event_inputs import EventInputs
from eigs.train.gaussian.ade import ADE, compute_dtype
from eigs.train.gaussian.methods import LatentMotion, Method, StepOutput
from eigs.train.gaussian.model import GaussianModel
from eigs.train.gaussian.options import MultiRenderOptions
from eigs.util.options import Options

log = logging.getLogger(__name__)


def rigid_inverse(c2w: Tensor) -> Tensor:
    """Inverse of a rigid (…, 4, 4) transform."""
    r, t = c2w[..., :3, :3], c2w[..., :3, 3:]
    out = torch.zeros_like(c2w)
    out[..., :3, :3] = r.transpose(-1, -2)
    out[..., :3, 3:] = -r.transpose(-1, -2) @ t
    out[..., 3, 3] = 1.0
    return out


class MultiRender(Method):
    """N+1 renders per step; the catalog's recipe of each method (``eigs``, ``eigs-b``, ``e2gs``, …) sets its
    :class:`MultiRenderOptions`."""

    def __init__(self, data: TrainData, cfg: TrainConfig, opts: Options, device: torch.device):
        super().__init__(data, cfg, opts, device)
        assert isinstance(self.opts, MultiRenderOptions)
        o: MultiRenderOptions = self.opts
        self.o = o
        self.views = data.reference_views()
        if self.views.size == 0:
            raise EigsError(data.scene.name, f"method {self.name}: no view has a valid reference pose")
        self.n_latent = data.n_latent
        # latent poses with invalid entries replaced by the view's reference pose
        c2w = data.c2w.clone()
        bad = torch.from_numpy(~data.valid)
        c2w[bad] = c2w[:, :1].expand_as(c2w)[bad]
        self.c2w = c2w  # (V, L, 4, 4) float64
        self.response = data.camera_response
        self.blurry = (data.blurry if o.blur_target == "blurry" else self.discrete_targets()).to(device)
        self.latent_weight = self.sharp_frame_weight(data.blurry)
        self.latent = data.latent.to(device) if self.latent_weight > 0 else None  # (V, L, H, W, C)
        self.valid = torch.from_numpy(data.valid)  # (V, L) latent poses SfM registered
        self.events = EventInputs.from_edi(data.edi, device)
        self.ade: ADE | None = None
        if o.ade:
            self.ade = ADE(
                n_latent=self.n_latent,
                n_moved=self.n_latent - 1,
                width=o.width,
                depth=o.depth,
                x_freqs=o.x_freqs,
                pose_freqs=o.pose_freqs,
                out_per_latent=10 if o.shape else 3,
                matmul_dtype=compute_dtype(o.ade_precision, device),
            ).to(device)
            if o.ade_zero_last:
                with torch.no_grad():
                    self.ade.last.weight.zero_()
            self.pose_inputs = torch.stack([self.ade.encode_poses(self.c2w[v]) for v in range(data.n_views)]).to(device)
        # P_0 · P_k⁻¹ moves the Gaussians the way the camera moved from P_0 to P_k (the pose prior; the motion of the
        # fixed-pose methods)
        self.relative = (self.c2w[:, :1] @ rigid_inverse(self.c2w[:, 1:])).float().to(device)  # (V, N, 4, 4)
        self.relative_lt = rotation_product_matrix(self.relative)  # (V, N, 4, 4): constants, made once

    def discrete_targets(self) -> Tensor:
        """(V, H, W, C) blur targets for the N+1-sample average: the EDI latent frames averaged in linear intensity
        with the blur weights. EDI's latents average to the blurry frame over the continuous exposure, so this is
        the blurry frame times the per-pixel ratio of the discrete to the continuous exposure average that the events
        imply. Where that ratio leaves [2/3, 3/2] (clipped pixels, noise) or the frame is darker than
        ``discrete_floor`` the blurry frame is kept."""
        d = self.data
        w = self.blur_weights(d.n_latent).reshape(1, -1, 1, 1, 1)
        disc = (to_linear(d.latent, self.response) * w).sum(dim=1)  # (V, H, W, C)
        blur = to_linear(d.blurry, self.response)
        ratio = disc / blur.clamp_min(1e-6)
        keep = (blur > self.o.discrete_floor) & (ratio > 2 / 3) & (ratio < 1.5)
        return torch.where(keep, from_linear(disc, self.response), d.blurry).clamp(0.0, 1.0)

    # ------------------------------------------------------------------ registry hooks
    def n_samples(self) -> int:
        return int(self.views.size)

    def param_groups(self) -> list[dict]:
        if self.ade is None:
            return []
        return [{"params": list(self.ade.parameters()), "lr": self.o.lr_ade, "name": "ade"}]

    def state_dict(self) -> dict:
        return {"ade": self.ade.state_dict()} if self.ade is not None else {}

    def load_state_dict(self, state: dict) -> None:
        if self.ade is not None:
            self.ade.load_state_dict(state["ade"])

    # ------------------------------------------------------------------ one step
    def renders(
        self, model: GaussianModel, v: int, sh_degree: int
    ) -> tuple[list[Tensor], list[dict], Tensor | None, list[int]]:
        """Renders of view v in time order, their infos, the raw ADE displacements (N_G, N, 3) or None, and the
        positions of the N+1 latent renders in the list (every render is one with ``subframes = 1``)."""
        o = self.o
        images, infos = [], []

        def render(c2w: Tensor, **moved: Tensor) -> None:
            img, info = self.render_view(model, v, c2w, sh_degree, **moved)
            images.append(img)
            infos.append(info)

        if self.ade is None:
            for k in range(self.n_latent):
                render(self.c2w[v, k])
            return images, infos, None, list(range(self.n_latent))
        p = model.params
        out, disp, prior_quats = self.latent_offsets(v, p["means"].detach(), p["quats"])
        dx = out[..., :3]
        lam = o.lambda_p
        shape = [None] + [lam * out[:, k - 1, 3:] for k in range(1, self.n_latent)] if o.shape else None
        sub = o.subframes
        latent_pos = []
        for k in range(self.n_latent):
            for j in range(sub if k > 0 else 1):
                f = 1.0 - j / sub  # fraction of the way from latent k−1 to latent k (1 = at k)
                if j == 0:
                    latent_pos.append(len(images))
                off = disp[k] if f == 1.0 else f * disp[k] + (1 - f) * disp[k - 1]
                moved = {"means": p["means"] + off} if k > 0 else {}
                if k > 0 and o.pose_prior:  # rotations follow the prior of the nearest latent time
                    q = prior_quats[k if f >= 0.5 else k - 1]
                    moved["quats"] = p["quats"] if q is None else q
                if shape is not None and k > 0:
                    prev = shape[k - 1] if shape[k - 1] is not None else torch.zeros_like(shape[k])
                    sk = shape[k] if f == 1.0 else f * shape[k] + (1 - f) * prev
                    moved["quats"] = moved.get("quats", p["quats"]) + sk[:, :4]
                    moved["log_scales"] = p["log_scales"] + sk[:, 4:7]
                render(self.c2w[v, 0], **moved)
        # time order: within each interval the renders were made from latent k backwards; sort by time
        order = sorted(range(len(images)), key=lambda i: self._render_time(i, sub))
        images, infos = [images[i] for i in order], [infos[i] for i in order]
        latent_pos = [order.index(i) for i in latent_pos]
        return images, infos, dx, latent_pos

    def latent_offsets(self, v: int, x: Tensor, quats: Tensor) -> tuple[Tensor, list[Tensor], list[Tensor | None]]:
        """The ADE's raw output (G, N, 3 or 10) for view v at centres ``x`` (G, 3) (detached), the centre offsets
        at the latent times k = 0..N (k = 0: zero) and, with the pose prior, the rotated quaternions per k."""
        o = self.o
        assert self.ade is not None
        out = self.ade(x, self.pose_inputs[v])  # (G, N, 3 or 10)
        lam = o.lambda_p
        disp = [torch.zeros_like(x)]
        prior_quats: list[Tensor | None] = [None] * self.n_latent
        if o.pose_prior:  # the Gaussians moved by P_0·P_k⁻¹ (centres and rotations) render what P_k sees
            moved_x, moved_q = transform_gaussians(x, quats, self.relative[v], self.relative_lt[v])  # (N, G, 3/4)
        for k in range(1, self.n_latent):
            dk = lam * out[:, k - 1, :3]
            if o.pose_prior:
                dk = dk + (moved_x[k - 1] - x)
                prior_quats[k] = moved_q[k - 1]
            disp.append(dk)
        return out, disp, prior_quats

    @torch.no_grad()
    def latent_motion(self, means: Tensor, quats: Tensor) -> LatentMotion:
        """The centre offsets of the renders at k = 1..N (ADE, with the prior when on), or for the fixed-pose
        methods (no ADE) the scene motion of their latent cameras, P_0·P_k⁻¹ x − x; zero for a view training never
        draws (no valid reference pose)."""
        x = means.detach().to(self.device)
        q = quats.detach().to(self.device)
        disp = []
        trained = set(int(v) for v in self.views)
        for v in range(self.data.n_views):
            if v not in trained:  # no valid reference pose (SfM did not register it): never drawn, no motion
                disp.append(torch.zeros(self.n_latent - 1, *x.shape, dtype=x.dtype, device=x.device))
            elif self.ade is not None:
                disp.append(torch.stack(self.latent_offsets(v, x, q)[1][1:]))
            else:
                disp.append(transform_gaussians(x, q, self.relative[v])[0] - x)
        views = np.zeros(self.data.n_views, bool)
        views[self.views] = True
        cams = None if self.ade is not None else self.c2w[:, 1:].clone()
        return LatentMotion(torch.stack(disp).cpu(), self.c2w[:, 0].clone(), views, cams)

    @staticmethod
    def _render_time(i: int, sub: int) -> float:
        """Time (in latent intervals) of the i-th render of :meth:`renders`' construction order."""
        if i == 0:
            return 0.0
        k, j = divmod(i - 1, sub)
        return k + 1 - j / sub

    def sharp_frame_weight(self, blurry: Tensor) -> float:
        """The latent term's weight: ``latent_weight_dark`` on a dark scene (its blurry frames (V, H, W, C) in [0, 1]
        hold texture SSIM cannot see: :data:`eigs.metrics.texture.DARK_TEXTURE`), else ``latent_weight``."""
        o = self.o
        if o.latent_weight_dark <= 0:
            return o.latent_weight
        visibility = ssim_texture_visibility(blurry)
        dark = visibility < DARK_TEXTURE
        weight = o.latent_weight_dark if dark else o.latent_weight
        log.info("blurry frames' texture over SSIM's C2: %.3f (%s below %.2f): sharp-frame weight %g", visibility,
                 "dark," if dark else "not", DARK_TEXTURE, weight)  # fmt: skip
        return weight

    def blur_weights(self, n: int) -> Tensor:
        """Weights of the n time-ordered renders in the blur average: uniform (Eq. 2) or trapezoidal."""
        if self.o.blur_weights == "uniform" or n == 1:
            return torch.full((n,), 1.0 / n)
        w = torch.ones(n)
        w[0] = w[-1] = 0.5
        return w / w.sum()

    def sharp_step(self, model: GaussianModel, v: int, sh_degree: int) -> StepOutput:
        """A view without motion (EDI marked it sharp): one render at its reference pose against the frame."""
        return self.photometric_step(model, self.c2w[v, 0], self.blurry[v], sh_degree, v)

    def step(self, model: GaussianModel, sample: int, step: int, sh_degree: int) -> StepOutput:
        o = self.o
        v = int(self.views[sample])
        if o.sharp_one_render and bool(self.events.sharp[v]):
            return self.sharp_step(model, v, sh_degree)
        images, infos, dx, latent_pos = self.renders(model, v, sh_degree)
        stack = torch.stack(images)  # (R, H, W, C) in time order
        w = self.blur_weights(len(images)).to(stack).reshape(-1, 1, 1, 1)
        blur = from_linear((to_linear(stack, self.response) * w).sum(dim=0), self.response)
        if latent_pos != list(range(len(images))):  # the N+1 latent renders for the event losses, in time order
            # (a stack, not stack[latent_pos]: the backward of an index is a scatter-add, ~7 ms at 346×260)
            stack = torch.stack([images[i] for i in latent_pos])
        loss, l1, dssim = photometric_loss(blur, self.blurry[v], self.cfg.lambda_dssim, self.cfg.ssim_range)
        terms = {"l1": l1.item(), "dssim": dssim.item()}
        if o.event_loss == "eigs":
            logs = log_intensity(stack, self.response, self.events.mode)  # (L, H, W)
            counts = self.events.counts[v]
            c_pos, c_neg = self.events.thresholds(v)
            dz, mm = o.event_deadzone, o.event_mismatch
            # the N intervals in one call: the mean of their losses
            ev = event_loss_over_renders(logs, counts, c_pos, c_neg, self.events.mask, deadzone=dz, mismatch=mm)
            loss = loss + o.lambda_event * ev
            terms["event"] = ev.item()
        elif o.event_loss == "e2nerf":
            logs = lin_log(255.0 * luma(stack.clamp(0, 1)))
            ev = e2nerf_event_loss(logs, self.events.counts[v])
            loss = loss + o.lambda_event * ev
            terms["event"] = ev.item()
        # a latent frame without a pose has no render of its own time (self.valid is on the CPU: no device sync)
        if self.latent is not None and bool(self.valid[v].any()):
            lam = self.cfg.lambda_dssim if o.latent_dssim else 0.0
            if bool(self.valid[v].all()):  # every latent frame posed: no index (its backward is a scatter-add)
                lat, _, _ = photometric_loss(stack, self.latent[v], lam, self.cfg.ssim_range)
            else:
                ok = self.valid[v].to(stack.device)
                lat, _, _ = photometric_loss(stack[ok], self.latent[v][ok], lam, self.cfg.ssim_range)
            loss = loss + self.latent_weight * lat
            terms["latent"] = lat.item()
        if o.consistency and dx is not None:
            x = model.params["means"].detach()
            cons = motion_consistency_loss(
                x, dx.transpose(0, 1), reg=o.consis_reg, delta=o.huber_delta, grad_through_fit=o.grad_through_fit
            )  # the mean over the N moved times
            loss = loss + o.lambda_consis * cons
            terms["consis"] = cons.item()
        if dx is not None:
            terms["disp"] = o.lambda_p * dx.detach().norm(dim=-1).mean().item()
        return StepOutput(loss, terms, infos)
