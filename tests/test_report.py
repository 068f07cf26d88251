"""``cmsensord report``: logs of simulated boards (replayed as a user would) -> an HTML page whose
figures, their axes and their PNGs are checked structurally; ``.part`` files; matplotlib missing;
a headless Chromium screenshot; ``cmsensord summary`` in ISO time with event lines."""

from __future__ import annotations

import html
import json
import re
import shutil
import struct
import subprocess
import sys
from datetime import datetime
from pathlib import Path

import pytest

from cmsensord.report.fast_read import FastScan
from cmsensord.sinks.mcap_chunk_check import check_chunk
from cmsensord.sinks.mcap_file import McapSink
from cmsensord.sinks.mcap_read import iter_messages_at, read_messages
from processes import ENV, cmsensord, on_terminal, run_module

SCHEMA_OF = {"events": "event", "diagnostics": "diagnostics", "severity": "severity", "orders": "orders",
             "indicators": "indicators", "log": "log", "alarms": "alarms"}

Image = pytest.importorskip("PIL.Image", reason="Pillow comes with matplotlib, the report extra")


def _replayed(tmp: Path, name: str, *sim_args: str) -> Path:
    """A firmware_sim capture replayed through `cmsensord replay`: the log directory."""
    cap = tmp / f"{name}.cap"
    p = run_module("firmware_sim", "--out", str(cap), *sim_args)
    assert p.returncode == 0, p.stderr
    out = tmp / name
    p = cmsensord("replay", str(cap), "--out", str(out))
    assert p.returncode == 0, p.stderr
    return out


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("report_logs")
    return {
        "faulty_raw": _replayed(tmp, "faulty_raw", "--scenario", "faulty", "--mode", "raw", "--tacho",
                                "--duration", "20"),
        "degrading_rms": _replayed(tmp, "degrading_rms", "--scenario", "degrading", "--duration", "120"),
        "close_orders": _replayed(tmp, "close_orders", "--scenario", "close_orders", "--mode", "raw",
                                  "--tacho"),
    }


def _report(tmp_path: Path, *logs: Path) -> tuple[subprocess.CompletedProcess, str, dict[str, dict]]:
    out = tmp_path / "report.html"
    p = cmsensord("report", *map(str, logs), "--out", str(out), "--png", str(tmp_path / "png"))
    assert p.returncode == 0, p.stderr
    page = out.read_text(encoding="utf-8")
    metas = {m["id"]: m for m in json.loads(re.search(
        r'<script type="application/json" id="figures">(.*?)</script>', page, re.S).group(1))}
    return p, page, metas


def _log_span(log_dir: Path) -> tuple[str, str]:
    """Local start and end (ISO, seconds) of the log as `cmsensord summary --json` gives them."""
    info = json.loads(cmsensord("summary", "--json", str(next(log_dir.glob("*.mcap")))).stdout)
    return tuple(datetime.fromtimestamp(info[k] / 1e9).isoformat(timespec="seconds")  # type: ignore[return-value]
                 for k in ("start_ns", "end_ns"))


def test_raw_report_has_severity_indicators_with_zones_and_orders(logs, tmp_path):
    p, page, metas = _report(tmp_path, logs["faulty_raw"])
    assert set(metas) == {"ch0-severity", "ch0-indicators", "ch0-orders"}
    assert p.stderr.strip().splitlines()[-1].startswith(f"report: {tmp_path / 'report.html'} (3 figures,")
    for fid, meta in metas.items():                   # each figure inline, with its metadata beside it
        assert f'id="{fid}" data-meta="{html.escape(json.dumps(meta), quote=True)}"' in page
        png = Image.open(tmp_path / "png" / f"{fid}.png")
        png.load()
        assert png.size[0] > 800 and json.loads(png.text["Description"]) == meta
    assert page.count('src="data:image/png;base64,') == 3 and "http://" not in page and "https://" not in page
    [sev] = metas["ch0-severity"]["axes"]          # the paper's index alone: no level / baseline
    assert sev["ylim"] == [0.0, 1.05] and sev["lines"][0] == "severity index"
    start, end = _log_span(logs["faulty_raw"])
    assert start <= sev["xlim_local"][0] < sev["xlim_local"][1] <= end
    ind = metas["ch0-indicators"]
    assert ind["main"] == "velocity_rms_mm_s" and ind["zones"] is True      # the faulty motor: zone D
    assert ind["axes"][0]["ylabel"] == "velocity RMS [mm/s]" and ind["axes"][0]["ylim"][1] >= 4.5 * 1.3
    assert ind["axes"][-1]["lines"] == ["kurtosis", "crest_factor"]
    orders = metas["ch0-orders"]             # the motor runs at 1720 rpm: bars per order at that speed
    assert orders["speed_rpm"][0] <= 1720 <= orders["speed_rpm"][1] and orders["axes"][0]["xlabel"] == "order"
    assert orders["orders"] == ["1x", "2x", "3x", "4x"]


