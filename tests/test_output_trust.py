"""What the daemon finds in its output directory is not trusted: a damaged ``.part`` is
salvaged around the damage and kept, a FIFO or a planted symbolic link is never opened
through, a long salvage never delays start-up nor holds a stop, retention keeps the history
when the free-space floor is out of reach, and ``--simulate`` never imports from the
working directory. Each case: one planted file, a real daemon process, the exact journal
line and what is left on disk."""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

from cmsensord.sinks.mcap_read import read_messages
from cmsensord.sinks.mcap_sink import McapSink
from fakes import FakeClock
from processes import ENV, ROOT, board_on_pty, daemon_on_short_board, start_daemon, stop

T0 = 1_700_000_000_000_000_000
STEM = "cmsensord-20231114T221320Z"
# the daemon run as an installed one is: the working directory is not on sys.path
SAFE_ENV = dict(ENV, PYTHONPATH=str(ROOT))


def _part(tmp_path: Path, n: int = 40) -> tuple[bytes, list[tuple[int, int, int]]]:
    """A ``.part`` as a kill leaves it (uncompressed chunks of 4 messages on one topic, all
    flushed), and its chunks as (start, end, messages), from mcap's reader of the same
    file finished."""
    clock = FakeClock()
    sink = McapSink(tmp_path / "src", compression="none", clock=clock, flush_s=1.0,
                    wall_clock=lambda: 1_700_000_000.0)
    for k in range(n):
        sink.write("/cm/ch0/severity", "severity", T0 + k * 10**9, {"severity_index": k / n})
        clock.t += 0.25
    sink.flush()
    data = sink.part_path.read_bytes()
    summary = make_reader(io.BytesIO(sink.close().read_bytes())).get_summary()
    assert summary is not None
    # one message a second: a chunk's messages from its time range
    chunks = [(ci.chunk_start_offset, ci.chunk_start_offset + ci.chunk_length,
               (ci.message_end_time - ci.message_start_time) // 10**9 + 1)
              for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)]
    assert sum(m for _a, _b, m in chunks) == n and len(chunks) >= 5
    return data, chunks


