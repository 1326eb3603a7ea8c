"""eigs.util.threads.set_threads: the budget reaches torch whether torch is loaded before or after, and a stage that
does not use torch does not load it."""

from __future__ import annotations

import subprocess
import sys

import pytest

from eigs.util.threads import set_threads


def _python(code: str) -> str:
    env = {"PATH": "/usr/bin:/bin"}  # no inherited OMP_NUM_THREADS
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    return proc.stdout.strip()


def test_torch_loaded_later_starts_with_the_budget():
    out = _python(
        "import sys; from eigs.util.threads import set_threads; r = set_threads(1); "
        "loaded = 'torch' in sys.modules; import torch; print(r, loaded, torch.get_num_threads())"
    )
    assert out == "1 False 1"


def test_torch_already_loaded_is_set_directly():
    out = _python("import torch; from eigs.util.threads import set_threads; before = torch.get_num_threads(); "
                  "print(set_threads(1), torch.get_num_threads(), before >= 1)")  # fmt: skip
    assert out == "1 1 True"


def test_a_torch_free_stage_does_not_load_torch(toy):
    """`eigs scene info --threads 1` (h5py and numpy only) leaves torch unloaded in its process."""
    out = _python(f"import sys; from eigs.cli import main; rc = main(['scene', 'info', {str(toy.scene)!r}, "
                  "'--threads', '1']); print(rc, 'torch' in sys.modules)")  # fmt: skip
    assert out.splitlines()[-1] == "0 False"


def test_invalid_budget():
    with pytest.raises(ValueError, match=">= 1"):
        set_threads(0)
