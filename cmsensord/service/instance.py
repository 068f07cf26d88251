"""One writer per output directory: a second ``cmsensord`` on the same configuration (started
by hand beside the service, say) would read the same port, splitting its bytes between the two
(each then loses frames), salvage the first one's open ``.part`` file as if left by a crash, and
share its MQTT queue and client id; a replay writing there meanwhile would mix its logs with the
daemon's.

:func:`claim_output_dir` (the daemon) and :func:`hold_output_dir` (a replay, ``vkf``) take an
exclusive, non-blocking ``flock`` on ``output.dir/.cmsensord.lock`` (writing their pid there) and
keep it while they write; the lock goes with the process, however it ends. A directory another
process holds is a one-line :class:`~cmsensord.errors.InstanceError` (exit 78: systemd does not
restart it) naming that process's pid. :class:`HeldDir` takes the lock again when its file is
removed under the daemon (the directory deleted).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path

from cmsensord.errors import InstanceError
from cmsensord.sinks.mcap_file import fsync_dir, make_dirs

__all__ = ["LOCK_NAME", "HeldDir", "claim_output_dir", "hold_output_dir"]

LOCK_NAME = ".cmsensord.lock"


def _take(directory: str | Path) -> tuple[int | None, str | None, bool]:
    """(the descriptor holding ``directory``'s lock, None, whether this call made the lock file);
    (None, the holder's pid, False) when another process holds it; (None, None, False) when the
    directory cannot be made or the lock file written."""
    path = Path(directory) / LOCK_NAME
    try:
        for new in make_dirs(Path(directory)):     # its name durable in its parent (a failure: the
            with contextlib.suppress(OSError):     # sink's own directory fsync says so)
                fsync_dir(new.parent)
        try:
            fd, made = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644), True
        except FileExistsError:
            fd, made = os.open(path, os.O_RDWR | os.O_CLOEXEC), False
    except OSError:
        return None, None, False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        pid = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
        os.close(fd)
        return None, pid, False
    try:                                # the pid, for the refusal's line: a full disk keeps the old one
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    except OSError:
        pass
    return fd, None, made


def claim_output_dir(directory: str | Path) -> int | None:
    """The daemon's: the descriptor holding ``directory``'s lock (keep it open while the daemon
    runs), or None when the directory cannot be made or the lock file written (the sink then says
    why, in its own words); InstanceError when another process holds it."""
    fd, pid, _ = _take(directory)
    if pid is not None:
        raise InstanceError(f"{directory}: another cmsensord (pid {pid}) writes its logs here; stop it first "
                            "(systemctl stop cmsensord), or give this one another output.dir")
    return fd


def hold_output_dir(directory: str | Path, command: str) -> HeldDir | None:
    """``command``'s (a replay, ``vkf``): as :func:`claim_output_dir`, held while it writes (a
    daemon started meanwhile is refused) until its ``close``, which removes the lock file if
    this call made it (a new directory is left with the logs alone); InstanceError when a daemon
    (or another replay) holds it: its logs, their retention and salvage, its alarm state and
    its MQTT queue are that process's, and ``command`` must write elsewhere."""
    fd, pid, made = _take(directory)
    if pid is not None:
        raise InstanceError(f"{directory}: the running cmsensord (pid {pid}) writes its logs here; give "
                            f"{command} another directory (--out DIR)")
    return HeldDir(directory, fd, made=made) if fd is not None else None


def _ident(st: os.stat_result) -> tuple[int, int]:
    return st.st_dev, st.st_ino


class HeldDir:
    """The daemon's lock of its output directory, kept while its file is there: the directory
    deleted (or the lock file alone), :meth:`retake` locks the new file of the same name; the
    old inode's lock held no one off."""

    def __init__(self, directory: str | Path, fd: int, *, made: bool = False):
        self.dir = Path(directory)
        self.fd = fd
        self.made = made                # close removes the lock file (a replay made it)
        self._ident = _ident(os.fstat(fd))

    def gone(self) -> bool:
        """Whether the lock file is no longer the one held (removed, or replaced): one stat."""
        try:
            return _ident(os.stat(self.dir / LOCK_NAME)) != self._ident
        except FileNotFoundError:
            return True
        except OSError:
            return False                # not known to be gone (a permission error): kept

    def retake(self) -> str | None:
        """Lock the lock file of the directory (made again if need be) instead of the one held:
        None when it is held now; else why not (another process holds it: its pid; the directory
        or the file cannot be made), the old descriptor kept and :meth:`gone` still true."""
        fd, pid, _ = _take(self.dir)
        if fd is None:
            return f"cmsensord (pid {pid}) holds it" if pid is not None else "it cannot be made"
        os.close(self.fd)
        self.fd, self._ident = fd, _ident(os.fstat(fd))
        return None

    def close(self) -> None:
        """Let the lock go; with ``made``, its file removed first (while held, and if it is still
        the one held)."""
        if self.made and not self.gone():
            with contextlib.suppress(OSError):
                (self.dir / LOCK_NAME).unlink()
        os.close(self.fd)
