"""Knowing a capture again after it was moved or renamed: its size and a digest of its ends.

``cmsensord calibrate`` writes, beside the capture's real path (``commissioned.capture``), its
size (``capture_bytes``) and the SHA-256 of its first and last :data:`END_BYTES` bytes
(``capture_ends_sha256``): two reads, however large the capture. A replay whose capture is not
at the commissioned path (:func:`commissioned_on`) is the commissioned capture when that path
no longer exists and the size and digest are the same; a site file without them (written by a
calibrate that did not write them) knows the capture by its path alone.
"""

from __future__ import annotations

import hashlib
import os

from cmsensord.config import CommissionedConfig

__all__ = ["END_BYTES", "capture_print", "commissioned_on"]

#: bytes read at each end of a capture for its digest (64 KiB: a board's first and last frames)
END_BYTES = 1 << 16


def capture_print(path: str) -> tuple[int, str]:
    """(size in bytes, SHA-256 hex of the first and last :data:`END_BYTES` bytes) of the file ``path``."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        digest.update(f.read(END_BYTES))
        if size > END_BYTES:
            f.seek(max(END_BYTES, size - END_BYTES))
            digest.update(f.read(END_BYTES))
    return size, digest.hexdigest()


def commissioned_on(path: str, learned: CommissionedConfig) -> tuple[bool, str]:
    """Whether ``learned`` (a site file's ``commissioned`` section) was commissioned on the capture
    at ``path``, and, when it was commissioned on a capture no longer found that this one is not
    known to be, why (a line); else an empty line."""
    real = os.path.realpath(path)
    if learned.capture is None or learned.capture == real:
        return learned.capture is not None, ""
    if os.path.exists(learned.capture):
        return False, ""                # another capture, still where it was
    gone = f"its commissioned capture {learned.capture} is not found"
    if learned.capture_bytes is None or learned.capture_ends_sha256 is None:
        return False, (f"{gone}, and the site file has no size and digest to know it moved by (if this "
                       f"is it: set commissioned.capture to {real}, or calibrate again)")
    try:
        size, digest = capture_print(path)
    except OSError:
        return False, f"{gone}, and this capture cannot be read to compare"
    if (size, digest) == (learned.capture_bytes, learned.capture_ends_sha256):
        return True, ""
    other = "another size" if size != learned.capture_bytes else "other first or last bytes"
    return False, f"{gone}, and {os.path.basename(path)} is not it ({other})"