def test_rms_report_and_a_run_up(logs, tmp_path):
    _, page, metas = _report(tmp_path, logs["degrading_rms"], logs["close_orders"])
    assert set(metas) == {"ch0-severity", "ch0-indicators", "ch0-orders", "ch0-campbell"}   # one channel in both
    assert metas["ch0-indicators"]["main"] == "velocity_rms_mm_s"           # the RAW log gives velocity
    orders = metas["ch0-orders"]["axes"][0]            # close_orders: a run-up 0 -> 3000 rpm
    assert orders["xlabel"] == "shaft speed [rpm]" and orders["xlim"][0] < 500 and orders["xlim"][1] > 2500
    assert orders["lines"] == ["order 1x", "order 2x", "order 3x", "order 4x"]   # the default orders
    campbell = metas["ch0-campbell"]                   # order frequency over speed, coloured by order RMS
    ax = campbell["axes"][0]
    assert ax["xlabel"] == "shaft speed [rpm]" and ax["ylabel"] == "frequency [Hz]"
    assert ax["xlim"][0] < 500 and ax["xlim"][1] > 2500 and campbell["orders"] == ["1x", "2x", "3x", "4x"]
    lo, hi = campbell["speed_rpm"]                     # 4x at the top speed: 4 x rpm / 60 Hz, within the y axis
    assert 4 * 2500 / 60 < campbell["freq_hz"][1] <= 4 * hi / 60 + 1 and ax["ylim"][1] >= campbell["freq_hz"][1]
    assert campbell["rms"][1] > campbell["rms"][0] >= 0
    png = Image.open(tmp_path / "png" / "ch0-campbell.png")
    png.load()
    assert json.loads(png.text["Description"]) == campbell
    assert "failure" in page and "<th>local time</th>" in page
    (tmp_path / "rms").mkdir()
    rms_only = _report(tmp_path / "rms", logs["degrading_rms"])[2]
    assert rms_only["ch0-indicators"]["main"] == "accel_rms" and "ch0-orders" not in rms_only


def test_title_option_heads_the_page_and_names_its_tab(logs, tmp_path):
    """`--title` replaces the default (`cmsensord report` and the time span) in the browser's tab and
    the page's heading, HTML-escaped."""
    out = tmp_path / "titled.html"
    p = cmsensord("report", str(logs["degrading_rms"]), "--out", str(out), "--title", 'Pump 3 <north> & "east"')
    assert p.returncode == 0, p.stderr
    page = out.read_text(encoding="utf-8")
    escaped = "Pump 3 &lt;north&gt; &amp; &quot;east&quot;"
    assert f"<title>{escaped}</title>" in page and f"<h1>{escaped}</h1>" in page
    assert "cmsensord report" not in page and "<north>" not in page

def test_events_table_in_local_time_and_link_summary(logs, tmp_path):
    _, page, _ = _report(tmp_path, logs["degrading_rms"])
    info = json.loads(cmsensord("summary", "--json", str(next(logs["degrading_rms"].glob("*.mcap")))).stdout)
    first = info["events"][0]
    when = datetime.fromtimestamp(first["time_ns"] / 1e9).isoformat(sep=" ", timespec="milliseconds")
    assert f'<td class="t">{when}</td><td>{first["kind"]}</td>' in page
    assert str(first["time_ns"]) not in page
    assert '<tr><td>frames_rms</td><td class="n">12,000</td></tr>' in page      # 120 s at 100 Hz
    assert "complete</td></tr>" in page


