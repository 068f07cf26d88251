"""Stream events: a change of channel count, losses that are
reported, and floods of events summarised — each fed by one small capture built with the
protocol encoder and replayed by a real ``cmsensord replay`` process, which must finish
(exit 0) with the exact event in its MCAP."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import pty
import re
import shutil
import threading
import time
import tty

import numpy as np
import pytest

from cmsensord.protocol import (
    MODE_RAW,
    MODE_RMS,
    FrameType,
    Status,
    decode_status,
    encode_frame,
    encode_raw,
    encode_rms,
    encode_status,
    encode_tacho,
    iter_frames,
)
from cmsensord.service.control import SOCKET_NAME
from cmsensord.service.live import DIAGNOSTICS_S
from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord, run_module, start_board, start_daemon, stop

FS, L = 25000, 250


def status(seq: int, t0: int, n: int, scale: float = 1.0) -> bytes:
    return encode_status(seq, t0, Status(0x0100, MODE_RMS, n, FS, L, 0, 0, 0, 0,
                                         (scale,) * n, (0.0,) * n))


def rms_stream(counts: list[int], statuses: dict[int, bytes] | None = None) -> bytes:
    """A STATUS of counts[0] channels, then one RMS frame of counts[k] channels per block k
    (a STATUS from ``statuses`` before block k)."""
    out = bytearray(status(0, 0, counts[0]))
    seq = 1
    for k, c in enumerate(counts):
        if statuses and k in statuses:
            out += statuses[k]
        out += encode_rms(seq, k * L, np.full(c, 0.5))
        seq += 1
    return bytes(out)


def replay(tmp_path, data: bytes, config: str | None = None) -> list[str]:
    """``cmsensord replay`` of ``data``: exit 0, and its events as 'kind | message' lines."""
    cap = tmp_path / "cap.bin"
    cap.write_bytes(data)
    args = ["replay", str(cap), "--out", str(tmp_path / "out")]
    if config is not None:
        (tmp_path / "c.yaml").write_text(f"output:\n  dir: {tmp_path / 'out'}\n{config}")
        args += ["--config", str(tmp_path / "c.yaml")]
    r = cmsensord(*args)
    assert r.returncode == 0, r.stderr
    (tmp_path / "stderr.txt").write_text(r.stderr)
    return [f"{m['kind']} | {m['message']}" for f in sorted((tmp_path / "out").glob("*.mcap"))
            for t, _, m in read_messages(f) if t == "/cm/events"]


def summary_observations(tmp_path) -> tuple[int, int]:
    """(observations, missing observations) of the replay's exit summary."""
    text = (tmp_path / "stderr.txt").read_text()
    m = re.search(r"(\d+) observations?, (\d+) missing", text)
    assert m, text
    return int(m.group(1)), int(m.group(2))


# ---- item 2: a change of channel count ------------------------------------------------
def test_one_rms_frame_of_another_channel_count_is_dropped_with_an_event(tmp_path):
    events = replay(tmp_path, rms_stream([4] * 200 + [2] + [4] * 199))
    assert "channels | 1 RMS frame(s) of 2 channel(s) in a 4-channel stream dropped (1 in all)" in events


def test_a_board_swapped_from_4_to_2_channels_reports_the_channels_gone(tmp_path):
    events = replay(tmp_path, rms_stream([4] * 300 + [2] * 300))
    assert ("channels | board now sends 2 channel(s), not 4: channel(s) ch2, ch3 not in the "
            "stream (observations missing)") in events


def test_channels_that_come_back_into_the_stream_are_said_to_be_in_it(tmp_path):
    events = replay(tmp_path, rms_stream([4] * 300 + [2] * 300 + [4] * 300))
    said = [e for e in events if e.startswith("channels | board now sends")]
    assert said == ["channels | board now sends 2 channel(s), not 4: channel(s) ch2, ch3 not in the stream "
                    "(observations missing)",
                    "channels | board now sends 4 channel(s), not 2: channel(s) ch2, ch3 now in the stream"], said


def test_a_board_swapped_from_2_to_4_channels_re_sets_auto_channels(tmp_path):
    events = replay(tmp_path, rms_stream([2] * 300 + [4] * 300, {300: status(9999, 300 * L, 4)}))
    assert "channels | board now sends 4 channel(s), not 2: channels re-set to ch0, ch1, ch2, ch3" in events


