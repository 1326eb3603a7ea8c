"""The C++ rasterizer extension: its sources, and its build and load (:mod:`eigs.util.extension`: JIT on first use,
cached by a hash of sources and flags in ``<cache>/torch_extensions/eigs_render_<hash>``).
"""

from __future__ import annotations

import threading
from pathlib import Path
from types import ModuleType

from eigs.util import extension
from eigs.util.cache import cache_dir  # noqa: F401  (where the builds live; tests read it from here)
from eigs.util.extension import CFLAGS, LDFLAGS, ninja_on_path  # noqa: F401  (bench/rasterizer.py builds with them)

CSRC = Path(__file__).resolve().parent / "csrc"
SOURCES = ("autograd.cpp", "ops.cpp", "projection.cpp", "rasterize_fwd.cpp", "rasterize_bwd.cpp")
HEADERS = ("kernels.h", "ops.h", "pair_math.h", "pair_lanes.inc", "raster_common.h", "rasterize_bwd_tile.inc",
           "tile_geom.h")

ISA_CODES = {"auto": 0, "baseline": 1, "avx2": 2, "avx512": 3}

_lock = threading.Lock()
_module: ModuleType | None = None


def source_hash() -> str:
    """Hash of the rasterizer's sources, headers, flags, torch version and folder (12 hex digits)."""
    return extension.source_hash(CSRC, SOURCES + HEADERS)


def load() -> ModuleType:
    """The compiled extension module (builds it on first use)."""
    global _module
    if _module is None:
        with _lock:
            if _module is None:
                _module = extension.load_extension("eigs_render", CSRC, SOURCES, HEADERS, "the C++ rasterizer")
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
