"""service/heap.py: a batch command's heap keeps the memory it frees (glibc's mallopt)."""

from __future__ import annotations

import platform

from cmsensord.service.heap import keep_freed_memory


def test_the_thresholds_are_taken_by_glibc_and_refused_quietly_elsewhere():
    """glibc takes both thresholds (mallopt returns 1 for each); another C library either
    has no mallopt or refuses them: False, and nothing raised."""
    assert keep_freed_memory() is (platform.libc_ver()[0] == "glibc")
    assert keep_freed_memory() is keep_freed_memory()            # setting them again: the same
