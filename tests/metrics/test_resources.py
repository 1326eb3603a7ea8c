"""Model files: conversion, manifests, checksum verification, clear errors, restricted unpickling."""

from __future__ import annotations

import json
import os
import pickle
import shutil

import numpy as np
import pytest
import torch

from eigs.errors import EigsError
from eigs.metrics import resources
from eigs.metrics.noreference import brisque


def test_manifests_list_every_file_with_its_checksum(resources_dir):
    for kind in resources.KINDS:
        manifest = json.loads((resources_dir / kind / "MANIFEST.json").read_text())
        assert manifest["kind"] == kind and manifest["files"]
        on_disk = {p.name for p in (resources_dir / kind).iterdir() if p.name != "MANIFEST.json"}
        assert set(manifest["files"]) == on_disk
        for name, digest in manifest["files"].items():
            assert resources.sha256_file(resources_dir / kind / name) == digest
        assert manifest["source"]["sha256"] == resources.SOURCES[kind].sha256


def test_converted_weights(resources_dir):
    alex = torch.load(resources.verified_file("lpips", "alex.pt", resources_dir), weights_only=True)
    assert alex["convs.0.weight"].shape == (64, 3, 11, 11)
    assert [alex[f"lins.{i}.weight"].shape[1] for i in range(5)] == [64, 192, 384, 256, 256]
    assert all(float(alex[f"lins.{i}.weight"].min()) >= 0 for i in range(5))  # LPIPS v0.1 lins are non-negative
    # the original release's allmodel: 774 support vectors, gamma 0.05, rho -153.591; allrange's first and last
    # rows (0.338..10 for the full-scale GGD shape, 0.001118..0.370399 for the last right variance)
    with np.load(resources.verified_file("brisque", "live_svr.npz", resources_dir)) as z:
        assert z["support_vectors"].shape == (774, 36)
        assert float(z["gamma"]) == 0.05 and float(z["rho"]) == pytest.approx(-153.591)
        assert (z["feature_min"][0], z["feature_max"][0]) == (0.338, 10.0)
        assert (z["feature_min"][-1], z["feature_max"][-1]) == (0.001118, 0.370399)
    allrange = (resources_dir / "brisque" / "allrange").read_text().splitlines()
    assert allrange[:2] == ["x", "-1 1"] and len(allrange) == 38 and allrange[2].split()[0] == "1"
    with np.load(resources.verified_file("brisque_opencv", "model.npz", resources_dir)) as z:
        assert z["support_vectors"].shape == (770, 36)
        assert float(z["gamma"]) == 0.05 and float(z["rho"]) == pytest.approx(-155.845)
        assert np.all(z["feature_max"] > z["feature_min"])


def test_prepare_keeps_valid_files(resources_dir):
    before = (resources_dir / "lpips" / "alex.pt").stat().st_mtime_ns
    resources.prepare(resources_dir)
    assert (resources_dir / "lpips" / "alex.pt").stat().st_mtime_ns == before


def test_missing_and_corrupt_files_name_the_command(resources_dir, tmp_path):
    with pytest.raises(EigsError, match=f"eigs resources --dir {tmp_path}"):
        resources.verified_file("brisque", "live_svr.npz", tmp_path)
    with pytest.raises(EigsError, match="eigs resources"):
        brisque(np.random.default_rng(0).random((40, 40)), tmp_path)
    shutil.copytree(resources_dir / "brisque", tmp_path / "brisque")
    resources.verified_file("brisque", "live_svr.npz", tmp_path)
    with open(tmp_path / "brisque" / "live_svr.npz", "r+b") as f:
        f.seek(200)
        byte = f.read(1)
        f.seek(200)
        f.write(bytes([byte[0] ^ 0xFF]))
    with pytest.raises(EigsError, match=r"checksum mismatch.*eigs resources --dir"):
        resources.verified_file("brisque", "live_svr.npz", tmp_path)
    assert not resources.is_valid("brisque", tmp_path)
    (tmp_path / "brisque" / "allmodel").unlink()
    with pytest.raises(EigsError, match="missing"):
        resources.verified_file("brisque", "allmodel", tmp_path)
    (tmp_path / "brisque" / "MANIFEST.json").write_text("{not json")
    with pytest.raises(EigsError, match="unreadable manifest"):
        resources.verified_file("brisque", "live_svr.npz", tmp_path)
    # `prepare` repairs it (the download is cached)
    resources.prepare(tmp_path, kinds=("brisque",))
    assert resources.is_valid("brisque", tmp_path)


