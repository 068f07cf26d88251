"""More capture triggers and what a capture's spectra show, through the commands a user types:
`cmsensord capture-now` to a running daemon on a simulated board (the capture holds pre_s + post_s
seconds of the received samples around the newest one), its one-line errors, a capture on an
operating-state change (`cmsensord replay` of a motor starting), and the shaft's 1x and the
bearing defect lines on the captured spectra and in `cmsensord report`'s figures."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import numpy as np
import pytest

from cmsensord.dsp.indicators.bearings import Geometry, defect_frequencies
from cmsensord.dsp.rms import rows_physical
from cmsensord.protocol import FrameType, decode_raw, decode_status, iter_frames
from cmsensord.service.control import SOCKET_NAME
from cmsensord.sinks.mcap_read import read_messages
from cmsensord.sinks.schemas import SCHEMAS
from foxglove_schema import message_problems
from processes import board_on_pty, cmsensord, run_module, start_daemon, stop
from test_capture import _input_raw

FS = 25000
S = 1_000_000_000
#: a 6206 bearing: the faulty motor's outer-race defect strikes at 3.58 x the shaft speed
BEARING = "bearings:\n  - {name: de, channel: ch0, elements: 9, ball_diameter: 9.525, pitch_diameter: 46}\n"
G = Geometry(9, 9.525, 46.0)


def _stamp(m: dict) -> int:
    return m["timestamp"]["sec"] * S + m["timestamp"]["nsec"]


def _valid(topic: str, schema: str, m: dict) -> None:
    import jsonschema
    jsonschema.validate(m, SCHEMAS[schema])
    assert not message_problems(m, SCHEMAS[schema]), (topic, message_problems(m, SCHEMAS[schema]))


def _received(cap: Path, first: int, n: int) -> np.ndarray:
    """Channel 0's samples [m/s²] of board samples first .. first + n - 1 as the capture file of
    the received bytes holds them (each one received)."""
    frames, _ = iter_frames(cap.read_bytes())
    st = next(decode_status(f.payload) for f in frames if f.type == FrameType.STATUS)
    x = np.full(n, np.nan)
    for f in frames:
        if f.type != FrameType.RAW or f.chan != 0:
            continue
        y = rows_physical(decode_raw(f.payload)[None, :], [st.scale[0]], [st.offset[0]])[0]
        a, b = max(first, f.t0_unwrapped), min(first + n, f.t0_unwrapped + len(y))
        if a < b:
            x[a - first:b - first] = y[a - f.t0_unwrapped:b - f.t0_unwrapped]
    assert np.isfinite(x).all()
    return x


def test_capture_now_keeps_pre_and_post_seconds_around_the_newest_sample(tmp_path):
    """A daemon on a faulty motor's board (RAW, tacho) with only manual captures: `cmsensord
    capture-now` says what it keeps; the log then holds exactly those samples, as received."""
    cfg = tmp_path / "cmsensord.yaml"
    received = tmp_path / "received.cap"
    conf = "capture:\n  triggers: [manual]\n  pre_s: 1\n  post_s: 2\n" + BEARING
    with board_on_pty("--scenario", "faulty", "--mode", "raw", "--tacho", "--duration", "30", "--speed", "2",
                      "--flow-control") as port:
        d = start_daemon(tmp_path, port, "--capture", str(received), config=conf)
        try:
            deadline = time.monotonic() + 60
            while not (tmp_path / "logs" / SOCKET_NAME).exists() and time.monotonic() < deadline:
                time.sleep(0.2)
            time.sleep(3.0)                     # more than pre_s of samples in the ring
            p = run_module("cmsensord", "capture-now", "--config", str(cfg))
            assert p.returncode == 0, p.stdout + p.stderr
            bad = run_module("cmsensord", "capture-now", "--channel", "nope", "--config", str(cfg))
            time.sleep(4.0)                     # post_s of board time (2x real time) and the writing
        finally:
            err = stop(d)
    line = p.stdout.strip()
    m = re.fullmatch(r"ch0: capturing 1 s before and 2 s after (\S+) \(RAW, from board index (\d+)\); "
                     r"written to the log in 2 s", line)
    assert m, line
    assert bad.returncode == 1 and bad.stderr == "cmsensord: capture-now: no channel named 'nope' (channels: ch0)\n"
    msgs = list(read_messages(next((tmp_path / "logs").glob("*.mcap"))))
    (wave,) = [x for t, _, x in msgs if t == "/cm/ch0/capture_waveform"]
    assert wave["trigger"] == {"kind": "manual", "message": "cmsensord capture-now"}
    assert wave["first_sample"] == int(m.group(2)) and len(wave["samples"]) == 3 * FS and wave["missing"] == 0
    np.testing.assert_allclose(wave["samples"], _received(received, wave["first_sample"], 3 * FS),
                               rtol=1e-6, atol=1e-5)
    assert "ch0: captured 3 s around manual (75000 samples, 0 lost)" in err
    spectra = [(t, x) for t, _, x in msgs if t in ("/cm/ch0/capture_spectrum", "/cm/ch0/capture_envelope")]
    assert len(spectra) == 2
    for t, s in spectra:                        # the speed over the capture and the lines at it
        _valid(t, "capture_spectrum", s)
        f_r = s["shaft_speed_rpm"] / 60
        assert s["speed_source"] == "tacho" and 1700 < s["shaft_speed_rpm"] < 1740
        want = [("1x", f_r)] + [(f"de {k.upper()}", hz) for k, hz in defect_frequencies(G, f_r)._asdict().items()]
        assert [(k["label"], k["freq_hz"]) for k in s["marks"]] == [(n, pytest.approx(hz, abs=1e-5)) for n, hz in want]


def test_capture_now_before_pre_s_is_held_says_when_to_try_again(tmp_path):
    """`cmsensord capture-now` with less than pre_s of samples received since the daemon started:
    not captured, saying why and in how many seconds of samples one can be (exit 1)."""
    cfg = tmp_path / "cmsensord.yaml"
    conf = "capture:\n  triggers: [manual]\n  pre_s: 30\n  post_s: 1\n"
    with board_on_pty("--scenario", "healthy", "--mode", "raw", "--duration", "30", "--flow-control") as port:
        d = start_daemon(tmp_path, port, config=conf)
        try:
            deadline = time.monotonic() + 60
            p = None
            while time.monotonic() < deadline:
                if (tmp_path / "logs" / SOCKET_NAME).exists():
                    p = run_module("cmsensord", "capture-now", "--config", str(cfg))
                    if "no samples received yet" not in p.stderr:
                        break
                time.sleep(0.2)
        finally:
            stop(d)
    assert p is not None and p.returncode == 1 and p.stderr == "", p
    m = re.fullmatch(r"ch0: not captured: its pre_s reaches back before the stream's start; "
                     r"try again in (\S+) s\n", p.stdout)
    assert m, p.stdout
    assert 20 < float(m.group(1)) <= 30


def test_capture_now_without_a_daemon_is_a_one_line_error(tmp_path):
    p = run_module("cmsensord", "capture-now", "--socket", str(tmp_path / "none.sock"))
    assert p.returncode == 1 and p.stdout == "" and p.stderr.count("\n") == 1
    assert p.stderr.startswith(f"cmsensord: no daemon answers on {tmp_path / 'none.sock'}: ")
    assert p.stderr.endswith("; a daemon started with --out DIR answers on --socket DIR/cmsensord.sock)\n")


def test_capture_now_to_a_daemon_without_captures_says_how_to_turn_them_on(tmp_path):
    cfg = tmp_path / "cmsensord.yaml"
    with board_on_pty("--scenario", "degrading", "--duration", "30", "--speed", "4") as port:
        d = start_daemon(tmp_path, port)
        try:
            deadline = time.monotonic() + 60
            while not (tmp_path / "logs" / SOCKET_NAME).exists() and time.monotonic() < deadline:
                time.sleep(0.2)
            p = run_module("cmsensord", "capture-now", "--config", str(cfg))
        finally:
            stop(d)
    assert p.returncode == 1 and p.stdout == ""
    assert p.stderr == ("cmsensord: capture-now: captures are off in this daemon's configuration: give "
                        "capture.triggers (e.g. [manual]) or capture.every_s\n")


OPERATING = "alarms:\n  operating: {source: speed, running_above: 600, startup_suppress_s: 2}\n"


@pytest.fixture(scope="module")
def starting(tmp_path_factory) -> Path:
    cap = tmp_path_factory.mktemp("starting") / "deg.cap"
    p = run_module("firmware_sim", "--out", str(cap), "--scenario", "degrading", "--mode", "raw", "--tacho",
                   "--duration", "12")
    assert p.returncode == 0, p.stderr
    return cap


def _replay(cap: Path, tmp: Path, yaml: str) -> list[tuple[str, int, dict]]:
    (tmp / "c.yaml").write_text(yaml)
    p = cmsensord("replay", str(cap), "--config", str(tmp / "c.yaml"), "--out", str(tmp / "logs"))
    assert p.returncode == 0, p.stderr
    return list(read_messages(next((tmp / "logs").glob("*.mcap"))))


def test_an_operating_state_change_triggers_a_capture(starting, tmp_path):
    """The motor starts (stopped -> starting at its first speed, running 2 s later): a capture
    on entering running holds pre_s + post_s seconds of the input around that event."""
    msgs = _replay(starting, tmp_path, OPERATING + "capture:\n  triggers: [operating_state]\n"
                   "  operating_states: [running]\n  pre_s: 2\n  post_s: 3\n  min_interval_s: 0\n")
    states = [x for t, _, x in msgs if t == "/cm/events" and x["kind"] == "operating_state"]
    assert [(e["details"]["previous"], e["details"]["state"]) for e in states] == \
        [("stopped", "starting"), ("starting", "running")]
    assert states[1]["message"] == "operating state starting -> running (speed 1720 rpm)"
    assert _stamp(states[1]) - _stamp(states[0]) == 2 * S
    for e in states:
        _valid("/cm/events", "event", e)
    (wave,) = [x for t, _, x in msgs if t == "/cm/ch0/capture_waveform"]
    assert wave["trigger"] == {"kind": "operating_state", "message": states[1]["message"]}
    assert _stamp(wave) == _stamp(states[1]) and len(wave["samples"]) == 5 * FS
    t0, x = _input_raw(starting)
    start = wave["first_sample"] - t0
    np.testing.assert_allclose(wave["samples"], x[start:start + 5 * FS], rtol=1e-6, atol=1e-5)
    assert not [x for t, _, x in msgs if t == "/cm/events" and x["kind"] == "capture_skipped"]


def test_every_operating_state_change_without_a_filter(starting, tmp_path):
    """Unfiltered, the start itself triggers too, 0.9 s into the stream: with pre_s 2 it reaches
    before the stream's start and is skipped, saying so; entering running is captured."""
    msgs = _replay(starting, tmp_path, OPERATING + "capture:\n  triggers: [operating_state]\n"
                   "  pre_s: 2\n  post_s: 1\n  min_interval_s: 0\n")
    kept = [x["trigger"]["message"] for t, _, x in msgs if t == "/cm/ch0/capture_waveform"]
    skipped = [x for t, _, x in msgs if t == "/cm/events" and x["kind"] == "capture_skipped"]
    states = [x for t, _, x in msgs if t == "/cm/events" and x["kind"] == "operating_state"]
    assert [x["message"] for x in skipped] == ["ch0: capture on operating_state skipped: its pre_s reaches back "
                                               "before the stream's start"]
    assert _stamp(skipped[0]) == _stamp(states[0])
    assert kept == ["operating state starting -> running (speed 1720 rpm)"]


def test_a_run_up_is_captured_as_it_reaches_running_speed(tmp_path):
    """close_orders runs up 0 -> 3000 rpm in 5 s (600 rpm a second): with running_above 1500 it
    starts running at the indicator record of 2-3 s; the capture of 2 s around it has the 1x
    mark at the tacho's speed during the capture, within the run-up's 1200-2400 rpm."""
    cap = tmp_path / "runup.cap"
    assert run_module("firmware_sim", "--out", str(cap), "--scenario", "close_orders", "--mode", "raw",
                      "--tacho").returncode == 0
    msgs = _replay(cap, tmp_path, "alarms:\n  operating: {source: speed, running_above: 1500}\n"
                   "capture: {triggers: [operating_state], pre_s: 1, post_s: 1, min_interval_s: 0}\n")
    (state,) = [x for t, _, x in msgs if t == "/cm/events" and x["kind"] == "operating_state"]
    assert state["message"] == "operating state stopped -> running (speed 1500 rpm)"
    first = next(_stamp(x) for t, _, x in msgs if t == "/cm/ch0/indicators")        # the record of 0-1 s
    assert _stamp(state) == first + 2 * S
    (wave,) = [x for t, _, x in msgs if t == "/cm/ch0/capture_waveform"]
    (spectrum,) = [x for t, _, x in msgs if t == "/cm/ch0/capture_spectrum"]
    assert _stamp(wave) == _stamp(spectrum) == _stamp(state) and len(wave["samples"]) == 2 * FS
    assert spectrum["speed_source"] == "tacho" and 1200 < spectrum["shaft_speed_rpm"] < 2400
    assert spectrum["marks"] == [{"label": "1x", "kind": "shaft",
                                  "freq_hz": pytest.approx(spectrum["shaft_speed_rpm"] / 60, abs=1e-5)}]


def test_an_operating_state_trigger_needs_an_operating_source(starting, tmp_path):
    (tmp_path / "c.yaml").write_text("capture:\n  triggers: [operating_state]\n")
    p = cmsensord("replay", str(starting), "--config", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "logs"))
    assert p.returncode == 78 and p.stderr.count("\n") == 1
    assert p.stderr.endswith("capture.triggers: operating_state needs alarms.operating.source speed or level "
                             "(and alarms.enabled) (got 'operating_state')\n")


Image = pytest.importorskip("PIL.Image", reason="Pillow comes with matplotlib, the report extra")


def test_the_report_marks_the_defect_lines_on_the_captured_spectra(tmp_path):
    """The faulty motor's outer-race defect: the report's capture figure has the 1x and the
    bearing's lines on its spectra, a zoom on the envelope spectrum where the highest peak is
    at the BPFO line, and the BPFO line's pixel column is drawn in its colour."""
    cap = tmp_path / "faulty.cap"
    assert run_module("firmware_sim", "--out", str(cap), "--scenario", "faulty", "--mode", "raw", "--tacho",
                      "--duration", "8").returncode == 0
    msgs = _replay(cap, tmp_path, "capture:\n  every_s: 4\n  pre_s: 1\n  post_s: 2\n" + BEARING)
    (env,) = [x for t, _, x in msgs if t == "/cm/ch0/capture_envelope"]
    bpfo = next(k["freq_hz"] for k in env["marks"] if k["kind"] == "bpfo")
    amp = np.array(env["amplitude"])
    f = env["freq_step_hz"] * np.arange(amp.size)
    band = (f > 5) & (f < 3.5 * max(k["freq_hz"] for k in env["marks"]))
    assert abs(f[band][np.argmax(amp[band])] / bpfo - 1) < 0.02       # the envelope's peak is at BPFO
    out = tmp_path / "r.html"
    p = cmsensord("report", str(tmp_path / "logs"), "--out", str(out), "--png", str(tmp_path / "png"))
    assert p.returncode == 0, p.stderr
    page = out.read_text(encoding="utf-8")
    metas = {m["id"]: m for m in json.loads(re.search(
        r'<script type="application/json" id="figures">(.*?)</script>', page, re.S).group(1))}
    fig = metas["ch0-capture-0"]
    assert fig["parts"] == ["waveform", "spectrum", "envelope", "envelope_zoom"]
    assert fig["marks"] == ["1x", "de FTF", "de BPFO", "de BPFI", "de BSF"]
    _, spectrum, whole, zoom = fig["axes"]
    labels = {f"{k['label']} {k['freq_hz']:.1f} Hz" for k in env["marks"]}
    for ax in (spectrum, whole, zoom):
        assert set(ax["lines"]) == labels
    assert zoom["xlim"] == [0.0, pytest.approx(3.5 * max(k["freq_hz"] for k in env["marks"]), abs=0.2)]
    img = np.asarray(Image.open(tmp_path / "png" / "ch0-capture-0.png").convert("RGB")).astype(int)
    left, top, right, bottom = zoom["box_px"]
    lo, hi = zoom["xlim"]

    def red_in_column(hz: float) -> int:
        """Pixels of the BPFO colour (#c62828, antialiased) in the zoom's pixel columns at hz."""
        x = round(left + (hz - lo) / (hi - lo) * (right - left))
        px = img[int(top) + 2:int(bottom) - 2, x - 1:x + 2]
        return int(((px[..., 0] - px[..., 1] > 80) & (px[..., 0] - px[..., 2] > 80)).sum())

    assert red_in_column(bpfo) > 0.4 * (bottom - top)                  # a dashed line through the axes
    assert red_in_column(bpfo * 1.25) == 0                              # and not elsewhere


def test_a_manual_capture_does_not_hold_back_the_triggers_after_it():
    """Someone's `capture-now` at 2 s, then the periodic trigger at 4 s with min_interval_s 60:
    it is kept (not skipped as '2 s after the last one', as an alarm's would then be too)."""
    from cmsensord.config import config_from_dict
    from cmsensord.monitor.processor import Processor
    from cmsensord.sinks.memory import ListSink
    from cmsensord.source import ByteStreamSource
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    data = Board(make_scenario("healthy", duration_s=8.0), BoardConfig(mode="raw")).generate(8.0)
    cfg = config_from_dict({"capture": {"triggers": ["manual"], "every_s": 4, "pre_s": 0.5, "post_s": 0.5,
                                        "min_interval_s": 60}})
    sink = ListSink()
    proc = Processor(cfg, sink)
    asked = None
    with ByteStreamSource.of(data, 4096) as source:
        for frames in source:
            proc.handle(frames)
            if asked is None and proc.adc_seconds >= 2.0:
                asked = proc.captures.manual(None)
    proc.finish()
    assert asked is not None and asked["ok"], asked
    kinds = [m["trigger"]["kind"] for t, _, m in sink.messages if t == "/cm/ch0/capture_waveform"]
    assert kinds == ["manual", "periodic"], kinds
