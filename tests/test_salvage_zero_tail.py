"""A power cut can leave a ``.part`` longer than what was written to it: the file system had
extended the file (its size on disk) but not its data, which reads back as zero bytes to the end.
That is a cut, as a file ending inside a record is: salvage drops the zeros and says so, and
keeps no ``.damaged`` copy (it kept one as big as the whole file, forever). The copies salvage
does keep (``.damaged``, ``.unreadable``) count in ``retain_mb`` and are deleted oldest first,
as the logs are (retention never saw them, and deleted real logs in their place).

The daemon on a simulated board (a pty), killed with SIGKILL, its ``.part`` then given the
zero tail (``truncate``, or zeros written over the end of its last chunk), and started again.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.opcode import Opcode

from cmsensord.sinks.mcap_records import RecordWalker
from cmsensord.sinks.mcap_salvage import salvage
from cmsensord.sinks.mcap_sink import log_files
from processes import ENV, board_on_pty, cmsensord, daemon_on_short_board, spawn, stop

pytestmark = pytest.mark.process
SIZE = 3_000_000      # the .part's size after the power cut
HOW = "as a file system leaves a file extended past its last write by a power cut"


def killed_part(tmp_path: Path, port: str) -> tuple[Path, Path]:
    """The daemon's config (logs in tmp_path/logs) and the ``.part`` it left when killed with
    SIGKILL after 6 s of AKF trace."""
    cfg = tmp_path / "cmsensord.yaml"
    cfg.write_text(f"link:\n  port: {port}\n  max_drift_s: 0\noutput:\n  dir: {tmp_path / 'logs'}\n"
                   "  status_line: false\n  akf_trace: true\n  rotate_mb: 0.2\n  retain_mb: 1\n  min_free_mb: 0\n")
    d = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.DEVNULL,
              stdout=subprocess.DEVNULL, env=ENV)
    time.sleep(6.0)
    d.send_signal(signal.SIGKILL)
    d.wait(timeout=10)
    _finished, parts = log_files(tmp_path / "logs", "cmsensord")
    assert len(parts) == 1
    return cfg, parts[0]


def salvaged_up_to(part: Path, end: int, scratch: Path) -> tuple[int, int, int]:
    """(messages, chunks, good bytes) salvage finds in the first ``end`` bytes of ``part``."""
    scratch.mkdir()
    copy = scratch / part.name
    copy.write_bytes(part.read_bytes()[:end])
    r = salvage(copy, durable=False)
    return r.messages, r.chunks, r.source_bytes - r.dropped_bytes


def restart(cfg: Path) -> list[str]:
    """The daemon started again for 4 s (it salvages the .part at start): its journal lines."""
    d = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)], stderr=subprocess.PIPE,
              stdout=subprocess.DEVNULL, text=True, env=ENV)
    time.sleep(4.0)
    err = stop(d)
    assert d.returncode == 0, err[-3000:]
    return err.splitlines()


def zeros_from(path: Path) -> int:
    return len(path.read_bytes().rstrip(b"\0"))


def test_a_zero_tail_after_the_last_record_is_a_cut_and_no_damaged_copy_is_kept(tmp_path):
    with board_on_pty("--scenario", "healthy") as port:
        cfg, part = killed_part(tmp_path, port)
        n, chunks, good = salvaged_up_to(part, part.stat().st_size, tmp_path / "scratch")
        subprocess.run(["truncate", "-s", str(SIZE), str(part)], check=True)
        zeros = zeros_from(part)
        lines = restart(cfg)
    where = "all zero bytes" if zeros <= good else f"zero bytes from byte {zeros} on, inside the chunk at byte {good}"
    stem = part.name.removesuffix(".mcap.part")
    assert (f"INFO salvage: {part.name}: salvaged {n} message(s) from {chunks} complete chunk(s) into "
            f"{stem}.salvaged.mcap; {SIZE - good} byte(s) after them dropped (a cut: {where}, {HOW})") in lines, \
        "\n".join(lines)[-3000:]
    assert sorted(p.name for p in part.parent.iterdir() if ".part" in p.name) == []


def test_zero_blocks_over_the_end_of_the_last_chunk_are_a_cut_too(tmp_path):
    """A write half on disk: its chunk's second half and everything after it zeros (the newest
    chunk of more than 1 kB: the one the kill left last may be a small one)."""
    with board_on_pty("--scenario", "healthy") as port:
        cfg, part = killed_part(tmp_path, port)
        with open(part, "rb") as f:
            chunks_at = [pos for pos, op, _raw in RecordWalker(f).records() if op == Opcode.CHUNK]
            lengths = []
            for pos in chunks_at:
                f.seek(pos + 1)
                lengths.append(int.from_bytes(f.read(8), "little"))
        last, length = [(pos, n) for pos, n in zip(chunks_at, lengths) if n > 1024][-1]
        n, chunks, good = salvaged_up_to(part, last, tmp_path / "scratch")
        assert good == last
        with open(part, "r+b") as f:
            f.truncate(last + 9 + length // 2)
            f.truncate(SIZE)
        zeros = zeros_from(part)
        lines = restart(cfg)
    stem = part.name.removesuffix(".mcap.part")
    assert (f"INFO salvage: {part.name}: salvaged {n} message(s) from {chunks} complete chunk(s) into "
            f"{stem}.salvaged.mcap; {SIZE - last} byte(s) after them dropped (a cut: zero bytes from byte "
            f"{zeros} on, inside the chunk at byte {last}, {HOW})") in lines, "\n".join(lines)[-3000:]
    assert sorted(p.name for p in part.parent.iterdir() if ".part" in p.name) == []


def test_kept_damaged_and_unreadable_copies_count_in_retain_mb_and_go_first(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    damaged = logs / "cmsensord-20200101T000000Z.mcap.part.damaged"
    unreadable = logs / "cmsensord-20200102T000000Z.mcap.part.unreadable"
    newer = logs / "cmsensord-20200103T000000Z.salvaged.mcap"
    for path, size in ((damaged, 1_500_000), (unreadable, 1_500_000)):
        path.write_bytes(b"\xff" * size)
    sim = tmp_path / "s"
    assert cmsensord("--simulate", "--duration", "2", "--speed", "20", "--out", str(sim)).returncode == 0
    shutil.copy(log_files(sim, "cmsensord")[0][0], newer)         # a real log, 0.1 MB at most
    _, err = daemon_on_short_board(tmp_path, config="  rotate_mb: 0.2\n  retain_mb: 1\n  min_free_mb: 0\n")
    assert (f"INFO retention: deleted the 2 oldest log file(s) (3.0 MB: {damaged.name}, "
            f"{unreadable.name}) to keep this prefix's files under retain_mb = 1 MB (now 0.0 MB)"
            in err.splitlines()), err[-3000:]
    assert newer.exists() and not damaged.exists() and not unreadable.exists()
