"""Thread budget: the caller (Snakemake's ``threads:``) decides, every numeric library obeys."""

from __future__ import annotations

import os


def set_threads(n: int | None) -> int:
    """Limit torch, OpenMP and BLAS to ``n`` threads (``None``: leave the defaults). Returns the count in force."""
    import torch

    if n is not None:
        if n < 1:
            raise ValueError(f"threads must be >= 1, got {n}")
        for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
            os.environ[var] = str(n)
        torch.set_num_threads(n)
    return torch.get_num_threads()
