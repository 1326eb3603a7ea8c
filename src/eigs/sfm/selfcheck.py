"""The SfM self-check: does the reconstructed camera path look like one camera moving in time? No ground truth.

The training views of an event recording are taken in time order by one camera, so the views' poses, in time, trace
one smooth path. A reconstruction that is right up to a similarity keeps that path; a wrong one — pieces of the
scene registered with their own, inconsistent geometry, or single views registered far off — bends or breaks it.
Per view (its registered latents' mean centre and chordal-mean orientation, at its mean latent time):

- ``path_error``: distance of the view's centre from where its registered neighbours in time put it (linear in time
  between the previous and the next view; extrapolated from the two nearest on one side at the ends), in units of
  the reconstruction's typical step between consecutive views (the median, per view interval);
- ``turn_error_deg``: angle between the view's orientation and the one its neighbours put there (slerp, or
  extrapolation at the ends).

A view *fails* when its path error exceeds :data:`MAX_PATH_ERROR` or its turn error exceeds :data:`MAX_TURN_DEG`
(on the ground-truth paths of the built-ins no view exceeds 0.5 step or 5.7°, on the default suite's reconstructions
0.6 step or 7.1°: docs/sfm.md, "Self-check"). Failing views are peeled one at a time, worst first (a wrong view also
spoils its neighbours' predictions), and the rest judged again without them; then the path is cut where its two
sides do not join, and its smallest piece fails, one piece at a time, until the rest joins as one path (the gap a
dropped piece leaves is judged as any other). The reconstruction *fails* as a whole when more
than :data:`MAX_FAILED_FRACTION` of the recording's views end without a place on the path (failed, or without a pose at
all) — a path broken into pieces or covering too little of the recording, not a few stray views — or when COLMAP
split the images into several models of which the second holds more than :data:`MAX_SECOND_MODEL` of the first's
images (pieces that no common geometry joins). Views that are not one path at all — independent viewpoints, as in a
synthetic set of random views — give a median path error far above a recording's (:data:`MAX_MEDIAN_PATH_ERROR`):
the check then does not apply and drops nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eigs.metrics.trajectory import project_to_rotation, rotation_angle_deg

MAX_PATH_ERROR = 1.0  # typical steps between consecutive views
MAX_TURN_DEG = 15.0  # degrees
MAX_FAILED_FRACTION = 0.2  # of the recording's views: failed ones and those without a pose
MAX_SECOND_MODEL = 0.25  # images of COLMAP's second model / images of the kept one
MIN_VIEWS = 4  # views with poses below which the path is not judged
MAX_GAP_VIEWS = 2.5  # a neighbour farther in time (median view intervals) predicts nothing
# Median path error above which the views are not one path in time but independent viewpoints (a synthetic set's
# random views, such as E²NeRF's Blender scenes: 0.77–0.82 measured on random views of a sphere, 0.14–0.23 on every
# recording's reconstruction, right or wrong): the check does not apply.
MAX_MEDIAN_PATH_ERROR = 0.5


@dataclass
class SelfCheck:
    """The self-check of one reconstruction. Per view (V,) float64, NaN where not judged: ``path_error``,
    ``turn_error_deg`` (figures of the last round that judged the view); ``failed_views``: views dropped, in the
    order they were peeled; ``passed``: the reconstruction as a whole; ``reasons``: why not (empty when passed);
    ``applicable``: False when the views are not one path in time (then nothing fails)."""

    path_error: np.ndarray
    turn_error_deg: np.ndarray
    failed_views: list[int] = field(default_factory=list)
    passed: bool = True
    reasons: list[str] = field(default_factory=list)
    applicable: bool = True

    def summary(self) -> dict:
        """report.json's ``self_check`` section."""

        def clean(a: np.ndarray) -> list[float | None]:
            return [None if not np.isfinite(x) else round(float(x), 4) for x in a]

        judged = np.isfinite(self.path_error)
        return {
            "applicable": self.applicable,
            "passed": self.passed,
            "reasons": self.reasons,
            "failed_views": self.failed_views,
            "limits": {"path_error": MAX_PATH_ERROR, "turn_error_deg": MAX_TURN_DEG,
                       "failed_fraction": MAX_FAILED_FRACTION, "second_model": MAX_SECOND_MODEL},  # fmt: skip
            "path_error_median": float(np.median(self.path_error[judged])) if judged.any() else None,
            "turn_error_deg_median": float(np.median(self.turn_error_deg[judged])) if judged.any() else None,
            "path_error": clean(self.path_error),
            "turn_error_deg": clean(self.turn_error_deg),
        }


