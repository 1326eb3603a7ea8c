"""COLMAP mode on a built-in synthetic scene (the small CI version of the SfM benchmark in bench/sfm.py).

24 training views of ``blocks`` at 128×96 (15° apart on the orbit, as in the benchmark; shaken during every
exposure), B = 2, with fewer sub-frames than the default so generation is quick. The latent frames given to
COLMAP are exact renders of the ground-truth latent poses (the generator's own ray caster), so this test checks
the COLMAP stage on the built-in geometry and textures independently of EDI's quality; bench/sfm.py measures
the whole chain on EDI latents.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from eigs.events.edi_file import latent_png_name, write_edi
from eigs.events.pipeline import EdiOptions, compute_edi
from eigs.sfm.artifacts import METHOD_REGISTERED, read_poses, read_test_cameras
from eigs.sfm.run import SfmConfig, run_sfm
from eigs.synth.generate import encode, generate, write_generated

OVERRIDES = {"n_train": 24, "n_novel": 4, "n_bins": 2, "subframes": 16, "gap_subframes": 8, "seed": 2}


@pytest.fixture(scope="module")
def blocks24(tmp_path_factory):
    d = tmp_path_factory.mktemp("blocks24")
    g = generate("blocks", OVERRIDES, show_progress=False, threads=2)
    write_generated(g, d / "scene.h5")
    edi = compute_edi(g.scene, EdiOptions(bins=2, show_progress=False))
    write_edi(edi, d / "edi.h5")
    poses = g.scene.poses
    cam = g.scene.camera
    latent = d / "latent"
    latent.mkdir()
    V, L = poses.latent_c2w.shape[:2]
    rgb = g.caster.render(poses.latent_c2w.reshape(-1, 4, 4), cam.K, cam.width, cam.height,
                          supersample=g.params["supersample"], threads=2).rgb
    u8 = encode(rgb, g.params["camera_response"])
    for i, im in enumerate(u8):
        cv2.imwrite(str(latent / latent_png_name(i // L, i % L)), cv2.cvtColor(im, cv2.COLOR_RGB2BGR))
    return {"dir": d, "scene": d / "scene.h5", "edi": d / "edi.h5", "latent": latent, "views": V, "latents": L}


def test_colmap_mode_on_a_builtin_scene(blocks24, tmp_path):
    out = tmp_path / "sfm"
    rep = run_sfm(blocks24["scene"], blocks24["edi"], out, latent_dir=blocks24["latent"],
                  cfg=SfmConfig(mode="colmap"))
    assert rep["mode"] == "colmap"
    assert rep["registration"]["fraction"] >= 0.95
    acc = rep["accuracy"]
    assert acc["ate_percent_of_extent"] <= 1.0
    assert acc["rotation_error_deg_median"] <= 0.5
    rel = acc["relative_latent"]
    assert rel["translation_ratio_median"] <= 0.25 and rel["rotation_ratio_median"] <= 0.25
    tc = read_test_cameras(out)
    assert len(tc) == 24 + 4
    reg = tc.method == METHOD_REGISTERED
    assert reg.mean() >= 0.75
    assert np.median(tc.reprojection_error_px[reg]) <= 0.5
    poses = read_poses(out)
    assert poses.valid.all()
