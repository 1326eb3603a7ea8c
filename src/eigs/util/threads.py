"""Thread budget: the caller (Snakemake's ``threads:``) decides, every numeric library obeys."""

from __future__ import annotations

import os
import sys

THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def set_threads(n: int | None) -> int | None:
    """Limit torch, OpenMP and BLAS to ``n`` threads (``None``: leave the defaults). Returns the count in force:
    torch's when torch is loaded, else ``n``.

    torch is not imported here: a stage that never uses it (EDI, SfM, init, tables) would pay its import, about 3 s
    of CPU on the 2-core VM, for nothing. The environment variables are read by OpenMP when torch loads later, so a
    later ``import torch`` starts with ``n`` intra-op threads; a torch already loaded is set directly."""
    if n is not None:
        if n < 1:
            raise ValueError(f"threads must be >= 1, got {n}")
        for var in THREAD_VARIABLES:
            os.environ[var] = str(n)
    torch = sys.modules.get("torch")
    if torch is None:
        return n
    if n is not None:
        torch.set_num_threads(n)
    return torch.get_num_threads()
