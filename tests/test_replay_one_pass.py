"""`cmsensord replay` with its one-pass paths (the wire kernel's scan of a read,
runs of frames decoded at once, regular tacho edges committed at once, long batches checked
at once, RMS interval sums at once, frames as columns (FrameBatch) from the decoder to the
banks, whole RMS intervals and decision periods at once, messages written in runs with a
severity message's r encoded once) writes what the frame-by-frame, edge-by-edge,
message-by-message daemon writes, message for message, on a RAW capture with a tacho and on
an RMS capture, both with line noise in them."""

from __future__ import annotations

import random
import subprocess
import sys

import pytest

from messages import comparable
from processes import ENV, cmsensord

#: `cmsensord replay` with every one-pass path turned off: the reference
REFERENCE = """
import sys
sys.modules["cmsensord._wirekernel"] = None         # the decoder's Python loop, not the C scan
import cmsensord.monitor.segments as segments
import cmsensord.protocol as protocol
import cmsensord.source as source
from cmsensord.dsp.tacho.edges import EdgeRuns
protocol.MIN_BYTES = 1 << 60
segments.SCAN_MIN = 1 << 60
EdgeRuns.batch_edges = False
source.Decoder.feed_batch = source.Decoder.feed
source.Decoder.flush_batch = source.Decoder.flush
import cmsensord.dsp.severity as severity
import cmsensord.monitor.indicators as indicators
import cmsensord.sinks.mcap_encoding as encoding
from cmsensord.sinks.rotating import RotatingSink
severity.ONE_PASS_PERIODS = indicators.ONE_PASS_INTERVALS = 1 << 60
encoding.REPEATED.clear()
del RotatingSink.write_many
from cmsensord.cli import main
sys.exit(main(sys.argv[1:]))
"""


def capture(path, mode: str, seconds: float) -> None:
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    C = 1 if mode == "raw" else 4
    sc = make_scenario("faulty", n_channels=C, duration_s=seconds, seed=2)
    Board(sc, BoardConfig(n_channels=C, mode=mode, tacho=True)).write_capture(path, seconds)
    data = bytearray(path.read_bytes())
    rnd = random.Random(3)
    for _ in range(40):                                     # line noise: flipped bits, lost bytes
        data[rnd.randrange(len(data))] ^= 1 << rnd.randrange(8)
    for _ in range(10):
        at = rnd.randrange(len(data))
        del data[at:at + rnd.randrange(1, 300)]
    path.write_bytes(bytes(data))


def messages(out):
    from cmsensord.sinks.mcap_sink import read_messages

    return [m for f in sorted(out.glob("*.mcap")) for m in read_messages(f)]


@pytest.mark.parametrize("mode,seconds", [("raw", 30.0), ("rms", 300.0)])
def test_replay_writes_what_the_frame_by_frame_daemon_writes(tmp_path, mode, seconds):
    cap = tmp_path / "cap.bin"
    capture(cap, mode, seconds)
    got = cmsensord("replay", str(cap), "--out", str(tmp_path / "got"))
    ref = subprocess.run([sys.executable, "-c", REFERENCE, "replay", str(cap), "--out", str(tmp_path / "ref")],
                         capture_output=True, text=True, env=ENV, timeout=300)
    assert got.returncode == ref.returncode == 0, got.stderr + ref.stderr
    a, b = messages(tmp_path / "got"), messages(tmp_path / "ref")
    assert comparable(a) == comparable(b)
    topics = {t for t, _, _ in a}
    assert "/cm/events" in topics and any(t.endswith("/severity") for t in topics)
    if mode == "raw":
        assert "/cm/ch0/orders" in topics
    kinds = {m["kind"] for t, _, m in a if t == "/cm/events"}
    assert "frames_lost" in kinds                            # the noise cost frames
