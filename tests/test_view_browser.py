"""``eigs view`` in a real browser: the test starts the viewer, drives headless Chromium (Debian's ``chromium``,
through Playwright's CDP driver; .ci/run installs it) to a test camera with the viewer's own panel, screenshots the
3D view and compares it with ``eigs render`` of the same camera. The comparison must pass at the right camera and
fail at a camera turned by 30° (yaw or roll), on a black page and on a white page; switching the run in the panel
must show the other run at the same camera. The page may load nothing from outside this machine.

Similarity (:func:`similarity`): both images to grey, box-downscaled to 80 × 60 (the viewer's splat renderer
sorts, filters and blends differently from ours, so fine detail is not compared), then SSIM and PSNR. Measured on
this scene (Chromium 156, SwiftShader WebGL, viser 1.1.1): right camera SSIM 0.975-0.994, PSNR 36-46 dB; 30° yaw
or roll SSIM 0.27-0.53, PSNR 7-13 dB; black page SSIM 0.00, 5.5 dB; white page SSIM 0.45, 5.8 dB. Thresholds:
SSIM >= 0.80 and PSNR >= 20 dB.
"""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from tests.conftest import require
from tests.test_view import WRONG_DEG, ViewerProcess, make_view_case

pytestmark = pytest.mark.slow

CHROMIUM = os.environ.get("EIGS_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"
# As root, offline, without a GPU: WebGL through SwiftShader; no sandbox (root), no background traffic.
CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--use-gl=angle", "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]  # fmt: skip
VIEWPORT = {"width": 640, "height": 480}  # the test cameras' 320 × 240 aspect
SSIM_MIN, PSNR_MIN = 0.80, 20.0
# everything but the 3D canvas hidden (the panel and notifications float over it)
CANVAS_ONLY = "body * { visibility: hidden !important; } canvas { visibility: visible !important; }"


def grey_small(img: np.ndarray, size: tuple[int, int] = (80, 60)) -> np.ndarray:
    return np.asarray(Image.fromarray(img).convert("L").resize(size, Image.Resampling.BOX), np.float64) / 255.0


