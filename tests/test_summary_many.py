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
