"""Keep freed memory in the process, so training steps do not page-fault their large temporaries afresh.

A training step allocates and frees tensors of tens of MB (the ADE's hidden activations: Gaussians × width × 4 B,
17.5 MB at 17k Gaussians and width 256). glibc serves blocks above its mmap threshold (128 kB at start) with
``mmap`` and returns them with ``munmap``, and trims the top of the heap once 128 kB is free, so each step's
temporaries are fresh pages and the kernel faults and zeroes every 4 kB page at first touch: about 1.6 ms per
17.5 MB on our machines (``bench/train.py`` measures the effect on a whole step, docs/benchmarks.md).

:func:`keep_freed_memory` turns mmap off for malloc (``M_MMAP_MAX`` 0: every block comes from the heap, also
those above the 32 MB that glibc's mmap threshold can be raised to, e.g. width-512 activations) and raises the trim
threshold to 2 GB, the same as starting Python with ``MALLOC_MMAP_MAX_=0`` and ``MALLOC_TRIM_THRESHOLD_`` set.
The process then keeps its peak heap until it exits (a training job's peak is its working set anyway). Results do
not change: only where the bytes live does.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import sys

log = logging.getLogger(__name__)

M_TRIM_THRESHOLD = -1  # glibc malloc.h
M_MMAP_MAX = -4
TRIM_THRESHOLD = 2**31 - 1  # 2 GB, mallopt's largest (an int): above any run's working set


def keep_freed_memory() -> bool:
    """Tune glibc malloc as above. Returns False (and changes nothing) where the C library is not glibc."""
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (macOS, musl without mallopt)
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    ok = mallopt(M_MMAP_MAX, 0) == 1
    ok = mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1 and ok
    log.debug("malloc tuned to keep freed memory: %s", ok)
    return ok


# PyTorch's CPU allocator aligns blocks of 2 MB and more to 2 MB and asks the kernel for transparent huge pages on
# them (madvise) when this variable is 1 (c10's alloc_cpu, read once, at the first allocation)
HUGE_PAGES_ENV = "THP_MEM_ALLOC_ENABLE"


def use_huge_pages() -> bool:
    """Ask for huge pages on PyTorch's large CPU tensors (``THP_MEM_ALLOC_ENABLE=1`` unless the environment sets it):
    a 4 kB page's TLB entry covers 4 kB, a huge page's 2 MB, so random reads across a large tensor (a field's voxel
    grid: the trilinear kernel's eight corners per sample) miss the TLB far less. Only memory placement changes, never
    a value. It must run before torch is imported (PyTorch reads the variable once); returns whether it applies."""
    os.environ.setdefault(HUGE_PAGES_ENV, "1")
    applies = "torch" not in sys.modules and os.environ[HUGE_PAGES_ENV] == "1"
    log.debug("huge pages for large tensors: %s", applies)
    return applies
