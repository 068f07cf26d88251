"""Randomised streams of valid-CRC frames with random field values, replayed by the real command.

Invariants, whatever the board sends: `cmsensord replay` exits 0 with no traceback,
its peak resident memory stays under 100 MB, every topic's timestamps go forwards,
and the events the summary counts are the events in the log (an event written one by
one counts 1, a rate-limit summary the events it stands for).

CI runs a few short streams; the long mode runs one stream of
CMSENSORD_FUZZ_EXAMPLES frames (>= 1e5 in under a minute):

    CMSENSORD_FUZZ_EXAMPLES=100000 python -m pytest tests/test_stream_random.py
"""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

from cmsensord.protocol import Status, encode_frame, encode_raw, encode_rms, encode_status, encode_tacho
from cmsensord.sinks.mcap_sink import read_messages
from processes import ENV

MEMORY_BOUND_MB = 100


def _status(rng: np.random.Generator, seq: int, t0: int) -> bytes:
    c = int(rng.integers(0, 10))
    scale = rng.choice([0.0125, 1e-3, 0.0, np.nan, np.inf, -0.5], size=c)
    status = Status(fw_version=int(rng.integers(0, 0x10000)), mode=int(rng.integers(0, 4)),
                    fs=int(rng.choice([1, 100, 20480, 25000, 25600, 1_000_000])),
                    block_len=int(rng.choice([1, 64, 250, 256, 4096])), n_channels=c,
                    tacho_inputs=int(rng.integers(0, 3)), tacho_ppr=int(rng.integers(0, 4)),
                    overruns=int(rng.integers(0, 5)), uptime_s=int(rng.integers(0, 1 << 20)),
                    scale=tuple(float(s) for s in scale),
                    offset=tuple(float(o) for o in rng.choice([2048.0, 0.0, np.nan], size=c)))
    return encode_status(seq, t0, status)


def _frame(rng: np.random.Generator, seq: int, t0: int) -> bytes:
    kind = rng.choice(["rms", "rms", "rms", "raw", "tacho", "status", "odd"], p=[.4, .1, .1, .2, .1, .05, .05])
    if kind == "rms":
        c = 4 if rng.random() < 0.95 else int(rng.integers(1, 12))
        values = rng.choice([1.0, 1.2, 0.8, 50.0, 0.0, np.nan, np.inf], size=c, p=[.3, .3, .3, .04, .02, .02, .02])
        return encode_rms(seq, t0, values)
    if kind == "raw":
        n = int(rng.choice([250, 256, 1, 17]))
        return encode_raw(seq, t0, int(rng.integers(0, 6)), rng.integers(0, 4096, n).astype(np.uint16))
    if kind == "tacho":
        edges = np.sort(rng.integers(0, 250 * 256, int(rng.integers(0, 40))))
        return encode_tacho(seq, t0, int(rng.integers(0, 2)), edges)
    if kind == "status":
        return _status(rng, seq, t0)
    payload = rng.integers(0, 256, int(rng.integers(0, 64))).astype(np.uint8).tobytes()
    return encode_frame(int(rng.integers(1, 5)), seq, t0, int(rng.integers(0, 256)), 0, payload)


def random_stream(seed: int, n_frames: int) -> bytes:
    """Mostly a plausible 4-channel RMS stream; now and then odd frames, t0 stuck, reset,
    jumping far ahead or back, seq gaps and restarts, frames sent twice."""
    rng = np.random.default_rng(seed)
    out = [_status(rng, 0, 0)]
    t0, seq = 0, 1
    for _ in range(n_frames):
        r = rng.random()
        if r < 0.90:
            t0 += 250
        elif r < 0.93:
            pass                                   # t0 stuck
        elif r < 0.95:
            t0 = int(rng.integers(0, 1 << 32))     # anywhere: a reset or a far jump
        elif r < 0.97:
            t0 += int(rng.integers(1, 600 * 25000))
        else:
            t0 -= int(rng.integers(1, 25000 * 10))
        seq = (seq + (1 if rng.random() < 0.97 else int(rng.integers(0, 1 << 16)))) & 0xFFFF
        out.append(_frame(rng, seq, t0 & 0xFFFFFFFF))
        if rng.random() < 0.01:
            out.append(out[-1])                    # the same frame twice
    return b"".join(out)


#: runs the command and prints its own peak resident memory (VmHWM: this image's, not the forking
#: parent's, which rusage would count) as the last line of stderr
_MEASURED = ("import sys\nfrom cmsensord.cli import main\ntry:\n    code = main(sys.argv[1:])\nfinally:\n"
             "    hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0]\n"
             "    print(hwm.split()[1], file=sys.stderr)\nsys.exit(code)\n")


def _replay(capture, out_dir) -> tuple[int, str, float]:
    """Exit status, stderr and peak resident memory [MB] of `cmsensord replay`."""
    p = subprocess.run([sys.executable, "-c", _MEASURED, "replay", str(capture), "--out", str(out_dir)],
                       capture_output=True, text=True, env=ENV, timeout=300)
    *lines, hwm_kb = p.stderr.rstrip("\n").split("\n")
    return p.returncode, "\n".join(lines), int(hwm_kb) / 1024


def _check(capture, out_dir) -> None:
    code, stderr, peak_mb = _replay(capture, out_dir)
    assert code == 0, stderr[-2000:]
    assert "Traceback" not in stderr, stderr[-2000:]
    assert peak_mb < MEMORY_BOUND_MB, f"peak RSS {peak_mb:.0f} MB"
    last: dict[str, int] = {}
    events = 0
    for path in sorted(out_dir.glob("*.mcap")):
        for topic, stamp, msg in read_messages(path):
            assert stamp >= last.get(topic, stamp), f"{topic} went back in time in {path.name}"
            last[topic] = stamp
            if topic == "/cm/events":
                events += msg.get("summarised", 1)
    counted = re.search(r"^  events: (.*)$", stderr, re.M)
    total = sum(int(n) for n in re.findall(r" (\d+)(?:,|$)", counted.group(1))) if counted else 0
    assert total == events


def _long_frames() -> int | None:
    value = os.environ.get("CMSENSORD_FUZZ_EXAMPLES")
    return int(value) if value else None


@pytest.mark.parametrize("seed", [1] if _long_frames() else [1, 2, 3, 6, 10])
def test_random_streams_keep_the_invariants(tmp_path, seed):
    capture = tmp_path / "random.bin"
    capture.write_bytes(random_stream(seed, _long_frames() or 3000))
    _check(capture, tmp_path / "logs")
