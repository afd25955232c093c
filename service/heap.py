"""The heap of a process that runs the stability engine (glibc): freed memory is kept for the
next temporary array instead of going back to the system.

glibc maps every block above M_MMAP_THRESHOLD on its own and gives memory at the top of the heap
back above M_TRIM_THRESHOLD; both start at 128 KiB and rise only once a large mapped block has
been freed. The engine's temporaries (a batch of segment exponentials, 0.2-2 MB) were then
mapped, zero-filled by the kernel page by page on first touch and unmapped again, call after
call: the issue-17 pose at one speed took 52-56 ms in a fresh process and 45 ms with the heap
kept (its matrix exponentials 2.4x faster). The CLI keeps it from its start, the schedule service's
spawned workers from theirs, Dask sweep workers (local or a scheduler's) from a worker plugin
(`service.sweep.runner`). A library user's own process can call `keep_freed_memory` too.
Elsewhere than glibc nothing changes."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

#: Freed memory at the top of the heap that is kept (glibc's M_TRIM_THRESHOLD): the process stays
#: at its peak instead of shrinking after it.
TRIM_THRESHOLD_BYTES = 1 << 30
#: Blocks up to this size come from the heap, larger ones are mapped (M_MMAP_THRESHOLD): the
#: 300-speed lobes' batches (30-40 MB) too (8.8 s in one process, 7.5-8.0 s with them kept, 8.0 s
#: with 32 MiB).
MMAP_THRESHOLD_BYTES = 1 << 28

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3


@functools.cache
def keep_freed_memory() -> bool:
    """Set this process's trim and mmap thresholds (above), once; True where glibc took both."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):  # no C library by that name, or no mallopt (not glibc)
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)) & bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))
