"""Knowing a capture again after it was moved, renamed or appended to: its size and a digest of its ends.

``cmsensord calibrate`` writes, beside the capture's real path (``commissioned.capture``), its
size (``capture_bytes``) and the SHA-256 of its first and last :data:`END_BYTES` bytes
(``capture_ends_sha256``): two reads, however large the capture. A capture is the commissioned
one (:func:`commissioned_on`) when its first ``capture_bytes`` bytes give that digest: the same
file, or the same file grown since (a daemon's ``--capture`` appends to it while it runs), at
the commissioned path or, when that path no longer exists, anywhere else. Another capture
written to the commissioned path (``cmsensord record`` to the same name) is not it. A site file
without the size and digest (written by a calibrate that did not write them) knows the capture
by its path alone.
"""

from __future__ import annotations

import hashlib
import os

from cmsensord.config import CommissionedConfig

__all__ = ["END_BYTES", "capture_print", "commissioned_on"]

#: bytes read at each end of a capture for its digest (64 KiB: a board's first and last frames)
END_BYTES = 1 << 16


def capture_print(path: str, size: int | None = None) -> tuple[int, str]:
    """(size in bytes, SHA-256 hex of the first and last :data:`END_BYTES` bytes) of the file
    ``path``, or of its first ``size`` bytes (the file may be longer: bytes appended after them
    are not read); a file shorter than ``size`` gives its own size and the digest of what it has."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        have = os.fstat(f.fileno()).st_size
        size = have if size is None else min(size, have)
        digest.update(f.read(min(size, END_BYTES)))
        if size > END_BYTES:
            at = max(END_BYTES, size - END_BYTES)
            f.seek(at)
            digest.update(f.read(size - at))
    return size, digest.hexdigest()


def commissioned_on(path: str, learned: CommissionedConfig) -> tuple[bool, str]:
    """Whether ``learned`` (a site file's ``commissioned`` section) was commissioned on the capture
    at ``path`` (or on its first bytes, the capture appended to since), and, when it was
    commissioned on a capture that this one is not known to be (no longer found, or another
    capture at its path), why (a line); else an empty line."""
    real = os.path.realpath(path)
    if learned.capture is None:
        return False, ""
    if learned.capture_bytes is None or learned.capture_ends_sha256 is None:
        if learned.capture == real:
            return True, ""
        if os.path.exists(learned.capture):
            return False, ""            # another capture, still where it was
        return False, (f"its commissioned capture {learned.capture} is not found, and the site file has no size "
                       f"and digest to know it moved by (if this is it: set commissioned.capture to {real}, or "
                       "calibrate again)")
    if learned.capture != real and os.path.exists(learned.capture):
        return False, ""                # another capture, the commissioned one still where it was
    try:
        size, digest = capture_print(path, learned.capture_bytes)
    except OSError:
        size, digest = -1, ""
    if (size, digest) == (learned.capture_bytes, learned.capture_ends_sha256):
        return True, ""
    name = os.path.basename(path)
    why = ("cannot be read to compare" if size < 0 else "shorter" if size < learned.capture_bytes
           else "other first or last bytes")
    if learned.capture == real:
        return False, (f"{name}, at the commissioned path, is not the capture calibrate read ({why}): a capture "
                       "written again to that name? calibrate again on it")
    return False, (f"its commissioned capture {learned.capture} is not found, and "
                   + (f"{name} {why}" if size < 0 else f"{name} is not it ({why})"))
