"""Build and load the C++ rasterizer extension (JIT on first use, cached by a hash of sources and flags).

The build directory is ``<cache>/torch_extensions/<name>`` (:func:`eigs.util.cache.cache_dir`: ``$EIGS_CACHE_DIR``,
else ``$XDG_CACHE_HOME/eigs``, else ``~/.cache/eigs``), where the name
carries a hash of the C++ sources, the compiler flags and the torch version, so an edit rebuilds and a cached
build loads in well under a second. A build failure raises :class:`eigs.errors.EigsError` naming the compiler
error.
"""

from __future__ import annotations

import hashlib
import re
import threading
from pathlib import Path
from types import ModuleType

from eigs.errors import EigsError
from eigs.util.cache import cache_dir

CSRC = Path(__file__).resolve().parent / "csrc"
SOURCES = ("autograd.cpp", "ops.cpp", "projection.cpp", "rasterize_fwd.cpp", "rasterize_bwd.cpp")
HEADERS = ("kernels.h", "ops.h", "pair_math.h", "raster_common.h", "tile_geom.h")
# Identical for every translation unit (forward and backward alike). Never -ffast-math:
# -fno-trapping-math and -fno-math-errno only let GCC vectorise the branch-free loops without changing IEEE
# results; -ffp-contract=off keeps the arithmetic identical across the baseline/AVX2/AVX-512 variants.
CFLAGS = ("-O3", "-fopenmp", "-fno-math-errno", "-fno-trapping-math", "-ffp-contract=off", "-DNDEBUG")
LDFLAGS = ("-fopenmp",)

ISA_CODES = {"auto": 0, "baseline": 1, "avx2": 2, "avx512": 3}

_lock = threading.Lock()
_module: ModuleType | None = None


def source_hash() -> str:
    """Hash of the C++ sources, headers, flags, torch version and the sources' folder (12 hex digits).

    The folder is part of it because the build file names the sources by path: two checkouts with the same sources
    sharing one cache would otherwise rewrite each other's build file, and each load would rebuild (measured: a
    load waiting 133 s on the other checkout's rebuild)."""
    import torch

    h = hashlib.sha256()
    h.update(str(CSRC).encode())
    for name in SOURCES + HEADERS:
        h.update(name.encode())
        h.update((CSRC / name).read_bytes())
    h.update(" ".join(CFLAGS + LDFLAGS).encode())
    h.update(torch.__version__.encode())
    return h.hexdigest()[:12]


def _compiler_error(text: str) -> str:
    """The first compiler error lines of a failed build log (or its tail)."""
    lines = [ln.strip() for ln in text.splitlines() if re.search(r"\berror\b", ln)]
    if not lines:
        lines = [ln.strip() for ln in text.splitlines() if ln.strip()][-5:]
    return "; ".join(lines[:5])


def ninja_on_path() -> None:
    """Put the interpreter's own scripts folder on PATH when no ``ninja`` is found there: PyTorch's extension loader
    looks for the ``ninja`` executable on PATH only, and the PyPI package ``ninja`` (a dependency) installs it beside
    the interpreter, which is not on PATH when ``.venv/bin/eigs`` or ``.venv/bin/pytest`` runs unactivated."""
    import os
    import shutil
    import sys

    if shutil.which("ninja") is None:
        scripts = os.path.dirname(sys.executable)
        if os.path.isfile(os.path.join(scripts, "ninja")):
            os.environ["PATH"] = scripts + os.pathsep + os.environ.get("PATH", "")


def load() -> ModuleType:
    """The compiled extension module (builds it on first use)."""
    global _module
    if _module is not None:
        return _module
    with _lock:
        if _module is not None:
            return _module
        from torch.utils import cpp_extension

        ninja_on_path()
        name = f"eigs_render_{source_hash()}"
        build = cache_dir() / "torch_extensions" / name
        try:
            build.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise EigsError(build, f"cannot create the extension build directory: {exc}") from exc
        try:
            _module = cpp_extension.load(
                name=name,
                sources=[str(CSRC / s) for s in SOURCES],
                extra_cflags=list(CFLAGS),
                extra_ldflags=list(LDFLAGS),
                extra_include_paths=[str(CSRC)],
                build_directory=str(build),
                verbose=False,
            )
        except (RuntimeError, OSError, ImportError) as exc:
            raise EigsError(CSRC, f"building the C++ rasterizer failed: {_compiler_error(str(exc))}") from exc
        return _module


def isa_code(isa: str) -> int:
    """Kernel ISA selector: ``auto`` (best the CPU has), ``baseline``, ``avx2`` or ``avx512``."""
    try:
        return ISA_CODES[isa]
    except KeyError:
        raise ValueError(f"isa must be one of {sorted(ISA_CODES)}, got {isa!r}") from None


def available_isas() -> list[str]:
    """The kernel variants this CPU can run, baseline first."""
    flags = load().cpu_isa_flags()
    out = ["baseline"]
    if flags & 1:
        out.append("avx2")
    if flags & 2:
        out.append("avx512")
    return out
