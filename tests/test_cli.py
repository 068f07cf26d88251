"""The command line end to end, through real processes and a real pty."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from cmsensord.protocol import iter_frames
from cmsensord.sinks.mcap_sink import read_messages
from messages import comparable
from processes import ENV, board_on_pty, cmsensord, spawn


def assert_messages_match_their_schemas(path):
    """Every message in the file validates against the jsonschema stored with it."""
    import json

    import jsonschema
    from mcap.reader import make_reader

    seen = set()
    validators: dict[int, jsonschema.protocols.Validator] = {}   # one per schema, checked once
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            if schema.id not in validators:
                spec = json.loads(schema.data)
                cls = jsonschema.validators.validator_for(spec)
                cls.check_schema(spec)
                validators[schema.id] = cls(spec)
            validators[schema.id].validate(json.loads(message.data))
            seen.add(schema.name)
    return seen


@pytest.fixture(scope="module")
def simulated_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sim")
    p = cmsensord("--simulate", "--scenario", "degrading", "--duration", "40", "--speed", "20",
                  "--channels", "2", "--out", str(tmp / "live"), "--capture", str(tmp / "cap.bin"))
    return tmp, p


def test_simulate_runs_the_chain_over_a_pty_and_writes_mcap(simulated_run):
    tmp, p = simulated_run
    assert p.returncode == 0, p.stderr
    files = list((tmp / "live").glob("*.mcap"))
    assert len(files) == 1 and not list((tmp / "live").glob("*.part"))
    assert f"MCAP log: {files[0]}" in p.stderr
    assert "/dev/pts/" in p.stderr                           # a real pseudo-terminal
    status = [ln for ln in p.stderr.splitlines() if ln.startswith("[") and "S=" in ln]
    assert status and "ch0 S=" in status[-1] and "ch1 S=" in status[-1]
    msgs = read_messages(files[0])
    topics = {t for t, _, _ in msgs}
    assert {"/cm/ch0/severity", "/cm/ch1/severity", "/cm/events", "/cm/diagnostics"} <= topics
    sev = [m for t, _, m in msgs if t == "/cm/ch0/severity"]
    assert 37 <= len(sev) <= 40
    # the degrading scenario squeezed into 40 s still rises through the levels
    assert max(m["severity_index"] for m in sev) >= 0.5
    diag = [m for t, _, m in msgs if t == "/cm/diagnostics"]
    assert diag[-1]["link"]["frames_rms"] > 3500 and diag[-1]["link"]["crc_failures"] == 0
    assert assert_messages_match_their_schemas(files[0]) == {
        "cmsensord.Severity", "cmsensord.Event", "cmsensord.Diagnostics", "foxglove.Log",
        "cmsensord.Indicators"}


def test_replaying_the_capture_gives_the_live_messages(simulated_run, tmp_path):
    tmp, p = simulated_run
    assert p.returncode == 0, p.stderr
    r = cmsensord("replay", str(tmp / "cap.bin"), "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    live = read_messages(next((tmp / "live").glob("*.mcap")))
    replayed = read_messages(next(tmp_path.glob("*.mcap")))
    a, b = comparable(live), comparable(replayed)
    assert len(a) > 80
    assert a == b


def test_simulate_help_lists_the_scenarios():
    p = cmsensord("--simulate", "--help")
    assert p.returncode == 0
    for name in ("healthy", "faulty", "degrading", "spikes"):
        assert name in p.stdout


def test_sigterm_finishes_the_mcap_file_promptly(tmp_path):
    proc = spawn([sys.executable, "-m", "cmsensord", "--simulate", "--duration", "3600",
                             "--speed", "5", "--out", str(tmp_path)], stderr=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=ENV)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not list(tmp_path.glob("*.part")):
        time.sleep(0.1)
    time.sleep(2.5)
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=10)
    elapsed = time.monotonic() - t0
    assert elapsed < 2.0, elapsed
    assert proc.returncode == 0, err
    files = list(tmp_path.glob("*.mcap"))
    assert len(files) == 1 and not list(tmp_path.glob("*.part"))
    msgs = read_messages(files[0])
    assert any(t == "/cm/ch0/severity" for t, _, _ in msgs)
    assert any(t == "/cm/events" and m["kind"] == "stop" and "SIGTERM" in m["message"] for t, _, m in msgs)


def test_record_captures_the_bytes_of_a_port(tmp_path):
    with board_on_pty("--scenario", "healthy", "--speed", "10", "--duration", "60") as port:
        out = tmp_path / "cap.bin"
        r = cmsensord("record", "--port", port, "--out", str(out), "--duration", "1.5")
        assert r.returncode == 0, r.stderr
        frames, counters = iter_frames(out.read_bytes())
        assert len(frames) > 500
        assert counters.crc_failures == 0 and counters.frames_lost == 0


def test_record_onto_a_full_disk_says_so_and_exits_1(tmp_path):
    """`record --out /dev/full` (every write: no space left): the error said once as it happens
    and in the last line, exit 1 (the buffered bytes' write at the file's close raised a traceback)."""
    with board_on_pty("--scenario", "healthy", "--speed", "10", "--duration", "60") as port:
        r = cmsensord("record", "--port", port, "--out", "/dev/full", "--duration", "1.5")
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    lines = r.stderr.splitlines()
    assert lines[-2] == "cmsensord record: capture file: No space left on device; stopping", r.stderr
    assert lines[-1].startswith("capture: /dev/full (") and lines[-1].endswith(
        "); incomplete: capture file: No space left on device (the bytes before it are in the file; free space "
        "or give another --out, and record again)"), r.stderr


def test_daemon_runs_on_the_configured_port_and_follows_the_board(tmp_path):
    """`cmsensord --config FILE` on a board's pty: channels from the board, clean SIGTERM."""
    with board_on_pty("--scenario", "faulty", "--channels", "3", "--speed", "10") as port:
        cfg = tmp_path / "cmsensord.yaml"
        cfg.write_text(f"link:\n  port: {port}\noutput:\n  dir: {tmp_path / 'logs'}\n"
                       "  akf_trace: true\n  status_line: false\n")
        d = spawn([sys.executable, "-m", "cmsensord", "--config", str(cfg)],
                             stderr=subprocess.PIPE, text=True, env=ENV)
        time.sleep(4.0)
        d.send_signal(signal.SIGTERM)
        _, err = d.communicate(timeout=10)
        assert d.returncode == 0, err
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    topics = {t for t, _, _ in msgs}
    assert {"/cm/ch0/severity", "/cm/ch1/severity", "/cm/ch2/severity",
            "/cm/ch0/akf", "/cm/ch2/akf"} <= topics
    akf = [m for t, _, m in msgs if t == "/cm/ch1/akf"]
    assert len(akf) > 1000 and all(m["filter"] == 10 for m in akf)
    assert "cmsensord.AkfTrace" in assert_messages_match_their_schemas(
        next((tmp_path / "logs").glob("*.mcap")))


