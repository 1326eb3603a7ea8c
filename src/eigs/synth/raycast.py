"""A small vectorised NumPy ray caster of textured spheres, oriented boxes and capped cylinders.

Independent of the Gaussian rasterizer on purpose: scenes made of analytic surfaces test our model under model
mismatch. Shading is Lambertian under fixed world lights (view-independent, so a radiance field can represent
it exactly), in **linear intensity**; textures come linearised from :mod:`eigs.synth.textures`.

Camera conventions (as everywhere in eigs): camera-to-world 4×4 in OpenCV axes (x right, y down, z forward);
intrinsics ``K`` with the centre of pixel (row i, column j) at image coordinates (j + 0.5, i + 0.5).

Implementation: one frame at a time, rays in structure-of-arrays form on the supersampled grid; every ray of
a frame shares the camera centre, so each primitive sees a scalar local origin. A primitive is only tested
against the rays inside the screen rectangle that conservatively bounds its bounding sphere. No BLAS calls
(small matrix products are slow and oversubscribe threads on shared machines).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from eigs.synth.textures import load_texture

ALBEDO_FLOOR = 0.03  # darkest linear albedo of a texture (before tint)
_BATCH_RAYS = 1 << 19  # rays per batch of frames traced together (bounds temporary memory to ~100 MB)
_EPS_T = 1e-4  # minimum ray parameter accepted as a hit (scene units)
F32 = np.float32


def rotation(axis: tuple[float, float, float] | np.ndarray, angle_deg: float) -> np.ndarray:
    """(3, 3) float64 rotation about ``axis`` by ``angle_deg`` degrees (right-hand rule)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / max(float(np.linalg.norm(a)), 1e-12)
    th = np.deg2rad(angle_deg)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * (k @ k)


@dataclass
class Material:
    """Surface appearance: a texture (linear albedo) times ``tint``; ``tile``: world units per texture repeat;
    ``crop``: the window (x0, y0, side) of the photograph used, as fractions of its centred square (so primitives
    can show different parts of one photograph); ``offset``: added to the texture coordinates (u, v), in repeats
    (places a face's visible window inside one period, away from the mirror seams)."""

    texture: str
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    tile: float = 1.0
    crop: tuple[float, float, float] = (0.0, 0.0, 1.0)
    offset: tuple[float, float] = (0.0, 0.0)


def material_albedo(m: Material, size: int, floor: float) -> np.ndarray:
    """(S, S, 3) float32 linear albedo ``tint · (floor + (1 − floor) · texture)`` of material ``m``, S = ``size``."""
    tex = floor + (1 - floor) * load_texture(m.texture, size, m.crop)
    return (tex * np.asarray(m.tint, F32)).astype(F32)


Vec = tuple[np.ndarray, np.ndarray, np.ndarray]  # structure-of-arrays 3-vectors, each (M,) float32


@dataclass
class Primitive(ABC):
    """Base class: a solid placed by ``center`` (3,) and ``rot`` (3, 3) local-to-world rotation."""

    center: tuple[float, float, float]
    material: Material
    rot: np.ndarray = field(default_factory=lambda: np.eye(3))

    @abstractmethod
    def intersect(self, o: np.ndarray, d: Vec) -> np.ndarray:
        """Ray parameter of the nearest hit ≥ ``_EPS_T`` per ray (+inf on a miss); ``o`` (3,) local origin shared
        by all rays, ``d`` local directions."""

    @abstractmethod
    def surface(self, p: Vec) -> tuple[Vec, np.ndarray, np.ndarray]:
        """Local normal and texture coordinates (u, v) in repeats at local surface points ``p``."""

    @abstractmethod
    def bound_radius(self) -> float:
        """Radius of a sphere about ``center`` that contains the solid (world units)."""

    def albedo(self, size: int, floor: float) -> np.ndarray:
        """(S, S, 3) float32 linear albedo texture of the material, S = ``size`` (:func:`material_albedo`)."""
        return material_albedo(self.material, size, floor)


def _pick_t(t0: np.ndarray, t1: np.ndarray, ok: np.ndarray) -> np.ndarray:
    t = np.where(t0 >= _EPS_T, t0, np.where(t1 >= _EPS_T, t1, np.inf))
    return np.where(ok, t, np.inf).astype(F32)


