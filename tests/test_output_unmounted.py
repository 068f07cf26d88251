"""``output.dir`` on a file system of its own (a USB disk) unmounted while the daemon runs: the
daemon makes nothing on the file system under the mount point (no directory, log, lock file or
control socket there, hidden by the next mount and out of retention's sight). It is a disk
outage, said in one ``disk_error`` line, the open file kept for salvage, a new file tried every
``retry_s``; once the file system is back at its place, logging resumes there and the file kept
is salvaged.

A real daemon on a simulated board over a pty; the file system a tmpfs bind-mounted at the
output directory's parent, unmounted (``umount -l``: the daemon's open files stay on it) and
bind-mounted again (the same device), or a new tmpfs with a copy of its files (another device).
Root only (mounts), skipped elsewhere; ``.ci/run`` is root.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from processes import spawn, start_board, stop


def _mount(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["mount", *args], capture_output=True, text=True, timeout=10)


def _umount(path: Path) -> None:
    subprocess.run(["umount", "-l", str(path)], capture_output=True, timeout=10)


@pytest.fixture
def disk(tmp_path):
    """(the file system's own root, its mount point): a tmpfs at tmp_path/store bind-mounted at
    tmp_path/usb; both unmounted at the end, whatever happened."""
    if os.geteuid() != 0:
        pytest.skip("mounts need root")
    store, usb = tmp_path / "store", tmp_path / "usb"
    store.mkdir()
    usb.mkdir()
    try:
        r = _mount("-t", "tmpfs", "-o", "size=16m", "tmpfs", str(store))
    except FileNotFoundError:
        pytest.skip("no mount command")
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        r = _mount("--bind", str(store), str(usb))
        if r.returncode != 0:
            pytest.skip(f"cannot bind-mount here: {r.stderr.strip()}")
        yield store, usb
    finally:
        _umount(usb)
        _umount(usb)
        _umount(store)


@pytest.mark.parametrize("back, sub", [("same", "logs"), ("another", "logs"), ("another", "")])
def test_an_unmounted_log_file_system_is_an_outage_nothing_is_made_under_it(disk, tmp_path, back, sub):
    """``back``: the file system comes back at its place on its device (bound again), or on
    another device holding its files (a disk re-plugged under another device number: a new
    tmpfs with a copy of them).  ``sub``: ``output.dir`` in a directory of the file system, or
    (``""``) its mount point itself, whose empty directory an unmount leaves on the root file
    system."""
    store, usb = disk
    logs, link = usb / sub if sub else usb, tmp_path / "ttyBOARD"
    board = start_board("--scenario", "healthy", "--speed", "5", "--link", str(link), "--flow-control")
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {link}\n  max_drift_s: 0\noutput:\n  dir: {logs}\n  status_line: false\n"
                   "  retry_s: 1\n  retain_mb: 0\n  min_free_mb: 0\n")
    daemon = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(4.0)
        assert list(logs.glob("*.mcap.part")), "no log file on the disk"
        _umount(usb)                                       # the disk goes away
        time.sleep(4.0)                                    # retry_s 1; the guard looks every 2 s
        under = sorted(p.name for p in usb.iterdir())      # the root file system under the mount point
        if back == "same":
            assert _mount("--bind", str(store), str(usb)).returncode == 0
        else:
            assert _mount("-t", "tmpfs", "-o", "size=16m", "tmpfs", str(usb)).returncode == 0
            subprocess.run(["cp", "-a", f"{store}/.", str(usb)], check=True, timeout=10)
            store = usb                                    # where the files are from now on
        time.sleep(4.0)
        err = stop(daemon, timeout=30)
    finally:
        board.terminate()
        board.wait(timeout=5)
    assert daemon.returncode == 0 and "Traceback" not in err, err[-3000:]
    assert under == [], under
    lines = err.splitlines()
    errors = [line for line in lines if line.startswith("ERROR")]
    gone = (re.escape(f"{logs}: not on its file system any more (device ")
            + r"\d+:\d+; the path is now on device \d+:\d+ \("
            + re.escape(f"{usb}: " + ("the directory is not there" if sub else f"on the file system under its "
                                      f"mount point {usb}") + "): unmounted? a disk pulled?); nothing is made "
                        "there, logging waits for it to be back"))
    assert len(errors) == 1 and re.fullmatch(
        rf"ERROR disk_error: {gone}; file kept as cmsensord-\S+\.mcap\.part for salvage; \d+ message\(s\) lost; "
        r"trying a new file at once, then every 1 s", errors[0]), errors
    assert [line for line in lines if re.fullmatch(
        rf"WARNING disk_error: {gone}; its lock file and control socket too \(cmsensord status, ack and "
        r"capture-now cannot reach this daemon meanwhile\)", line)], lines[-30:]
    assert not [line for line in lines if "removed while open" in line]
    taken = [line for line in lines if "taken again" in line]      # the lock and socket on the other device
    assert len(taken) == (back == "another"), taken
    resumed = [line for line in lines if line.startswith("INFO disk_error: logging resumed in cmsensord-")]
    assert len(resumed) == 1, lines[-30:]
    assert [line for line in lines if re.match(r"INFO salvage: .*cmsensord-\S+\.mcap\.part", line)], lines[-30:]
    names = sorted(p.name for p in (store / sub).iterdir() if not p.name.startswith("."))
    assert not [n for n in names if n.endswith(".part")], names
    assert [n for n in names if n.endswith(".salvaged.mcap")] and len(names) >= 2, names
    _umount(usb)
    assert sorted(p.name for p in usb.iterdir()) == []     # nothing was made under it meanwhile
