"""Pose conventions → camera-to-world 4×4 in OpenCV axes (x right, y down, z forward).

- Blender/OpenGL camera (x right, y up, z backward): negate the camera y and z axes (columns 1, 2 of R).
- LLFF ``poses_bounds.npy`` (camera columns [down, right, back]): x = column 1, y = column 0, z = −column 2.
- Quaternions ``qx qy qz qw`` (Hamilton, w last) of T_world_cam (ECD ``groundtruth.txt``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.scene.model import Trajectory

QUAT_NORM_TOL = 1e-3  # |‖q‖ − 1| accepted (text files print ~9 digits); q is then normalised


def blender_to_opencv(c2w: np.ndarray) -> np.ndarray:
    """(..., 4, 4) Blender/OpenGL camera-to-world → (..., 4, 4) OpenCV camera-to-world (float64)."""
    out = np.array(c2w, dtype=np.float64, copy=True)
    out[..., :3, 1:3] *= -1.0
    return out


def llff_to_opencv(rows: np.ndarray) -> np.ndarray:
    """(N, 15+) LLFF rows ``[R | t | hwf]`` (3×5, row-major) → (N, 4, 4) OpenCV camera-to-world (float64).
    No recentring, spherifying or rescaling."""
    m = np.asarray(rows, dtype=np.float64)[:, :15].reshape(-1, 3, 5)
    out = np.zeros((m.shape[0], 4, 4))
    out[:, :3, 0] = m[:, :, 1]
    out[:, :3, 1] = m[:, :, 0]
    out[:, :3, 2] = -m[:, :, 2]
    out[:, :3, 3] = m[:, :, 3]
    out[:, 3, 3] = 1.0
    return out


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions ``qx qy qz qw`` → (N, 3, 3) rotation matrices (float64)."""
    x, y, z, w = (q[:, i] for i in range(4))
    r = np.empty((q.shape[0], 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def read_groundtruth(path: Path) -> Trajectory:
    """ECD ``groundtruth.txt``: lines ``t tx ty tz qx qy qz qw`` (t in s, position in m, T_world_cam) →
    :class:`Trajectory` (t int64 µs strictly increasing, c2w (T, 4, 4)). ``#`` lines are skipped."""
    from eigs.ingest.timeconv import to_us

    rows = read_table(path, 8, "t tx ty tz qx qy qz qw")
    if rows.shape[0] == 0:
        raise EigsError(path, "ground-truth file has no poses")
    t = to_us(rows[:, 0], "s", str(path))
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise EigsError(
            path,
            f"timestamps go backwards or repeat at pose {i} "
            f"({float(rows[i, 0])!r} s after {float(rows[i - 1, 0])!r} s)",
        )
    q = rows[:, 4:8]
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > QUAT_NORM_TOL)
    if bad.size:
        raise EigsError(path, f"pose {int(bad[0])} has a quaternion of norm {norm[bad[0]]:.6f}, not a unit quaternion")
    c2w = np.zeros((rows.shape[0], 4, 4))
    c2w[:, :3, :3] = quat_to_matrix(q / norm[:, None])
    c2w[:, :3, 3] = rows[:, 1:4]
    c2w[:, 3, 3] = 1.0
    return Trajectory(t_us=t, c2w=c2w)


def read_table(path: Path, ncols: int, what: str) -> np.ndarray:
    """A small whitespace-separated numeric text file with exactly ``ncols`` columns → (N, ncols) float64.
    ``#`` lines and blank lines are skipped; errors name the line."""
    if not path.is_file():
        raise EigsError(path, "no such file")
    rows: list[list[float]] = []
    try:
        with open(path) as f:
            for lineno, line in enumerate(f, start=1):
                s = line.strip()
                if not s or s.startswith("#"):
                    continue
                parts = s.split()
                if len(parts) != ncols:
                    raise EigsError(path, f"line {lineno} has {len(parts)} fields, expected {ncols} ({what})")
                try:
                    vals = [float(v) for v in parts]
                except ValueError:
                    raise EigsError(path, f"line {lineno} holds something that is not a number") from None
                if not all(np.isfinite(vals)):
                    raise EigsError(path, f"line {lineno} has NaN/Inf")
                rows.append(vals)
    except UnicodeDecodeError:
        raise EigsError(path, "not a text file") from None
    return np.asarray(rows, dtype=np.float64).reshape(-1, ncols)
