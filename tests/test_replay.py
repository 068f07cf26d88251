"""Record and replay: paced replay with a progress bar, and live == replay for RAW captures
with line noise (real processes on a real pty)."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time

from cmsensord.service.simulate import RUNUP_ORDERS
from cmsensord.sinks.mcap_sink import read_messages
from firmware_sim.board import Board, BoardConfig
from firmware_sim.scenarios import make_scenario
from messages import comparable
from processes import cmsensord, on_terminal, spawn, start_board, start_daemon, stop


def test_replay_paced_with_speed_shows_a_progress_bar_on_a_terminal(tmp_path):
    cap = tmp_path / "cap.bin"
    sc = make_scenario("faulty", n_channels=1, duration_s=20.0, seed=0)
    Board(sc, BoardConfig(n_channels=1)).write_capture(cap, 20.0)
    t = time.monotonic()
    fast = cmsensord("replay", str(cap), "--out", str(tmp_path / "fast"))
    t_fast = time.monotonic() - t
    assert fast.returncode == 0, fast.stderr
    assert "%" not in fast.stderr                        # not a terminal: no progress bar

    t = time.monotonic()
    status, out = on_terminal([sys.executable, "-m", "cmsensord", "replay", str(cap), "--speed", "8",
                               "--out", str(tmp_path / "paced")], stdout=subprocess.DEVNULL)
    t_paced = time.monotonic() - t
    assert status == 0, out.decode(errors="replace")
    text = out.decode(errors="replace")
    assert "replay cap.bin [" in text and "100.0%" in text and text.count("\r") >= 5
    assert t_paced >= 20.0 / 8 - 0.1 and t_paced > t_fast
    # pacing changes nothing in the results
    a = read_messages(next((tmp_path / "fast").glob("*.mcap")))
    b = read_messages(next((tmp_path / "paced").glob("*.mcap")))
    assert comparable(a) == comparable(b)


def test_a_paced_replay_interrupted_has_replayed_what_its_pace_allows(tmp_path):
    """A 20-s RMS capture (one read of the file holds all of it) at --speed 4, Ctrl-C after 2 s:
    about 8 s of board time replayed, not the whole read (guards against 20.0 s of ADC time in
    2.0 s wall: the read handed on at once, the replay 12 s ahead of its pace)."""
    cap = tmp_path / "cap.bin"
    Board(make_scenario("healthy", n_channels=1, duration_s=20.0, seed=0), BoardConfig(n_channels=1)).write_capture(
        cap, 20.0)
    p = spawn([sys.executable, "-m", "cmsensord", "replay", str(cap), "--speed", "4", "--out", str(tmp_path / "o")],
              stderr=subprocess.PIPE, text=True)
    time.sleep(2.0)
    p.send_signal(signal.SIGINT)
    err = p.communicate(timeout=30)[1]
    assert p.returncode == 130, err
    adc, wall = (float(x) for x in re.search(r"([\d.]+) s of ADC time in ([\d.]+) s wall", err).groups())
    assert 4 * wall - 2.0 <= adc <= 4 * wall + 0.5, err


def test_a_warning_during_a_replay_on_a_terminal_starts_a_line_of_its_own(tmp_path):
    """The whirl run-up's tacho passes the observations per decision at 117 s of 180: its
    decision_rule warning came on the bar's line (`... 117 sWARNING decision_rule: ...`); the
    bar's line is erased first, and the bar drawn again after it."""
    cap = tmp_path / "whirl.bin"
    p = subprocess.run([sys.executable, "-m", "firmware_sim", "--scenario", "whirl", "--mode", "raw", "--tacho",
                        "--out", str(cap)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    status, out = on_terminal([sys.executable, "-m", "cmsensord", "replay", str(cap), "--out", str(tmp_path / "o")],
                              stdout=subprocess.DEVNULL)
    text = out.decode(errors="replace")
    assert status == 0, text
    warning = text.index("WARNING decision_rule: ch0: tacho f_r")
    assert "replay whirl.bin [" in text[:warning], text             # a bar was on the line
    assert text[warning - 4:warning] == "\r\x1b[K", text[:warning + 20]
    assert "replay whirl.bin [" in text[warning:], text              # and drawn again after


def per_topic(messages):
    """comparable() messages grouped by topic (and order-tracker method), each in file order:
    in RAW mode with a tacho, how the topics interleave follows the reads; each topic's own
    sequence does not (events: the same set, the tacho's and the frames' interleaved by read)."""
    out: dict[str, list] = {}
    for topic, stamp, msg in comparable(messages):
        if topic == "/cm/events" and msg["kind"] in ("link_lost", "link_restored", "link_stalled"):
            continue                                     # wall-clock events of the live link
        if topic == "/cm/log" and msg["message"].startswith(("link_lost: ", "link_restored: ",
                                                             "link_stalled: ")):
            continue                                     # ... and their foxglove.Log records
        key = topic if "method" not in msg else f"{topic} {msg['method']}"
        out.setdefault(key, []).append((stamp, msg))
    return out


def test_raw_capture_with_line_noise_replays_to_the_live_messages(tmp_path):
    """RAW blocks + TACHO (close_orders, orders tracked) with byte errors at 1e-3: the
    daemon's live messages and a replay of its capture are field for field the same."""
    link = tmp_path / "ttyBOARD"
    sim = start_board("--scenario", "close_orders", "--mode", "raw", "--tacho", "--duration", "6",
                      "--speed", "1", "--byte-error-rate", "1e-3", "--link", str(link), "--flow-control")
    orders = "orders:\n" + "".join(f"  {k}: {json.dumps(v)}\n" for k, v in RUNUP_ORDERS["close_orders"].items())
    d = start_daemon(tmp_path, link, "--capture", str(tmp_path / "cap.bin"), config=orders)
    stats = json.loads(sim.stdout.readline())["stats"]
    time.sleep(1.5)
    err = stop(d)
    sim.terminate()
    sim.wait(timeout=5)
    assert d.returncode == 0, err
    assert stats["frames"] > 1000     # (bytes sent before the daemon opened the port may drop)
    live = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    r = cmsensord("replay", str(tmp_path / "cap.bin"), "--config", str(tmp_path / "cmsensord.yaml"),
                  "--out", str(tmp_path / "replay"))
    assert r.returncode == 0, r.stderr
    replayed = read_messages(next((tmp_path / "replay").glob("*.mcap")))
    a, b = per_topic(live), per_topic(replayed)
    assert len(a["/cm/ch0/orders recursive"]) > 40 and len(a["/cm/ch0/orders smoothed"]) > 40
    lost = [m for _, m in a["/cm/events"] if m["kind"] == "frames_lost"]
    assert len(lost) > 3                                 # the noise did hit frames
    assert a.keys() == b.keys()
    for topic in a:
        if topic in ("/cm/events", "/cm/log"):  # events of the tacho and of the frames interleave by read
            assert sorted(a[topic], key=repr) == sorted(b[topic], key=repr)
        else:
            assert a[topic] == b[topic], topic


def test_junk_in_front_of_a_capture_is_counted_in_the_summary(tmp_path):
    """A capture with 1000 bytes of line junk before its first frame: replayed whole, the
    summary's link line counts exactly those bytes, and no 'no frame' line."""
    cap = tmp_path / "cap.bin"
    sc = make_scenario("healthy", n_channels=1, duration_s=3.0, seed=0)
    Board(sc, BoardConfig(n_channels=1)).write_capture(cap, 3.0)
    size = cap.stat().st_size
    cap.write_bytes(bytes(1000) + cap.read_bytes())
    r = cmsensord("replay", str(cap), "--out", str(tmp_path / "out"))
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert f"  link: 1000 of {size + 1000} bytes in no frame (0 CRC failure(s), 0 bad header(s))" in lines
    assert not [x for x in lines if "no frame in" in x]


def _interrupted_replay(tmp_path, seconds: float, speed: str):
    """A faulty motor's capture of ``seconds`` replayed at ``speed``, sent SIGINT after 3 s:
    the capture and the process."""
    cap = tmp_path / "cap.bin"
    sc = make_scenario("faulty", n_channels=1, duration_s=seconds, seed=0)
    Board(sc, BoardConfig(n_channels=1)).write_capture(cap, seconds)
    proc = spawn([sys.executable, "-m", "cmsensord", "replay", str(cap), "--speed", speed, "--out",
                  str(tmp_path / "out")], stderr=subprocess.PIPE, text=True)
    time.sleep(3.0)
    proc.send_signal(signal.SIGINT)
    return cap, proc


def test_ctrl_c_ends_a_replay_with_its_log_finished_and_its_summary(tmp_path):
    """Ctrl-C during a replay (it exited 130 in silence): the log is finished, the summary
    says how far it got, exit status 130."""
    cap, proc = _interrupted_replay(tmp_path, 600.0, "20")
    err = proc.communicate(timeout=30)[1]
    assert proc.returncode == 130, err
    line = next(ln for ln in err.splitlines() if ln.startswith("  interrupted (Ctrl-C) at "))
    assert line.endswith(f" of {cap.stat().st_size:,} bytes): the log holds what was replayed"), line
    logs = list((tmp_path / "out").iterdir())
    assert len(logs) == 1 and logs[0].suffix == ".mcap", logs
    assert f"MCAP log: {logs[0]}" in err
    severity = [m for t, _, m in read_messages(logs[0]) if t == "/cm/ch0/severity"]
    assert 20 < len(severity) < 590
    assert cmsensord("summary", str(logs[0])).returncode == 0


def test_ctrl_c_ends_a_slowly_paced_replay_at_once(tmp_path):
    """At --speed 0.05 a read of 4 KiB is 2 s of sleep at least: Ctrl-C ended the run only after it."""
    _, proc = _interrupted_replay(tmp_path, 120.0, "0.05")
    t = time.monotonic()
    err = proc.communicate(timeout=60)[1]
    assert proc.returncode == 130, err
    assert time.monotonic() - t < 5.0
    assert "  interrupted (Ctrl-C) at " in err, err
