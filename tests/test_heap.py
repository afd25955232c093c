"""service.heap: glibc takes both thresholds (a refused value, e.g. an mmap threshold above its
limit, would leave every large temporary array mapped and unmapped again, call after call)."""

import platform

import pytest

from service.heap import keep_freed_memory


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc only")
def test_glibc_takes_both_thresholds():
    assert keep_freed_memory() is True

