"""glibc's heap kept for ptwin's tensors. Below every room, beside ``threads.py``: the faces call it once their imports
are done, a map's engine before each spot it runs (a worker's first spot sets it for the rest; setting it again
changes nothing).

glibc maps an allocation above its mmap threshold anew and gives it back to the kernel when it is freed, and gives
back the heap's free top above its trim threshold; both thresholds start at 128 KiB and grow only as large blocks
come back. A fit makes and drops its tensors at every LM step (a power law's 43 modes × 8000 samples: 2.7 MB each),
so each was page-faulted again: the demo's power-law fit took 0.77–0.85 s, 0.54–0.69 s with the heap kept, and the
warm demo 6.53–7.14 s against 6.48–6.81 s (eight runs each, interleaved). Dask's nannies start their workers with
``MALLOC_TRIM_THRESHOLD_`` set, which also freezes the mmap threshold at 128 KiB: a third of a map spot's time was in
the kernel there until its worker kept the mmap threshold, and 48 spots on two workers took 36.7 and 37.4 s with the
trim threshold left at 64 KiB against 34.7 and 35.0 s with it kept too.
"""

from __future__ import annotations

import ctypes

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)
LARGEST_MMAP_THRESHOLD = 32 * 2**20  # glibc's DEFAULT_MMAP_THRESHOLD_MAX on a 64-bit machine [bytes]


def keep_heap() -> None:
    """Allocations up to 32 MiB from the heap, and up to 64 MiB free at its top kept there: the largest thresholds
    glibc's own adjustment would reach (the trim threshold twice the mmap one), from the start. The process holds at
    most that much memory it no longer uses. Without glibc: nothing."""
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:  # not glibc
        return
    libc.mallopt(M_MMAP_THRESHOLD, LARGEST_MMAP_THRESHOLD)
    libc.mallopt(M_TRIM_THRESHOLD, 2 * LARGEST_MMAP_THRESHOLD)
