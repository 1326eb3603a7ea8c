"""Motion errors against closed forms: a known rigid camera motion, seen from a model frame that differs from the
ground truth's by a similarity, gives zero error when the method moves the scene exactly, 1 - f when it moves it by
a fraction f, and the known rotation error for a camera turned by a known angle."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eigs.metrics.motion import camera_errors, displacement_errors, motion_errors, rigid_inverse, spread_scale


def _pose(rotvec, centre) -> np.ndarray:
    p = np.eye(4)
    p[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    p[:3, 3] = centre
    return p


def _similarity(p: np.ndarray, s: float, w: np.ndarray, t: np.ndarray) -> np.ndarray:
    """A camera-to-world pose mapped by x -> s W x + t (the camera keeps its metric axes)."""
    out = np.eye(4)
    out[:3, :3] = w @ p[:3, :3]
    out[:3, 3] = s * w @ p[:3, 3] + t
    return out


@pytest.fixture
def case():
    rng = np.random.default_rng(3)
    V, L = 5, 5
    gt = np.zeros((V, L, 4, 4))
    for v in range(V):
        base = _pose(rng.normal(size=3) * 0.5, rng.normal(size=3) * 3)
        step = _pose(rng.normal(size=3) * 0.01, rng.normal(size=3) * 0.05)  # the shake: a constant camera twist
        for k in range(L):
            gt[v, k] = base @ np.linalg.matrix_power(step, k)
    s, w, t = 0.37, Rotation.from_rotvec([0.3, -1.0, 0.2]).as_matrix(), np.array([1.0, 2.0, -0.5])
    model = np.stack([[_similarity(gt[v, k], s, w, t) for k in range(L)] for v in range(V)])  # (V, L, 4, 4)
    points = rng.normal(size=(64, 3))
    # the exact scene motion that renders P_k from P_0 in the model frame, computed directly: P_0 P_k^-1 x - x
    a = model[:, :1] @ np.linalg.inv(model[:, 1:])
    exact = np.einsum("vnij,gj->vngi", a[..., :3, :3], points) + a[..., None, :3, 3] - points
    return {"gt": gt, "model": model, "points": points, "exact": exact, "scale": s, "views": np.ones(V, bool)}


def test_exact_motion_scores_zero_error_and_unit_cosine(case):
    c = case
    out = motion_errors(c["points"], c["exact"], c["model"][:, 0], c["gt"], c["views"], c["model"][:, 1:])
    assert out["scale"] == pytest.approx(c["scale"], rel=1e-12)
    assert out["displacement_relative_error"] < 1e-9
    assert out["displacement_cosine"] == pytest.approx(1.0, abs=1e-12)
    assert out["rotation_error_deg"] < 1e-9 and out["translation_relative_error"] < 1e-9
    assert out["views"] == 5


@pytest.mark.parametrize("f", [0.0, 0.25, 0.5, 2.0])
def test_a_fraction_of_the_motion_scores_one_minus_the_fraction(case, f):
    c = case
    out = motion_errors(c["points"], f * c["exact"], c["model"][:, 0], c["gt"], c["views"])
    assert out["displacement_relative_error"] == pytest.approx(abs(1 - f), abs=1e-9)
    if f == 0:
        assert out["displacement_cosine"] is None or math.isnan(out["displacement_cosine"])
    else:
        assert out["displacement_cosine"] == pytest.approx(1.0, abs=1e-12)


def test_orthogonal_field_has_zero_cosine():
    t = np.zeros((1, 1, 2, 3))
    t[..., 0] = 1.0
    p = np.zeros_like(t)
    p[..., 1] = 1.0
    out = displacement_errors(p, t)
    assert out["displacement_cosine"] == pytest.approx(0.0)
    assert out["displacement_relative_error"] == pytest.approx(math.sqrt(2))


def test_a_camera_turned_by_a_known_angle(case):
    c = case
    ref = c["model"][:, 0]
    cams = c["model"][:, 1:].copy()
    turn = _pose([0.0, math.radians(2.0), 0.0], [0, 0, 0])
    cams = cams @ turn  # every latent camera turned 2 degrees about its own y axis, centres unchanged
    deltas = rigid_inverse(c["gt"][:, :1]) @ c["gt"][:, 1:]
    deltas[..., :3, 3] *= c["scale"]
    out = camera_errors(ref, cams, deltas)
    assert out["rotation_error_deg"] == pytest.approx(2.0, abs=1e-9)
    assert out["translation_relative_error"] < 1e-9


def test_views_without_ground_truth_are_left_out_and_no_view_gives_a_reason(case):
    c = case
    gt = c["gt"].copy()
    gt[1] = np.nan
    out = motion_errors(c["points"], c["exact"], c["model"][:, 0], gt, c["views"])
    assert out["views"] == 4 and out["displacement_relative_error"] < 1e-9
    out = motion_errors(c["points"], c["exact"], c["model"][:, 0], gt, np.zeros(5, bool))
    assert out["views"] == 0 and "reason" in out


def test_spread_scale_edges():
    a = np.random.default_rng(0).normal(size=(10, 3))
    assert spread_scale(3 * a + 1, a) == pytest.approx(3.0)
    assert math.isnan(spread_scale(a, np.zeros((10, 3))))  # all GT centres equal: undefined, not a division by 0