@dataclass
class Sphere(Primitive):
    radius: float = 0.5

    def intersect(self, o: np.ndarray, d: Vec) -> np.ndarray:
        dx, dy, dz = d
        a = dx * dx + dy * dy + dz * dz
        b = o[0] * dx + o[1] * dy + o[2] * dz
        c = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] - self.radius**2
        disc = b * b - a * c
        ok = disc >= 0
        sq = np.sqrt(np.where(ok, disc, 0.0))
        inv = 1.0 / np.maximum(a, 1e-20)
        return _pick_t((-b - sq) * inv, (-b + sq) * inv, ok)

    def surface(self, p: Vec) -> tuple[Vec, np.ndarray, np.ndarray]:
        r = self.radius
        n = (p[0] / r, p[1] / r, p[2] / r)
        az = np.arctan2(n[1], n[0])
        pol = np.arccos(np.clip(n[2], -1.0, 1.0))
        s = r / self.material.tile
        return n, az * s, pol * s

    def bound_radius(self) -> float:
        return float(self.radius)


@dataclass
class Box(Primitive):
    half: tuple[float, float, float] = (0.5, 0.5, 0.5)

    def intersect(self, o: np.ndarray, d: Vec) -> np.ndarray:
        tmin = tmax = None
        for ax in range(3):
            h = self.half[ax]
            da = d[ax]
            inv = 1.0 / np.where(np.abs(da) < 1e-12, F32(1e-12), da)
            ta = (-h - o[ax]) * inv
            tb = (h - o[ax]) * inv
            lo, hi = np.minimum(ta, tb), np.maximum(ta, tb)
            tmin = lo if tmin is None else np.maximum(tmin, lo)
            tmax = hi if tmax is None else np.minimum(tmax, hi)
        hit = tmax >= np.maximum(tmin, _EPS_T)
        return np.where(hit, np.where(tmin >= _EPS_T, tmin, tmax), np.inf).astype(F32)

    def surface(self, p: Vec) -> tuple[Vec, np.ndarray, np.ndarray]:
        q = np.stack([np.abs(p[k] / self.half[k]) for k in range(3)])
        axis = q.argmax(axis=0)
        zero = np.zeros_like(p[0])
        n = tuple(np.where(axis == k, np.sign(p[k]), zero) for k in range(3))
        tile = self.material.tile
        # in-face coordinates: the two other axes in cyclic order; faces offset so they differ
        u = np.choose(axis, (p[1], p[2], p[0])) / tile + 0.37 * axis
        v = np.choose(axis, (p[2], p[0], p[1])) / tile + 0.21 * axis
        return n, u, v

    def bound_radius(self) -> float:
        return float(np.linalg.norm(self.half))


@dataclass
class Patchwork(Primitive):
    """A horizontal floor through ``center``: n × n square cells covering ±``half`` (local x, y), seen from
    above, each showing its own material (texture window and tint); ``material`` is unused. One ray–plane test
    per ray, however many cells. Cell (i, j) spans x ∈ [−half + i·side, −half + (i+1)·side), likewise y with j,
    side = 2·half/n; inside it the texture coordinates run over [0.05, 0.95] of the cell's texture, i.e. exactly
    what a flat box of that size with ``tile = side/0.9`` and a centred window would show, without the cost of
    n² primitives."""

    half: float = 7.5
    cells: tuple[Material, ...] = ()  # n² materials, index i·n + j

    @property
    def n(self) -> int:
        return int(round(len(self.cells) ** 0.5))

    def intersect(self, o: np.ndarray, d: Vec) -> np.ndarray:
        dz = d[2]
        t = -o[2] / np.where(np.abs(dz) < 1e-12, F32(1e-12), dz)
        x, y = o[0] + t * d[0], o[1] + t * d[1]
        hit = (t >= _EPS_T) & (np.abs(x) <= self.half) & (np.abs(y) <= self.half)
        return np.where(hit, t, np.inf).astype(F32)

    def surface(self, p: Vec) -> tuple[Vec, np.ndarray, np.ndarray]:
        n = self.n
        fx = np.clip((p[0] + self.half) / (2 * self.half) * n, 0.0, n - 1e-4)
        fy = np.clip((p[1] + self.half) / (2 * self.half) * n, 0.0, n - 1e-4)
        i, j = np.floor(fx), np.floor(fy)
        # the atlas holds cell (i, j) at texture columns i·S… and rows j·S…: (u, v) in atlas repeats
        u = (i + 0.05 + 0.9 * (fx - i)) / n
        v = (j + 0.05 + 0.9 * (fy - j)) / n
        zero = np.zeros_like(p[0])
        return (zero, zero, zero + 1), u.astype(F32), v.astype(F32)

    def bound_radius(self) -> float:
        return float(self.half * np.sqrt(2.0))

    def albedo(self, size: int, floor: float) -> np.ndarray:
        n = self.n
        if n * n != len(self.cells) or n == 0:
            raise ValueError(f"Patchwork needs n² cell materials, got {len(self.cells)}")
        atlas = np.empty((n * size, n * size, 3), F32)
        for idx, m in enumerate(self.cells):
            i, j = divmod(idx, n)
            atlas[j * size : (j + 1) * size, i * size : (i + 1) * size] = material_albedo(m, size, floor)
        return atlas