def _simulate(tmp_path: Path, *extra: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``cmsensord --simulate`` for 3 s of board time at 20x into tmp_path/logs."""
    return subprocess.run([sys.executable, "-P", "-m", "cmsensord", "--simulate", "--duration", "3",
                           "--speed", "20", "--out", str(tmp_path / "logs"), *extra],
                          capture_output=True, text=True, env=SAFE_ENV, timeout=60,
                          cwd=cwd or tmp_path)


def _lines(stderr: str, kind: str) -> list[str]:
    return [line for line in stderr.splitlines() if f" {kind}: " in line]


def test_a_damaged_chunk_is_skipped_every_intact_one_kept_and_the_source_kept(tmp_path):
    data, chunks = _part(tmp_path)
    start, end, lost = chunks[1]
    bad = bytearray(data)
    bad[end - 20] ^= 0x01                          # one bit of a message in chunk 2: CRC fails
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / f"{STEM}.mcap.part").write_bytes(bytes(bad))
    run = _simulate(tmp_path)
    assert run.returncode == 0, run.stderr
    kept = 40 - lost
    assert _lines(run.stderr, "salvage") == [
        f"INFO salvage: {STEM}.mcap.part: salvaged {kept} message(s) from {len(chunks) - 1} "
        f"complete chunk(s) into {STEM}.salvaged.mcap; 1 damaged chunk(s) skipped, {lost} "
        f"message(s) known lost (damaged chunk at byte {start}: chunk CRC mismatch); source kept "
        f"as {STEM}.mcap.part.damaged"]
    got = [t for _topic, t, _m in read_messages(logs / f"{STEM}.salvaged.mcap")]
    first = chunks[0][2]
    assert got == [T0 + k * 10**9 for k in range(40) if not first <= k < first + lost]
    assert (logs / f"{STEM}.mcap.part.damaged").read_bytes() == bytes(bad)
    assert not (logs / f"{STEM}.mcap.part").exists()


def test_a_fifo_named_like_a_part_is_skipped_and_start_up_goes_on(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    fifo = logs / f"{STEM}.mcap.part"
    os.mkfifo(fifo)
    run = _simulate(tmp_path)                      # would block for ever opening the FIFO
    assert run.returncode == 0, run.stderr
    assert _lines(run.stderr, "salvage") == [
        f"INFO salvage: {STEM}.mcap.part: a FIFO, not a regular file; skipped"]
    assert fifo.is_fifo()
    assert len(list(logs.glob("cmsensord-2*Z.mcap"))) == 1     # the run's own log


def test_a_planted_symlink_as_the_salvage_tmp_file_is_never_followed(tmp_path):
    data, chunks = _part(tmp_path)
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / f"{STEM}.mcap.part").write_bytes(data)
    target = tmp_path / "root-only.conf"
    target.write_text("do not truncate\n")
    tmp_link = logs / f"{STEM}.salvaged.mcap.tmp"
    tmp_link.symlink_to(target)
    run = _simulate(tmp_path)
    assert run.returncode == 0, run.stderr
    assert _lines(run.stderr, "salvage") == [
        f"INFO salvage: {STEM}.mcap.part: salvaged 40 message(s) from {len(chunks)} complete "
        f"chunk(s) into {STEM}.salvaged.mcap"]
    assert target.read_text() == "do not truncate\n"
    salvaged = logs / f"{STEM}.salvaged.mcap"
    assert not salvaged.is_symlink() and len(read_messages(salvaged)) == 40
    assert not tmp_link.exists() and not tmp_link.is_symlink()


def test_simulate_never_imports_from_the_working_directory(tmp_path):
    (tmp_path / "numpy.py").write_text(
        "open('PLANTED_NUMPY_IMPORTED', 'w').close()\nraise ImportError('planted numpy.py')\n")
    run = _simulate(tmp_path, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "simulated board (degrading, RMS mode, 1 channel(s), seed 0) on /dev/" in run.stderr
    assert not (tmp_path / "PLANTED_NUMPY_IMPORTED").exists()
    assert len(list((tmp_path / "logs").glob("cmsensord-2*Z.mcap"))) == 1


def test_an_unreachable_free_space_floor_keeps_the_history_and_says_so(tmp_path):
    logs = tmp_path / "logs"
    McapSink(logs, wall_clock=lambda: 1_577_836_800.0).close()
    old = logs / "cmsensord-20200101T000000Z.mcap"
    assert old.exists()
    _, err = daemon_on_short_board(tmp_path, config="  min_free_mb: 1000000000\n")
    (line,) = _lines(err, "disk_error")
    assert re.fullmatch(
        rf"ERROR disk_error: {re.escape(str(logs))}: [0-9.]+ MB free, below min_free_mb = "
        r"1e\+09 MB, which deleting the 0 older finished log\(s\) of prefix 'cmsensord' "
        r"\(0.0 MB; never the newest\) cannot reach: none deleted for it", line), line
    assert old.exists()


def test_sigterm_stops_a_long_salvage_and_leaves_the_part_as_it_was(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    data, _chunks = _part(tmp_path)
    part = logs / f"{STEM}.mcap.part"
    # intact chunks, then 20 MB of bytes that each look like the start of a chunk record:
    # the scan for the next intact chunk after them takes many seconds
    part.write_bytes(data + b"\x06" * 20_000_000)
    with board_on_pty("--scenario", "healthy", "--duration", "600") as port:
        daemon = start_daemon(tmp_path, port)
        lines = []
        for line in daemon.stderr:                 # READY: the run has started
            lines.append(line)
            if " start: " in line:
                break
        err = "".join(lines) + stop(daemon, timeout=30)
    assert daemon.returncode == 0, err
    assert f"INFO {STEM}.mcap.part: salvage interrupted by stop; left for the next start" in \
        err.splitlines()
    assert part.read_bytes() == data + b"\x06" * 20_000_000
    assert not list(logs.glob("*.tmp")) and not list(logs.glob("*.salvaged.mcap"))
