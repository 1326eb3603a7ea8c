"""The Gaussian methods' base class: how one training step explains its target (what it renders, the loss), and the
methods that render once per step (``3dgs``, ``edi-3dgs``, ``oracle``).

Every method shares the model, optimiser, densification and budget of :mod:`eigs.train.gaussian.trainer`; a method only
says which samples a step draws from and how it turns renders into a loss. Add a method by subclassing :class:`Method`
and adding its entry to :mod:`eigs.train.catalog` (docs/development.md).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from eigs.errors import EigsError
from eigs.losses import photometric_loss
from eigs.train.catalog import GAUSSIAN
from eigs.train.catalog import method as method_spec
from eigs.train.config import TrainConfig
from eigs.train.data import TrainData
from eigs.train.gaussian.camera_refine import CameraRefinement
from eigs.train.gaussian.model import GaussianModel
from eigs.util.options import Options, options_json


@dataclass
class LatentMotion:
    """What a method does within the exposures (written to ``motion.npz``, :mod:`eigs.artifacts.motion`).

    ``displacement``: (V, N, G, 3) offsets that render latent k = 1..N of view v from its reference camera;
    ``reference_c2w``: (V, 4, 4) float64; ``views``: (V,) bool, the views steps are drawn from;
    ``camera_c2w``: (V, N, 4, 4) float64 camera poses at the latent times, for methods that have them."""

    displacement: Tensor
    reference_c2w: Tensor
    views: np.ndarray
    camera_c2w: Tensor | None = None


@dataclass
class StepOutput:
    """One step's loss, the terms to log (floats) and the rasterizer infos of its renders (for densification)."""

    loss: Tensor
    terms: dict[str, float]
    infos: list[dict] = field(default_factory=list)


class Method(ABC):
    """Base class. ``spec``: the method's catalog entry (:mod:`eigs.train.catalog`); ``opts``: its options (the
    catalog's recipe with ``TrainConfig.method_options`` over it, checked once where the run is resolved);
    ``options``: the same as JSON (what ``config.json`` records)."""

    family = GAUSSIAN

    def __init__(self, data: TrainData, cfg: TrainConfig, opts: Options, device: torch.device):
        self.spec = method_spec(cfg.method)
        self.name, self.description = self.spec.name, self.spec.description
        self.opts = opts
        self.options = options_json(opts)
        self.data = data
        self.cfg = cfg
        self.device = device
        self.K = data.K.to(device)
        self.background = data.background.to(device)
        # a learned correction of every view's cameras (TrainConfig.camera_refine), None when off
        self.camera = CameraRefinement(data.c2w[:, 0], device) if cfg.camera_refine else None

    def refined(self, v: int, means: Tensor, quats: Tensor) -> tuple[Tensor, Tensor]:
        """View v's Gaussians (centres (N, 3), rotations (N, 4)) as its refined cameras see them: unchanged when
        camera refinement is off (:mod:`eigs.train.gaussian.camera_refine`)."""
        if self.camera is None:
            return means, quats
        return self.camera.move(v, means, quats)

    def render_view(
        self, model: GaussianModel, v: int, c2w: Tensor, sh_degree: int, means: Tensor | None = None,
        quats: Tensor | None = None, **moved: Tensor,
    ) -> tuple[Tensor, dict]:
        """Render view v's Gaussians (the model's, or ``means``/``quats``/``log_scales`` moved by the method) at
        ``c2w`` (4, 4), its cameras refined when that is on; returns the image (H, W, C) and the rasterizer's info
        with ``means2d`` retaining its gradient (densification reads it)."""
        d, p = self.data, model.params
        if self.camera is not None:
            means = p["means"] if means is None else means
            means, quats = self.camera.move(v, means, p["quats"] if quats is None else quats)
        image, _, info = model.render(c2w, self.K, d.width, d.height, self.background, sh_degree, means=means,
                                      quats=quats, **moved)  # fmt: skip
        info["means2d"].retain_grad()
        return image, info

    @abstractmethod
    def n_samples(self) -> int:
        """Number of training samples a step draws from."""

    @abstractmethod
    def step(self, model: GaussianModel, sample: int, step: int, sh_degree: int) -> StepOutput:
        """One training step's loss on ``sample``."""

    def photometric_step(
        self, model: GaussianModel, c2w: Tensor, target: Tensor, sh_degree: int, view: int = -1
    ) -> StepOutput:
        """One render at ``c2w`` (4, 4) against ``target`` (H, W, C): L1 + D-SSIM. ``view``: the scene view the
        sample belongs to (its cameras are refined when camera refinement is on; −1: none)."""
        if view < 0 and self.camera is not None:
            raise EigsError(self.data.scene.name, f"method {self.name} does not name its samples' views: it cannot "
                                                  "refine cameras (camera_refine)")  # fmt: skip
        image, info = self.render_view(model, view, c2w, sh_degree)
        loss, l1, dssim = photometric_loss(image, target, self.cfg.lambda_dssim, self.cfg.ssim_range)
        return StepOutput(loss, {"l1": l1.item(), "dssim": dssim.item()}, [info])

    def param_groups(self) -> list[dict]:
        """Extra Adam param groups (e.g. a network), each with ``name`` and ``lr``."""
        return []

    def all_param_groups(self) -> list[dict]:
        """:meth:`param_groups` and, with camera refinement, the cameras' group (what the trainer's Adam gets)."""
        groups = self.param_groups()
        if self.camera is not None:
            groups.append(self.camera.param_group(self.cfg.lr_camera, self.cfg.camera_reg))
        return groups

    def latent_motion(self, means: Tensor, quats: Tensor) -> LatentMotion | None:
        """The motion this method applies within each view's exposure to Gaussians at ``means`` (G, 3) with
        ``quats`` (G, 4): None for methods that model none (one render per step)."""
        return None

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict) -> None:  # noqa: B027 (a method without state has nothing to load)
        """Restore what :meth:`state_dict` returned (nothing by default)."""