def test_close_orders_through_the_pty_meet_the_papers_bounds(tmp_path):
    """The whole chain: 25 kHz RAW frames and TACHO over a real pty, speed from the tacho,
    decimation, tracker; smoothed orders above 800 rpm within 5 % (order 4) and 3 % (4.2)."""
    p = cmsensord("--simulate", "--scenario", "close_orders", "--duration", "5", "--speed", "1",
                  "--out", str(tmp_path))
    assert p.returncode == 0, p.stderr
    msgs = read_messages(next(tmp_path.glob("*.mcap")))
    smoothed = [m for t, _, m in msgs if t == "/cm/ch0/orders" and m["method"] == "smoothed"]
    assert len(smoothed) >= 40
    worst = {"o4": 0.0, "o4_2": 0.0}
    n = 0
    for m in smoothed:
        rpm = m["speed_rpm"]
        if not m["valid"] or not 800 <= rpm <= 2950:
            continue
        n += 1
        # Yeh, Pan & Le's signal 2: order-4 RMS 10 rpm/3000, order-4.2 RMS 2 + 10 rpm/3000 (linear in
        # time, so the RMS over a 0.1 s block is that at the block's mean speed)
        truth = {"o4": 10.0 * rpm / 3000.0, "o4_2": 2.0 + 10.0 * rpm / 3000.0}
        for o in m["orders"]:
            if o["name"] in worst:
                worst[o["name"]] = max(worst[o["name"]], abs(o["rms"] - truth[o["name"]]) / truth[o["name"]] * 100)
    assert n >= 25
    assert worst["o4"] < 5.0 and worst["o4_2"] < 3.0, worst
