"""Options of the radiance-field methods (``nerf``, ``deblur-nerf``, ``edi-nerf``, ``e2nerf``; no torch): the one
source of their defaults and checks. A run sets them in ``options: {method_options: {…}}``; the shared keys of
:class:`eigs.train.config.TrainConfig` that a field run reads are ``steps``, ``seed``, ``log_every``, ``eval_every``,
``checkpoint_every`` and ``max_bad_steps`` (the Gaussian learning rates and densification keys do not apply). A
field method's default budget (``steps``) is its catalog entry's (:mod:`eigs.train.catalog`).

Units: world units of the canonical SfM frame (RMS camera radius 1); voxel counts are totals over the grid (its
shape follows the box's aspect); fractions are of the run's steps.
"""

from __future__ import annotations

from dataclasses import dataclass

from eigs.util.options import Options


@dataclass(frozen=True)
class FieldOptions(Options):
    """Every option of the radiance field and its training, with its default."""

    # the representation: "grid" (a dense voxel grid of density and colour, DVGO / Plenoxels style) or "grid+vm" (the
    # grid plus TensoRF vector-matrix colour factors, the vm_* options, whose raw colour adds to the grid's: colour
    # detail finer than its voxels). Measured on the still chair (docs/training.md): grid+vm +0.5 dB at step 300 but
    # 3.7× the CPU per step, so the grid is the default
    field: str = "grid"
    batch_rays: int = 4096  # rays per step (e2nerf / deblur-nerf: rays rendered, shared among latents / kernel)
    n_samples: int = 128  # samples per ray inside the box at the final grid (fewer on coarser grids, ∝ resolution)
    near: float = 0.3  # nearest distance sampled (canonical frame: RMS camera radius 1; no floaters at the lens)
    # box: the init.ply points between these quantiles per axis, padded by box_margin × the extent each side, grown
    # to hold every training camera centre ± box_camera_margin (SfM finds few points on surfaces seen at grazing
    # angles, such as the upper walls of a room, which the cameras still see)
    box_quantile: float = 0.01
    box_margin: float = 0.05
    box_camera_margin: float = 0.5
    # the core: voxels core_ratio times finer than in the rest of the box, over the points within core_radius of the
    # cameras' centre (the object and the floor around it, seen from ~1 unit; the walls are seen from 2–3 units, so
    # their pixels are larger); its range per axis is those points' box_quantile range padded by box_margin. Off (1)
    # by default: measured on a still chair, a 3M-voxel grid with a 3× finer core fitted slower per step than the
    # uniform 96³ grid (novel view 19.9 vs 21.9 dB at step 300) and cost ~2× per step (docs/training.md)
    core_radius: float = 1.2
    core_ratio: float = 1.0
    # coarse-to-fine: the grid grows from voxels_start to voxels_final in len(grow_at) steps (geometric)
    voxels_start: int = 48**3
    voxels_final: int = 96**3
    grow_at: tuple[float, ...] = (0.1, 0.2, 0.3, 0.4)
    # σ = density_scale · softplus(raw + shift) with raw = 0 at the start and the shift chosen so that a fresh voxel
    # has this α over one sample interval (DVGO's alpha_init); the interval is the box diagonal / the samples per ray
    # on the first grid (the longest there is: a fresh voxel stays below occupancy_weight on every grid)
    alpha_init: float = 1e-3
    # σ = density_scale · softplus(raw + shift) (DVGO measures density per voxel, TensoRF scales it by 25): Adam moves
    # raw by ~lr per step, and an opaque sample needs σδ ≈ 3, i.e. σ ≈ 100 per world unit at δ = 0.03; unscaled,
    # raw must climb to ~100 (~1000 steps at lr 0.1). Measured on the still chair (docs/results.md): novel view 19.65
    # dB at step 300 unscaled, 24.69 at 25 (300-step runs); 27.95 at 25 and 28.17 at 100 at step 1000
    density_scale: float = 100.0
    # start from the SfM points (init.ply, as the Gaussian methods): voxels next to a point get the points' mean
    # colour and a density of α = 0.5 over one voxel (not in DVGO / NeRF: it saves the CPU the geometry search)
    init_from_points: bool = True
    lr_grid: float = 0.1  # Adam on the grid (DVGO), decayed exponentially to lr_grid · lr_decay at the end
    # measured on the still chair, 800 steps: novel view 28.34 dB at the end with 0.3, 27.88 with DVGO's 0.1
    lr_decay: float = 0.3
    # total-variation weights on the raw grid (mean squared neighbour differences; Plenoxels' smoothness prior): 24
    # views do not determine a voxel grid, and without it the novel views fill with floaters (docs/training.md)
    tv_density: float = 1e-2
    tv_colour: float = 1e-3
    # mip-NeRF 360's distortion loss on each ray's weights (positions in fractions of the ray's stretch in the box):
    # pulls each ray's weight into one short stretch, against fog and floaters
    distortion: float = 0.0
    # occupancy: every occupancy_every steps from occupancy_start, voxels none of whose samples since the last update
    # had a compositing weight T·α of occupancy_weight or more, and no neighbour that had, are skipped (above
    # alpha_init: space no ray needed, hidden space and space no ray saw are empty)
    occupancy_every: int = 50
    occupancy_start: int = 20
    occupancy_weight: float = 2e-3
    # the VM colour factors of "grid+vm": per axis pair a plane, along the third axis a line, with the corner counts
    # of a dense grid of vm_voxels_* voxels over the box (growing from start to final at grow_at, as the grid),
    # vm_colour_channels channels each; raw colour += basis (C, 3 · channels) · the plane-line products; the factors
    # start at vm_init_scale · N(0, 1), the basis as nn.Linear's weight
    vm_voxels_start: int = 128**3
    vm_voxels_final: int = 300**3
    vm_colour_channels: int = 16
    vm_init_scale: float = 0.1
    lr_factors: float = 0.02  # Adam on the factors and the basis (TensoRF), decayed as lr_grid by lr_decay
    lr_basis: float = 1e-3
    vm_tv_colour: float = 0.0  # total variation of the colour factors (mean squared neighbour differences, summed)

    def problems(self) -> list[str]:
        grow = self.grow_at
        checks = [
            (self.batch_rays >= 1 and self.n_samples >= 1, "batch_rays and n_samples must be >= 1"),
            (0 <= self.box_quantile < 0.5 and min(self.box_margin, self.box_camera_margin) >= 0,
             "box_quantile must lie in [0, 0.5), box_margin and box_camera_margin >= 0"),
            (8 <= self.voxels_start <= self.voxels_final, "need 8 <= voxels_start <= voxels_final"),
            (all(0 < f <= 1 for f in grow) and list(grow) == sorted(grow), "grow_at: increasing in (0, 1]"),
            (0 < self.alpha_init < 1 and 0 < self.occupancy_weight < 1,
             "alpha_init and occupancy_weight must lie in (0, 1)"),
            (self.lr_grid >= 0 and 0 < self.lr_decay <= 1, "lr_grid must be >= 0 and lr_decay in (0, 1]"),
            (min(self.tv_density, self.tv_colour, self.distortion, self.near) >= 0,
             "tv weights, distortion and near must be >= 0"),
            (self.occupancy_every >= 1 and self.occupancy_start >= 0, "occupancy_every >= 1, occupancy_start >= 0"),
            (self.core_ratio >= 1 and self.core_radius > 0, "core_ratio must be >= 1 and core_radius > 0"),
            (self.field in ("grid", "grid+vm"), f"field must be 'grid' or 'grid+vm', got {self.field!r}"),
            (8 <= self.vm_voxels_start <= self.vm_voxels_final, "need 8 <= vm_voxels_start <= vm_voxels_final"),
            (self.vm_colour_channels >= 1 and self.vm_init_scale > 0 and self.density_scale > 0,
             "vm_colour_channels >= 1, vm_init_scale and density_scale > 0"),
            (min(self.lr_factors, self.lr_basis, self.vm_tv_colour) >= 0,
             "lr_factors, lr_basis and vm_tv_colour must be >= 0"),
        ]  # fmt: skip
        return [msg for ok, msg in checks if not ok]


