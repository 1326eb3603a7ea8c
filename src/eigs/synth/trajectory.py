"""Camera paths of the synthetic scenes: an orbit around the object, smooth moves between views, and a
non-linear random shake (rotation + translation) that never stops.

All poses are camera-to-world 4×4 float64 in OpenCV axes (x right, y down, z forward); the world is z-up.
Times are microseconds (float64 inside, int64 where they are stored).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

WORLD_UP = np.array([0.0, 0.0, 1.0])


def look_at(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(N, 4, 4) OpenCV camera-to-world for cameras at ``position`` (N, 3) looking at ``target`` (N, 3) or (3,),
    with image 'up' (−y) as close to world +z as possible. Cameras must not look straight up or down."""
    position = np.atleast_2d(np.asarray(position, dtype=np.float64))
    target = np.broadcast_to(np.asarray(target, dtype=np.float64), position.shape)
    z = target - position
    z /= np.maximum(np.linalg.norm(z, axis=1, keepdims=True), 1e-12)
    x = np.cross(z, WORLD_UP)
    x /= np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-12)
    y = np.cross(z, x)
    m = np.zeros((position.shape[0], 4, 4))
    m[:, :3, 0], m[:, :3, 1], m[:, :3, 2], m[:, :3, 3] = x, y, z, position
    m[:, 3, 3] = 1.0
    return m


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vectors ``w`` (N, 3) in radians → (N, 3, 3) rotations (exact at w = 0)."""
    w = np.atleast_2d(np.asarray(w, dtype=np.float64))
    th = np.linalg.norm(w, axis=1)
    small = th < 1e-8
    th_safe = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th**2 / 6.0, np.sin(th) / th_safe)
    b = np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(th)) / th_safe**2)
    k = np.zeros((w.shape[0], 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return np.eye(3) + a[:, None, None] * k + b[:, None, None] * (k @ k)


@dataclass
class Orbit:
    """Orbit parameters per view: azimuth and elevation (degrees), radius (scene units) around ``target`` (3,)."""

    azimuth_deg: np.ndarray
    elevation_deg: np.ndarray
    radius: np.ndarray
    target: np.ndarray

    def positions(self, az_deg: np.ndarray, el_deg: np.ndarray, radius: np.ndarray) -> np.ndarray:
        az, el = np.deg2rad(az_deg), np.deg2rad(el_deg)
        d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)
        return self.target + np.asarray(radius)[..., None] * d

    def poses(self) -> np.ndarray:
        """(V, 4, 4) unshaken camera-to-world of each view."""
        return look_at(self.positions(self.azimuth_deg, self.elevation_deg, self.radius), self.target)


def spiral_orbit(
    n: int, *, radius: float, el_min: float, el_max: float, target=(0.0, 0.0, 0.0), az0: float = 0.0,
    turns: float = 1.0, phase: float = 0.0,
) -> Orbit:
    """``n`` views on a spiral: azimuth az0 + 360°·turns·v/n, elevation oscillating twice per turn between
    ``el_min`` and ``el_max`` (degrees), shifted by ``phase`` views (0.5 gives the in-between poses)."""
    v = np.arange(n, dtype=np.float64) + phase
    az = az0 + 360.0 * turns * v / n
    el = el_min + (el_max - el_min) * 0.5 * (1 - np.cos(2 * np.pi * 2.0 * turns * v / n))
    return Orbit(az, el, np.full(n, float(radius)), np.asarray(target, dtype=np.float64))


@dataclass
class Shake:
    """Smooth non-linear random camera shake, defined for all times: a sum of sinusoids per axis.

    ω(t) = Σ_k a_k sin(2π f_k t + φ_k) (radians, about the camera's x, y, z axes) and the same form for the
    translation τ(t) (scene units, camera axes). The shaken pose is ``base · [Exp(ω) | τ]``. Arrays: (3, K).
    """

    rot_amp: np.ndarray
    rot_freq: np.ndarray
    rot_phase: np.ndarray
    trans_amp: np.ndarray
    trans_freq: np.ndarray
    trans_phase: np.ndarray

    @staticmethod
    def random(
        rng: np.random.Generator, *, rot_deg: float, trans: float, fmin_hz: float, fmax_hz: float, n_sines: int = 5,
        roll_scale: float = 0.5,
    ) -> Shake:
        """Random shake with RMS rotation ``rot_deg`` (degrees, per pitch/yaw axis; roll × ``roll_scale``) and RMS
        translation ``trans`` per axis; frequencies log-uniform in [fmin_hz, fmax_hz]."""

        def comp(rms: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            w = rng.uniform(0.5, 1.0, size=(3, n_sines))
            w *= np.sqrt(2.0) / np.linalg.norm(w, axis=1, keepdims=True)  # RMS of Σ w sin(...) is 1
            f = np.exp(rng.uniform(np.log(fmin_hz), np.log(fmax_hz), size=(3, n_sines)))
            ph = rng.uniform(0, 2 * np.pi, size=(3, n_sines))
            return w * rms[:, None], f, ph

        ra, rf, rp = comp(np.deg2rad(rot_deg) * np.array([1.0, 1.0, roll_scale]))
        ta, tf, tp = comp(np.full(3, float(trans)))
        return Shake(ra, rf, rp, ta, tf, tp)

    @staticmethod
    def none() -> Shake:
        z = np.zeros((3, 1))
        return Shake(z, z + 1.0, z, z, z + 1.0, z)

    def offsets(self, t_us: np.ndarray) -> np.ndarray:
        """(N, 4, 4) camera-frame shake transforms at times ``t_us`` (N,)."""
        ts = np.asarray(t_us, dtype=np.float64)[:, None, None] * 1e-6
        w = (self.rot_amp * np.sin(2 * np.pi * self.rot_freq * ts + self.rot_phase)).sum(axis=2)
        tau = (self.trans_amp * np.sin(2 * np.pi * self.trans_freq * ts + self.trans_phase)).sum(axis=2)
        m = np.zeros((ts.shape[0], 4, 4))
        m[:, :3, :3] = so3_exp(w)
        m[:, :3, 3] = tau
        m[:, 3, 3] = 1.0
        return m


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


@dataclass
class Timeline:
    """The time base of a synthetic recording (µs, int64).

    View v is exposed during [start_v, end_v) with start_v = lead_us + v·period_us, end_v = start_v +
    exposure_us. The stream runs from t = 0 to end_{V−1}; frames are rendered at ``subframes`` + 1 times
    start_v + i·exposure_us/subframes (i = 0..subframes, both ends included), at ``gap_subframes`` steps
    between exposures and ``lead_subframes`` steps before the first. Latent time k (k = 0..B) of view v is
    start_v + k·exposure_us/B, which is one of the exposure sub-frame times.
    """

    n_views: int
    exposure_us: int
    period_us: int
    lead_us: int
    subframes: int
    gap_subframes: int
    lead_subframes: int

    @property
    def starts(self) -> np.ndarray:
        return self.lead_us + np.arange(self.n_views, dtype=np.int64) * self.period_us

    @property
    def exposures(self) -> np.ndarray:
        """(V, 2) int64 [start, end) µs."""
        s = self.starts
        return np.stack([s, s + self.exposure_us], axis=1)

    def latent_times(self, n_bins: int) -> np.ndarray:
        """(V, B+1) int64: start_v + k·exposure_us/B, k = 0..B (exact: exposure_us is a multiple of B)."""
        k = np.arange(n_bins + 1, dtype=np.int64)
        return self.starts[:, None] + (k * self.exposure_us)[None, :] // n_bins

    def exposure_frame_times(self, v: int) -> np.ndarray:
        """(subframes + 1,) int64 sub-frame times of view v's exposure, both ends included."""
        step = self.exposure_us // self.subframes
        return self.starts[v] + step * np.arange(self.subframes + 1, dtype=np.int64)

    def gap_frame_times(self, v: int) -> np.ndarray:
        """Times strictly between view v's exposure end and the next start (empty for the last view)."""
        if v >= self.n_views - 1:
            return np.zeros(0, np.int64)
        gap = self.period_us - self.exposure_us
        step = gap // self.gap_subframes
        return self.starts[v] + self.exposure_us + step * np.arange(1, self.gap_subframes, dtype=np.int64)

    def lead_frame_times(self) -> np.ndarray:
        """Times from 0 up to (excluding) the first exposure start."""
        if self.lead_us == 0:
            return np.zeros(0, np.int64)
        step = self.lead_us // self.lead_subframes
        return step * np.arange(self.lead_subframes, dtype=np.int64)

    def all_frame_times(self) -> np.ndarray:
        parts = [self.lead_frame_times()]
        for v in range(self.n_views):
            parts += [self.exposure_frame_times(v), self.gap_frame_times(v)]
        return np.concatenate(parts)


def still_view_indices(n_views: int, fraction: float) -> np.ndarray:
    """(n,) int64 indices of the views held still, n = round(``fraction``·``n_views``), spread evenly over the
    recording: view ⌊(i + ½)·V/n⌋ for i = 0..n−1 (V = 8, n = 2 → views 2 and 6). Independent of the seed."""
    n = int(np.floor(fraction * n_views + 0.5))
    n = min(max(n, 0), n_views)
    if n == 0:
        return np.zeros(0, np.int64)
    return np.floor((np.arange(n) + 0.5) * n_views / n).astype(np.int64)


@dataclass
class CameraPath:
    """The full ground-truth camera path: orbit base poses (static during each exposure, smooth moves in the
    gaps) composed with the :class:`Shake`, which never stops except during the exposures of the ``still`` views.

    ``still``: (V,) bool or None (no view held still). During a still view's exposure [start_v, end_v] the shake
    is frozen at its value at start_v, so every sub-frame of that exposure has the same pose; in the gap that
    follows, the shake runs at period/gap speed until it is back in step at start_{v+1} (a continuous,
    monotone time warp, so later views shake exactly as they would without the pause).
    """

    orbit: Orbit
    timeline: Timeline
    shake: Shake
    still: np.ndarray | None = None

    def shake_time(self, t_us: np.ndarray) -> np.ndarray:
        """(N,) float64 time (µs) at which the shake is evaluated for path times ``t_us`` (N,): ``t`` itself,
        except during a still view's exposure (start_v) and the gap after it (warped linearly from start_v at
        end_v back to start_{v+1})."""
        t = np.asarray(t_us, dtype=np.float64)
        if self.still is None or not np.any(self.still):
            return t
        tl = self.timeline
        s = tl.starts.astype(np.float64)
        v = np.clip(np.searchsorted(s, t, side="right") - 1, 0, tl.n_views - 1)
        hold = np.asarray(self.still, dtype=bool)[v] & (t >= s[v])
        e = s[v] + tl.exposure_us
        last = v + 1 >= tl.n_views  # the stream ends with the last exposure: nothing to catch up with
        nxt = np.where(last, e, s[np.minimum(v + 1, tl.n_views - 1)])
        u = np.clip((t - e) / np.maximum(nxt - e, 1.0), 0.0, 1.0)  # 0 up to end_v, 1 at start_{v+1}
        warped = np.where(last, s[v], s[v] + u * (nxt - s[v]))
        return np.where(hold, warped, t)

    def base(self, t_us: np.ndarray) -> np.ndarray:
        """(N, 4, 4) unshaken poses: view v's orbit pose until end_v, then a smoothstep move (azimuth, elevation,
        radius) to view v+1's pose, reached at start_{v+1}."""
        t = np.asarray(t_us, dtype=np.float64)
        tl, o = self.timeline, self.orbit
        s = tl.starts.astype(np.float64)
        v = np.clip(np.searchsorted(s, t, side="right") - 1, 0, tl.n_views - 1)
        e = s[v] + tl.exposure_us
        nxt = np.minimum(v + 1, tl.n_views - 1)
        span = np.maximum(s[nxt] - e, 1.0)
        u = _smoothstep((t - e) / span)
        u = np.where(nxt == v, 0.0, u)
        daz = (o.azimuth_deg[nxt] - o.azimuth_deg[v] + 180.0) % 360.0 - 180.0
        az = o.azimuth_deg[v] + u * daz
        el = o.elevation_deg[v] + u * (o.elevation_deg[nxt] - o.elevation_deg[v])
        r = o.radius[v] + u * (o.radius[nxt] - o.radius[v])
        return look_at(o.positions(az, el, r), o.target)

    def __call__(self, t_us: np.ndarray) -> np.ndarray:
        """(N, 4, 4) ground-truth camera-to-world at times ``t_us`` (N,) µs."""
        t = np.atleast_1d(np.asarray(t_us, dtype=np.float64))
        return self.base(t) @ self.shake.offsets(self.shake_time(t))


def interpolate_poses(t_query: np.ndarray, t_samples: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """Poses at ``t_query`` (N,) from samples (``t_samples`` (T,) increasing, ``c2w`` (T, 4, 4)): linear in
    translation, spherical-linear in rotation; clamped at both ends; exact at sample times."""
    from scipy.spatial.transform import Rotation, Slerp

    tq = np.clip(np.asarray(t_query, dtype=np.float64), t_samples[0], t_samples[-1])
    ts = np.asarray(t_samples, dtype=np.float64)
    out = np.zeros((tq.shape[0], 4, 4))
    out[:, 3, 3] = 1.0
    if ts.shape[0] == 1:
        out[:] = c2w[0]
        return out
    out[:, :3, :3] = Slerp(ts, Rotation.from_matrix(c2w[:, :3, :3]))(tq).as_matrix()
    for k in range(3):
        out[:, k, 3] = np.interp(tq, ts, c2w[:, k, 3])
    exact = np.searchsorted(ts, tq)
    hit = (exact < ts.shape[0]) & (ts[np.minimum(exact, ts.shape[0] - 1)] == tq)
    out[hit] = c2w[exact[hit]]
    return out