def similarity(shot: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(SSIM, PSNR dB) of two RGB uint8 images on grey 80 × 60 versions."""
    from skimage.metrics import structural_similarity

    a, b = grey_small(shot), grey_small(ref)
    ssim = float(structural_similarity(a, b, data_range=1.0, win_size=7))
    psnr = float(10 * np.log10(1.0 / max(float(np.mean((a - b) ** 2)), 1e-12)))
    return ssim, psnr


def render_reference(run: Path, case: dict[str, Path], out: Path) -> list[np.ndarray]:
    """``eigs render RUN --cameras test`` → the test cameras' images (H, W, 3) uint8."""
    cmd = [sys.executable, "-m", "eigs", "render", str(run), str(case["scene"]), str(case["sfm"]), "--cameras", "test",
           "-o", str(out)]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    return [np.asarray(Image.open(p).convert("RGB")) for p in sorted(out.glob("test_*.png"))]


def settled_view(page: Any, previous: np.ndarray | None = None, timeout: float = 60.0) -> np.ndarray:
    """Screenshot of the 3D canvas alone once two consecutive shots agree, it is not one colour and (when
    ``previous`` is given) it differs from ``previous``."""
    style = page.add_style_tag(content=CANVAS_ONLY)
    try:
        last = None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            page.wait_for_timeout(700)
            shot = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"))
            if last is not None and np.abs(shot.astype(int) - last.astype(int)).mean() < 0.05 and shot.std() > 1.0 \
                    and (previous is None or np.abs(shot.astype(int) - previous.astype(int)).mean() > 1.0):  # fmt: skip
                return shot
            last = shot
        raise AssertionError("the viewer's canvas did not settle on a new picture")
    finally:
        style.evaluate("e => e.remove()")


def choose(page: Any, label: str, option: str) -> None:
    """Pick ``option`` in the viewer panel's dropdown ``label`` (a searchable select)."""
    page.get_by_label(label, exact=True).click()
    page.get_by_role("option", name=option, exact=True).click()


def test_viewer_in_chromium_matches_eigs_render_and_fails_on_a_wrong_pose(tmp_path):
    require(Path(CHROMIUM).is_file(), f"no Chromium at {CHROMIUM} (apt-get install chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        sync_playwright = None
    require(sync_playwright is not None, "the playwright package is not installed (pip install -e '.[dev]')")
    assert sync_playwright is not None
    t0 = time.monotonic()
    case = make_view_case(tmp_path / "case")
    ref = render_reference(case["3dgs"], case, tmp_path / "render_3dgs")
    ref_other = render_reference(case["eigs"], case, tmp_path / "render_eigs")
    assert len(ref) == 3 and ref[0].shape == (240, 320, 3)

    t_render = time.monotonic() - t0
    outside: list[str] = []
    viewer = ViewerProcess(str(case["3dgs"]), "--camera", "test:0")
    url = viewer.url
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport=VIEWPORT)
                local = url.rstrip("/")

                def only_local(route: Any) -> None:
                    u = route.request.url
                    if u.startswith(local) or u.startswith(("blob:", "data:")):
                        route.continue_()
                    else:
                        outside.append(u)
                        route.abort()

                page.route("**/*", only_local)
                page.goto(url + "?fixedDpr=1")  # fixedDpr: no resolution drops when software WebGL is slow
                page.get_by_text("Show cameras", exact=True).click()  # frustums off: the bare scene
                t_page = time.monotonic()
                at_test0 = settled_view(page)
                choose(page, "Camera", "test 1")  # the same camera turned by 30° (yaw)
                at_test1 = settled_view(page, previous=at_test0)
                choose(page, "Camera", "test 2")  # rolled by 30°
                at_test2 = settled_view(page, previous=at_test1)
                page.mouse.move(320, 240)  # orbit away with the mouse, then pick the same camera again
                page.mouse.down()
                page.mouse.move(420, 300, steps=8)
                page.mouse.up()
                orbited = settled_view(page, previous=at_test2)
                choose(page, "Camera", "test 2")
                again_at_test2 = settled_view(page, previous=orbited)
                choose(page, "Camera", "test 0")
                back_at_test0 = settled_view(page, previous=again_at_test2)
                choose(page, "Run", "b4/eigs")  # the other run, same camera
                other_run = settled_view(page, previous=back_at_test0)
                t_page = time.monotonic() - t_page
                Image.fromarray(at_test0).save(tmp_path / "viewer_test0.png")
            finally:
                browser.close()
    finally:
        code = viewer.stop()
    assert code == 0, "".join(viewer.stderr)
    assert outside == [], f"the viewer page asked for outside resources: {outside}"

    scores = {
        "test 0": similarity(at_test0, ref[0]),
        "test 1 (menu)": similarity(at_test1, ref[1]),
        "test 2 (menu)": similarity(at_test2, ref[2]),
        "test 2 again, after orbiting": similarity(again_at_test2, ref[2]),
        "test 0 again": similarity(back_at_test0, ref[0]),
        "other run at test 0": similarity(other_run, ref_other[0]),
        f"wrong pose: yawed {WRONG_DEG:.0f}°": similarity(at_test1, ref[0]),
        f"wrong pose: rolled {WRONG_DEG:.0f}°": similarity(at_test2, ref[0]),
        "wrong run": similarity(other_run, ref[0]),
        "orbited by mouse": similarity(orbited, ref[2]),
        "black page": similarity(np.zeros_like(ref[0]), ref[0]),
        "white page": similarity(np.full_like(ref[0], 255), ref[0]),
    }
    report = "; ".join(f"{k}: SSIM {s:.3f}, PSNR {p:.1f} dB" for k, (s, p) in scores.items())
    print(f"{report}\n(eigs render: {t_render:.1f} s; the browser from the first screenshot on: {t_page:.1f} s)")
    for key in list(scores)[:6]:
        s, p = scores[key]
        assert s >= SSIM_MIN and p >= PSNR_MIN, f"{key} should match eigs render: {report}"
    for key in list(scores)[6:]:
        s, p = scores[key]
        assert not (s >= SSIM_MIN and p >= PSNR_MIN), f"{key} should not match: {report}"
