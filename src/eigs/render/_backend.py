"""Build and load the C++ rasterizer extension (JIT on first use, cached by a hash of sources and flags).

The build directory is ``<cache>/torch_extensions/<name>`` (:func:`eigs.util.cache.cache_dir`: ``$EIGS_CACHE_DIR``,
else ``$XDG_CACHE_HOME/eigs``, else ``~/.cache/eigs``), where the name
carries a hash of the C++ sources, the compiler flags and the torch version, so an edit rebuilds and a cached
build loads in well under a second. A build failure raises :class:`eigs.errors.EigsError` naming the compiler
error.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import re
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

from eigs.errors import EigsError
from eigs.util.cache import cache_dir

CSRC = Path(__file__).resolve().parent / "csrc"
SOURCES = ("autograd.cpp", "ops.cpp", "projection.cpp", "rasterize_fwd.cpp", "rasterize_bwd.cpp")
HEADERS = ("kernels.h", "ops.h", "pair_math.h", "pair_lanes.inc", "raster_common.h", "rasterize_bwd_tile.inc",
           "tile_geom.h")
# Identical for every translation unit (forward and backward alike). Never -ffast-math:
# -fno-trapping-math and -fno-math-errno only let GCC vectorise the branch-free loops without changing IEEE
# results; -ffp-contract=off keeps the arithmetic identical across the baseline/AVX2/AVX-512 variants.
CFLAGS = ("-O3", "-fopenmp", "-fno-math-errno", "-fno-trapping-math", "-ffp-contract=off", "-DNDEBUG")
LDFLAGS = ("-fopenmp",)

ISA_CODES = {"auto": 0, "baseline": 1, "avx2": 2, "avx512": 3}

log = logging.getLogger(__name__)
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
    """Put the interpreter's own scripts folder first on PATH when it holds ``ninja``: PyTorch's extension loader runs
    the first ``ninja`` on PATH, and the pinned PyPI package ``ninja`` (a dependency) installs it beside the
    interpreter, which is not on PATH when ``.venv/bin/eigs`` or ``.venv/bin/pytest`` runs unactivated. Always that
    one, not a system ninja found first: two ninja versions hash the build commands differently (Debian's 1.11.1 and
    the pinned 1.13.2), so processes alternating between them rebuilt the extension on every switch (measured in a
    CI run: six full rebuilds of 1.5–2 minutes each, tests and Snakemake jobs taking turns)."""
    import os
    import shutil

    scripts = os.path.dirname(sys.executable)
    own = os.path.join(scripts, "ninja")
    if os.path.isfile(own) and shutil.which("ninja") != own:
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
            with _build_lock(build):
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


@contextlib.contextmanager
def _build_lock(build: Path) -> Iterator[None]:
    """Hold an OS lock on ``build`` (released by the kernel when its holder dies) around PyTorch's load, and remove
    PyTorch's own ``lock`` file left there. PyTorch marks a build in progress with that file (every load takes it,
    also to find the build up to date) and waits without end while it exists; a process killed inside a load leaves
    it behind, and every later job hung (the workflow killed with SIGKILL: tests/faults). Every load of this build
    goes through this lock, so while we hold it no live process holds PyTorch's: the file is stale."""
    import fcntl

    with open(build / ".eigs_load.lock", "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            stale = build / "lock"
            if stale.exists():
                log.warning("removing %s, left by a process that died while loading the rasterizer", stale)
                stale.unlink(missing_ok=True)
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


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
