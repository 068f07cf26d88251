"""The output directory's file system: the device it was on when the run started, and whether
its path still leads there.

``output.dir`` on a file system of its own (a USB disk, a second SD partition) that goes away
while the daemon runs leaves its path on the file system under the mount point (the root one):
a directory made again there, with logs, lock and control socket, would fill the root file
system, be hidden by the next mount and be out of retention's sight. The sink and the daemon's
directory guard make nothing on another device than the one recorded at start
(:func:`device_of`): they wait for the directory to be back on it, or to be there on another
device (the disk back under another device number), and make nothing meanwhile
(:func:`off_device`).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["device_of", "off_device"]


def _nearest(path: Path) -> tuple[Path, int] | None:
    """The first of ``path`` and its parents that exists, and its device (None: none readable)."""
    at = Path(os.path.abspath(path))
    while True:
        try:
            return at, os.stat(at).st_dev
        except FileNotFoundError:
            if at == at.parent:
                return None
            at = at.parent
        except OSError:
            return None


def device_of(path: str | Path) -> int | None:
    """The device of ``path``, or of its nearest existing parent (where ``mkdir -p`` makes it):
    None when it cannot be told."""
    found = _nearest(Path(path))
    return None if found is None else found[1]


def _name(dev: int) -> str:
    return f"{os.major(dev)}:{os.minor(dev)}"


def off_device(path: str | Path, device: int | None) -> str | None:
    """None while ``path`` (or, absent, its nearest existing parent) is on ``device`` (or either
    cannot be told), or while the directory itself is there, on whatever device (a disk plugged
    back under another device number, or mounted after the run started: it holds the
    directory); else why not, a phrase for an event."""
    found = _nearest(Path(path))
    if device is None or found is None or found[1] == device:
        return None
    at, dev = found
    if at == Path(os.path.abspath(path)):
        return None
    where = "" if at == Path(os.path.abspath(path)) else f" ({at}: the directory is not there)"
    return (f"not on its file system any more (device {_name(device)}; the path is now on device "
            f"{_name(dev)}{where}: unmounted? a disk pulled?); nothing is made there, logging waits for "
            "it to be back")
