"""The log under systemd: sd-daemon priority prefixes when stderr is the journal, and -v / -vv.

Each test runs ``cmsensord`` as a process whose stderr is a pipe named by ``JOURNAL_STREAM``
(``<device>:<inode>``, as systemd sets it), and reads the lines it wrote.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from processes import ENV, spawn

PREFIX = re.compile(r"<[0-7]>")
#: a degrading motor squeezed into 60 simulated seconds: severity changes, a failure (a warning)
SIMULATE = ("--simulate", "--scenario", "degrading", "--duration", "60", "--speed", "30")


def _run(args, *, journal: bool = True, stream: str | None = None, timeout=120) -> tuple[int, list[str]]:
    """``python -m cmsensord ARGS`` with stderr on a pipe; JOURNAL_STREAM names that pipe
    (``journal``), or is ``stream``; returns (exit status, stderr lines)."""
    r, w = os.pipe()
    st = os.fstat(w)
    env = dict(ENV)
    env.pop("JOURNAL_STREAM", None)
    if journal:
        env["JOURNAL_STREAM"] = stream or f"{st.st_dev}:{st.st_ino}"
    proc = spawn([sys.executable, "-m", "cmsensord", *args], stderr=w,
                            stdout=subprocess.DEVNULL, env=env)
    os.close(w)
    with os.fdopen(r, "rb") as f:
        out = f.read().decode()
    return proc.wait(timeout=timeout), [line for line in out.split("\n") if line]


@pytest.fixture(scope="module")
def quiet_config(tmp_path_factory):
    """The status line off, as systemd/cmsensord.yaml has it."""
    path = tmp_path_factory.mktemp("journal") / "q.yaml"
    path.write_text("output:\n  status_line: false\n")
    return path


@pytest.fixture(scope="module")
def runs(tmp_path_factory, quiet_config):
    """The same simulated run with no -v, -v and -vv: stderr lines of each."""
    out = {}
    for flags in ((), ("-v",), ("-vv",)):
        logs = tmp_path_factory.mktemp("logs")
        status, lines = _run([*SIMULATE, "--out", str(logs), "--config", str(quiet_config), *flags])
        assert status == 0, lines
        out[flags] = lines
    return out


def test_every_line_under_the_journal_carries_its_priority(runs):
    lines = runs[()]
    assert lines and all(PREFIX.match(line) for line in lines), [x for x in lines if not PREFIX.match(x)]
    assert "<4>WARNING failure: ch0: FAILURE: AKF_10 with R_max=0.13 flags an anomaly" in lines
    assert any(line.startswith("<6>INFO start: cmsensord ") for line in lines)
    assert any(line.startswith("<6>MCAP log: ") for line in lines)   # printed, not logged: info


def test_v_shows_more_and_vv_is_debug(runs):
    plain, v, vv = runs[()], runs[("-v",)], runs[("-vv",)]
    assert not any(line.startswith("<7>") for line in plain)
    onsets = [line for line in v if line.startswith("<7>VERBOSE anomaly_onset: ch0: AKF_")]
    assert len(onsets) == 10                        # AKF_1 .. AKF_10 on the way to the failure
    assert len(v) > len(plain)
    assert not any(line.startswith("<7>DEBUG ") for line in v)
    assert len([line for line in vv if line.startswith("<7>VERBOSE anomaly_onset: ch0: AKF_")]) == 10
    status = [line for line in vv if line.startswith("<7>DEBUG status: [")]
    assert status                                   # -vv adds the status line once a second


def test_no_prefix_when_stderr_is_not_the_journal(tmp_path, quiet_config):
    status, lines = _run([*SIMULATE[:4], "20", *SIMULATE[5:], "--out", str(tmp_path),
                          "--config", str(quiet_config)], stream="1:2")
    assert status == 0
    assert lines and not any(PREFIX.match(line) for line in lines)
    assert any(line.startswith("INFO start: cmsensord ") for line in lines)


def test_a_configuration_error_is_an_error_in_the_journal(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("monitor:\n  r_mx: 1\n")
    status, lines = _run(["--config", str(bad)])
    assert status == 78
    assert lines == [f"<3>cmsensord: configuration error: {bad}: monitor.r_mx: unknown key 'r_mx' "
                     f"(did you mean 'r_max'?)"]


def test_the_status_line_goes_to_the_journal_once_a_minute_not_each_second(tmp_path):
    """With the default ``output.status_line: true`` (a site file from ``config --default``):
    each second on a terminal, under the journal the first line and then once a minute."""
    status = re.compile(r"^(<6>)?\[\s*[\d.]+ s\] ch0 S=")
    run = ("--simulate", "--scenario", "healthy", "--duration", "60", "--speed", "6")
    counts = {}
    for journal in (True, False):
        code, lines = _run([*run, "--out", str(tmp_path / str(journal))], journal=journal)
        assert code == 0, lines
        counts[journal] = sum(bool(status.match(line)) for line in lines)
    assert counts[True] == 1 and counts[False] >= 6, counts
