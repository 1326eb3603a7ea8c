"""Build and load eigs's C++ extensions (JIT on first use, cached by a hash of sources and flags).

Two extensions use it: the rasterizer (:mod:`eigs.render._backend`) and the fused SSIM (:mod:`eigs.metrics.fused_ssim`).
Each builds in ``<cache>/torch_extensions/<prefix>_<hash>`` (:func:`eigs.util.cache.cache_dir`), where the hash
covers the C++ sources and headers, the compiler flags, the torch version and the sources' folder, so an edit
rebuilds and a cached build loads in well under a second. A build failure raises :class:`eigs.errors.EigsError`
naming the compiler error.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import re
import shutil
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import ModuleType

from eigs.errors import EigsError
from eigs.util.cache import cache_dir

# Identical for every translation unit. Never -ffast-math: -fno-trapping-math and -fno-math-errno only let GCC
# vectorise the branch-free loops without changing IEEE results; -ffp-contract=off keeps the arithmetic identical
# across the baseline/AVX2/AVX-512 variants of a kernel.
CFLAGS = ("-O3", "-fopenmp", "-fno-math-errno", "-fno-trapping-math", "-ffp-contract=off", "-DNDEBUG")
LDFLAGS = ("-fopenmp",)

log = logging.getLogger(__name__)
_lock = threading.Lock()
_modules: dict[tuple[str, str, tuple[str, ...], tuple[str, ...]], ModuleType] = {}


def source_hash(csrc: Path, names: Sequence[str]) -> str:
    """Hash of the files ``names`` under ``csrc``, the flags, the torch version and the folder (12 hex digits).

    The folder is part of it because the build file names the sources by path: two checkouts with the same sources
    sharing one cache would otherwise rewrite each other's build file, and each load would rebuild (measured: a
    load waiting 133 s on the other checkout's rebuild)."""
    import torch

    h = hashlib.sha256()
    h.update(str(csrc).encode())
    for name in names:
        h.update(name.encode())
        h.update((csrc / name).read_bytes())
    h.update(" ".join(CFLAGS + LDFLAGS).encode())
    h.update(torch.__version__.encode())
    return h.hexdigest()[:12]


def compiler_error(text: str) -> str:
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
    scripts = os.path.dirname(sys.executable)
    own = os.path.join(scripts, "ninja")
    if os.path.isfile(own) and shutil.which("ninja") != own:
        os.environ["PATH"] = scripts + os.pathsep + os.environ.get("PATH", "")


@contextlib.contextmanager
def build_lock(build: Path) -> Iterator[None]:
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
                log.warning("removing %s, left by a process that died while loading a C++ extension", stale)
                stale.unlink(missing_ok=True)
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def load_extension(prefix: str, csrc: Path, sources: Sequence[str], headers: Sequence[str], what: str) -> ModuleType:
    """The compiled module of ``sources`` under ``csrc`` (built on first use, then cached in this process).

    ``prefix``: the module name's start (``eigs_render``); ``what``: the extension in words, for the error message.
    The kernels call this on every use: once loaded, the module comes from a dictionary, without reading or hashing
    the sources again (an edit made while a process runs takes effect in the next process).
    """
    key = (prefix, str(csrc), tuple(sources), tuple(headers))
    module = _modules.get(key)
    if module is not None:
        return module
    with _lock:
        if key in _modules:
            return _modules[key]
        from torch.utils import cpp_extension

        name = f"{prefix}_{source_hash(csrc, (*sources, *headers))}"
        ninja_on_path()
        build = cache_dir() / "torch_extensions" / name
        try:
            build.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise EigsError(build, f"cannot create the extension build directory: {exc}") from exc
        try:
            with build_lock(build):
                module = cpp_extension.load(
                    name=name,
                    sources=[str(csrc / s) for s in sources],
                    extra_cflags=list(CFLAGS),
                    extra_ldflags=list(LDFLAGS),
                    extra_include_paths=[str(csrc)],
                    build_directory=str(build),
                    verbose=False,
                )
        except (RuntimeError, OSError, ImportError) as exc:
            raise EigsError(csrc, f"building {what} failed: {compiler_error(str(exc))}") from exc
        _modules[key] = module
        return module
