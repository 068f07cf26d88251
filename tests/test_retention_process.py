"""Retention through the commands a user types: the daemon (on a simulated board over a pty) in
a directory holding older logs of its prefix deletes them under ``retain_mb`` (a ``retention``
event), and one it cannot delete for a reason of its own (here a directory under a log's name)
is a ``retention_failed`` event and a journal line, said once, passed over for the next oldest,
and the run goes on. ``cmsensord replay`` or ``cmsensord --simulate`` into such a directory (the
service's, by its configuration) leaves every log it did not write alone, says so in one line,
and keeps its own under the limits."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord, daemon_on_short_board, run_module

OLD = "cmsensord-20200101T000000Z.mcap"      # the oldest name of the default prefix
NEWER = "cmsensord-20200102T000000Z.mcap"
CONFIG = "  rotate_mb: 1\n  retain_mb: 1\n  min_free_mb: 0\n"      # more of the daemon's output section


@pytest.fixture(scope="module")
def capture(tmp_path_factory) -> Path:
    """5 s of a healthy board's RMS frames."""
    cap = tmp_path_factory.mktemp("cap") / "cap.bin"
    r = run_module("firmware_sim", "--scenario", "healthy", "--duration", "5", "--out", str(cap))
    assert r.returncode == 0, r.stderr
    return cap


def daemon_into(tmp_path: Path) -> tuple[str, list[dict]]:
    """The daemon on a 3-s board into tmp_path/logs with a 1-MB cap: exit 0; (its stderr, the
    /cm/events messages of the log it wrote)."""
    out = tmp_path / "logs"
    _, err = daemon_on_short_board(tmp_path, config=CONFIG)
    new = [p for p in out.glob("cmsensord-*.mcap") if p.name not in (OLD, NEWER)]
    assert len(new) == 1, sorted(out.iterdir())                # the run's own log
    return err, [m for t, _, m in read_messages(new[0]) if t == "/cm/events"]


def plant(path: Path, mb: float) -> None:
    path.write_bytes(b"\0" * int(mb * 1_000_000))


def test_older_logs_over_retain_mb_are_deleted_with_one_event(tmp_path):
    out = tmp_path / "logs"
    out.mkdir()
    plant(out / OLD, 1.5)
    plant(out / NEWER, 0.2)
    other = out / "other-20200101T000000Z.mcap"         # another prefix's file: never counted
    plant(other, 1.5)
    _, events = daemon_into(tmp_path)
    assert not (out / OLD).exists() and (out / NEWER).exists() and other.exists()
    [ev] = [e for e in events if e["kind"] == "retention"]
    assert not [e for e in events if e["kind"] == "disk_error"]
    assert ev["message"].startswith(f"deleted the 1 oldest log file(s) (1.5 MB: {OLD}) "
                                    "to keep this prefix's files under retain_mb = 1 MB (now 0.2 MB)")


def test_a_log_retention_cannot_delete_is_one_event_passed_over_and_the_run_goes_on(tmp_path):
    out = tmp_path / "logs"
    (out / OLD).mkdir(parents=True)                       # a directory under a log's name: EISDIR
    (out / OLD / "kept").write_text("x")
    plant(out / NEWER, 1.5)
    err, events = daemon_into(tmp_path)
    message = f"{out / OLD}: retention cannot delete: Is a directory"
    assert f"ERROR disk_error: {message}" in err.splitlines()
    told = [e["message"] for e in events if e["kind"] in ("disk_error", "retention")]
    assert told[0] == message and len(told) == 2, told
    assert [e["kind"] for e in events if e["message"] in told] == ["disk_error", "retention"]
    assert re.fullmatch(rf"deleted the 1 oldest log file\(s\) \(1\.5 MB: {NEWER}\) to keep this "
                        r"prefix's files under retain_mb = 1 MB \(now [0-9.]+ MB, besides 0\.0 MB in 1 "
                        r"file\(s\) passed over\)( and at least min_free_mb = .*)?", told[1]), told[1]
    assert (out / OLD / "kept").exists() and not (out / NEWER).exists()   # the next oldest went
    assert "disk_error 1" in err and "retention 1" in err


