"""The radiance-field methods of Table I's NeRF columns, on the voxel-grid field (``docs/methods.md``):

- ``nerf``: rays of the blurry frames at the views' reference poses (latent k = 0), MSE;
- ``edi-nerf``: rays of the EDI latent frames at their latent poses, MSE;
- ``deblur-nerf``: Deblur-NeRF's deformable sparse kernel: K rays per pixel whose origins and directions a small
  per-view MLP moves, their colours averaged with learned weights, MSE against the blurry pixel;
- ``e2nerf``: each pixel rendered at the N + 1 latent poses of its view, MSE of their mean against the blurry pixel
  plus E²NeRF's pairwise event loss on the N + 1 renders.

A step draws ``batch_rays`` rays (``deblur-nerf``: batch_rays / K pixels, ``e2nerf``: batch_rays / (N + 1) pixels of
one view) from the method's torch generator, so a resumed run draws the same rays.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor, nn

from eigs.errors import EigsError
from eigs.losses.events import e2nerf_event_loss, from_linear, lin_log, luma, to_linear
from eigs.render.field import pixel_rays, render_rays
from eigs.train.catalog import FIELD
from eigs.train.catalog import method as method_spec
from eigs.train.config import TrainConfig
from eigs.train.data import TrainData
from eigs.train.field.model import FieldModel
from eigs.train.field.options import DeblurNerfOptions, E2NerfOptions, FieldOptions
from eigs.util.options import Options, options_json


@dataclass
class FieldStep:
    """One step's loss and the terms to log (floats)."""

    loss: Tensor
    terms: dict[str, float]


class FieldMethod(ABC):
    """Base class. ``spec``: the method's catalog entry (:mod:`eigs.train.catalog`); ``field_opts``: its options (a
    :class:`FieldOptions`, with the method's own fields for ``deblur-nerf`` and ``e2nerf``), checked; ``options``: the
    same as JSON (what ``config.json`` records)."""

    family = FIELD

    def __init__(self, data: TrainData, cfg: TrainConfig, opts: Options, device: torch.device):
        self.spec = method_spec(cfg.method)
        self.name, self.description = self.spec.name, self.spec.description
        assert isinstance(opts, FieldOptions), f"{self.name}: field options must be FieldOptions"
        self.field_opts: FieldOptions = opts
        self.options = options_json(opts)
        self.data, self.cfg, self.device = data, cfg, device
        self.K = data.K.to(device)
        self.background = data.background.to(device)
        self.views = data.reference_views()
        self.distortions: list[Tensor] = []

    def rays(self, c2w: Tensor, px: Tensor, py: Tensor) -> tuple[Tensor, Tensor]:
        return pixel_rays(c2w.to(self.device), self.K, px.to(self.device), py.to(self.device))

    def render(self, model: FieldModel, origins: Tensor, dirs: Tensor, gen: torch.Generator) -> Tensor:
        """Colours (R, C) with stratified samples (one jitter per ray from ``gen``)."""
        jitter = torch.rand((origins.shape[0], 1), generator=gen).to(self.device)
        stats: dict[str, Tensor] = {}
        rgb = render_rays(model.tensors(), origins, dirs, self.background, jitter, stats)[0]
        model.record_weights(stats["voxels"], stats["weights"])
        self.distortions.append(stats["distortion"].mean())
        return rgb

    def take_distortion(self) -> Tensor | None:
        """Mean distortion of the rays rendered since the last call (None when none were)."""
        d, self.distortions = self.distortions, []
        return torch.stack(d).mean() if d else None

    def pixels(self, n: int, gen: torch.Generator) -> tuple[Tensor, Tensor]:
        """``n`` random pixel indices (column, row)."""
        d = self.data
        return torch.randint(0, d.width, (n,), generator=gen), torch.randint(0, d.height, (n,), generator=gen)

    @abstractmethod
    def step(self, model: FieldModel, step: int, gen: torch.Generator) -> FieldStep:
        """One training step's loss."""

    def parameters(self) -> list[Tensor]:
        """Trainable tensors of the method besides the field (e.g. Deblur-NeRF's kernel network)."""
        return []

    def lr(self) -> float:
        return 0.0

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict) -> None:  # noqa: B027 (a method without state has nothing to load)
        """Restore what :meth:`state_dict` returned (nothing by default)."""


