"""The exhaustive pass of `sfm` mode colmap: when sequential + spatial matching leave the scene split into several
COLMAP models, `matcher: auto` matches the remaining pairs exhaustively and maps again (issue 18: at B = 6 and 8,
10 of 24 views of `blocks` and `tree` fell outside the kept model). COLMAP itself is replaced by stand-ins that
record the calls, so the control flow is tested without a reconstruction."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eigs.sfm import colmap as cm
from eigs.sfm import outliers
from eigs.sfm import run as sfm_run
from eigs.sfm.options import ColmapOptions, SfmConfig


class _Model:
    """Stands in for a pycolmap.Reconstruction (only its identity matters here)."""

    def __init__(self, tag: str) -> None:
        self.tag = tag


def _result(tag: str, sizes: list[int], lost: int) -> cm.MappingResult:
    return cm.MappingResult(_Model(tag), sizes, lost)


@pytest.fixture
def colmap_stub(monkeypatch):
    """Replace matching and mapping; ``maps`` is the sequence of mapping results, in call order."""
    calls: dict[str, list] = {"match": [], "map": []}
    maps: list[cm.MappingResult] = []

    def match(db, n_images, n_latent, opts, *, spatial=False, px=1.0):
        kind = "spatial" if spatial else ("sequential" if opts.matcher == "auto" else opts.matcher)
        calls["match"].append(kind)
        return kind

    def map_images(db, image_dir, out_dir, opts, **kw):
        calls["map"].append(Path(out_dir).name)
        return maps.pop(0)

    monkeypatch.setattr(cm, "match", match)
    monkeypatch.setattr(cm, "map_images", map_images)
    monkeypatch.setattr(sfm_run, "_spatial_pass", lambda db, ldir, work, res, *a: maps.pop(0))
    monkeypatch.setattr(outliers, "reject_sibling_outliers", lambda rec, view_of_name, refine_intrinsics: [])
    return calls, maps


def _reconstruct(tmp_path: Path, matcher: str = "auto"):
    lat = sfm_run._Latents.of(np.zeros(24, bool), 24, 7)  # 168 images: above the exhaustive limit of 150
    cfg = SfmConfig(colmap=ColmapOptions(matcher=matcher))
    report: dict = {}
    rec, _ = sfm_run._colmap_reconstruction(
        tmp_path / "db", tmp_path, tmp_path, lat, 1.0, cfg, sfm_run._Timer(), report
    )
    return rec, report


def test_split_scene_is_matched_exhaustively_and_the_larger_model_kept(tmp_path, colmap_stub):
    calls, maps = colmap_stub
    maps += [_result("seq", [98, 90], 70), _result("spatial", [98, 90], 70), _result("exh", [168], 0)]
    rec, report = _reconstruct(tmp_path)
    assert calls["match"] == ["sequential", "exhaustive"]
    assert calls["map"] == ["map", "map3"]
    assert rec.tag == "exh"
    assert report["matcher"] == "sequential+exhaustive"
    assert report["models"] == [168]
    assert "models_note" not in report


def test_exhaustive_pass_that_registers_no_more_keeps_the_first_model(tmp_path, colmap_stub):
    calls, maps = colmap_stub
    maps += [_result("seq", [98, 90], 70), _result("spatial", [98, 90], 70), _result("exh", [98, 60], 70)]
    rec, report = _reconstruct(tmp_path)
    assert calls["match"] == ["sequential", "exhaustive"]
    assert rec.tag == "spatial"
    assert report["matcher"] == "sequential"
    assert report["models_note"].startswith("COLMAP split the scene into 2 models")


def test_one_model_after_the_spatial_pass_needs_no_exhaustive_pass(tmp_path, colmap_stub):
    calls, maps = colmap_stub
    maps += [_result("seq", [120, 40], 48), _result("spatial", [168], 0)]
    rec, report = _reconstruct(tmp_path)
    assert calls["match"] == ["sequential"]
    assert rec.tag == "spatial"
    assert report["matcher"] == "sequential"


def test_a_chosen_sequential_matcher_is_not_overridden(tmp_path, colmap_stub):
    calls, maps = colmap_stub
    maps += [_result("seq", [98, 90], 70), _result("spatial", [98, 90], 70)]
    rec, report = _reconstruct(tmp_path, matcher="sequential")
    assert calls["match"] == ["sequential"]
    assert rec.tag == "spatial"
    assert "models_note" in report