def test_a_replay_into_the_services_directory_deletes_none_of_its_logs_and_says_so(tmp_path):
    """The service stopped, ``cmsensord replay CAP --config <its configuration>``: the service's
    logs are left alone, one line says so, and the replay keeps its own files under retain_mb (it
    rotates at 0.05 MB and deletes its oldest).  Guards against the replay's retention counting the
    service's logs with its own and deleting the oldest, saying nothing on the terminal (4 service
    logs gone for a replay's one)."""
    out = tmp_path / "logs"
    out.mkdir()
    service = [out / f"cmsensord-20200101T00000{i}Z.mcap" for i in range(4)]
    for path in service:
        plant(path, 0.2)
    cap = tmp_path / "cap.bin"
    assert run_module("firmware_sim", "--scenario", "healthy", "--channels", "8", "--duration", "600",
                      "--out", str(cap)).returncode == 0
    (tmp_path / "c.yaml").write_text(f"output:\n  dir: {out}\n  rotate_mb: 0.05\n  retain_mb: 0.15\n")
    r = cmsensord("replay", str(cap), "--config", str(tmp_path / "c.yaml"))
    assert r.returncode == 0, r.stderr
    assert r.stderr.splitlines()[0] == (
        f"WARNING retention: the 4 log(s) of prefix 'cmsensord' already in {out} are not this replay's: "
        "left alone; it counts and deletes only its own under retain_mb and min_free_mb")
    assert all(p.exists() for p in service)
    own = [p for p in out.glob("cmsensord-*.mcap") if p not in service]
    events = [m["message"] for p in own for t, _, m in read_messages(p) if t == "/cm/events"]
    assert any(m.startswith("deleted the 1 oldest log file(s)") and "to keep this run's files under "
               "retain_mb = 0.15 MB" in m for m in events), events
    assert 0 < sum(p.stat().st_size for p in own) < 0.3e6, own


def test_a_log_retention_keeps_failing_on_is_one_event_over_many_rotations(tmp_path):
    """The daemon on a board at 10x, rotating every few kB: each rotation's retention meets
    the same undeletable log, says so once, not once a rotation, and deletes the run's own
    older logs past it."""
    out = tmp_path / "logs"
    (out / OLD).mkdir(parents=True)
    _, err = daemon_on_short_board(tmp_path, config="  rotate_mb: 0.005\n  retain_mb: 0.005\n  min_free_mb: 0\n"
                                   "  flush_s: 0.1\n", board=("--duration", "20", "--speed", "10"))
    message = f"{out / OLD}: retention cannot delete: Is a directory"
    assert [line for line in err.splitlines() if "cannot delete" in line] == [f"ERROR disk_error: {message}"]
    deleted = re.findall(r"INFO retention: deleted the 1 oldest log file\(s\) \([0-9.]+ MB: "
                         r"(cmsensord-\S+\.mcap)\)", err)
    logs = sorted(p.name for p in out.glob("cmsensord-*.mcap") if p.name != OLD)
    assert len(deleted) >= 3 and not set(deleted) & set(logs), (deleted, logs)   # one a rotation
    assert len(logs) <= 2, logs                              # the cap held past the refusal
    assert (out / OLD).is_dir()


def test_a_simulated_board_into_the_services_directory_deletes_none_of_its_logs_and_says_so(tmp_path):
    """``cmsensord --simulate --config <the service's configuration>`` with the service stopped:
    the simulated run's retention leaves the service's logs alone (one line says so) and keeps
    its own files under retain_mb."""
    out = tmp_path / "logs"
    out.mkdir()
    service = [out / f"cmsensord-20200101T00000{i}Z.mcap" for i in range(4)]
    for path in service:
        plant(path, 0.2)
    (tmp_path / "c.yaml").write_text(f"output:\n  dir: {out}\n  rotate_mb: 0.01\n  retain_mb: 0.03\n"
                                     "  min_free_mb: 0\n  flush_s: 0.1\n")
    r = cmsensord("--simulate", "--duration", "20", "--speed", "10", "--channels", "4",
                  "--config", str(tmp_path / "c.yaml"))
    assert r.returncode == 0, r.stderr
    assert (f"WARNING retention: the 4 log(s) of prefix 'cmsensord' already in {out} are not this simulated "
            "run's: left alone; it counts and deletes only its own under retain_mb and min_free_mb"
            in r.stderr.splitlines()), r.stderr[-3000:]
    assert all(p.exists() for p in service)
    assert re.search(r"INFO retention: deleted the 1 oldest log file\(s\) .* to keep this run's "
                     r"files under retain_mb = 0\.03 MB", r.stderr), r.stderr[-3000:]
