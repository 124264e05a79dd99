"""glibc's allocator in worker processes: keep freed image-sized blocks for reuse.

Dask's nanny starts its workers with ``MALLOC_TRIM_THRESHOLD_=65536`` (its
``distributed.nanny.pre-spawn-environ``, to hand memory back to the system). Setting any
malloc threshold turns off glibc's dynamic mmap threshold, so every array over 128 kB — a
fit allocates several image-sized ones per evaluation — is mapped fresh from the kernel and
unmapped on free: each use pays its page faults again. Measured on walk frame 12 (2 cores,
the same run, ms per evaluation at full / half resolution): 6.0 / 4.2 ms in a plain process,
9.8 / 6.1 ms with the nanny's setting, 5.7 / 4.2 ms with it and :func:`keep_large_blocks`.
That was most of why a frame took ~1.5× longer in a Dask worker than in a local one.
"""

from __future__ import annotations

import ctypes
import sys

__all__ = ["keep_large_blocks", "MMAP_THRESHOLD", "TRIM_THRESHOLD"]

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: Blocks below this come from the heap and are reused after free (glibc's dynamic
#: threshold grows to at most 32 MB on 64-bit systems, the same figure).
MMAP_THRESHOLD = 32 << 20
#: Free memory at the top of the heap kept rather than returned to the system.
TRIM_THRESHOLD = 64 << 20


def keep_large_blocks() -> bool:
    """Make this process keep freed blocks up to :data:`MMAP_THRESHOLD` for reuse (glibc
    ``mallopt``); True when applied, False where there is no glibc (nothing to change)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # pragma: no cover - musl or another libc
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
