"""Latent frames registered far from their own exposure are found (closed-form poses) and removed."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from eigs.sfm.outliers import sibling_outliers

from . import raycast as rc


def latents(views: int = 8, L: int = 5, seed: int = 0) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """Orbit views with a realistic intra-exposure motion: ≤ 3° rotation and ≤ 0.03 units per latent."""
    rng = np.random.default_rng(seed)
    base = rc.orbit(views)
    poses, view_of = {}, {}
    for v in range(views):
        for k in range(L):
            t = base[v].copy()
            t[:3, :3] = t[:3, :3] @ Rotation.from_rotvec(np.radians(rng.uniform(-1.7, 1.7, 3))).as_matrix()
            t[:3, 3] += rng.uniform(-0.03, 0.03, 3)
            poses[f"v{v}_k{k}"] = t
            view_of[f"v{v}_k{k}"] = v
    return poses, view_of


def test_consistent_latents_are_kept():
    poses, view_of = latents()
    assert sibling_outliers(poses, view_of) == []


def test_flipped_and_displaced_latents_are_found():
    poses, view_of = latents()
    flip = poses["v0_k1"].copy()
    flip[:3, :3] = flip[:3, :3] @ Rotation.from_rotvec([0, np.pi * 0.96, 0]).as_matrix()
    poses["v0_k1"] = flip
    far = poses["v5_k3"].copy()
    far[:3, 3] = poses["v2_k0"][:3, 3]  # registered at another view's place
    poses["v5_k3"] = far
    tilted = poses["v3_k4"].copy()
    tilted[:3, :3] = tilted[:3, :3] @ Rotation.from_rotvec(np.radians([12.0, 0, 0])).as_matrix()
    poses["v3_k4"] = tilted
    assert sibling_outliers(poses, view_of) == ["v0_k1", "v3_k4", "v5_k3"]


def test_views_with_too_few_latents_are_not_judged():
    poses, view_of = latents(views=3, L=2)  # two latents per view: no median to compare with
    poses["v1_k1"] = np.eye(4)
    assert sibling_outliers(poses, view_of) == []
    assert sibling_outliers({}, {}) == []
