"""One daemon per output directory: a second ``cmsensord`` on the same configuration (started
by hand beside the service, say) would read the same port, splitting its bytes between the two
(each then loses frames), salvage the first one's open ``.part`` file as if left by a crash, and
share its MQTT queue and client id.

:func:`claim_output_dir` takes an exclusive, non-blocking ``flock`` on ``output.dir/.cmsensord.lock``
(it writes its pid there); the lock goes with the process, however it ends. A directory another
daemon holds is a one-line :class:`~cmsensord.errors.InstanceError` (exit 78: systemd does not
restart it) naming that daemon's pid.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path

from cmsensord.errors import InstanceError
from cmsensord.sinks.mcap_file import fsync_dir, make_dirs

__all__ = ["LOCK_NAME", "claim_output_dir", "refuse_if_held"]

LOCK_NAME = ".cmsensord.lock"


def claim_output_dir(directory: str | Path) -> int | None:
    """The descriptor holding ``directory``'s lock (keep it open while the daemon runs), or None
    when the directory cannot be made or the lock file written (the sink then says why, in its
    own words); InstanceError when another process holds it."""
    path = Path(directory) / LOCK_NAME
    try:
        for new in make_dirs(Path(directory)):     # its name durable in its parent (a failure: the
            with contextlib.suppress(OSError):     # sink's own directory fsync says so)
                fsync_dir(new.parent)
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        pid = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
        os.close(fd)
        raise InstanceError(f"{directory}: another cmsensord (pid {pid}) writes its logs here; stop it first "
                        "(systemctl stop cmsensord), or give this one another output.dir") from None
    try:                                # the pid, for the refusal's line: a full disk keeps the old one
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    except OSError:
        pass
    return fd


def refuse_if_held(directory: str | Path, command: str) -> None:
    """InstanceError when a daemon holds ``directory``: its logs, their retention and salvage,
    its alarm state and its MQTT queue are that daemon's, and ``command`` (a replay) must write
    elsewhere. Checked (a shared lock tried and let go), not kept."""
    try:
        fd = os.open(Path(directory) / LOCK_NAME, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        pid = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
        raise InstanceError(f"{directory}: the running cmsensord (pid {pid}) writes its logs here; give "
                            f"{command} another directory (--out DIR)") from None
    finally:
        os.close(fd)
