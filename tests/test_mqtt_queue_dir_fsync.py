"""A new segment of the MQTT store-and-forward queue keeps its name through a power cut: its
directory (and, made by the daemon, its parent) is fsynced after the segment is created, with
the segment's first fsync (it never
was: a strictly POSIX file system could lose the whole segment, against "a power cut loses at
most the last second"). ``cmsensord replay --publish`` runs under ``strace``."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from mosquitto import needs_mosquitto
from test_dir_fsync import TRACED, traced_calls
from test_mqtt import broker, mqtt_yaml  # noqa: F401 - broker: a fixture
from test_mqtt_runs import capture

STRACE = shutil.which("strace")
pytestmark = [needs_mosquitto, pytest.mark.skipif(STRACE is None, reason="strace is not installed")]


def test_a_new_queue_segment_is_fsynced_into_its_directory(tmp_path, broker):  # noqa: F811
    cfg = tmp_path / "site.yaml"
    cfg.write_text(mqtt_yaml(broker.port))
    trace, out = tmp_path / "strace.txt", tmp_path / "out"
    p = subprocess.run([STRACE, "-f", "-o", str(trace), "-e", TRACED, sys.executable, "-m",
                        "cmsensord", "replay", str(capture(tmp_path)), "--config", str(cfg), "--out", str(out),
                        "--publish"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    calls = traced_calls(trace, out / "mqtt-queue", ".seg")
    segment = next(c.removeprefix("create ") for c in calls if c.startswith("create "))
    assert "mkdir dir" in calls, calls
    lease = [i + 1 for i, c in enumerate(calls) if c == "rename seq-lease.tmp"]    # its own directory fsync
    own = [c for i, c in enumerate(calls)
           if c != "fsync parent" and not c.startswith("rename ") and i not in lease]  # out/'s, acked's, the lease's
    at = own.index(f"create {segment}")
    assert own[at:at + 3] == [f"create {segment}", f"fsync {segment}", "fsync dir"], calls
    synced = calls.index(f"fsync {segment}")
    assert "fsync parent" in calls[synced:calls.index("fsync dir", synced)], calls


def test_a_directory_fsync_that_fails_is_said_once_and_the_acknowledgements_are_still_saved(tmp_path, broker):  # noqa: F811
    """A file system that refuses to fsync a directory (EINVAL): the acked cursor was never
    written again, so the next run sent every message a second time."""
    cfg = tmp_path / "site.yaml"
    cfg.write_text(mqtt_yaml(broker.port))
    out = tmp_path / "out"
    code = ("import errno, sys\n"
            "import cmsensord.publish.disk_queue as q\n"
            "def refuse(path):\n"
            "    raise OSError(errno.EINVAL, 'Invalid argument')\n"
            "q.fsync_dir = refuse\n"
            "from cmsensord.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    p = subprocess.run([sys.executable, "-c", code, "replay", str(capture(tmp_path)), "--config", str(cfg),
                        "--out", str(out), "--publish"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    said = [ln for ln in p.stderr.splitlines() if " mqtt_queue: " in ln]
    assert said == [f"ERROR mqtt_queue: store-and-forward queue {out / 'mqtt-queue'}: cannot make it durable "
                    "(Invalid argument)"], p.stderr
    sent = int(p.stderr.split("  mqtt: ")[1].split(" message(s)")[0])
    assert sent > 50 and (out / "mqtt-queue" / "acked").read_text() == f"{sent}\n"