def test_the_exit_summary_covers_the_whole_run_of_a_channel_through_a_change_of_channels(tmp_path):
    """A degrading 2-channel board reconfigured to 3 channels at 100 s of 120 (STATUS and RMS
    frames of 3; ch2 copies ch0): ch0 and ch1 keep their names, so the exit summary counts their
    decisions and failures of the whole run, as the log has them, and their timeline starts at
    2 s with the first levels where the log has them; it says their filters restarted at 100 s.
    Guards against counting only the new chain's 20 decisions and 1 failure, its timeline '2-20 s'."""
    cap = tmp_path / "deg2.bin"
    assert run_module("firmware_sim", "--scenario", "degrading", "--channels", "2", "--duration", "120",
                      "--out", str(cap)).returncode == 0
    out = bytearray()
    for f in iter_frames(cap.read_bytes())[0]:
        if f.t0 < 100 * FS:
            out += encode_frame(f.type, f.seq, f.t0, f.chan, f.flags, f.payload)
        elif f.type == FrameType.STATUS:
            st = decode_status(f.payload)
            out += encode_status(f.seq, f.t0, dataclasses.replace(st, n_channels=3, scale=st.scale + st.scale[:1],
                                                                  offset=st.offset + st.offset[:1]))
        else:
            v = np.frombuffer(f.payload, "<f4")
            out += encode_rms(f.seq, f.t0, [v[0], v[1], v[0]])
    events = replay(tmp_path, bytes(out))
    assert "channels | board now sends 3 channel(s), not 2: channels re-set to ch0, ch1, ch2" in events
    err = (tmp_path / "stderr.txt").read_text()
    msgs = [(t, s, m) for f in (tmp_path / "out").glob("*.mcap") for t, s, m in read_messages(f)]
    start = min(s for t, s, _ in msgs if t.endswith("/severity"))
    for ch, restarted in (("ch0", True), ("ch1", True), ("ch2", False)):
        sev = [(s, m["severity_index"]) for t, s, m in msgs if t == f"/cm/{ch}/severity"]
        failures = [m for t, _, m in msgs if t == "/cm/events" and m["kind"] == "failure" and m["channel"] == ch]
        line = re.search(rf"  {ch}: final severity ([\d.]+), max ([\d.]+), (\d+) failure event\(s\), "
                         rf"(\d+) decisions(.*)", err)
        assert line, err
        assert (float(line[1]), float(line[2])) == (round(sev[-1][1], 1), round(max(v for _, v in sev), 1))
        assert (int(line[3]), int(line[4])) == (len(failures), len(sev)), line[0]
        assert line[5] == ("; its filters restarted at 100 s (a new set of channels)" if restarted else ""), line[0]
        first = {lv: next((s - start) / 1e9 + 1 for s, v in sev if v >= lv - 1e-9) for lv in (0.1, 0.5, 1.0)}
        timeline = re.search(rf"  {ch}: \|.*\| (\d+)-120 s; first 0.1 at (\d+) s, 0.5 at (\d+) s, 1 at (\d+) s", err)
        assert timeline, err
        assert [int(x) for x in timeline.groups()] == [102 if ch == "ch2" else 2, *map(round, first.values())], \
            timeline[0]
    assert len(failures) == 1 and len([m for t, _, m in msgs if t == "/cm/ch0/severity"]) == 120


def level_stream(segments: list[tuple[int, int]], spiking: int = 2) -> bytes:
    """Per segment (seconds, channels): RMS frames of 1.0 +- 5 % per channel, a STATUS announcing
    the count each second; channel ``spiking`` has 6.0 more in 40 % of its blocks from 2 s into
    its first segment on (outliers in every AKF: a failure), and none later."""
    rng = np.random.default_rng(1)
    out, seq, k = bytearray(), 0, 0
    spiked = False
    for seconds, n in segments:
        spikes = not spiked and n > spiking
        spiked |= spikes
        for b in range(seconds * 100):
            if b % 100 == 0:
                out += status(seq, k * L, n)
                seq += 1
            v = rng.normal(1.0, 0.05, n)
            if spikes and b > 200 and rng.random() < 0.4:
                v[spiking] += 6.0
            out += encode_rms(seq, k * L, np.abs(v))
            seq, k = seq + 1, k + 1
    return bytes(out)