def view_poses(c2w: np.ndarray, registered: np.ndarray, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per view from its registered latents: centres (V, 3), orientations (V, 3, 3) and times (V,) float64 µs;
    NaN for views without a registered latent. ``c2w`` (V, L, 4, 4), ``registered`` (V, L) bool, ``t_us`` (V, L)."""
    V = c2w.shape[0]
    centres = np.full((V, 3), np.nan)
    rots = np.full((V, 3, 3), np.nan)
    times = np.full(V, np.nan)
    for v in range(V):
        k = np.flatnonzero(registered[v])
        if k.size == 0:
            continue
        centres[v] = c2w[v, k, :3, 3].mean(0)
        rots[v] = project_to_rotation(c2w[v, k, :3, :3].sum(0))
        times[v] = np.asarray(t_us[v, k], np.float64).mean()
    return centres, rots, times


def _rotvec(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_rotvec()


def _rotation(w: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(w).as_matrix()


def predict(centres: np.ndarray, rots: np.ndarray, times: np.ndarray, a: int, b: int, t: float):
    """Centre (3,) and orientation (3, 3) at time ``t`` on the constant-velocity path through views ``a`` and ``b``
    (interpolation between them, extrapolation beyond): linear centres, geodesic rotations."""
    dt = times[b] - times[a]
    f = (t - times[a]) / dt if dt != 0 else 0.0
    c = centres[a] + f * (centres[b] - centres[a])
    R = rots[a] @ _rotation(f * _rotvec(rots[a].T @ rots[b]))
    return c, R


def _neighbours(keep: np.ndarray, times: np.ndarray, j: int, max_gap: float) -> tuple[int, int] | None:
    """Two views of ``keep`` (time order) that predict view ``keep[j]``: the previous and the next one, else the two
    nearest on one side; each within ``max_gap`` (units of ``times``) of the view (or of the other, one-sided).
    None: none close."""
    t = times[keep]
    prev_ok = j > 0 and t[j] - t[j - 1] <= max_gap
    next_ok = j < keep.size - 1 and t[j + 1] - t[j] <= max_gap
    if prev_ok and next_ok:
        return int(keep[j - 1]), int(keep[j + 1])
    if prev_ok and j > 1 and t[j - 1] - t[j - 2] <= max_gap:
        return int(keep[j - 2]), int(keep[j - 1])
    if next_ok and j < keep.size - 2 and t[j + 2] - t[j + 1] <= max_gap:
        return int(keep[j + 1]), int(keep[j + 2])
    return None


def _typical_step(centres, times, keep: np.ndarray, interval: float) -> float:
    """Median distance between consecutive views of ``keep`` per median view interval (pairs within the gap limit)."""
    gaps = np.diff(times[keep])
    close = gaps <= MAX_GAP_VIEWS * interval
    if not close.any():
        return 1.0
    steps = np.linalg.norm(np.diff(centres[keep], axis=0), axis=1)
    step = float(np.median(steps[close] / np.maximum(gaps[close], 1e-9))) * interval
    return step if step > 0 else 1.0


def _judge(centres, rots, times, keep: np.ndarray, interval: float) -> tuple[np.ndarray, np.ndarray]:
    """Path and turn errors (V,) of the views in ``keep`` (indices in time order), NaN elsewhere and for views
    without close neighbours; ``interval``: the recording's median time between consecutive views."""
    V = centres.shape[0]
    path = np.full(V, np.nan)
    turn = np.full(V, np.nan)
    if keep.size < MIN_VIEWS:
        return path, turn
    step = _typical_step(centres, times, keep, interval)
    for j, v in enumerate(keep):
        ab = _neighbours(keep, times, j, MAX_GAP_VIEWS * interval)
        if ab is None:
            continue
        c, R = predict(centres, rots, times, *ab, times[v])
        path[v] = np.linalg.norm(centres[v] - c) / step
        turn[v] = rotation_angle_deg(rots[v][None], R[None])[0]
    return path, turn


def _pieces(
    centres, rots, times, keep: np.ndarray, interval: float, bridged: frozenset = frozenset()
) -> list[np.ndarray]:
    """``keep`` (time order) cut where the path breaks: at a gap between two consecutive views whose sides disagree —
    the path extrapolated forward from the two views before the gap and backward from the two after it meet more than
    :data:`MAX_PATH_ERROR` steps or :data:`MAX_TURN_DEG` apart at the gap's middle. A gap longer than the neighbour
    limit, or one without two close views on each side, is not judged (nothing there to compare), except a gap
    after a view of ``bridged``: one that dropped views opened, which must join as any other."""
    max_gap = MAX_GAP_VIEWS * interval
    t = times[keep]
    step = _typical_step(centres, times, keep, interval)
    cuts = []
    for j in range(1, keep.size - 2):
        wide = t[j + 1] - t[j] > max_gap and int(keep[j]) not in bridged
        if wide or t[j] - t[j - 1] > max_gap or t[j + 2] - t[j + 1] > max_gap:
            continue
        mid = 0.5 * (t[j] + t[j + 1])
        c1, R1 = predict(centres, rots, times, keep[j - 1], keep[j], mid)
        c2, R2 = predict(centres, rots, times, keep[j + 1], keep[j + 2], mid)
        if (np.linalg.norm(c1 - c2) / step > MAX_PATH_ERROR
                or rotation_angle_deg(R1[None], R2[None])[0] > MAX_TURN_DEG):  # fmt: skip
            cuts.append(j + 1)
    return np.split(keep, cuts)


def self_check(c2w: np.ndarray, registered: np.ndarray, t_us: np.ndarray, models: list[int] | None = None) -> SelfCheck:
    """The self-check of the latent poses ``c2w`` (V, L, 4, 4) (only ``registered`` (V, L) latents count; times
    ``t_us`` (V, L)); ``models``: COLMAP's model sizes, largest first (None: one model)."""
    centres, rots, times = view_poses(np.asarray(c2w, np.float64), np.asarray(registered, bool), t_us)
    n_views = times.size
    has = np.flatnonzero(np.isfinite(times))
    mean_t = np.asarray(t_us, np.float64).mean(axis=1)
    if np.all(np.diff(mean_t) > 0):  # absolute times: the views' spacing in time
        interval = float(np.median(np.diff(mean_t))) if mean_t.size > 1 else 1.0
    else:  # times relative to each exposure (the E²NeRF real layout): views in index order, evenly spaced
        times, interval = np.arange(n_views, dtype=np.float64), 1.0
    keep = has[np.argsort(times[has], kind="stable")]
    # views that may end without a place on the path: a fifth of the recording, the unposed ones included
    budget = int(np.floor(MAX_FAILED_FRACTION * n_views)) - (n_views - has.size)
    failed: list[int] = []
    peeled: dict[int, tuple[float, float]] = {}  # a peeled view keeps the figures that failed it
    path, turn = _judge(centres, rots, times, keep, interval)
    judged = np.isfinite(path)
    if judged.any() and float(np.median(path[judged])) > MAX_MEDIAN_PATH_ERROR:
        return SelfCheck(path, turn, applicable=False)
    while keep.size >= MIN_VIEWS and len(failed) <= budget:
        bad = (path > MAX_PATH_ERROR) | (turn > MAX_TURN_DEG)
        if not bad.any():
            break
        worst = int(np.nanargmax(np.where(bad, np.maximum(path / MAX_PATH_ERROR, turn / MAX_TURN_DEG), -np.inf)))
        failed.append(worst)
        peeled[worst] = (path[worst], turn[worst])
        keep = keep[keep != worst]
        path, turn = _judge(centres, rots, times, keep, interval)
    peeled_too_many = len(failed) > budget
    split = [keep]  # the path's pieces as first cut (the message names them)
    if not peeled_too_many and keep.size >= MIN_VIEWS:
        pieces = split = _pieces(centres, rots, times, keep, interval)
        bridged: set[int] = set()
        # the smallest piece leaves the path, one at a time, and the rest is cut again: a few wrong views in the
        # middle split the path in three, and the two sides may join once they are gone (the gap they leave is
        # judged as any other)
        while len(pieces) > 1 and len(failed) <= budget:
            smallest = min(range(len(pieces)), key=lambda i: (pieces[i].size, -i))
            gone = pieces[smallest]
            failed += [int(v) for v in gone]
            if smallest > 0:
                bridged.add(int(pieces[smallest - 1][-1]))
            keep = np.concatenate([p for i, p in enumerate(pieces) if i != smallest])
            pieces = _pieces(centres, rots, times, keep, interval, frozenset(bridged))
    for v, (p, t) in peeled.items():
        path[v], turn[v] = p, t
    out = SelfCheck(path, turn, failed_views=failed)
    limit = f"limit {MAX_FAILED_FRACTION:.0%} of the views; path error > {MAX_PATH_ERROR:g} steps or turn > " \
            f"{MAX_TURN_DEG:g}°"  # fmt: skip
    if has.size < MIN_VIEWS:
        out.reasons.append(f"only {has.size} views have poses: a camera path needs at least {MIN_VIEWS}")
    elif budget < 0:
        out.reasons.append(f"only {has.size} of {n_views} views have a pose ({limit})")
    elif peeled_too_many:
        out.reasons.append(
            f"the camera path breaks: more than {budget} of the {has.size} views with poses lie off the path their "
            f"neighbours in time give, and {n_views - has.size} have none ({limit})"
        )
    elif len(failed) > budget:
        sizes = ", ".join(str(p.size) for p in split)
        out.reasons.append(
            f"the camera path breaks into {len(split)} pieces of {sizes} views that do not join: "
            f"{len(failed) + n_views - has.size} of {n_views} views lie off the path or have no pose ({limit})"
        )
    if models and len(models) > 1 and models[1] > MAX_SECOND_MODEL * models[0]:
        out.reasons.append(
            f"COLMAP split the images into models of {', '.join(str(m) for m in models)}: the second holds "
            f"{models[1] / models[0]:.0%} of the kept one's images (limit {MAX_SECOND_MODEL:.0%})"
        )
    out.passed = not out.reasons
    return out