def test_directory_from_another_source_is_rebuilt(resources_dir, tmp_path):
    """A brisque/ made from the older source (the brisque wheel) has valid checksums but is not the original
    model: it is not valid and `prepare` replaces it."""
    shutil.copytree(resources_dir / "brisque_opencv", tmp_path / "brisque")
    manifest = json.loads((tmp_path / "brisque" / "MANIFEST.json").read_text())
    manifest["kind"] = "brisque"
    (tmp_path / "brisque" / "MANIFEST.json").write_text(json.dumps(manifest))
    assert not resources.is_valid("brisque", tmp_path)
    resources.prepare(tmp_path, kinds=("brisque",))
    assert resources.is_valid("brisque", tmp_path) and (tmp_path / "brisque" / "live_svr.npz").is_file()


def test_parse_svm_scale_ranges():
    src = "class B:\n    def __init__(self):\n        self._scaler = np.array([[-1, 1], [0.5, 2], [-3, 1e-05]])\n"
    lo, hi = resources.parse_svm_scale_ranges(src, n_features=2)
    np.testing.assert_array_equal(lo, [0.5, -3]) and np.testing.assert_array_equal(hi, [2, 1e-05])
    with pytest.raises(ValueError, match="table"):
        resources.parse_svm_scale_ranges("x = 1\n", n_features=2)
    with pytest.raises(ValueError):  # a call in the table is not a literal: never executed
        resources.parse_svm_scale_ranges(src.replace("[0.5, 2]", "[__import__('os'), 2]"), n_features=2)


class _Evil:
    def __reduce__(self):
        return (os.system, ("echo pwned",))


def test_restricted_unpicklers():
    arrays = {"a": {"kernel": np.arange(6, dtype=np.float32).reshape(2, 3)}, "b": np.float32(2.5)}
    out = resources.load_numpy_pickle(pickle.dumps(arrays))
    np.testing.assert_array_equal(out["a"]["kernel"], arrays["a"]["kernel"])
    with pytest.raises(pickle.UnpicklingError, match="refusing"):
        resources.load_numpy_pickle(pickle.dumps(_Evil()))
    with pytest.raises(pickle.UnpicklingError, match="refusing"):
        resources.load_plain_pickle(pickle.dumps(np.zeros(3)))
    assert resources.load_plain_pickle(pickle.dumps({"min_": [0.5, 1.0]})) == {"min_": [0.5, 1.0]}


def test_parse_libsvm_model():
    text = (
        "svm_type epsilon_svr\nkernel_type rbf\ngamma 0.5\nnr_class 2\ntotal_sv 2\nrho -1.5\n"
        "SV\n2 1:0.5 3:-1\n-1 2:0.25\n"
    )
    m = resources.parse_libsvm_model(text, n_features=3)
    np.testing.assert_array_equal(m["support_vectors"], [[0.5, 0, -1], [0, 0.25, 0]])
    np.testing.assert_array_equal(m["dual_coef"], [2, -1])
    assert m["gamma"] == 0.5 and m["rho"] == -1.5
    with pytest.raises(ValueError, match="epsilon_svr"):
        resources.parse_libsvm_model(text.replace("rbf", "linear"), n_features=3)
    with pytest.raises(ValueError, match="total_sv"):
        resources.parse_libsvm_model(text.replace("total_sv 2", "total_sv 3"), n_features=3)