def channel_lines(tmp_path, marks: dict[str, str]) -> tuple[list[str], list[str]]:
    """(the replay's exit summary lines of the channels' figures, those the log's severity
    messages and failure events make with ``marks``: what each channel's line ends with)."""
    msgs = [(t, m) for f in (tmp_path / "out").glob("*.mcap") for t, _, m in read_messages(f)]
    want = []
    for ch, mark in marks.items():
        sev = [m["severity_index"] for t, m in msgs if t == f"/cm/{ch}/severity"]
        failures = sum(t == "/cm/events" and m["kind"] == "failure" and m["channel"] == ch for t, m in msgs)
        want.append(f"  {ch}: final severity {sev[-1]:.1f}, max {max(sev):.1f}, {failures} failure event(s), "
                    f"{len(sev)} decisions{mark}")
    err = (tmp_path / "stderr.txt").read_text()
    return [ln for ln in err.splitlines() if re.match(r"  ch\d: final severity", ln)], want


def test_the_exit_summary_keeps_the_channels_that_left_the_stream(tmp_path):
    """2 channels 5 s, 4 for 10 s (ch2 fails), 1 for 3 s, 2 for 3 s (the channels re-set to ch0,
    ch1): the exit summary still has ch2, with its failure and decisions as the log has them, and
    ch3, each saying since when it is not in the stream; ch1 says it was not 15-18 s.  Guards
    against a summary of the last set of channels only (ch2's failure counted in `events:` but no
    line of it)."""
    replay(tmp_path, level_stream([(5, 2), (10, 4), (3, 1), (3, 2)]))
    restarted = "; its filters restarted at 5 s, 18 s (a new set of channels)"
    got, want = channel_lines(tmp_path, {"ch0": restarted, "ch1": f"{restarted}; not in the stream 15-18 s",
                                         "ch2": "; not in the stream since 15 s",
                                         "ch3": "; not in the stream since 15 s"})
    assert got == want
    assert want[2].startswith("  ch2: final severity 1.0, max 1.0, 1 failure event(s), 13 decisions"), want


def test_a_channel_back_in_the_stream_goes_on_with_its_figures(tmp_path):
    """As above, then 4 channels again for 3 s: ch2 and ch3 come back under their names and go on
    with their decisions, maximum and failures of the run (ch2: 16 decisions, max 1.0, its one
    failure), saying when they were not in the stream."""
    replay(tmp_path, level_stream([(5, 2), (10, 4), (3, 1), (3, 2), (3, 4)]))
    restarted = "; its filters restarted at 5 s, 18 s, 21 s (a new set of channels)"
    back = "; its filters restarted at 21 s (a new set of channels); not in the stream 15-21 s"
    got, want = channel_lines(tmp_path, {"ch0": restarted, "ch1": f"{restarted}; not in the stream 15-18 s",
                                         "ch2": back, "ch3": back})
    assert got == want
    assert want[2].startswith("  ch2: final severity 0.0, max 1.0, 1 failure event(s), 16 decisions"), want


def test_a_channel_in_and_out_of_the_stream_many_times_has_its_newest_absences_said_and_the_rest_counted(tmp_path):
    """4 channels for 3 s, then 2 and 4 for 2 s each, 7 times, then 2: ch2 and ch3 leave the
    stream 8 times; the exit summary names the newest 5 ended absences and the one since 31 s,
    and counts the 2 before them, so a board doing this for months does not grow the line (nor
    the daemon's memory) without bound."""
    replay(tmp_path, level_stream([(3, 4)] + [(2, 2), (2, 4)] * 7 + [(2, 2)], spiking=9))
    absent = "; not in the stream 11-13 s, 15-17 s, 19-21 s, 23-25 s, 27-29 s, since 31 s, and 2 time(s) before"
    got, want = channel_lines(tmp_path, {"ch0": "", "ch1": "", "ch2": absent, "ch3": absent})
    assert got == want


def test_a_channel_whose_filters_restarted_many_times_has_the_newest_restarts_said_and_the_rest_counted(tmp_path):
    """4 channels, then 1, 2 and 4 for 2 s each, 3 times: ch0's filters restart at each new set
    of channels (2 -> 1 -> 2 re-sets to ch0, ch1; then to ch0-ch3), 6 times; the exit summary
    names the newest 5 and counts the one before."""
    replay(tmp_path, level_stream([(2, 4)] + [(2, 1), (2, 2), (2, 4)] * 3, spiking=9))
    got, _ = channel_lines(tmp_path, {})
    assert got[0].endswith("; its filters restarted at 6 s, 10 s, 12 s, 16 s, 18 s and 1 time(s) before "
                           "(a new set of channels)"), got