class ImageField(FieldMethod):
    """Rays of training images at their cameras, MSE against the pixels."""

    def __init__(self, data: TrainData, cfg: TrainConfig, opts: Options, device: torch.device):
        super().__init__(data, cfg, opts, device)
        images, c2w = self.samples()
        if images.shape[0] == 0:
            raise EigsError(data.scene.name, f"method {self.name}: no training sample has a valid pose")
        self.images = images  # (S, H, W, C) on the CPU (indexed per ray)
        self.c2w = c2w.to(torch.float32)  # (S, 4, 4)

    @abstractmethod
    def samples(self) -> tuple[Tensor, Tensor]:
        """(S, H, W, C) target images and (S, 4, 4) camera-to-world."""

    def step(self, model: FieldModel, step: int, gen: torch.Generator) -> FieldStep:
        n = self.field_opts.batch_rays
        s = torch.randint(0, self.images.shape[0], (n,), generator=gen)
        x, y = self.pixels(n, gen)
        origins, dirs = self.rays(self.c2w[s], x.float() + 0.5, y.float() + 0.5)
        rgb = self.render(model, origins, dirs, gen)
        target = self.images[s, y, x].to(self.device)
        mse = (rgb - target).pow(2).mean()
        return FieldStep(mse, {"mse": mse.item()})


class Nerf(ImageField):
    """``nerf``: rays of the blurry frames at the views' reference poses."""

    def samples(self) -> tuple[Tensor, Tensor]:
        return self.data.blurry[self.views], self.data.c2w[self.views, 0]


class EdiNerf(ImageField):
    """``edi-nerf``: rays of the EDI latent frames at their latent poses."""

    def samples(self) -> tuple[Tensor, Tensor]:
        v, k = np.nonzero(self.data.valid)
        return self.data.latent[v, k], self.data.c2w[v, k]


def latent_poses(data: TrainData) -> Tensor:
    """(V, L, 4, 4) float32 latent poses, invalid ones replaced by the view's reference pose."""
    c2w = data.c2w.clone()
    bad = torch.from_numpy(~data.valid)
    c2w[bad] = c2w[:, :1].expand_as(c2w)[bad]
    return c2w.to(torch.float32)


class E2Nerf(FieldMethod):
    """``e2nerf``: each pixel rendered at the N + 1 latent poses of its view, blur MSE + pairwise event loss."""

    def __init__(self, data: TrainData, cfg: TrainConfig, opts: Options, device: torch.device):
        super().__init__(data, cfg, opts, device)
        assert isinstance(self.field_opts, E2NerfOptions)
        self.own: E2NerfOptions = self.field_opts
        if self.views.size == 0:
            raise EigsError(data.scene.name, f"method {self.name}: no view has a valid reference pose")
        self.c2w = latent_poses(data)
        self.counts = torch.from_numpy(data.edi.cum_counts)  # (V, L, H, W)
        self.response = data.camera_response

    def step(self, model: FieldModel, step: int, gen: torch.Generator) -> FieldStep:
        n_lat = self.data.n_latent
        n = max(self.field_opts.batch_rays // n_lat, 1)
        v = int(self.views[int(torch.randint(0, self.views.size, (1,), generator=gen))])
        x, y = self.pixels(n, gen)
        px, py = (x.float() + 0.5).repeat(n_lat), (y.float() + 0.5).repeat(n_lat)
        c2w = self.c2w[v].repeat_interleave(n, dim=0)  # (L·n, 4, 4), latent-major
        origins, dirs = self.rays(c2w, px, py)
        stack = self.render(model, origins, dirs, gen).reshape(n_lat, n, -1)  # (L, n, C)
        blur = from_linear(to_linear(stack, self.response).mean(dim=0), self.response)
        target = self.data.blurry[v, y, x].to(self.device)
        mse = (blur - target).pow(2).mean()
        logs = lin_log(255.0 * luma(stack.clamp(0, 1)))  # (L, n)
        ev = e2nerf_event_loss(logs, self.counts[v][:, y, x].to(self.device))
        loss = mse + self.own.lambda_event * ev
        return FieldStep(loss, {"mse": mse.item(), "event": ev.item()})


class KernelNet(nn.Module):
    """Deblur-NeRF's DSK network: per-view embedding + positional encoding of the pixel → K × (Δq (2, pixels),
    Δo (3, camera frame, world units / 100), weight logit). The last layer starts at zero, so the kernel starts at
    the fixed initial pattern with equal weights."""

    def __init__(self, n_views: int, o: DeblurNerfOptions):
        super().__init__()
        self.o = o
        self.embed = nn.Embedding(n_views, o.embed_dim)
        nn.init.normal_(self.embed.weight, std=0.1)
        dims = [o.embed_dim + 2 + 4 * o.dsk_freqs] + [o.dsk_width] * (o.dsk_depth - 1) + [6 * o.kernel_points]
        layers: list[nn.Module] = []
        for i in range(len(dims) - 1):
            layers.append(nn.Linear(dims[i], dims[i + 1]))
            if i < len(dims) - 2:
                layers.append(nn.ReLU())
        self.mlp = nn.Sequential(*layers)
        last = self.mlp[-1]
        assert isinstance(last, nn.Linear)
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)

    def forward(self, view: Tensor, uv: Tensor) -> Tensor:
        """``view`` (R,) long, ``uv`` (R, 2) pixel position in [−1, 1] → (R, K, 6)."""
        freqs = (2.0 ** torch.arange(self.o.dsk_freqs, dtype=uv.dtype, device=uv.device)) * math.pi
        ang = uv.unsqueeze(-1) * freqs  # (R, 2, F)
        enc = torch.cat([uv, ang.sin().flatten(1), ang.cos().flatten(1)], dim=-1)
        out = self.mlp(torch.cat([self.embed(view), enc], dim=-1))
        return out.reshape(view.shape[0], self.o.kernel_points, 6)


