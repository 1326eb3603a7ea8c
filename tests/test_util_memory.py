"""eigs.util.memory: a step's large temporaries reuse the process's pages instead of faulting new ones
(keep_freed_memory), and large tensors lie on huge pages (use_huge_pages)."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

# The child allocates, touches and frees a tensor of SIZE bytes per round, alternating with one of 17.4 MB (an ADE
# activation at 17k Gaussians), and prints its minor page faults per round. SIZE is above the 32 MB that glibc's
# mmap threshold can ever reach, so with glibc's defaults the block is mmapped and unmapped every round, whatever
# the heap's history: every page faults again. Tuned, the heap still grows for the first rounds while glibc's bins
# settle (5-7 rounds of 10,240 faults here, glibc 2.36; the CI check once counted them in: 5,120 per round over
# 10), then stays put: the child warms up WARMUP rounds before it counts.
SIZE = 40 * 2**20
WARMUP = 30
CHILD = f"""
import resource, sys, torch
from eigs.util.memory import keep_freed_memory
tuned = keep_freed_memory() if sys.argv[1] == "1" else None
def faults():
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
def round_():  # torch.ones writes every page of its result
    torch.ones({SIZE} // 4)
    torch.ones(17_000, 256)
for _ in range({WARMUP}):
    round_()
f = faults()
for _ in range(10):
    round_()
print(tuned, (faults() - f) / 10)
"""
PAGES = SIZE // 4096  # 10,240 pages of 4 kB in the large tensor


def faults_per_round(tune: bool) -> tuple[str, float]:
    # on 4 kB pages: an eigs command run in this process (use_huge_pages) leaves THP_MEM_ALLOC_ENABLE=1 behind
    env = {**os.environ, "THP_MEM_ALLOC_ENABLE": "0"}
    out = subprocess.run([sys.executable, "-c", CHILD, "1" if tune else "0"], capture_output=True, text=True,
                         check=True, env=env).stdout.split()  # fmt: skip
    return out[0], float(out[1])


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc malloc only")
def test_freed_memory_is_reused_without_page_faults():
    _, before = faults_per_round(False)
    assert before >= 0.9 * PAGES, f"only {before:.0f} faults per round with glibc's defaults (expected ≥ {PAGES})"
    tuned, after = faults_per_round(True)
    assert tuned == "True"
    # measured (glibc 2.36): 13,640 faults per round with the defaults, 0 tuned once warm
    assert after <= 0.05 * before, f"{after:.0f} page faults per round tuned vs {before:.0f} with glibc's defaults"


THP = Path("/sys/kernel/mm/transparent_hugepage/enabled")
HUGE_CHILD = """
import sys
from pathlib import Path
from eigs.util.memory import keep_freed_memory, use_huge_pages
keep_freed_memory()
applies = use_huge_pages()
import torch
t = torch.ones(64 * 2**20 // 4)  # 64 MB, every page written
kb = [int(l.split()[1]) for l in open("/proc/self/smaps_rollup") if l.startswith("AnonHugePages:")][0]
print(applies, use_huge_pages(), kb)
"""


def huge_kb(env: dict[str, str]) -> tuple[str, str, int]:
    base = {k: v for k, v in os.environ.items() if k != "THP_MEM_ALLOC_ENABLE"}  # the variable only as given
    out = subprocess.run([sys.executable, "-c", HUGE_CHILD], capture_output=True, text=True, check=True,
                         env={**base, **env}).stdout.split()  # fmt: skip
    return out[0], out[1], int(out[2])


@pytest.mark.skipif(not THP.exists() or "[never]" in THP.read_text(), reason="no transparent huge pages (Linux only)")
def test_large_tensors_get_huge_pages_and_the_environment_can_say_no():
    """use_huge_pages before torch: a 64 MB tensor lies on 2 MB pages (also with keep_freed_memory's heap-only
    malloc); THP_MEM_ALLOC_ENABLE=0 in the environment keeps 4 kB pages (unless the kernel gives huge pages to every
    mapping); once torch is loaded the call says it no longer applies."""
    first, after_torch, kb = huge_kb({})
    assert (first, after_torch) == ("True", "False")
    assert kb >= 32 * 1024, f"only {kb} kB of the 64 MB tensor on huge pages"
    first, _, kb = huge_kb({"THP_MEM_ALLOC_ENABLE": "0"})
    assert first == "False"
    if "[always]" not in THP.read_text():
        assert kb == 0
