"""Render a radiance field: camera rays, samples inside the field's box, empty space skipped by the occupancy grid,
raw density and colour at the samples, and the alpha-compositing quadrature of :func:`eigs.render.volume.composite`.

The field (``FieldTensors``) is the model file's content as tensors (:mod:`eigs.artifacts.field` documents the
layout): a dense voxel grid (DVGO / Plenoxels style) ``grid`` (1, 1 + C, Z, Y, X) of raw values, trilinearly
interpolated (``grid_sample``), optionally plus TensoRF's vector-matrix factors ``vm`` (:class:`VMFactors`: per
component m the product of a plane over two axes and a line along the third, bilinear / linear interpolation; raw
colour a linear basis (C, 3·Cc) of the colour components, raw density the sum of the density components, if any),
whose raw values add to the grid's. Density σ = ``density_scale`` · softplus(raw + ``density_shift``) per world unit,
colour sigmoid(raw colour); ``lo``, ``hi`` (3,) the box; ``occupancy`` (Z, Y, X) bool; ``warp`` (2, 3, K) the
per-axis piecewise-linear map from world coordinates to normalised coordinates in [0, 1] (a finer core, coarser
shells; ``None``: linear over the box).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from eigs.artifacts.field import FieldArrays
from eigs.render.trilinear import trilinear
from eigs.render.volume import TAU_MAX, composite, distortion, ray_aabb

# the grid's memory layout: channels last, as the trilinear kernel reads it (eigs.render.trilinear)
CHANNELS_LAST = torch.channels_last_3d
TRANS_MIN = 1e-4  # samples behind a transmittance this low are not composited
# TensoRF's VM components: plane m spans axes PLANE_AXES[m] = (a, b) (a its width, b its height; x = 0, y = 1,
# z = 2), line m runs along LINE_AXES[m]
PLANE_AXES = ((0, 1), (0, 2), (1, 2))
LINE_AXES = (2, 1, 0)


@dataclass
class VMFactors:
    """TensoRF vector-matrix factors (tensors may be leaves being trained). ``density_planes[m]`` (1, Cd, R_b, R_a)
    and ``density_lines[m]`` (1, Cd, R_c, 1) with (a, b) = ``PLANE_AXES[m]``, c = ``LINE_AXES[m]`` and R_x, R_y, R_z
    the corner counts per axis (corners aligned with the box's faces); ``colour_planes`` / ``colour_lines`` the same
    with Cc channels; ``basis`` (C, 3·Cc). The density lists may be empty (colour factors only)."""

    density_planes: list[Tensor]
    density_lines: list[Tensor]
    colour_planes: list[Tensor]
    colour_lines: list[Tensor]
    basis: Tensor

    def leaves(self) -> list[Tensor]:
        return [*self.density_planes, *self.density_lines, *self.colour_planes, *self.colour_lines, self.basis]

    @property
    def dims(self) -> tuple[int, int, int]:
        """(R_x, R_y, R_z) corner counts."""
        r = [0, 0, 0]
        for m, c in enumerate(LINE_AXES):
            r[c] = int(self.colour_lines[m].shape[2])
        return r[0], r[1], r[2]


def _vm_components(planes: list[Tensor], lines: list[Tensor], pg: list[Tensor], lg: list[Tensor]) -> list[Tensor]:
    """Per component m the product plane_m · line_m (Ch, N) at the sample grids ``pg[m]``, ``lg[m]`` (1, 1, N, 2)."""
    out = []
    for m in range(3):
        p = F.grid_sample(planes[m], pg[m], mode="bilinear", padding_mode="border", align_corners=True)
        q = F.grid_sample(lines[m], lg[m], mode="bilinear", padding_mode="border", align_corners=True)
        out.append((p * q).reshape(p.shape[1], -1))
    return out


def vm_query(vm: VMFactors, u: Tensor, density_only: bool = False) -> Tensor:
    """Raw values (N, 1 + C) (or (N, 1): the density only) of the VM factors at normalised coordinates ``u`` (N, 3)
    in [0, 1]: raw density Σ_m Σ_k P_m[k](u_a, u_b) L_m[k](u_c), raw colour ``basis`` · concat_m(P_m ⊙ L_m)."""
    v = u * 2.0 - 1.0
    n = v.shape[0]
    pg = [torch.stack([v[:, a], v[:, b]], dim=-1).reshape(1, 1, n, 2) for a, b in PLANE_AXES]
    lg = [torch.stack([torch.zeros_like(v[:, c]), v[:, c]], dim=-1).reshape(1, 1, n, 2) for c in LINE_AXES]
    if vm.density_planes:
        dens = torch.cat(_vm_components(vm.density_planes, vm.density_lines, pg, lg), dim=0).sum(dim=0)
    else:  # colour factors only
        dens = v.new_zeros(n)
    if density_only:
        return dens.unsqueeze(-1)
    feats = torch.cat(_vm_components(vm.colour_planes, vm.colour_lines, pg, lg), dim=0)  # (3·Cc, N)
    return torch.cat([dens.unsqueeze(-1), (vm.basis @ feats).T], dim=-1)


@dataclass
class FieldTensors:
    """A field ready to render (``grid`` and the ``vm`` factors may be leaves being trained): raw values from the grid,
    plus the VM factors' when there are any."""

    grid: Tensor
    lo: Tensor
    hi: Tensor
    occupancy: Tensor
    density_shift: float
    n_samples: int
    near: float
    warp: np.ndarray | None = None  # (2, 3, K) knots: world (warp[0]) and normalised in [0, 1] (warp[1]) per axis
    vm: VMFactors | None = None
    density_scale: float = 1.0

    @classmethod
    def from_arrays(cls, f: FieldArrays, device: torch.device) -> FieldTensors:
        def t(a: np.ndarray) -> Tensor:
            return torch.tensor(a, dtype=torch.float32, device=device)

        vm = None
        if f.vm is not None:
            vm = VMFactors(
                density_planes=[t(p).unsqueeze(0) for p in f.vm.density_planes],
                density_lines=[t(q)[None, :, :, None] for q in f.vm.density_lines],
                colour_planes=[t(p).unsqueeze(0) for p in f.vm.colour_planes],
                colour_lines=[t(q)[None, :, :, None] for q in f.vm.colour_lines],
                basis=t(f.vm.basis),
            )
        return cls(
            grid=t(f.grid).unsqueeze(0).contiguous(memory_format=CHANNELS_LAST),
            lo=torch.tensor(f.lo, dtype=torch.float32, device=device),
            hi=torch.tensor(f.hi, dtype=torch.float32, device=device),
            occupancy=torch.tensor(f.occupancy, dtype=torch.bool, device=device),
            density_shift=float(f.density_shift),
            n_samples=int(f.n_samples),
            near=float(f.near),
            warp=None if f.warp is None else np.asarray(f.warp, np.float64),
            vm=vm,
            density_scale=float(f.density_scale),
        )

    @property
    def channels(self) -> int:
        return int(self.grid.shape[1]) - 1

    @property
    def n_voxels(self) -> int:
        """Voxel corners of the grid."""
        return int(np.prod(self.grid.shape[2:]))

    @property
    def device(self) -> torch.device:
        return self.lo.device


def pixel_rays(c2w: Tensor, K: Tensor, px: Tensor, py: Tensor) -> tuple[Tensor, Tensor]:
    """Rays through pixel positions ``px``, ``py`` (R,) (pixel centres at j + 0.5, i + 0.5; OpenCV axes).

    ``c2w`` (4, 4) or (R, 4, 4) camera-to-world, ``K`` (3, 3). Returns origins (R, 3) and unit directions (R, 3),
    float32."""
    c2w = c2w.to(torch.float32)
    K = K.to(torch.float32)
    d_cam = torch.stack([(px - K[0, 2]) / K[0, 0], (py - K[1, 2]) / K[1, 1], torch.ones_like(px)], dim=-1)
    rot = c2w[..., :3, :3]
    dirs = (rot @ d_cam.unsqueeze(-1)).squeeze(-1) if rot.dim() == 3 else d_cam @ rot.T
    dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    origins = c2w[..., :3, 3].expand_as(dirs)
    return origins, dirs


def image_rays(c2w: Tensor, K: Tensor, width: int, height: int) -> tuple[Tensor, Tensor]:
    """Rays of every pixel centre of a W × H image, row-major: origins, directions (H·W, 3)."""
    dev = K.device
    ys, xs = torch.meshgrid(torch.arange(height, device=dev, dtype=torch.float32),
                            torch.arange(width, device=dev, dtype=torch.float32), indexing="ij")  # fmt: skip
    return pixel_rays(c2w.to(dev), K, xs.reshape(-1) + 0.5, ys.reshape(-1) + 0.5)


def warp_coords(field: FieldTensors, pts: Tensor) -> Tensor:
    """Normalised grid coordinates in [0, 1] (…, 3) of world points ``pts`` (…, 3): per axis the piecewise-linear
    map through the knots ``field.warp`` (linear over the box when there is none), constant outside the box."""
    if field.warp is None:
        return ((pts - field.lo) / (field.hi - field.lo)).clamp(0.0, 1.0)
    xs, us = field.warp[0].tolist(), field.warp[1].tolist()
    out = []
    for a in range(3):
        x, u = pts[..., a], None
        for k in range(len(xs[a]) - 1):
            slope = (us[a][k + 1] - us[a][k]) / (xs[a][k + 1] - xs[a][k])
            term = slope * (x.clamp(xs[a][k], xs[a][k + 1]) - xs[a][k])
            u = term + us[a][0] if u is None else u + term
        out.append(u)
    return torch.stack(out, dim=-1)


def query(field: FieldTensors, pts: Tensor, density_only: bool = False) -> Tensor:
    """Raw values (N, 1 + C) (or (N, 1): the density only) at world points ``pts`` (N, 3): trilinear interpolation of
    the grid, or the VM factors (:func:`vm_query`), in the warped coordinates (border-clamped)."""
    return query_warped(field, warp_coords(field, pts), density_only)


def query_warped(field: FieldTensors, u: Tensor, density_only: bool = False) -> Tensor:
    """:func:`query` at normalised grid coordinates ``u`` (N, 3) in [0, 1] (:func:`warp_coords` of the points)."""
    out = trilinear(field.grid, u, 1 if density_only else None)  # (N, 1 + C) or (N, 1)
    if field.vm is None or (density_only and not field.vm.density_planes):
        return out
    return out + vm_query(field.vm, u, density_only)


def occupied(field: FieldTensors, pts: Tensor) -> Tensor:
    """Whether the voxel corner nearest each point (…, 3) is occupied (…,) bool."""
    occ = field.occupancy
    dims = torch.tensor([occ.shape[2], occ.shape[1], occ.shape[0]], device=pts.device, dtype=pts.dtype)
    idx = torch.round(warp_coords(field, pts) * (dims - 1))
    idx = torch.minimum(idx.clamp_min(0), dims - 1).long()
    return occ[idx[..., 2], idx[..., 1], idx[..., 0]]


def _occupied_along(
    field: FieldTensors, origins: Tensor, dirs: Tensor, t: Tensor
) -> tuple[Tensor, Tensor, Tensor | None]:
    """:func:`occupied` at the points origins + t · dirs ((R, 3), (R, 3), (R, S) → (R, S)), the flat index of each
    point's nearest voxel corner (R, S), and with a warp the points' normalised coordinates (R, S, 3) (without
    one, the points are never formed: None)."""
    occ = field.occupancy
    z, y, x = occ.shape
    dims = torch.tensor([x, y, z], device=t.device, dtype=t.dtype)
    if field.warp is not None:
        u = warp_coords(field, origins.unsqueeze(1) + t.unsqueeze(-1) * dirs.unsqueeze(1))
        i = torch.minimum(torch.round(u * (dims - 1)), dims - 1).long()
        flat = (i[..., 2] * y + i[..., 1]) * x + i[..., 0]
        return _take(occ, flat), flat, u
    scale = (dims - 1) / (field.hi - field.lo)
    a = (origins - field.lo) * scale  # (R, 3) grid coordinates of the origin
    b = dirs * scale
    flat = torch.zeros_like(t, dtype=torch.long)
    for axis, stride in ((0, 1), (1, x), (2, x * y)):
        i = torch.round(a[:, axis : axis + 1] + t * b[:, axis : axis + 1]).clamp(0, float(dims[axis] - 1))
        flat += i.long() * stride
    return _take(occ, flat), flat, None


# Gathers and scatters as index_select / index_copy_ on flattened axes: the same values as advanced indexing and
# index_put (and the same gradients: a gather's is a scatter of the cotangent and back), without PyTorch's generic
# advanced-indexing path, which took 3–10 times longer on the CPU.
def _take(x: Tensor, flat: Tensor) -> Tensor:
    """``x.reshape(-1)[flat]`` for a long ``flat`` of any shape."""
    return x.reshape(-1).index_select(0, flat.reshape(-1)).reshape(flat.shape)


def _gather(x: Tensor, rows: Tensor, cols: Tensor) -> Tensor:
    """``x[rows, cols]`` for ``x`` (R, S, …): one ``index_select`` on the flattened first two axes."""
    return x.reshape(x.shape[0] * x.shape[1], *x.shape[2:]).index_select(0, rows * x.shape[1] + cols)


def _scatter(values: Tensor, at: Tensor, n_rays: int, width: int) -> Tensor:
    """Zeros (R, W, …) with ``values`` (N, …) at the flat slots ``at`` = row · W + slot (N,), each slot at most once:
    ``zeros.index_put((rows, slot), values)``."""
    out = values.new_zeros((n_rays * width, *values.shape[1:]))
    return out.index_copy_(0, at, values).reshape(n_rays, width, *values.shape[1:])


def _select(mask: Tensor, *xs: Tensor) -> list[Tensor]:
    """``[x[mask] for x in xs]`` for a (N,) bool ``mask`` and (N, …) tensors, the mask's indices found once."""
    idx = mask.nonzero().squeeze(1)
    return [x.index_select(0, idx) for x in xs]


def render_rays(
    field: FieldTensors,
    origins: Tensor,
    dirs: Tensor,
    background: Tensor,
    jitter: Tensor | None = None,
    stats: dict[str, Tensor] | None = None,
) -> tuple[Tensor, Tensor]:
    """Colours (R, C) and opacities (R,) of rays (``origins``, unit ``dirs`` (R, 3)).

    ``field.n_samples`` = S samples per ray evenly spaced over the ray's stretch inside the box (from ``field.near``
    on): at the interval midpoints, or at ``(i + jitter)/S`` of it with ``jitter`` (R, 1) or (R, S) in [0, 1)
    (stratified sampling for training). Samples nearest an unoccupied voxel have zero density: they are neither
    interpolated nor composited (an empty sample leaves the transmittance unchanged, so the occupied samples of each
    ray are packed to the front and composited alone; exact). Samples whose transmittance has fallen below
    ``TRANS_MIN`` are dropped after a density-only pass without gradients (the colour changes by less than
    ``TRANS_MIN`` × the largest colour difference). A ray that misses the box sees the background.

    ``stats``: when given, filled with ``voxels`` (N,) the flat index (into ``occupancy``) of the voxel nearest each
    composited sample and ``weights`` (N,) its compositing weight T·α (detached), for the occupancy update, and
    ``distortion`` (R,) each ray's distortion (:func:`eigs.render.volume.distortion`, differentiable) with sample
    positions in fractions of the ray's stretch inside the box."""
    s = field.n_samples
    # pixel_rays' origins are a strided view of the poses (or one origin expanded): index_select below gathers them
    # per sample, and on a non-contiguous tensor it takes PyTorch's generic path, ~15× slower (40 vs 2.6 ms for 500k
    # samples, one thread); the values are the same
    origins, dirs = origins.contiguous(), dirs.contiguous()
    t_near, t_far = ray_aabb(origins, dirs, field.lo, field.hi, field.near)
    length = (t_far - t_near).unsqueeze(-1)  # (R, 1), 0 for rays that miss the box
    steps = torch.arange(s, device=origins.device, dtype=origins.dtype)
    frac = (steps + (0.5 if jitter is None else jitter)) / s
    t = t_near.unsqueeze(-1) + frac * length  # (R, S)
    keep, flat, u = _occupied_along(field, origins, dirs, t)
    keep &= length > 0
    n_rays = keep.shape[0]
    delta = length / s  # (R, 1)
    rows, cols = keep.nonzero(as_tuple=True)  # row-major: front to back within each ray

    def at(r: Tensor, k: Tensor, density_only: bool = False) -> Tensor:
        if u is not None:
            return query_warped(field, _gather(u, r, k), density_only)
        pts = origins.index_select(0, r) + _gather(t, r, k).unsqueeze(-1) * dirs.index_select(0, r)
        return query(field, pts, density_only)

    if rows.numel():  # drop the samples behind opaque ones (density-only pass, no gradient)
        with torch.no_grad():
            slot = _gather(torch.cumsum(keep, dim=1) - 1, rows, cols)
            width = int(slot.max()) + 1
            sig = F.softplus(at(rows, cols, density_only=True)[:, 0] + field.density_shift) * field.density_scale
            tau = (sig * delta.reshape(-1).index_select(0, rows)).clamp(0.0, TAU_MAX)
            packed = _scatter(tau, rows * width + slot, n_rays, width)
            excl = torch.cumsum(packed, dim=1) - packed
            live = _gather(excl, rows, slot) <= -math.log(TRANS_MIN)
            rows, cols, slot = _select(live, rows, cols, slot)
    else:
        slot = rows
    width = int(slot.max()) + 1 if slot.numel() else 1
    packed_at = rows * width + slot  # (N,) flat slot of each composited sample in the packed (R, width) layout
    raw = at(rows, cols)  # (N, 1 + C)
    sig = F.softplus(raw[:, 0] + field.density_shift) * field.density_scale
    col = torch.sigmoid(raw[:, 1:])
    sigmas = _scatter(sig, packed_at, n_rays, width)
    colours = _scatter(col, packed_at, n_rays, width)
    deltas = delta.expand(-1, width)
    rgb, acc, weights = composite(sigmas, colours, deltas, background.to(raw.dtype))
    if stats is not None:
        stats["voxels"] = _gather(flat, rows, cols)
        stats["weights"] = weights.detach().reshape(-1).index_select(0, packed_at)
        at_pos = _gather(frac.expand_as(t), rows, cols).to(raw.dtype)
        pos = _scatter(at_pos, packed_at, n_rays, width)
        stats["distortion"] = distortion(weights, pos, torch.full_like(pos, 1.0 / s))
    return rgb, acc


@torch.no_grad()
def render_image(
    field: FieldTensors, c2w: Tensor, K: Tensor, width: int, height: int, background: Tensor, chunk: int = 16384
) -> Tensor:
    """(H, W, C) float32 render at ``c2w`` (4, 4) with intrinsics ``K`` (3, 3), midpoint samples, in ray chunks."""
    origins, dirs = image_rays(c2w, K, width, height)
    bg = background.to(origins.device, torch.float32)
    parts = [render_rays(field, origins[i : i + chunk], dirs[i : i + chunk], bg)[0]
             for i in range(0, origins.shape[0], chunk)]  # fmt: skip
    return torch.cat(parts).reshape(height, width, -1)