def test_the_daemon_says_which_channels_left_the_stream_in_its_status_and_exit_summary(tmp_path):
    """The stream of the test above, written to a pty with the daemon on it: ``cmsensord status``
    names ch2 and ch3 as not in the stream after ch0 and ch1, and the daemon's exit summary has the
    lines of the replay's."""
    data = level_stream([(5, 2), (10, 4), (3, 1), (3, 2)])
    master, slave = os.openpty()
    tty.setraw(slave)
    d = start_daemon(tmp_path, os.ttyname(slave))
    sock = str(tmp_path / "logs" / SOCKET_NAME)
    try:
        time.sleep(1.0)
        for i in range(0, len(data), 997):
            os.write(master, data[i:i + 997])
            time.sleep(0.002)
        line = ""
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not line.startswith("[    21.0 s]"):
            time.sleep(0.2)
            line = cmsensord("status", "--socket", sock).stdout.strip()
    finally:
        err = stop(d)
        os.close(master)
        os.close(slave)
    assert d.returncode == 0 and "Traceback" not in err, err
    assert re.fullmatch(r"\[    21\.0 s\] ch0 S=0\.0 out/s= +\d+ F=[01]+ ch1 S=0\.0 out/s= +\d+ F=[01]+ "
                        r"ch2 \(not in the stream\) ch3 \(not in the stream\)( \| .*)?", line), line
    (tmp_path / "replay").mkdir()
    replay(tmp_path / "replay", data)
    said = [ln for ln in (tmp_path / "replay" / "stderr.txt").read_text().splitlines() if re.match(r"  ch\d: ", ln)]
    assert [ln for ln in err.splitlines() if re.match(r"  ch\d: ", ln)] == said
    assert len(said) == 8 and said[4].endswith("; not in the stream since 15 s"), said


def test_new_board_channels_that_are_not_configured_are_named_as_not_monitored(tmp_path):
    config = "channels:\n  - {name: a, index: 0}\n  - {name: b, index: 1}\n"
    events = replay(tmp_path, rms_stream([2] * 300 + [4] * 300), config)
    assert ("channels | board now sends 4 channel(s), not 2: board channel(s) 2, 3 not configured, "
            "not monitored") in events


# ---- item 8: event floods and false events ---------------------------------------------
def tacho_stream(lose: int | None = None, flood: range = range(0)) -> bytes:
    """1 RMS channel and a tacho (1 pulse per rev at 25 Hz: an edge every 4th block) for
    600 blocks; the TACHO frame of block ``lose`` lost on the link (its seq skipped); the
    blocks in ``flood`` with 1023 edges at random times."""
    out = bytearray(encode_status(0, 0, Status(0x0100, MODE_RMS, 1, FS, L, 1, 1, 0, 0, (1.0,), (0.0,))))
    seq = 1
    for k in range(600):
        out += encode_rms(seq, k * L, [0.5])
        seq += 1
        edges = [100 * 256] if k % 4 == 1 else []
        if k in flood:
            edges = np.sort(np.random.default_rng(k).integers(0, L * 256, 1023)).tolist()
        if k != lose:
            out += encode_tacho(seq, k * L, 0, edges)
        seq += 1
    return bytes(out)


def seq_stream(seqs: list[int]) -> bytes:
    """A STATUS, then one 1-channel RMS frame a block under ``seqs[k]`` for block k (t0 going on)."""
    return status(0, 0, 1) + b"".join(encode_rms(q, k * L, [0.5]) for k, q in enumerate(seqs))


@pytest.mark.parametrize(("seqs", "said", "lost"), [
    ([*range(1, 151), *range(150, 300)], ["seq 150 after seq 150 while t0 went on 250 sample(s) (0.01 s): the seq "
                                          "did not go on with t0 (a seq glitch, or a frame sent again with new "
                                          "content); not counted as 65535 frame(s) lost"], 0),
    ([*range(1, 151), 30_000, *range(151, 300)], ["seq 30000 after seq 150 while t0 went on 250 sample(s) (0.01 s): "
                                                  "the seq did not go on with t0 (a seq glitch); not counted as 29849 "
                                                  "frame(s) lost",
                                                  "seq 151 after seq 30000 while t0 went on 250 sample(s) (0.01 s): "
                                                  "the seq did not go on with t0 (a seq glitch, or a frame sent again "
                                                  "with new content); not counted as 35686 frame(s) lost"], 0),
    ([*range(1, 151), *range(152, 302)], ["1 frame(s) lost before seq 152 (seq gap)"], 1)])