class ImageMethod(Method):
    """One render per step at a sample's camera, L1 + D-SSIM against the sample's image."""

    def __init__(self, data: TrainData, cfg: TrainConfig, opts: Options, device: torch.device):
        super().__init__(data, cfg, opts, device)
        images, c2w, views = self.samples()
        if images.shape[0] == 0:
            raise EigsError(data.scene.name, f"method {self.name}: no training sample has a valid pose")
        self.images = images.to(device)  # (S, H, W, C)
        self.c2w = c2w  # (S, 4, 4) float64
        self.sample_views = np.asarray(views, dtype=np.int64)  # (S,) the scene view of each sample

    @abstractmethod
    def samples(self) -> tuple[Tensor, Tensor, np.ndarray]:
        """(S, H, W, C) target images, (S, 4, 4) float64 camera-to-world and (S,) the scene view of each."""

    def n_samples(self) -> int:
        return int(self.images.shape[0])

    def step(self, model: GaussianModel, sample: int, step: int, sh_degree: int) -> StepOutput:
        return self.photometric_step(model, self.c2w[sample], self.images[sample], sh_degree,
                                     int(self.sample_views[sample]))  # fmt: skip


class Blurry3DGS(ImageMethod):
    """``3dgs``: the blurry frames at the reference pose (latent k = 0)."""

    def samples(self) -> tuple[Tensor, Tensor, np.ndarray]:
        views = self.data.reference_views()
        return self.data.blurry[views], self.data.c2w[views, 0], views


class Edi3DGS(ImageMethod):
    """``edi-3dgs``: the EDI latent sharp frames at their latent poses."""

    def samples(self) -> tuple[Tensor, Tensor, np.ndarray]:
        v, k = np.nonzero(self.data.valid)
        return self.data.latent[v, k], self.data.c2w[v, k], v


class Oracle(ImageMethod):
    """``oracle``: the ground-truth sharp images of the training views at their reference pose."""

    def samples(self) -> tuple[Tensor, Tensor, np.ndarray]:
        d = self.data
        views = np.nonzero(d.valid[:, 0] & d.has_sharp_train)[0]
        return d.sharp_train[views], d.c2w[views, 0], views  # type: ignore[index]
