"""Fuzzed artifacts: every reader of a file passed between stages, given truncated or corrupted bytes, either
returns a valid object or raises one :class:`~eigs.errors.EigsError` whose single-line message starts with the
file's path; never another exception (a traceback for the user). A stage given such a file exits 2 with that one
line and leaves no output (complete or partial) behind.

Extends the corrupted-file tests of the ingest readers (tests/io) to the artifacts of eigs' own stages:
``scene.h5``, ``edi.h5``, ``sfm/poses.h5``, ``sfm/test_cameras.h5``, the 3DGS PLY and run checkpoints.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
import torch
from hypothesis import assume, example, given
from hypothesis import strategies as st

from eigs.artifacts.edi import read_edi
from eigs.artifacts.gaussians import read_gaussian_ply
from eigs.artifacts.poses import read_poses, read_test_cameras
from eigs.errors import EigsError
from eigs.scene import read_scene
from eigs.scene.validate import validate
from tests.stress import toy
from tests.stress.budget import PROFILE, stress

READERS = {
    "scene": read_scene,
    "edi": read_edi,
    "poses": read_poses,
    "tests": read_test_cameras,
    "init": read_gaussian_ply,
}


class Originals(dict):
    """name → (file name, bytes); a short repr, so hypothesis reports do not print every byte."""

    def __repr__(self) -> str:
        return f"Originals({', '.join(f'{k}: {len(v[1])} B' for k, v in self.items())})"


@pytest.fixture(scope="module")
def originals(tmp_path_factory) -> Originals:
    """name → (file name, bytes) of every valid artifact of the toy scene and a run checkpoint."""
    from eigs.train.config import TrainConfig
    from eigs.train.gaussian.trainer import Trainer

    root = tmp_path_factory.mktemp("orig")
    paths = toy.write_all(root)
    out = Originals({name: (p.name, p.read_bytes()) for name, p in paths.items()})
    tr = Trainer(toy.train_data(), TrainConfig(steps=10), torch.device("cpu"))
    for _ in range(3):
        tr.train_step()
    ckpt = root / "checkpoint.pt"
    tr.save_checkpoint(ckpt)
    out["checkpoint"] = (ckpt.name, ckpt.read_bytes())
    return out


@st.composite
def mutations(draw, size: int):
    """A damaged copy of ``size`` bytes, described as (kind, offset, payload)."""
    kind = draw(st.sampled_from(["truncate", "flip", "block", "zero-block"]))
    if kind == "truncate":
        return kind, draw(st.integers(0, size - 1)), b""
    off = draw(st.integers(0, size - 1))
    if kind == "flip":
        n = draw(st.integers(1, 8))
        return kind, off, bytes(draw(st.lists(st.integers(0, 255), min_size=n, max_size=n)))
    n = draw(st.integers(8, 512))
    payload = b"\0" * n if kind == "zero-block" else draw(st.binary(min_size=n, max_size=n))
    return kind, off, payload


def damage(data: bytes, mutation) -> bytes:
    kind, off, payload = mutation
    if kind == "truncate":
        return data[:off]
    if kind == "flip":  # scattered single bytes, spaced through the file from `off`
        b = bytearray(data)
        step = max(1, len(b) // (len(payload) + 1))
        for i, v in enumerate(payload):
            b[(off + i * step) % len(b)] = v
        return bytes(b)
    return (data[:off] + payload + data[off + len(payload) :])[: len(data)]


def global_heaps(data: bytes) -> list[tuple[int, int]]:
    """[start, stop) byte ranges of the HDF5 global heap collections ("GCOL": they hold the variable-length string
    attributes). Damage there is left out: libhdf5 2.0.0 loops forever on some of it (zeroing the heap index of a
    string attribute, e.g. the scene's ``camera_response``, hangs ``H5Aread``), which no in-process reader can
    guard against."""
    out, i = [], data.find(b"GCOL")
    while i >= 0:
        size = int.from_bytes(data[i + 8 : i + 16], "little")
        out.append((i, i + max(size, 16)))
        i = data.find(b"GCOL", i + 4)
    return out


def touches_global_heap(data: bytes, mutation) -> bool:
    kind, off, payload = mutation
    if kind == "truncate":
        return False
    if kind == "flip":
        step = max(1, len(data) // (len(payload) + 1))
        spots = [(off + i * step) % len(data) for i in range(len(payload))]
    else:
        spots = [off, off + len(payload) - 1]
    return any(a <= x < b for a, b in global_heaps(data) for x in spots) or any(
        off <= a < off + len(payload) for a, _ in global_heaps(data)
    )


def assert_one_line_naming(err: EigsError, path: Path) -> None:
    msg = str(err)
    assert msg.startswith(f"{path}: "), msg
    assert "\n" not in msg and len(msg) < 2000, msg


def _check_reader(name: str, originals, mutation, directory: Path) -> None:
    fname, data = originals[name]
    bad = damage(data, mutation)
    path = directory / fname
    path.write_bytes(bad)
    try:
        obj = READERS[name](path)
    except EigsError as err:
        assert_one_line_naming(err, path)
        return
    assert mutation[0] != "truncate", "a truncated file was read without an error"
    if name == "scene":
        validate(str(path), obj)  # what came back is valid
    else:
        obj.validate(path)


def _data_size(name: str, originals) -> int:
    return len(originals[name][1])


@pytest.mark.parametrize("name", list(READERS))
def test_truncated_artifacts_raise_one_line_naming_the_file(name, originals, tmp_path_factory):
    size = _data_size(name, originals)
    directory = tmp_path_factory.mktemp(name)
    for frac in (0.0, 0.01, 0.1, 0.5, 0.9, 0.999):
        _check_reader(name, originals, ("truncate", int(frac * size), b""), directory)


@pytest.mark.parametrize(
    "name,kind,offset",
    [
        ("scene", "zero-block", 112),  # h5py KeyError reading the format attribute: was a traceback
        ("scene", "zero-block", 680),  # RuntimeError "bad local heap signature" in the header: was a traceback
        ("scene", "zero-block", 1376),  # RuntimeError from H5Tget_ebias reading a dataset: was a traceback
        ("edi", "zero-block", 112),
        ("edi", "zero-block", 1368),
        ("poses", "zero-block", 112),
        ("poses", "zero-block", 800),
        ("tests", "zero-block", 112),
        ("tests", "zero-block", 800),
    ],
)
def test_damage_found_by_the_sweep(name, kind, offset, originals, tmp_path_factory):
    """Regressions: 8 zero bytes where the sweep below first found a traceback (offsets of the toy files written
    by h5py 3.16 / HDF5 2.0; elsewhere they still test the same property)."""
    _check_reader(name, originals, (kind, offset, b"\0" * 8), tmp_path_factory.mktemp(name))


@pytest.mark.parametrize("name", ["scene", "edi", "poses", "tests"])
def test_hdf5_metadata_sweep(name, originals, tmp_path_factory):
    """Every 8-byte word of the first 4 KiB (superblock, root group, attribute and B-tree headers; not the global
    heaps, see :func:`global_heaps`) zeroed and inverted in turn: a systematic sweep of the metadata the random
    mutations may miss."""
    size = min(4096, _data_size(name, originals))
    heaps = global_heaps(originals[name][1])
    directory = tmp_path_factory.mktemp(name)
    # ci: every word of the first KiB (superblock, root group, its attributes) zeroed and every other one inverted,
    # every eighth word after it both; exhaustive: every word both ways
    full = PROFILE == "exhaustive"
    for off in range(0, size, 8):
        if any(a - 8 < off < b for a, b in heaps) or not (full or off < 1024 or off % 64 == 0):
            continue
        _check_reader(name, originals, ("zero-block", off, b"\0" * 8), directory)
        if full or off % 16 == 0:
            word = originals[name][1][off : off + 8]
            _check_reader(name, originals, ("block", off, bytes(255 - b for b in word)), directory)


def _fuzz(name: str):
    @stress(40)
    @given(data=st.data())
    def run(originals, tmp_path_factory, data) -> None:
        mutation = data.draw(mutations(_data_size(name, originals)), label="mutation")
        assume(name in ("init", "checkpoint") or not touches_global_heap(originals[name][1], mutation))
        _check_reader(name, originals, mutation, tmp_path_factory.mktemp(name))

    return run


test_fuzz_scene = _fuzz("scene")
test_fuzz_edi = _fuzz("edi")
test_fuzz_poses = _fuzz("poses")
test_fuzz_test_cameras = _fuzz("tests")
test_fuzz_ply = _fuzz("init")


# ----------------------------------------------------------------------------------------------- run checkpoints


def _fresh_trainer():
    from eigs.train.config import TrainConfig
    from eigs.train.gaussian.trainer import Trainer

    return Trainer(toy.train_data(), TrainConfig(steps=10), torch.device("cpu"))


@pytest.fixture(scope="module")
def fresh_params() -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in _fresh_trainer().model.params.items()}


@stress(25)
@given(data=st.data())
@example(data=None)  # a NaN written into a parameter (silent damage: torch's zip reader checks no CRC)
def test_damaged_checkpoints_are_ignored_or_resume_finite(originals, fresh_params, tmp_path_factory, caplog, data):
    """A checkpoint is a cache: a damaged one is ignored with a warning naming it (the run starts over) or, when the
    damage missed what it restores, resumes a finite state; never an exception, never NaN parameters (a NaN
    resumed would fail the run after ``max_bad_steps`` and be saved again: the run could never finish)."""
    fname, raw = originals["checkpoint"]
    if data is None:
        state = torch.load(__import__("io").BytesIO(raw), weights_only=False)
        state["params"]["means"][3, 1] = float("nan")
        path = tmp_path_factory.mktemp("ckpt") / fname
        torch.save(state, path)
    else:
        bad = damage(raw, data.draw(mutations(len(raw)), label="mutation"))
        path = tmp_path_factory.mktemp("ckpt") / fname
        path.write_bytes(bad)
    tr = _fresh_trainer()
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="eigs.train.gaussian.trainer"):
        resumed = tr.load_checkpoint(path)
    if not resumed:
        assert any(str(path) in r.getMessage() for r in caplog.records), caplog.text
        assert tr.step == 0
        for k, v in fresh_params.items():  # started over from the initial cloud
            assert torch.equal(tr.model.params[k].detach(), v), k
    for k, v in tr.model.params.items():
        assert torch.isfinite(v).all(), k
        assert v.shape[1:] == fresh_params[k].shape[1:], k
    tr.train_step()  # and training goes on
    for v in tr.model.params.values():
        assert torch.isfinite(v).all()


@pytest.mark.parametrize(
    "damage_kind", ["renamed key", "wrong shape", "negative second moment", "zero step", "zero eps", "beta of 1"]
)
def test_checkpoint_with_damaged_adam_state_is_ignored(originals, fresh_params, tmp_path_factory, caplog, damage_kind):
    """Regressions (found by the fuzz test above): a flipped byte renamed an Adam moment's key in the pickle
    ('exp_avg' → another name), the checkpoint loaded, and the first optimiser step after resuming raised KeyError;
    a flipped sign bit made an exp_avg_sq entry negative (-1.9e-9), and the first step wrote NaN into the parameter
    (Adam divides by its square root). The Adam state is now checked (its keys, moments of the parameter's shape,
    exp_avg_sq ≥ 0, step ≥ 1, and the groups' lr, eps, betas) before resuming."""
    fname, raw = originals["checkpoint"]
    state = torch.load(__import__("io").BytesIO(raw), weights_only=False)
    entry = state["optimizer"]["state"][0]
    if damage_kind == "renamed key":
        entry["exp_avc"] = entry.pop("exp_avg")
    elif damage_kind == "wrong shape":
        entry["exp_avg"] = entry["exp_avg"][:-1]
        entry["exp_avg_sq"] = entry["exp_avg_sq"][:-1]
    elif damage_kind == "negative second moment":
        entry["exp_avg_sq"].view(-1)[0] = -1.862645149230957e-09
    elif damage_kind == "zero step":
        entry["step"] = torch.zeros_like(entry["step"])
    elif damage_kind == "zero eps":
        state["optimizer"]["param_groups"][0]["eps"] = 0.0
    else:
        state["optimizer"]["param_groups"][0]["betas"] = (0.9, 1.0)
    path = tmp_path_factory.mktemp("ckpt") / fname
    torch.save(state, path)
    tr = _fresh_trainer()
    with caplog.at_level(logging.WARNING, logger="eigs.train.gaussian.trainer"):
        assert not tr.load_checkpoint(path)
    assert any(str(path) in r.getMessage() and "optimizer" in r.getMessage() for r in caplog.records), caplog.text
    for k, v in fresh_params.items():
        assert torch.equal(tr.model.params[k].detach(), v), k
    tr.train_step()


def test_ply_header_damage(originals, tmp_path_factory):
    """Each property of the header renamed in turn (same length, so the binary body still parses), and an odd
    number of f_rest properties: a one-line error or a valid cloud, as for any other damage."""
    fname, data = originals["init"]
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header, body = data[:end].decode("ascii"), data[end:]
    names = [ln.split()[-1] for ln in header.splitlines() if ln.startswith("property")]
    directory = tmp_path_factory.mktemp("ply")
    path = directory / fname
    for name in names:
        bogus = "q" * len(name)
        path.write_bytes(header.replace(f" {name}\n", f" {bogus}\n").encode("ascii") + body)
        try:
            read_gaussian_ply(path)
        except EigsError as err:
            assert_one_line_naming(err, path)
        else:
            assert name in ("nx", "ny", "nz"), f"{name} renamed, yet the cloud was read"
    # one f_rest property (not 3 × ((d+1)² − 1)) in an otherwise valid file
    import numpy as np
    from plyfile import PlyData, PlyElement

    fields = [*names[:9], "f_rest_0", *names[9:]]
    arr = np.zeros(4, dtype=[(f, "<f4") for f in fields])
    arr["rot_0"] = 1.0
    PlyData([PlyElement.describe(arr, "vertex")], text=False).write(str(path))
    with pytest.raises(EigsError) as info:
        read_gaussian_ply(path)
    assert_one_line_naming(info.value, path)


@pytest.mark.parametrize("damage_kind", [("truncate", 0.5), ("zero-block", 112)])
def test_stages_given_a_damaged_input_exit_2_on_one_line_and_write_nothing(damage_kind, tmp_path, capsys):
    """``eigs edi`` on a damaged scene.h5 and ``eigs train`` on a damaged edi.h5 / poses.h5 / init.ply: exit code
    2, one line on stderr naming the file, and no output (nor temporary file) left in the output directory."""
    from eigs.cli import main

    scene = toy.write_all(tmp_path / "in")["scene"]
    kind, where = damage_kind

    def spoil(p: Path) -> Path:
        data = p.read_bytes()
        off = int(where * len(data)) if kind == "truncate" else where
        p.write_bytes(damage(data, (kind, off, b"\0" * 8)))
        return p

    def run(argv: list[str], bad: Path, out_dir: Path) -> None:
        capsys.readouterr()
        assert main(argv) == 2
        err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
        assert len(err) == 1 and err[0].startswith(f"eigs {argv[0]}: error: {bad}: "), err
        assert not out_dir.exists() or not any(out_dir.iterdir()), sorted(out_dir.iterdir())

    out = tmp_path / "out"
    out.mkdir()
    bad_scene = spoil(scene)
    run(["edi", str(bad_scene), "-o", str(out / "edi.h5"), "--latent-dir", str(out / "latent")], bad_scene, out)
    for name in ("edi", "poses", "init"):
        fresh = toy.write_all(tmp_path / name)
        bad = spoil(fresh[name])
        argv = ["train", str(fresh["scene"]), str(fresh["edi"]), str(fresh["poses"].parent), str(fresh["init"]),
                "-o", str(out / "run"), "--config", '{"steps": 2}']  # fmt: skip
        run(argv, bad, out)