def test_a_seq_that_does_not_go_on_with_t0_is_no_frame_loss(tmp_path, seqs, said, lost):
    """300 blocks of a 1-channel RMS board whose t0 goes on a block a frame: the seq steps back by one at
    block 150 (the same seq again, new values), or one frame's seq is off by 30,000: a ``decode_error``
    naming the seqs and the t0 step, nothing counted lost (exit summary, diagnostics).  A seq gap of one
    with t0 going on is the frame lost it may be.  Guards against '65535 frame(s) lost before seq 150' and
    the summary's 65535 frames lost (as many for the glitch, in two gaps) with 0 missing observations."""
    events = replay(tmp_path, seq_stream(seqs))
    assert [e.split(" | ")[1] for e in events if e.startswith(("decode_error", "frames_lost"))] == said
    assert summary_observations(tmp_path) == (300, 0)
    assert f", {lost} frames lost)" in (tmp_path / "stderr.txt").read_text()
    diag = [m for f in (tmp_path / "out").glob("*.mcap") for t, _, m in read_messages(f) if t == "/cm/diagnostics"]
    assert diag[-1]["link"]["frames_lost"] == lost


def test_a_lost_tacho_frame_is_a_frame_loss_not_a_missed_pulse(tmp_path):
    events = replay(tmp_path, tacho_stream(lose=201))
    assert "frames_lost | 1 frame(s) lost before seq 405 (seq gap)" in events
    assert not [e for e in events if e.startswith("tacho_")]


def test_100_tacho_frames_of_1023_edges_are_summarised(tmp_path):
    events = replay(tmp_path, tacho_stream(flood=range(200, 300)))
    extra = [e for e in events if e.startswith("tacho_extra_pulse")]
    assert len(extra) == 6 and extra[:5] == [
        f"tacho_extra_pulse | spurious tacho pulse removed at sample {x}"
        for x in ("50003.2", "50003.6", "50004.6", "50007.8", "50014.4")]
    assert extra[5] == ("tacho_extra_pulse | 7825 more tacho_extra_pulse event(s) in 1 s (7825 pulse(s) between them): "
                        "at most 5 per 1 s are written one by one")
    assert len(events) == 33            # of 23,682 events (7,830 extra and 15,852 missed pulses)


# ---- item 7: losses that are reported --------------------------------------------------
def test_one_rms_frame_of_a_wrong_payload_length_costs_only_that_frame(tmp_path):
    data = bytearray(status(0, 0, 4))
    for k in range(400):
        payload = np.full(4, 0.5, dtype="<f4").tobytes()
        data += encode_frame(FrameType.RMS, k + 1, k * L, 4, 0, payload[:12] if k == 200 else payload)
    events = replay(tmp_path, bytes(data))
    assert [e for e in events if e.startswith("decode_error")] == [
        f"decode_error | RMS frame at t0 {200 * L} dropped: 12 bytes, not 16 (4 channel(s) of 4 bytes)"]
    obs = summary_observations(tmp_path)
    assert obs == (399 * 4, 4)            # (observations, missing): the frame's 4 only


def raw_stream(bad_scale: float) -> bytes:
    """RAW mode, 1 channel: a STATUS (scale 0.01), 400 blocks, a STATUS with ``bad_scale``
    after block 200."""
    def st(seq, t0, scale):
        return encode_status(seq, t0, Status(0x0100, MODE_RAW, 1, FS, L, 0, 0, 0, 0, (scale,), (2048.0,)))
    out = bytearray(st(0, 0, 0.01))
    seq = 1
    counts = (2048 + 100 * np.sin(np.arange(L) / 5)).astype(np.uint16)
    for k in range(400):
        if k == 200:
            out += st(seq, k * L, bad_scale)
            seq += 1
        out += encode_raw(seq, k * L, 0, counts)
        seq += 1
    return bytes(out)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), 0.0])
