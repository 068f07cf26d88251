"""`cmsensord summary` of several logs or a directory: each file's summary in the order the
files were opened (it took one file: "is a directory, not an MCAP file"); JSON a list; the exit
status the worst; a name that is no log one line."""

from __future__ import annotations

import json

from processes import cmsensord, run_module


def _two_logs(tmp_path):
    cap = tmp_path / "cap.bin"
    assert run_module("firmware_sim", "--scenario", "healthy", "--duration", "120", "--out", str(cap)).returncode == 0
    for _ in range(2):                  # two runs into one directory
        assert cmsensord("replay", str(cap), "--out", str(tmp_path / "logs")).returncode == 0
    files = sorted((tmp_path / "logs").glob("*.mcap"), key=lambda f: f.stat().st_mtime_ns)   # as written
    assert len(files) == 2
    return files


def test_a_directory_is_each_of_its_logs_in_order(tmp_path):
    files = _two_logs(tmp_path)
    p = cmsensord("summary", str(tmp_path / "logs"))
    assert p.returncode == 0, p.stderr
    heads = [ln.removeprefix("== ") for ln in p.stdout.splitlines() if ln.startswith("== ")]
    assert heads == [str(f) for f in files]
    assert p.stdout.count("\npath: ") + p.stdout.startswith("path: ") == len(files)
    p = cmsensord("summary", "--json", str(files[1]), str(files[0]))
    assert p.returncode == 0, p.stderr
    assert [i["path"] for i in json.loads(p.stdout)] == [str(files[1]), str(files[0])]


def test_the_worst_status_and_one_line_for_what_is_no_log(tmp_path):
    files = _two_logs(tmp_path)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    p = cmsensord("summary", str(files[0]), str(junk))
    assert p.returncode == 2
    assert p.stderr == f"cmsensord: {junk}: not an MCAP file (bad magic)\n", p.stderr
    p = cmsensord("summary", str(tmp_path / "nothing"))
    assert p.returncode == 2 and p.stderr == f"cmsensord: {tmp_path / 'nothing'}: file not found\n"
    (tmp_path / "empty").mkdir()
    p = cmsensord("summary", str(tmp_path / "empty"))
    assert p.returncode == 2
    assert p.stderr == f"cmsensord: {tmp_path / 'empty'}: no MCAP logs (*.mcap, *.mcap.part) in this directory\n"


def test_thousands_of_empty_logs_in_a_directory_are_one_line(tmp_path):
    # a crash loop that opened a log each time leaves thousands of 0-byte .mcap files: summary
    # printed a summary and a line each (tens of thousands of lines), report a line each
    cap = tmp_path / "cap.bin"
    assert run_module("firmware_sim", "--scenario", "healthy", "--duration", "10", "--out", str(cap)).returncode == 0
    logs = tmp_path / "logs"
    assert cmsensord("replay", str(cap), "--out", str(logs)).returncode == 0
    (log,) = logs.glob("*.mcap")
    empty = [logs / f"cmsensord-20261130T17{k // 60:02d}{k % 60:02d}Z.mcap" for k in range(3000)]
    for f in empty:
        f.touch()
    said = f"3,000 empty file(s) (0 bytes): {', '.join(map(str, empty[:5]))}, ... (2,995 more)"
    p = cmsensord("summary", str(logs))
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines() == [f"cmsensord: summary: {said}: left out"]
    assert p.stdout.startswith(f"path: {log}\n") and "== " not in p.stdout
    p = cmsensord("report", str(logs), "--out", str(tmp_path / "r.html"))
    assert p.returncode == 0, p.stderr
    assert [ln for ln in p.stderr.splitlines() if ln.startswith("cmsensord")] == [
        f"cmsensord: report: {said}: left out"]
    assert p.stderr.splitlines()[-1].endswith(" messages from 1 file(s))"), p.stderr
    log.unlink()
    for cmd in (["summary", str(logs)], ["report", str(logs), "--out", str(tmp_path / "r.html")]):
        p = cmsensord(*cmd)
        assert (p.returncode, p.stderr) == (2, f"cmsensord: {said}: no MCAP data in them\n")