@dataclass(frozen=True)
class DeblurNerfOptions(FieldOptions):
    """The field's options and Deblur-NeRF's deformable sparse kernel (DSK)."""

    kernel_points: int = 5  # K rays per pixel (Deblur-NeRF synthetic)
    embed_dim: int = 32  # per-view embedding
    dsk_width: int = 64
    dsk_depth: int = 3  # linear layers
    dsk_freqs: int = 4  # positional-encoding frequencies of the pixel position
    init_window: float = 1.0  # initial kernel points drawn uniformly within ± this many pixels (fixed pattern)
    lr_dsk: float = 1e-3
    lambda_align: float = 0.1  # pulls the first kernel point onto the pixel's own ray

    def problems(self) -> list[str]:
        out = super().problems()
        if (self.kernel_points < 1 or self.embed_dim < 1 or self.dsk_width < 1 or self.dsk_depth < 2
                or self.dsk_freqs < 0):  # fmt: skip
            out.append("kernel_points, embed_dim, dsk_width >= 1, dsk_depth >= 2")
        return out


@dataclass(frozen=True)
class E2NerfOptions(FieldOptions):
    """The field's options and E²NeRF's: N + 1 latent renders per pixel, blur loss on their mean and the pairwise
    event loss."""

    lambda_event: float = 0.001  # E²NeRF code's weight beside its MSE blur loss (../shared/docs/edi-and-events.md §4)