def test_a_status_with_a_bad_scale_is_ignored_with_an_event(tmp_path, bad):
    events = replay(tmp_path, raw_stream(bad))
    at = raw_stream(bad).index(encode_status(201, 200 * L, Status(0x0100, MODE_RAW, 1, FS, L, 0, 0, 0, 0,
                                                                   (bad,), (2048.0,))))
    assert (f"decode_error | STATUS at byte {at} ignored: channel(s) 0 with scale/offset {bad:g}/2048, "
            "not finite (and a scale not 0): the previous STATUS is kept") in events
    assert summary_observations(tmp_path) == (400, 0)


def wait_until(cond, what: str, limit_s: float = 20.0) -> None:
    """Poll ``cond`` until it holds (a bound against a hang, not a timing assertion)."""
    deadline = time.monotonic() + limit_s
    while not cond():
        assert time.monotonic() < deadline, f"still waiting for {what}"
        time.sleep(0.05)


def test_output_directory_deleted_while_running_is_reported_at_the_next_flush(tmp_path):
    link = tmp_path / "ttyBOARD"
    logs = tmp_path / "logs"
    sim = start_board("--scenario", "healthy", "--link", str(link))
    d = start_daemon(tmp_path, link, config="  flush_s: 0.2\n")
    try:
        wait_until(lambda: list(logs.glob("*.part")), "the first file")
        first = next(logs.glob("*.part"))
        gone = tmp_path / "gone"            # moved away at once, then deleted: an rmtree in place
        logs.rename(gone)                   # could meet the daemon's new file in it (ENOTEMPTY)
        shutil.rmtree(gone)
        wait_until(lambda: list(logs.glob("*.part")), "a new file in the directory made again")
        assert d.poll() is None                               # still running
        err = stop(d)
    finally:
        sim.terminate()
        sim.wait(timeout=5)
    assert d.returncode == 0, err
    line = next(x for x in err.splitlines() if "was removed while open" in x)
    head, _, tail = line.partition(" message(s) written to it lost")
    assert head.startswith(f"ERROR disk_error: {first} was removed while open (output directory "
                           "deleted?): ") and head.rsplit(" ", 1)[1].isdigit(), line
    assert tail == "; logging goes on in a new file", line
    events = [m["message"] for f in logs.glob("*.mcap") for t, _, m in read_messages(f) if t == "/cm/events"]
    assert line.split("disk_error: ", 1)[1] in events


def test_a_link_sending_only_garbage_is_link_stalled_with_diagnostics(tmp_path):
    """A board at the wrong baud rate: bytes, never a valid frame."""
    master, slave = pty.openpty()
    port = os.ttyname(slave)
    os.set_blocking(master, False)      # once the daemon has stopped reading, a full pty must not block the writer
    stop_writing = threading.Event()

    def garbage():
        rng = np.random.default_rng(0)
        while not stop_writing.is_set():
            with contextlib.suppress(OSError):
                os.write(master, rng.integers(0, 256, 512, dtype=np.uint8).tobytes())
            time.sleep(0.01)

    writer = threading.Thread(target=garbage, daemon=True)
    writer.start()
    d = start_daemon(tmp_path, port, config="  flush_s: 0.2\n")
    lines: list[str] = []
    try:
        def stalled():
            lines.append(d.stderr.readline())
            return "link_stalled" in lines[-1]
        wait_until(stalled, "link_stalled")
        time.sleep(DIAGNOSTICS_S + 1.5)                      # no decision: diagnostics come anyway
        assert d.poll() is None                               # still running
        err = stop(d)
    finally:
        stop_writing.set()
        writer.join()
        os.close(master)
        os.close(slave)
    assert d.returncode == 0, err
    assert re.fullmatch(rf"WARNING link_stalled: {port}: bytes but no valid frame for \d+\.\d s "
                        r"\(wrong baud rate, or line noise\?\)", lines[-1].strip()), lines[-1]
    msgs = [(t, m) for f in (tmp_path / "logs").glob("*.mcap") for t, _, m in read_messages(f)]
    diag = [m for t, m in msgs if t == "/cm/diagnostics"]
    assert diag and diag[0]["link"]["bytes_discarded"] > 0 and diag[0]["observations"] == 0
    assert len(diag) >= 2 and diag[-1]["link"]["bytes_discarded"] > diag[0]["link"]["bytes_discarded"]
    assert [m["kind"] for t, m in msgs if t == "/cm/events"] == ["start", "link_stalled", "stop"]