class DeblurNerf(FieldMethod):
    """``deblur-nerf``: K rays per pixel moved by a per-view MLP (the DSK), their weighted mean against the pixel."""

    def __init__(self, data: TrainData, cfg: TrainConfig, opts: Options, device: torch.device):
        super().__init__(data, cfg, opts, device)
        o = self.field_opts
        assert isinstance(o, DeblurNerfOptions)
        self.own: DeblurNerfOptions = o
        if self.views.size == 0:
            raise EigsError(data.scene.name, f"method {self.name}: no view has a valid reference pose")
        g = torch.Generator().manual_seed(cfg.seed + 1)
        pattern = (torch.rand((o.kernel_points, 2), generator=g) * 2 - 1) * o.init_window
        pattern[0] = 0.0  # the first kernel point starts on the pixel's own ray
        self.pattern = pattern.to(device)
        self.net = KernelNet(data.n_views, o).to(device)
        self.c2w = data.c2w[:, 0].to(torch.float32)

    def parameters(self) -> list[Tensor]:
        return list(self.net.parameters())

    def lr(self) -> float:
        return self.own.lr_dsk

    def state_dict(self) -> dict:
        return {"net": self.net.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.net.load_state_dict(state["net"])

    def step(self, model: FieldModel, step: int, gen: torch.Generator) -> FieldStep:
        d, o = self.data, self.own
        kp = o.kernel_points
        n = max(self.field_opts.batch_rays // kp, 1)
        v = torch.from_numpy(self.views)[torch.randint(0, self.views.size, (n,), generator=gen)]
        x, y = self.pixels(n, gen)
        px, py = x.float() + 0.5, y.float() + 0.5
        uv = torch.stack([px / d.width * 2 - 1, py / d.height * 2 - 1], dim=-1).to(self.device)
        out = self.net(v.to(self.device), uv)  # (n, K, 6)
        dq = self.pattern + out[..., :2]  # pixels
        do = 0.01 * out[..., 2:5]
        do = torch.cat([torch.zeros_like(do[:, :1]), do[:, 1:]], dim=1)  # the first point keeps the origin
        w = torch.softmax(out[..., 5], dim=-1)  # (n, K)
        c2w = self.c2w[v].to(self.device)  # (n, 4, 4)
        c2w_k = c2w.repeat_interleave(kp, dim=0)
        origins, dirs = pixel_rays(c2w_k, self.K, (px.to(self.device).unsqueeze(1) + dq[..., 0]).reshape(-1),
                                   (py.to(self.device).unsqueeze(1) + dq[..., 1]).reshape(-1))  # fmt: skip
        origins = origins + (c2w_k[:, :3, :3] @ do.reshape(-1, 3, 1)).squeeze(-1)
        rgb = self.render(model, origins, dirs, gen).reshape(n, kp, -1)
        blur = (w.unsqueeze(-1) * rgb).sum(dim=1)
        target = d.blurry[v, y, x].to(self.device)
        mse = (blur - target).pow(2).mean()
        align = dq[:, 0].abs().mean()
        loss = mse + o.lambda_align * align
        return FieldStep(loss, {"mse": mse.item(), "align": align.item()})
