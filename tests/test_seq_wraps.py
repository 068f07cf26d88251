"""An outage longer than a wrap of the u16 seq (65536 frames: 131 s of RAW 4 channels and a
tacho) hides whole wraps from the seq gap; the t0 gap at the board's frame rate (STATUS) shows
them, and they are counted lost too (it said 14464 of 80000)."""

from __future__ import annotations

import struct
import subprocess
import sys


def _frame_offsets(data: bytes) -> list[int]:
    offs, p = [], 0
    while p < len(data):
        assert data[p:p + 2] == b"\xa5\x5a"
        offs.append(p)
        p += 18 + struct.unpack_from("<H", data, p + 12)[0]
    return offs + [len(data)]


def _replay_cut(tmp_path, duration: str, keep: int, resume: int) -> subprocess.CompletedProcess:
    """``cmsensord replay`` of a RAW 4-channel + tacho capture whose frames ``keep`` to
    ``resume`` - 1 are cut out (a link outage)."""
    cap = tmp_path / "raw4.bin"
    subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "healthy", "--mode", "raw", "--tacho",
                    "--channels", "4", "--duration", duration, "--out", str(cap)], check=True, capture_output=True)
    data = cap.read_bytes()
    offs = _frame_offsets(data)
    cut = tmp_path / "cut.bin"
    cut.write_bytes(data[:offs[keep]] + data[offs[resume]:])
    p = subprocess.run([sys.executable, "-m", "cmsensord", "replay", str(cut), "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    return p


def test_a_gap_of_more_than_a_seq_wrap_counts_every_frame_lost(tmp_path):
    p = _replay_cut(tmp_path, "170", 5000, 85000)         # 80,000 frames: 159.7 s of the stream
    lines = p.stderr.splitlines()
    assert ("WARNING frames_lost: 80000 frame(s) lost before seq 19464 (seq gap of 14464 and 1 whole wrap(s) of "
            "the seq: t0 jumped 159.7 s)") in lines, p.stderr
    assert any(ln.endswith(", 0 missing, 80000 frames lost)") for ln in lines), p.stderr


def test_a_gap_within_a_wrap_is_the_seq_gap(tmp_path):
    p = _replay_cut(tmp_path, "20", 1000, 4000)
    assert "WARNING frames_lost: 3000 frame(s) lost before seq 4000 (seq gap)" in p.stderr.splitlines(), p.stderr
