"""Freed image-sized blocks are reused in worker processes, whatever malloc setting the
process was started with (a Dask nanny's ``MALLOC_TRIM_THRESHOLD_``)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc mallopt is Linux-only")

# 200 allocate/touch/free cycles of a 2 MiB array; prints the minor page faults they cost
_CYCLES = """
import resource, sys
import numpy as np
if sys.argv[1] == "keep":
    from studio.allocator import keep_large_blocks
    assert keep_large_blocks()
elif sys.argv[1] == "worker":
    from studio.execution import worker_setup
    worker_setup(die_with_parent=False)
np.ones(1 << 18)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(200):
    a = np.ones(1 << 18)  # 2 MiB
    del a
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str, env: dict) -> int:
    # (a Dask nanny started earlier in this process leaves its setting in os.environ)
    base = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    out = subprocess.run([sys.executable, "-c", _CYCLES, mode], env={**base, **env},
                         capture_output=True, text=True, check=True, cwd=os.getcwd())
    return int(out.stdout.split()[-1])


def test_a_trim_threshold_makes_every_large_array_fault_again_until_kept():
    nanny = {"MALLOC_TRIM_THRESHOLD_": "65536"}
    # 200 fresh mappings of 512 pages each: every cycle faults its pages in again
    assert _faults("plain", nanny) >= 200 * 512 * 0.9
    # kept in the heap: the first cycle's pages serve all the others
    assert _faults("keep", nanny) < 2 * 512
    assert _faults("worker", nanny) < 2 * 512
    # glibc's own dynamic threshold without the setting: reused as well (what the fix restores)
    assert _faults("plain", {}) < 2 * 512