def test_a_part_file_is_read_up_to_its_last_complete_record(logs, tmp_path):
    """The log of a daemon that died: its .part file, one chunk a second, ending inside a chunk."""
    whole = next(logs["faulty_raw"].glob("*.mcap"))
    clock = [0.0]
    sink = McapSink(tmp_path / "writing", clock=lambda: clock[0])
    for topic, t, msg in read_messages(whole):
        clock[0] = t / 1e9                  # log time: a chunk is finished every second
        sink.write(topic, SCHEMA_OF[topic.rsplit("/", 1)[-1]], t, msg)
    (part_now,) = (tmp_path / "writing").glob("*.mcap.part")
    data = part_now.read_bytes()            # as the file is while the daemon writes it
    sink.close()
    part = tmp_path / "logs" / "cut.mcap.part"
    part.parent.mkdir()
    part.write_bytes(data[: len(data) - 100])
    p, page, metas = _report(tmp_path, part.parent)
    assert "ch0-severity" in metas
    assert "unfinished (read up to its last complete record)" in page
    n = int(re.search(r"([0-9,]+) messages from 1 file", p.stderr).group(1).replace(",", ""))
    full = json.loads(cmsensord("summary", "--json", str(whole)).stdout)["messages"]
    assert 0 < n < full and n == json.loads(cmsensord("summary", "--json", str(part)).stdout)["messages"]