@dataclass
class Cylinder(Primitive):
    """Capped cylinder along local z: radius ``radius``, from z = −``half_height`` to +``half_height``."""

    radius: float = 0.5
    half_height: float = 0.5

    def intersect(self, o: np.ndarray, d: Vec) -> np.ndarray:
        r, hz = self.radius, self.half_height
        dx, dy, dz = d
        a = dx * dx + dy * dy
        b = o[0] * dx + o[1] * dy
        c = o[0] ** 2 + o[1] ** 2 - r * r
        disc = b * b - a * c
        ok = (disc >= 0) & (a > 1e-12)
        sq = np.sqrt(np.where(ok, disc, 0.0))
        inv = 1.0 / np.where(a > 1e-12, a, 1.0)
        best = np.full(dx.shape, np.inf, dtype=F32)
        for t in ((-b - sq) * inv, (-b + sq) * inv):
            z = o[2] + t * dz
            good = ok & (t >= _EPS_T) & (np.abs(z) <= hz) & (t < best)
            best = np.where(good, t, best)
        inv_z = 1.0 / np.where(np.abs(dz) < 1e-12, F32(1e-12), dz)
        for zc in (-hz, hz):
            t = (zc - o[2]) * inv_z
            x = o[0] + t * dx
            y = o[1] + t * dy
            good = (t >= _EPS_T) & (x * x + y * y <= r * r) & (t < best)
            best = np.where(good, t, best)
        return best.astype(F32)

    def surface(self, p: Vec) -> tuple[Vec, np.ndarray, np.ndarray]:
        r, hz = self.radius, self.half_height
        tile = self.material.tile
        rad = np.sqrt(p[0] ** 2 + p[1] ** 2)
        # a point is on a cap when it is nearer the cap plane than the side surface
        on_cap = (hz - np.abs(p[2])) < (r - rad)
        inv = 1.0 / np.maximum(rad, 1e-9)
        zero = np.zeros_like(rad)
        n = (np.where(on_cap, zero, p[0] * inv), np.where(on_cap, zero, p[1] * inv),
             np.where(on_cap, np.sign(p[2]), zero))
        az = np.arctan2(p[1], p[0])
        u = np.where(on_cap, p[0] / tile + 0.5, az * (r / tile))
        v = np.where(on_cap, p[1] / tile + 0.5, p[2] / tile)
        return n, u, v

    def bound_radius(self) -> float:
        return float(np.hypot(self.radius, self.half_height))


@dataclass
class Lighting:
    """Lambertian lighting: ``ambient`` + Σ gain·max(0, n·l). ``lights``: ((direction towards light (3,), gain), …)."""

    ambient: float = 0.3
    lights: tuple[tuple[tuple[float, float, float], float], ...] = (((0.4, -0.5, 1.0), 0.8), ((-0.6, 0.4, 0.3), 0.25))


