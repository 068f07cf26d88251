"""`cmsensord replay` of captures whose TACHO frames carry many edges: memory stays bounded
however long the dense tacho goes on, a dense encoder's speed is read right, and a burst of
edges at one instant is said as bad input and leaves the speed of the tacho after it right."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cmsensord.protocol import MODE_RAW, Status, encode_raw, encode_status, encode_tacho
from cmsensord.sinks.mcap_read import read_messages
from processes import ENV, peak_rss_mb

L = 250


def capture(path: Path, tacho: list[np.ndarray], ppr: int) -> Path:
    """A RAW capture of one channel (a 50-Hz sine) with one TACHO frame a block, the edge offsets
    ``tacho[b]`` (1/256 sample) in block b, a STATUS every second announcing ``ppr``."""
    st = Status(0x0100, MODE_RAW, 1, 25000, L, 1, ppr, 0, 0, (0.0958,), (2048.0,))
    parts, seq = [], 0
    for b, edges in enumerate(tacho):
        t0 = b * L
        if b % 100 == 0:
            parts.append(encode_status(seq, t0, st))
            seq += 1
        x = 2048 + 400 * np.sin(2 * np.pi * 50 * (t0 + np.arange(L)) / 25000)
        parts.append(encode_raw(seq, t0, 0, x.astype(np.uint16)))
        parts.append(encode_tacho(seq + 1, t0, 0, np.asarray(edges, dtype=np.uint32)))
        seq += 2
    path.write_bytes(b"".join(parts))
    return path


def replay(cap: Path, out: Path) -> tuple[str, float, list[dict]]:
    """(stderr, peak resident memory in MB, the /cm/ch0/indicators messages) of ``cmsensord replay``."""
    code, err, peak = peak_rss_mb("replay", cap, "--out", out)
    assert code == 0, err
    (log,) = out.glob("*.mcap")
    return err, peak, [m for t, _, m in read_messages(log) if t == "/cm/ch0/indicators"]


#: 1000 edges a block, a quarter sample apart: 100 000 pulses a second, a 255-ppr encoder at 23 529 rpm
DENSE = np.arange(1000) * 64


def test_a_dense_tacho_holds_bounded_memory_and_its_speed(tmp_path):
    """Three times the seconds of the densest tacho cost well under the 80 MB that keeping 60 s
    of its knots and causal segments would add (about 10 MB a second; the peak of one length
    varies by up to 15 MB from run to run), and the speed is its own."""
    peaks = []
    for seconds in (4, 12):
        cap = capture(tmp_path / f"dense{seconds}.bin", [DENSE] * (100 * seconds), ppr=255)
        err, peak, ind = replay(cap, tmp_path / f"out{seconds}")
        assert [round(m["speed_rpm"], 1) for m in ind[1:]] == [23529.4] * (seconds - 1), err
        peaks.append(peak)
    assert peaks[1] - peaks[0] < 40, peaks


def test_a_burst_of_impossible_edges_is_bad_input_and_the_speed_comes_back(tmp_path):
    """3 s of one edge every 500 samples (3000 rpm), 1 s of 1023 edges a block, 1 s of 1023 edges
    a block all at one offset, then the 3000-rpm tacho again: the frames with edges at one
    instant are decode errors, dropped; the tacho is lost in the silence they leave and, restored,
    reads 3000 rpm (taking their first edges as a pulse a block had the tacho read 6000 rpm, a
    missed pulse after every real one, for as long as it went on)."""
    normal = [np.array([12 * 256 + 128]) if b % 2 == 0 else np.zeros(0) for b in range(100)]
    tacho = normal * 3 + [np.arange(1023) * 62] * 100 + [np.full(1023, 100)] * 100 + normal * 6
    err, _, ind = replay(capture(tmp_path / "burst.bin", tacho, ppr=1), tmp_path / "out")
    assert [round(m["speed_rpm"]) for m in ind[:3] + ind[5:]] == [3000] * 9, err
    (line,) = [x.strip() for x in err.splitlines() if x.strip().startswith("events:")]
    assert "decode_error 100," in line and "tacho_lost 1, tacho_restored 1" in line, line
    assert "tacho_missed_pulse" not in line, line


def test_frames_of_two_edges_at_one_offset_in_a_slow_tacho_are_bad_input(tmp_path):
    """A slow tacho (one edge every other block) with 1 s of frames each of two edges at one
    offset: a batch holds no more edges than frames, and the broken frames are still decode
    errors, dropped (fed to the tracker they read 6000 rpm, a missed pulse after every real one)."""
    normal = [np.array([12 * 256 + 128]) if b % 2 == 0 else np.zeros(0) for b in range(100)]
    tacho = normal * 3 + [np.array([100, 100])] * 100 + normal * 6
    err, _, ind = replay(capture(tmp_path / "pairs.bin", tacho, ppr=1), tmp_path / "out")
    assert [round(m["speed_rpm"]) for m in ind[:3] + ind[5:]] == [3000] * 8, err
    (line,) = [x.strip() for x in err.splitlines() if x.strip().startswith("events:")]
    assert "decode_error 100," in line and "tacho_missed_pulse" not in line, line


def test_the_pulses_of_dropped_frames_are_no_missed_pulses(tmp_path):
    """1500 rpm on 2 pulses a revolution (an edge every other block), five frames of the edge
    twice: dropped as decode errors, and their pulses not said again as the encoder's missed
    pulses, as those of lost frames are not (it said 'tacho_missed_pulse 1': 5 pulses inserted)."""
    tacho = [np.array([64] * (2 if 300 <= b < 310 else 1)) if b % 2 == 0 else np.zeros(0) for b in range(1000)]
    err, _, ind = replay(capture(tmp_path / "dup.bin", tacho, ppr=2), tmp_path / "out")
    (line,) = [x.strip() for x in err.splitlines() if x.strip().startswith("events:")]
    assert "decode_error 5" in line and "tacho_missed_pulse" not in line, line
    speeds = [round(m["speed_rpm"]) for m in ind]
    assert speeds[:3] + speeds[4:] == [1500] * 9 and abs(speeds[3] - 1500) < 100, speeds   # 3 s: the dropped


@pytest.mark.process
def test_a_second_of_noise_on_the_tacho_line_is_said_as_it_was(tmp_path):
    """1 s of 1023 edges a block at random offsets (noise on the tacho input) between 2 s of a
    3000-rpm tacho on each side, through `cmsensord replay`: the edges are said as they were,
    missed and extra pulses, and the replay ends."""
    cap = capture(tmp_path / "noise.bin", noisy_second(), ppr=1)
    run = subprocess.run([sys.executable, "-m", "cmsensord", "replay", str(cap), "--out", str(tmp_path / "out")],
                         capture_output=True, text=True, env=ENV, timeout=120)
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr
    (line,) = [x.strip() for x in run.stderr.splitlines() if x.strip().startswith("events:")]
    assert line == "events: config 2, decision_rule 2, tacho_extra_pulse 7997, tacho_missed_pulse 15734", line


def noisy_second() -> list[np.ndarray]:
    """2 s of a 3000-rpm tacho (ppr 1), 1 s of 1023 edges a block at random offsets, 2 s of it again."""
    rng = np.random.default_rng(0)
    normal = [np.array([12 * 256 + 128]) if b % 2 == 0 else np.zeros(0) for b in range(100)]
    noise = [np.sort(rng.integers(0, L * 256, 1023)) for _ in range(100)]
    return normal * 2 + noise + normal * 2


def test_edges_that_are_not_regular_cost_a_bounded_look_ahead_each(tmp_path, monkeypatch, capsys):
    """The same noisy second through `cmsensord replay` (in this process): the one-pass checks of
    regular edges look at a bounded number of edges per edge (each looked at every edge of the
    batch still to come after each edge that was not regular: quadratic, 20 s of processor time
    for this second, 80 s for two; a daemon behind takes larger batches and fell further behind)."""
    from cmsensord.cli import main
    from cmsensord.dsp.tacho import edges

    looked = []
    plain = edges.regular_prefix

    def counted(st, q, *args):
        looked.append(len(q))
        return plain(st, q, *args)

    monkeypatch.setattr(edges, "regular_prefix", counted)
    tacho = noisy_second()
    cap = capture(tmp_path / "noise.bin", tacho, ppr=1)
    assert main(["replay", str(cap), "--out", str(tmp_path / "out")]) == 0
    n = sum(len(e) for e in tacho)
    assert looked and sum(looked) <= (edges.SPAN_START + 2) * n, (sum(looked), n)