def test_without_matplotlib_one_line_says_how_to_install_it(logs, tmp_path):
    code = ("import sys; sys.modules['matplotlib'] = None; from cmsensord.cli import main; "
            f"sys.exit(main(['report', {str(logs['faulty_raw'])!r}, '--out', {str(tmp_path / 'r.html')!r}]))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=60)
    assert p.returncode == 2
    assert p.stderr.splitlines() == ["cmsensord: report needs matplotlib: install it with "
                                     "pip install 'cmsensord[report]' (or pip install matplotlib)"]
    assert not (tmp_path / "r.html").exists()


def test_the_daemon_never_imports_matplotlib(logs, tmp_path):
    code = ("import sys; from cmsensord.cli import main; rc = main(['replay', sys.argv[1], '--out', sys.argv[2]]);"
            "print(sorted(m for m in sys.modules if m.startswith(('matplotlib', 'PIL', 'cmsensord.report.'))))")
    cap = logs["faulty_raw"].parent / "faulty_raw.cap"
    p = subprocess.run([sys.executable, "-c", code, str(cap), str(tmp_path)], capture_output=True, text=True,
                       env=ENV, timeout=120)
    assert p.returncode == 0, p.stderr
    # only the times of `summary` (a replay builds its own parser alone): no figures, no matplotlib
    assert p.stdout.strip() == "['cmsensord.report.localtime']"


def test_missing_log_is_one_line(tmp_path):
    p = cmsensord("report", str(tmp_path / "nothing"), "--out", str(tmp_path / "r.html"))
    assert p.returncode == 2 and p.stderr.strip() == f"cmsensord: {tmp_path / 'nothing'}: file not found"
    p = cmsensord("report", str(tmp_path), "--out", str(tmp_path / "r.html"))
    assert p.stderr.strip() == f"cmsensord: {tmp_path}: no MCAP logs (*.mcap, *.mcap.part) in this directory"


def test_a_report_onto_a_full_disk_names_its_file(logs):
    """/dev/full (every write: no space left): the line names the page (a write error of a full
    disk carries no file name: it said 'None: cannot write')."""
    p = cmsensord("report", str(logs["faulty_raw"]), "--out", "/dev/full")
    assert (p.returncode, p.stderr) == (2, "cmsensord: /dev/full: cannot write: No space left on device\n")


def test_a_file_that_is_not_mcap_is_one_line_and_no_report(tmp_path):
    junk = tmp_path / "song.wav"
    junk.write_bytes(b"RIFF" + bytes(range(256)) * 8)
    p = cmsensord("report", str(junk), "--out", str(tmp_path / "r.html"))
    assert p.returncode == 2 and p.stderr.strip() == f"cmsensord: {junk}: not an MCAP file (bad magic)"
    assert not (tmp_path / "r.html").exists()


def test_a_file_that_is_not_mcap_beside_logs_is_one_line_and_the_report_goes_on(logs, tmp_path):
    junk = tmp_path / "song.wav"
    junk.write_bytes(b"RIFF" + bytes(range(256)) * 8)
    p, page, metas = _report(tmp_path, junk, logs["degrading_rms"])
    assert [line for line in p.stderr.splitlines() if "song.wav" in line] == [
        f"cmsensord: report: {junk}: not an MCAP file (bad magic); the report holds its 0 message(s) before that"]
    assert "ch0-severity" in metas


def _chunks(data: bytes) -> list[tuple[int, int]]:
    """(offset, end) of each top-level chunk record of an MCAP file's bytes."""
    out, pos = [], 8
    while pos + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x06:
            out.append((pos, pos + 9 + length))
        if opcode == 0x02:
            return out
        pos += 9 + length
    return out


def _chunked(log_dir: Path, tmp_path: Path) -> Path:
    """The log of ``log_dir`` written again as the daemon writes it live: a chunk a second."""
    clock = [0.0]
    sink = McapSink(tmp_path / "chunked", clock=lambda: clock[0])
    for topic, t, msg in read_messages(next(log_dir.glob("*.mcap"))):
        clock[0] = t / 1e9
        sink.write(topic, SCHEMA_OF[topic.rsplit("/", 1)[-1]], t, msg)
    return sink.close()


def test_the_fast_reader_gives_what_the_lenient_reader_gives(logs, tmp_path):
    """The report's reader against the plain lenient one: every log, and an unfinished file
    cut inside a chunk, message for message."""
    whole = _chunked(logs["faulty_raw"], tmp_path)
    cut = tmp_path / "cut.mcap.part"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size * 2 // 3])
    for log in [next(logs[k].glob("*.mcap")) for k in sorted(logs)] + [whole, cut]:
        scan = FastScan(log)
        fast = [(topic, t, bytes(data)) for topic, t, data, _ in scan.messages()]
        plain = [(topic, t, bytes(data)) for topic, t, data, _ in iter_messages_at(log)]
        assert fast == plain and len(plain) > 50, log
        assert scan.error is None and scan.skipped == [] and scan.complete == (log != cut), log


def _hit(logs, tmp_path: Path) -> tuple[Path, int, int]:
    """The chunked faulty_raw log with its second chunk hit (bit rot on an SD card, say):
    (the file, the chunk's offset, the messages of the intact chunks)."""
    whole = _chunked(logs["faulty_raw"], tmp_path)
    full = len(read_messages(whole))
    data = bytearray(whole.read_bytes())
    start, end = _chunks(bytes(data))[1]
    _chunk, _index, n, _schemas, _channels, dropped = check_chunk(bytes(data[start:end]), {})
    for i in range(start + 80, start + 90):
        data[i] ^= 0x55
    hit = tmp_path / "logs" / "hit.mcap"
    hit.parent.mkdir()
    hit.write_bytes(bytes(data))
    return hit, start, full - n - dropped


def test_a_damaged_chunk_is_read_past_and_one_line_says_so(logs, tmp_path):
    """A log with its second chunk hit: the report holds every message of the intact chunks
    after it, and one line on stderr and the file table say what was skipped."""
    hit, start, kept = _hit(logs, tmp_path)
    p, page, metas = _report(tmp_path, hit)
    why = rf"the first: bad chunk at byte {start}: cannot decompress \(zstd\): [^;)]+"   # zstd's own words
    [line] = [line for line in p.stderr.splitlines() if "hit.mcap" in line]
    assert re.fullmatch(rf"cmsensord: report: {re.escape(str(hit))}: 1 damaged stretch\(es\) skipped \({why}\); "
                        rf"the report holds the {kept:,} message\(s\) of its intact chunks", line), line
    assert f"{kept:,} messages from 1 file" in p.stderr and "ch0-severity" in metas
    assert re.search(rf"damaged: 1 stretch\(es\) skipped \({why}\); complete", page)


def test_summary_and_the_lenient_reader_read_past_a_damaged_chunk(logs, tmp_path):
    """`cmsensord summary` of a log with its second chunk hit counts the messages of every intact
    chunk, says what it skipped and that the file is complete (guards against ending at the damage:
    the messages of the first chunk, "error: bad record ..."); read_messages(lenient=True) and
    the plain lenient reader give what the report's reader gives."""
    hit, start, kept = _hit(logs, tmp_path)
    info = json.loads(cmsensord("summary", "--json", str(hit)).stdout)
    assert info["messages"] == kept and info["complete"] and info["error"] is None
    assert info["valid_bytes"] == info["file_bytes"]
    [skipped] = info["skipped"]
    assert skipped.startswith(f"bad record at byte {start}: "), skipped
    assert f"\nerror: None\nskipped: 1 item(s)\n  {skipped}\n" in cmsensord("summary", str(hit)).stdout
    fast = [(topic, t, bytes(data)) for topic, t, data, _ in FastScan(hit).messages()]
    plain = [(topic, t, bytes(data)) for topic, t, data, _ in iter_messages_at(hit)]
    assert plain == fast and len(plain) == kept == len(read_messages(hit, lenient=True))


def test_summary_prints_iso_times_and_event_lines(logs):
    log = next(logs["degrading_rms"].glob("*.mcap"))
    info = json.loads(cmsensord("summary", "--json", str(log)).stdout)
    text = cmsensord("summary", str(log)).stdout
    start = datetime.fromtimestamp(info["start_ns"] / 1e9).astimezone().isoformat(timespec="milliseconds")
    assert f"\nstart: {start}\n" in text and "start_ns" not in text
    onset = next(e for e in info["events"] if e["kind"] == "anomaly_onset")
    when = datetime.fromtimestamp(onset["time_ns"] / 1e9).astimezone().isoformat(timespec="milliseconds")
    assert f"\n  {when} anomaly_onset ch0: {onset['message'][len('ch0: '):]}\n" in text
    assert "{'time_ns'" not in text


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(_chromium() is None, reason="no chromium (Debian package chromium) on this machine")
def test_headless_chromium_renders_the_report(logs, tmp_path):
    _report(tmp_path, logs["faulty_raw"])
    shot = tmp_path / "shot.png"
    p = subprocess.run([_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                        "--window-size=1200,1600", f"--screenshot={shot}", (tmp_path / "report.html").as_uri()],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    img = Image.open(shot).convert("L")
    assert img.size == (1200, 1600)
    lo, hi = img.getextrema()
    assert hi - lo > 200                            # not a blank page: dark text and plot lines on white
    assert len(img.getcolors(maxcolors=1 << 20)) > 50


def test_progress_bar_on_a_terminal_only(logs, tmp_path):
    status, seen = on_terminal([sys.executable, "-m", "cmsensord", "report", str(logs["faulty_raw"]), "--out",
                                str(tmp_path / "r.html")], stdout=subprocess.PIPE)
    assert status == 0
    assert b"\r[" + b"#" * 30 + b"] 100%" in seen
    piped = cmsensord("report", str(logs["faulty_raw"]), "--out", str(tmp_path / "r2.html"))
    assert "[#" not in piped.stderr and piped.stderr.count("\n") == 1


def test_captured_waveform_spectrum_and_envelope_are_drawn(logs, tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("capture:\n  every_s: 6\n  pre_s: 1\n  post_s: 2\n  min_interval_s: 0\n")
    cap = logs["faulty_raw"].parent / "faulty_raw.cap"
    assert cmsensord("replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "logs")).returncode == 0
    _, page, metas = _report(tmp_path, tmp_path / "logs")
    captures = [m for m in metas.values() if m["kind"] == "capture"]
    # ticks at 6, 12 and 18 s of 20: the last one ends with the stream
    assert [m["id"] for m in captures] == ["ch0-capture-0", "ch0-capture-1", "ch0-capture-2"]
    for m in captures:
        assert m["trigger"] == "periodic" and m["parts"] == ["waveform", "spectrum", "envelope"]
        wave, spectrum, env = m["axes"]
        assert wave["xlabel"] == "time from trigger [s]" and wave["xlim"][0] <= -1 and 2 <= wave["xlim"][1] < 2.5
        assert spectrum["xlabel"] == "frequency [Hz]" and 12000 < spectrum["xlim"][1] < 13500   # up to fs/2
        assert env["ylabel"] == "envelope spectrum\nRMS per bin [m/s²]" and 950 < env["xlim"][1] < 1100
    assert page.count('src="data:image/png;base64,') == 3 + 3


def _cut_replay(logs, tmp_path: Path) -> tuple[Path, str]:
    """A replay's log (its messages in one chunk, as a replay writes them) cut inside that chunk,
    as `head -c` leaves it: (the file, what the cut lost as the report and summary say it)."""
    data = next(logs["faulty_raw"].glob("*.mcap")).read_bytes()
    [(start, end)] = _chunks(data)
    first, last = struct.unpack_from("<QQ", data, start + 9)
    cut = tmp_path / "tr" / "cut.mcap"
    cut.parent.mkdir()
    cut.write_bytes(data[: (start + end) // 2])
    lost = (f"cut short at byte {(start + end) // 2:,}, inside the chunk at byte {start:,} "
            f"({(start + end) // 2 - start:,} of its {end - start:,} bytes; its messages over "
            f"{(last - first) / 1e9:.1f} s of log time lost), no footer")
    return cut, lost


def test_a_replay_cut_short_is_one_line_and_exit_2_when_nothing_could_be_read(logs, tmp_path):
    """A finished log cut short (no footer, its one chunk cut off): one line naming the file and
    what was lost; alone, that line is the error (exit 2, no page; not an empty page, exit 0);
    beside a good log, the report goes on."""
    cut, lost = _cut_replay(logs, tmp_path)
    out = tmp_path / "cut.html"
    p = cmsensord("report", str(cut), "--out", str(out))
    assert (p.returncode, p.stderr.splitlines()) == (2, [f"cmsensord: {cut}: {lost}"])
    assert not out.exists()
    p, page, metas = _report(tmp_path, cut, logs["degrading_rms"])
    assert f"cmsensord: report: {cut}: {lost}; the report holds its 0 message(s) before that" \
        in p.stderr.splitlines()
    assert "ch0-severity" in metas and html.escape(f"{lost}; read up to there") in page


def test_summary_of_a_replay_cut_short_says_what_was_lost(logs, tmp_path):
    """`cmsensord summary` of the cut log: the error is the cut (not `error: None`, exit 0),
    one line on stderr, exit 2 as nothing could be read; cut after its chunk, a warning, exit 0."""
    cut, lost = _cut_replay(logs, tmp_path)
    p = cmsensord("summary", str(cut))
    assert (p.returncode, p.stderr.splitlines()) == (2, [f"cmsensord: {cut}: {lost}"])
    assert f"\nerror: {lost}\n" in p.stdout and "\nmessages: 0\n" in p.stdout and "\ncut: " not in p.stdout
    info = json.loads(cmsensord("summary", "--json", str(cut)).stdout)
    assert (info["error"], info["cut"], info["messages"]) == (lost, lost, 0)
    data = next(logs["faulty_raw"].glob("*.mcap")).read_bytes()
    [(_, end)] = _chunks(data)
    cut.write_bytes(data[:end])                  # the chunk whole, what follows it lost
    p = cmsensord("summary", str(cut))
    n = json.loads(cmsensord("summary", "--json", str(cut)).stdout)["messages"]
    assert p.returncode == 0 and n > 50 and p.stderr.splitlines() == [
        f"cmsensord: summary: {cut}: cut short at byte {end:,}, after its last complete record: no footer "
        f"(anything written after it lost); the summary holds its {n:,} message(s) before that"]
