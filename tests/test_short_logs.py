"""A finished-named ``.mcap`` shorter than the 8-byte MCAP magic (a copy interrupted at 0 bytes,
cut inside the magic, a few bytes of something else): ``cmsensord summary`` and ``cmsensord
report`` say the same one line on it, and neither reads it as a log being written; a log cut
inside a chunk of one moment's messages says what such a chunk holds."""

from __future__ import annotations

import html

import pytest

from cmsensord.sinks.mcap_chunks import MAGIC
from cmsensord.sinks.mcap_file import McapSink
from cmsensord.sinks.mcap_read import read_messages
from processes import cmsensord, run_module
from test_report import SCHEMA_OF, _chunks

#: file -> (its bytes, the line both commands say on it)
SHORT = {
    "cmsensord-20261130T170000Z.mcap": (b"", "empty file (0 bytes): no MCAP data"),
    "cmsensord-20261130T170001Z.mcap": (MAGIC[:5],
                                        "cut short at byte 5, inside the 8-byte MCAP magic: no record in it"),
    "cmsensord-20261130T170002Z.mcap": (b"junk", "not an MCAP file (bad magic)"),
}


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """A replayed log beside the short files."""
    tmp = tmp_path_factory.mktemp("short")
    r = run_module("firmware_sim", "--scenario", "healthy", "--duration", "20", "--out", str(tmp / "h.bin"))
    assert r.returncode == 0, r.stderr
    r = cmsensord("replay", str(tmp / "h.bin"), "--out", str(tmp / "logs"))
    assert r.returncode == 0, r.stderr
    for name, (data, _) in SHORT.items():
        (tmp / "logs" / name).write_bytes(data)
    return tmp / "logs"


@pytest.mark.parametrize("name", list(SHORT))
def test_summary_of_a_file_shorter_than_the_magic_is_its_one_line_and_exit_2(logs, name):
    path, text = logs / name, SHORT[name][1]
    p = cmsensord("summary", str(path))
    assert (p.returncode, p.stderr.splitlines()) == (2, [f"cmsensord: {path}: {text}"])
    if SHORT[name][0] != b"junk":                # an MCAP file cut short: its summary too, as one cut later
        assert {f"error: {text}", "messages: 0"} <= set(p.stdout.splitlines())


@pytest.mark.parametrize("name", list(SHORT))
def test_report_of_a_file_shorter_than_the_magic_alone_is_the_same_line(logs, tmp_path, name):
    path, text = logs / name, SHORT[name][1]
    p = cmsensord("report", str(path), "--out", str(tmp_path / "r.html"))
    assert (p.returncode, p.stderr.splitlines()) == (2, [f"cmsensord: {path}: {text}"])
    assert not (tmp_path / "r.html").exists()


def test_report_beside_a_log_says_that_line_on_each_and_goes_on(logs, tmp_path):
    out = tmp_path / "r.html"
    p = cmsensord("report", str(logs), "--out", str(out))
    assert p.returncode == 0, p.stderr
    empty = [name for name, (data, _) in SHORT.items() if not data]     # said together (summary_many)
    assert [line for line in p.stderr.splitlines() if line.startswith("cmsensord:")] == [
        f"cmsensord: report: 1 empty file(s) (0 bytes): {logs / empty[0]}: left out"] + [
        f"cmsensord: report: {logs / name}: {text}; the report holds its 0 message(s) before that"
        for name, (data, text) in SHORT.items() if data]
    page = out.read_text(encoding="utf-8")
    for name, (data, text) in SHORT.items():
        state = f"{'damaged: ' if data == b'junk' else ''}{text}; read up to there"
        assert f"<td>{html.escape(str(logs / name))}</td><td class=\"n\">{len(data)}</td>" \
               f"<td class=\"n\">0</td><td>{html.escape(state)}</td>" in page


def test_a_log_cut_inside_a_chunk_of_one_moment_says_so(tmp_path):
    """A log written a chunk a second, as the daemon writes it, cut inside a chunk whose messages
    all carry one stamp (a capture's, 774 kB of it on a real board): it said 'its messages over
    0.0 s of log time lost'; it says what such a chunk holds."""
    r = run_module("firmware_sim", "--scenario", "healthy", "--duration", "6", "--out", str(tmp_path / "h.bin"))
    assert r.returncode == 0, r.stderr
    r = cmsensord("replay", str(tmp_path / "h.bin"), "--out", str(tmp_path / "logs"))
    assert r.returncode == 0, r.stderr
    msgs = read_messages(next((tmp_path / "logs").glob("*.mcap")))
    clock = [0.0]
    sink = McapSink(tmp_path / "live", clock=lambda: clock[0])
    for k, (topic, t, msg) in enumerate(msgs):        # the first message alone, a second later
        clock[0] = t / 1e9 + (0.0 if k == 0 else 1.5)
        sink.write(topic, SCHEMA_OF[topic.rsplit("/", 1)[-1]], t, msg)
    whole = sink.close()
    data = whole.read_bytes()
    start, end = _chunks(data)[0]
    cut = tmp_path / "cut" / "cmsensord-20261201T000000Z.mcap"
    cut.parent.mkdir()
    cut.write_bytes(data[: (start + end) // 2])
    p = cmsensord("summary", str(cut))
    assert p.stderr.splitlines() == [
        f"cmsensord: {cut}: cut short at byte {(start + end) // 2:,}, inside the chunk at byte {start:,} "
        f"({(start + end) // 2 - start:,} of its {end - start:,} bytes; its messages of one moment of log time "
        "lost (a capture's waveform and spectra, say)), no footer"], p.stderr
