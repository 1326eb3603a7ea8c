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
