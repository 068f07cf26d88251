"""The output directory's file system: the device and mount it was on when the run started,
and whether its path still leads there.

``output.dir`` on a file system of its own (a USB disk, a second SD partition) that goes away
while the daemon runs leaves its path on the file system under the mount point (the root one):
a directory made again there, with logs, lock and control socket, would fill the root file
system, be hidden by the next mount and be out of retention's sight. The sink and the daemon's
directory guard make nothing on another device than the one recorded at start
(:func:`place_of`): they wait for the directory to be back on it, or to be there on another
device mounted at the same place or deeper (the disk back under another device number, or
mounted after the run started), and make nothing meanwhile (:func:`off_device`).  The empty
mount point left by an unmount (``output.dir`` the mount point itself) is not the directory:
it is on the file system the mount hid.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import NamedTuple

__all__ = ["Place", "off_device", "place_of"]


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


class Place(NamedTuple):
    """Where a directory is: its file system's device and the mount point it is under."""
    device: int
    mount: Path


def _mount_of(at: Path, dev: int) -> Path:
    """The mount point of the file system (device ``dev``) that holds the existing path ``at``:
    the outermost of ``at`` and its parents on that device."""
    while at != at.parent:
        try:
            if os.stat(at.parent).st_dev != dev:
                break
        except OSError:
            break
        at = at.parent
    return at


def place_of(path: str | Path) -> Place | None:
    """The device and mount point of ``path``, or of its nearest existing parent (where
    ``mkdir -p`` makes it): None when they cannot be told."""
    found = _nearest(Path(path))
    return None if found is None else Place(found[1], _mount_of(*found))


def _name(dev: int) -> str:
    return f"{os.major(dev)}:{os.minor(dev)}"


def off_device(path: str | Path, place: Place | None) -> str | None:
    """None while ``path`` (or, absent, its nearest existing parent) is on ``place``'s device
    (or either cannot be told), or while the directory itself is there on another device
    mounted at ``place``'s mount point or deeper (a disk plugged back under another device
    number, or mounted after the run started: it holds the directory); else why not, a phrase
    for an event.  A directory on a file system mounted above ``place``'s (the one an unmount
    uncovered) is not taken."""
    found = _nearest(Path(path))
    if place is None or found is None or found[1] == place.device:
        return None
    at, dev = found
    if at != Path(os.path.abspath(path)):
        where = f"{at}: the directory is not there"
    else:
        mount = _mount_of(at, dev)
        if mount != place.mount and mount in place.mount.parents:
            where = f"{at}: on the file system under its mount point {place.mount}"
        else:
            return None
    return (f"not on its file system any more (device {_name(place.device)}; the path is now on device "
            f"{_name(dev)} ({where}): unmounted? a disk pulled?); nothing is made there, logging waits "
            "for it to be back")