def test_a_fault_that_never_stops_is_summarised_in_the_journal_every_ten_minutes(tmp_path):
    """One RMS frame lost every 2 s for 1300 s (650 losses, a marginal cable): in the journal ten
    events one by one in each 600 s, then one summary of the rest; /cm/events has each one."""
    out = bytearray(status(0, 0, 1))
    for k in range(130_000):
        if k % 200 != 100:
            out += encode_rms(k + 1, k * L, [0.5])
    events = replay(tmp_path, bytes(out))
    assert len([e for e in events if e.startswith("frames_lost")]) == 650
    journal = [ln for ln in (tmp_path / "stderr.txt").read_text().splitlines() if "WARNING frames_lost" in ln]
    summaries = [ln for ln in journal if "more frames_lost" in ln]
    assert (len(journal), len(summaries)) == (33, 3), journal
    assert summaries[0] == ("WARNING frames_lost: 290 more frames_lost event(s) in 598 s (290 frame(s) between them): "
                            "at most 10 per 600 s are written one by one")
    assert "frames_lost 650" in (tmp_path / "stderr.txt").read_text()     # the run's counts


def test_a_flood_that_never_stops_is_ten_journal_lines_and_a_summary_each_ten_minutes(tmp_path):
    """650 s of RMS frames, every tenth followed by three copies of one RMS frame of a wrong
    payload length (one decode_error and a frames_repeated of 2 frames: 10 a second of each).
    The journal writes at most 10 lines of a kind in 600 s, the per-second summaries among them,
    and one summary of the rest per window (not a per-second summary of each kind every
    second, 650 of them); every event is written one by one or counted in one summary, and a
    summary names what its count counts (frames, not events).  /cm/events keeps its 5 a second."""
    out = bytearray(status(0, 0, 1))
    seq = 1
    for k in range(65_000):
        out += encode_rms(seq, k * L, [0.5])
        for _ in range(3 if k % 10 == 0 else 0):
            out += encode_frame(FrameType.RMS, seq + 1, k * L, 1, 0, bytes(12))   # 12 bytes, not 4
            seq += 1
        seq += 1
    events = replay(tmp_path, bytes(out))
    err = (tmp_path / "stderr.txt").read_text()
    assert "decode_error 6500, frames_repeated 6500" in err              # the run's counts
    for kind, frames in (("decode_error", None), ("frames_repeated", 2)):
        journal = [ln for ln in err.splitlines() if ln.startswith(f"WARNING {kind}: ")]
        more = [re.fullmatch(rf"WARNING {kind}: (\d+) more {kind} event\(s\) in [\d.]+ s \((.*)\): at most "
                             r"(\d+) per (\d+) s are written one by one", ln) for ln in journal]
        summaries = [m for m in more if m]
        assert len(journal) == 2 * (10 + 1) and [m[4] for m in summaries] == ["1", "600"] * 2, journal
        assert len(journal) - len(summaries) + sum(int(m[1]) for m in summaries) == 6500, journal
        for m in summaries:
            assert m[2] == (f"{frames * int(m[1])} frame(s) between them" if frames
                            else f"their counts add up to {m[1]}"), m[0]
        written = [e for e in events if e.startswith(f"{kind} |")]
        per_second = [e for e in written if "at most 5 per 1 s" in e]
        assert len(per_second) == 650 and len(written) == 650 * 6, written[:12]


def test_a_configured_channel_back_in_the_stream_is_said_beside_a_board_channel_not_configured(tmp_path):
    """ch0-ch2 configured, the board at 4, then 2, then 4 again: coming back, ch2 is said to be in
    the stream again with board channel 3 not monitored, not the idle channel alone."""
    events = replay(tmp_path, rms_stream([4] * 300 + [2] * 300 + [4] * 300),
                    "channels:\n  - {name: ch0, index: 0}\n  - {name: ch1, index: 1}\n  - {name: ch2, index: 2}\n")
    said = [e for e in events if e.startswith("channels | board now sends")]
    assert said == ["channels | board now sends 2 channel(s), not 4: channel(s) ch2 not in the stream "
                    "(observations missing)",
                    "channels | board now sends 4 channel(s), not 2: channel(s) ch2 now in the stream; board "
                    "channel(s) 3 not configured, not monitored"], said