def _box_corners(b: Box) -> np.ndarray:
    """(8, 3) world coordinates of a box's corners, pushed out by 0.1 % (a conservative culling bound)."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64)
    local = signs * (np.asarray(b.half, np.float64) * 1.001 + 1e-6)
    return local @ np.asarray(b.rot, np.float64).T + np.asarray(b.center, np.float64)


def mirror_tile(tex: np.ndarray) -> np.ndarray:
    """(S, S, 3) texture → (2S·2S, 3) flat period of its mirrored repeat (for :func:`sample_texture`)."""
    top = np.concatenate([tex, tex[:, ::-1]], axis=1)
    return np.ascontiguousarray(np.concatenate([top, top[::-1]], axis=0).reshape(-1, tex.shape[2]))


def sample_texture(tile: np.ndarray, size: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear lookup with mirrored repeat. ``tile``: :func:`mirror_tile` of an (S, S, 3) texture, ``size`` = S;
    ``u``, ``v``: (M,) texture coordinates in repeats (1 = one texture width) → (M, 3)."""
    period = 2 * size

    def wrap(c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        m = np.mod(c * F32(size) - F32(0.5), F32(period))
        i0 = m.astype(np.int32)
        f = (m - i0).astype(F32)
        i0 = np.minimum(i0, period - 1)  # guard m == period after float rounding
        i1 = i0 + 1
        i1[i1 == period] = 0
        return i0, i1, f[:, None]

    x0, x1, fx = wrap(u)
    y0, y1, fy = wrap(v)
    y0 *= period
    y1 *= period
    top = tile[y0 + x0]
    top += (tile[y0 + x1] - top) * fx
    bot = tile[y1 + x0]
    bot += (tile[y1 + x1] - bot) * fx
    top += (bot - top) * fy
    return top


@dataclass
class RenderResult:
    """``rgb``: (F, H, W, 3) float32 linear intensity in [0, 1]; ``depth``: (F, H, W) float32 z-depth of the
    pixel-centre ray (+inf on background), only when requested."""

    rgb: np.ndarray
    depth: np.ndarray | None


class RayCaster:
    """Renders a list of primitives. ``background``: (3,) linear colour of rays that hit nothing.

    A surface's linear albedo is ``tint · (albedo_floor + (1 − albedo_floor) · texture)``: real materials are
    rarely darker than a few percent, and the floor keeps ln(Y + ε) from exploding on black texels."""

    def __init__(
        self,
        primitives: list[Primitive],
        *,
        background: tuple[float, float, float] = (0.0, 0.0, 0.0),
        lighting: Lighting | None = None,
        texture_size: int = 128,
        albedo_floor: float = ALBEDO_FLOOR,
    ):
        self.primitives = list(primitives)
        self.background = np.asarray(background, dtype=F32)
        self.lighting = lighting or Lighting()
        self._lights = [
            (np.asarray(dvec, np.float64) / np.linalg.norm(dvec), float(gain)) for dvec, gain in self.lighting.lights
        ]
        self._tex, self._tex_size = [], []
        for p in self.primitives:
            albedo = p.albedo(int(texture_size), albedo_floor)
            self._tex.append(mirror_tile(albedo))
            self._tex_size.append(albedo.shape[0])
        self._rot = [np.asarray(p.rot, dtype=np.float64) for p in self.primitives]
        self._ctr = [np.asarray(p.center, dtype=np.float64) for p in self.primitives]
        self._rad = [p.bound_radius() for p in self.primitives]
        self._corners = [_box_corners(p) if isinstance(p, Box) else None for p in self.primitives]

    def _grid(self, K: np.ndarray, width: int, height: int, s: int) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame ray directions (z = 1) on the supersampled grid: x, y each (H·s, W·s) float32."""
        offs = (np.arange(s) + 0.5) / s
        cols = (np.arange(width)[:, None] + offs[None, :]).ravel()
        rows = (np.arange(height)[:, None] + offs[None, :]).ravel()
        kinv = np.linalg.inv(np.asarray(K, dtype=np.float64))
        # K is upper triangular: x = (c − cx − skew·y)/fx; y = (r − cy)/fy
        yy = (rows - K[1, 2]) * kinv[1, 1]
        xx = cols[None, :] * kinv[0, 0] + rows[:, None] * kinv[0, 1] + kinv[0, 2]
        return xx.astype(F32), np.broadcast_to(yy[:, None], xx.shape).astype(F32)

    def _screen_box(
        self, k: int, w2c: np.ndarray, K: np.ndarray, gh: int, gw: int, s: int
    ) -> tuple[int, int, int, int] | None:
        """Rows/cols [r0, r1) × [c0, c1) of the supersampled grid that may see primitive k; None if none."""
        corners = self._corners[k]
        if corners is not None:  # a box: its projection lies in the hull of its corners' projections
            pc = corners @ w2c[:3, :3].T + w2c[:3, 3]  # (8, 3) camera frame
            if pc[:, 2].max() <= _EPS_T:
                return None
            if pc[:, 2].min() > 1e-3:
                xs, ys = list(pc[:, 0] / pc[:, 2]), list(pc[:, 1] / pc[:, 2])
                return self._pixel_box(xs, ys, K, gh, gw, s)
        c = w2c[:3, :3] @ self._ctr[k] + w2c[:3, 3]
        r = self._rad[k] * 1.001 + 1e-6
        if c[2] + r <= _EPS_T:
            return None
        if c[2] - r <= 1e-3:
            return 0, gh, 0, gw
        zs = (c[2] - r, c[2] + r)
        xs = [(c[0] + a) / z for a in (-r, r) for z in zs]
        ys = [(c[1] + a) / z for a in (-r, r) for z in zs]
        return self._pixel_box(xs, ys, K, gh, gw, s)

    @staticmethod
    def _pixel_box(xs: list, ys: list, K: np.ndarray, gh: int, gw: int, s: int) -> tuple[int, int, int, int] | None:
        """Grid rows/cols covering normalised image points with these x and y extremes (one-pixel margin)."""
        x0 = (K[0, 0] * min(xs) + K[0, 1] * (min(ys) if K[0, 1] >= 0 else max(ys)) + K[0, 2]) * s
        x1 = (K[0, 0] * max(xs) + K[0, 1] * (max(ys) if K[0, 1] >= 0 else min(ys)) + K[0, 2]) * s
        y0 = (K[1, 1] * min(ys) + K[1, 2]) * s
        y1 = (K[1, 1] * max(ys) + K[1, 2]) * s
        c0, c1 = max(int(np.floor(x0)) - 1, 0), min(int(np.ceil(x1)) + 1, gw)
        r0, r1 = max(int(np.floor(y0)) - 1, 0), min(int(np.ceil(y1)) + 1, gh)
        if c0 >= c1 or r0 >= r1:
            return None
        return r0, r1, c0, c1

    def _frames(
        self, c2w: np.ndarray, K: np.ndarray, gx: np.ndarray, gy: np.ndarray, s: int, shade: bool = True
    ) -> tuple[np.ndarray | None, np.ndarray]:
        """A batch of F frames on the supersampled grid: (rgb (F, H·s, W·s, 3) or None, t (F, H·s, W·s) z-depth).

        Frames are processed together (fewer, larger array operations); each primitive is tested on the union of
        its screen rectangles over the batch (exact: the rectangles are only a culling bound)."""
        n_f = c2w.shape[0]
        gh, gw = gx.shape
        r_cam, o_w = c2w[:, :3, :3], c2w[:, :3, 3]
        best = np.full((n_f, gh, gw), np.inf, dtype=F32)
        pid = np.full((n_f, gh, gw), -1, dtype=np.int16)
        boxes: list[tuple[int, int, int, int] | None] = []
        frames_geo = []
        for k in range(len(self.primitives)):
            rk = self._rot[k]
            a = np.einsum("ji,fjk->fik", rk, r_cam).astype(F32)  # camera → local, per frame (F, 3, 3)
            o_l = np.einsum("ji,fj->if", rk, o_w - self._ctr[k]).astype(F32)[:, :, None, None]  # (3, F, 1, 1)
            frames_geo.append((a, o_l))
            rects = []
            for f in range(n_f):
                w2c = np.eye(4)
                w2c[:3, :3], w2c[:3, 3] = r_cam[f].T, -r_cam[f].T @ o_w[f]
                box = self._screen_box(k, w2c, K, gh, gw, s)
                if box is not None:
                    rects.append(box)
            if not rects:
                boxes.append(None)
                continue
            r = np.array(rects)
            boxes.append((int(r[:, 0].min()), int(r[:, 1].max()), int(r[:, 2].min()), int(r[:, 3].max())))
        for k, prim in enumerate(self.primitives):
            box = boxes[k]
            if box is None:
                continue
            r0, r1, c0, c1 = box
            a, o_l = frames_geo[k]
            x, y = gx[None, r0:r1, c0:c1], gy[None, r0:r1, c0:c1]
            d = tuple(a[:, i, 0, None, None] * x + a[:, i, 1, None, None] * y + a[:, i, 2, None, None]
                      for i in range(3))
            t = prim.intersect(o_l, d)
            bv, pv = best[:, r0:r1, c0:c1], pid[:, r0:r1, c0:c1]
            np.copyto(pv, k, where=t < bv)
            np.minimum(bv, t, out=bv)
        if not shade:
            return None, best
        out = np.empty((n_f, gh, gw, 3), dtype=F32)
        out[:] = self.background
        for k, prim in enumerate(self.primitives):
            box = boxes[k]
            if box is None:
                continue
            r0, r1, c0, c1 = box
            mask = pid[:, r0:r1, c0:c1] == k
            fi, ii, jj = np.nonzero(mask)
            if fi.size == 0:
                continue
            x, y = gx[r0:r1, c0:c1][ii, jj], gy[r0:r1, c0:c1][ii, jj]
            t = best[:, r0:r1, c0:c1][mask]
            a, o_l = frames_geo[k]
            af, of = a[fi], o_l[:, :, 0, 0][:, fi]
            p = tuple(of[i] + t * (af[:, i, 0] * x + af[:, i, 1] * y + af[:, i, 2]) for i in range(3))
            n, u, v = prim.surface(p)
            shade_k = np.full(t.shape, self.lighting.ambient, dtype=F32)
            for ldir, gain in self._lights:
                ll = (self._rot[k].T @ ldir).astype(F32)  # light direction in the local frame
                shade_k += F32(gain) * np.maximum(n[0] * ll[0] + n[1] * ll[1] + n[2] * ll[2], 0.0)
            du, dv = prim.material.offset
            if du or dv:
                u, v = u + F32(du), v + F32(dv)
            col = sample_texture(self._tex[k], self._tex_size[k], u, v) * shade_k[:, None]
            out[:, r0:r1, c0:c1][mask] = col
        np.clip(out, 0.0, 1.0, out=out)
        return out, best

    def render(
        self,
        c2w: np.ndarray,
        K: np.ndarray,
        width: int,
        height: int,
        *,
        supersample: int = 2,
        want_depth: bool = False,
        threads: int = 1,
    ) -> RenderResult:
        """Render F views. ``c2w``: (F, 4, 4) (or (4, 4)) OpenCV camera-to-world; ``K``: (3, 3).

        Each pixel averages ``supersample``² stratified rays (box filter) in linear intensity. Returns (F, H, W, 3)
        float32 images; with ``want_depth`` also the z-depth of one ray through each pixel centre. ``threads`` > 1
        renders batches of frames in parallel threads (NumPy releases the GIL in its array loops); results do not
        depend on ``threads`` or the batching.
        """
        c2w = np.asarray(c2w, dtype=np.float64)
        if c2w.ndim == 2:
            c2w = c2w[None]
        K = np.asarray(K, dtype=np.float64)
        s = max(int(supersample), 1)
        gx, gy = self._grid(K, width, height, s)
        n = c2w.shape[0]
        rgb = np.empty((n, height, width, 3), dtype=F32)
        inv = F32(1.0 / (s * s))
        batch = max(1, min(_BATCH_RAYS // gx.size, -(-n // max(threads, 1))))
        chunks = [range(f0, min(n, f0 + batch)) for f0 in range(0, n, batch)]

        def run(fs: range) -> None:
            img, _ = self._frames(c2w[fs.start : fs.stop], K, gx, gy, s)
            a = img.reshape(len(fs), height, s, width, s, 3)
            acc = a[:, :, 0, :, 0].copy()
            for i in range(s):
                for j in range(s):
                    if i or j:
                        acc += a[:, :, i, :, j]
            rgb[fs.start : fs.stop] = acc * inv

        if threads > 1 and len(chunks) > 1:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(max_workers=threads) as pool:
                list(pool.map(run, chunks))
        else:
            for fs in chunks:
                run(fs)
        depth = None
        if want_depth:
            cx, cy = self._grid(K, width, height, 1)
            depth = self._frames(c2w, K, cx, cy, 1, shade=False)[1]
        return RenderResult(rgb, depth)
