"""Which compiled kernels this installation has, and what it means when one is missing.

Three optional C extensions are built by ``pip install`` when a C compiler is present
(``setup.py``): ``cmsensord.dsp._akfkernel`` (the AKF bank's per-sample loop),
``cmsensord.dsp._trackerkernel`` (the order tracker's loops) and ``cmsensord._wirekernel``
(the wire decoder's scan of a receive buffer, :mod:`cmsensord.wire_scan`). Without one the
identical Python/numpy implementation runs, slower. The daemon says so at start (one log
line) and in its status (:func:`fallback_note`).
"""

from __future__ import annotations

import importlib.util

__all__ = ["KERNELS", "missing_kernels", "fallback_note", "fallback_warning"]

#: module -> what it runs
KERNELS = {
    "cmsensord.dsp._akfkernel": "the AKF bank",
    "cmsensord.dsp._trackerkernel": "the order tracker",
    "cmsensord._wirekernel": "the wire decoder",
}


def missing_kernels() -> list[str]:
    """The kernel modules that are not built (importable), in :data:`KERNELS` order."""
    return [name for name in KERNELS if importlib.util.find_spec(name) is None]


def fallback_note() -> str:
    """A short note for the status line, or "" when every kernel is built."""
    missing = missing_kernels()
    return f"numpy fallback: no {', '.join(m.rsplit('.', 1)[1] for m in missing)}" if missing else ""


def fallback_warning() -> str | None:
    """The one start-up line naming the missing kernels, or None when all are built."""
    missing = missing_kernels()
    if not missing:
        return None
    what = ", ".join(f"{m} ({KERNELS[m]})" for m in missing)
    return (f"C kernel(s) not built: {what}; the numpy fallback runs instead (same results, the AKF "
            f"bank ~200x slower, the wire decoder 3-16x): install a C compiler and the Python headers "
            f"(apt install gcc python3-dev) and reinstall cmsensord")
