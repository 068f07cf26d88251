"""Every error a user can cause: one line naming the thing and the fix, exit 2 (usage)
or 78 (configuration), no traceback.  The table below is the specification.

Each case runs the real command line in a scratch directory holding:
``bad.yaml`` (an out-of-range value), ``typo.yaml`` (a misspelt key), ``broken.yaml``
(YAML syntax), ``unit.yaml`` (a unit that does not fit the channel's kind), ``nocal.yaml`` (a
microphone without a calibration), ``port.yaml`` (a valid config), ``notmcap.mcap`` (text),
``capdir/`` (a directory), ``logdir/`` (a directory of logs), ``loop.mcap``, ``loop.tty`` (symlink
loops), ``dangling.mcap`` (a symlink to nothing), ``afile`` (a regular file, so
``afile/logs`` cannot be a directory).
"""

from __future__ import annotations

import pytest

from processes import cmsensord, spawn

USAGE, CONFIG = 2, 78

CASES = [
    # (command line, exit status, what the one line must say)
    # -- configuration (78)
    (["--config", "bad.yaml"], CONFIG, "bad.yaml: monitor.r_max: must be greater than"),
    (["--config", "typo.yaml"], CONFIG, "did you mean 'r_max'"),
    (["--config", "broken.yaml"], CONFIG, "broken.yaml: YAML syntax error at line 2"),
    (["--config", "missing.yaml"], CONFIG, "missing.yaml: file not found"),
    (["replay", "notmcap.mcap", "--config", "bad.yaml"], CONFIG, "monitor.r_max"),
    # a capture or a log given as the configuration: what reads it, and what --config takes
    (["--config", "capture.bin"], CONFIG,
     "cmsensord: configuration error: capture.bin: a capture of the board's serial stream, not a configuration: "
     "replay, calibrate and vkf read it (`cmsensord replay capture.bin --config site.yaml`); --config takes a "
     "YAML site file (`cmsensord config --default > site.yaml` writes one)"),
    (["replay", "capture.bin", "--config", "logdir/cmsensord-20261201T120000Z.mcap"], CONFIG,
     "cmsensord: configuration error: logdir/cmsensord-20261201T120000Z.mcap: an MCAP log (cmsensord's output), "
     "not a configuration: `cmsensord summary` and `cmsensord report` read it; --config takes a YAML site file"),
    (["replay", "capture.bin", "--out", "afile/logs"], CONFIG,
     "afile/logs: cannot create output directory"),
    (["replay", "capture.bin", "--out", "afile"], CONFIG,
     "afile: cannot create output directory: it is a file, not a directory"),
    (["--simulate", "--duration", "1", "--out", "afile/logs"], CONFIG,
     "set output.dir or --out to a writable directory"),
    (["--config", "port.yaml", "--capture", "afile/cap.bin"], CONFIG,
     "cmsensord: afile/cap.bin: cannot write the capture file: Not a directory; give --capture a file in a "
     "writable directory"),
    (["--config", "port.yaml", "--capture", "./port.yaml"], CONFIG,
     "cmsensord: ./port.yaml: is the input port.yaml: writing it would destroy it; give --capture another "
     "file name"),
    (["--config", "port.yaml", "--capture", "capdir"], CONFIG,
     "cmsensord: capdir: is a directory, not a regular file: --capture takes a file to append the port's "
     "bytes to"),
    (["--config", "port.yaml", "--capture", "/dev/null"], CONFIG,
     "cmsensord: /dev/null: is a character device, not a regular file: --capture takes a file to append the "
     "port's bytes to"),
    (["replay", "capture.bin", "--config", "unit.yaml"], CONFIG,
     "unit.yaml: channels[1].unit: Pa is not what a channel of kind accelerometer measures (m/s^2): "
     "set kind: microphone (got 'Pa')"),
    (["replay", "capture.bin", "--config", "nocal.yaml"], CONFIG,
     "nocal.yaml: channels[0].kind: a microphone channel needs an acoustic calibration file"),
    # -- usage (2)
    (["replay", "missing.bin"], USAGE, "missing.bin: capture file not found"),
    (["replay", "capdir"], USAGE, "capdir: is a directory, not a capture file: replay, calibrate and vkf read a "
                                  "capture file (`--capture`, `cmsensord record`, `cmsensord import`)"),
    # a directory of logs where a capture is expected, and a capture where logs are: what reads each
    (["replay", "logdir"], USAGE, "cmsensord: logdir: a directory of MCAP logs (cmsensord's output), not a "
                                  "capture file: `cmsensord summary` and `cmsensord report` read it; replay, "
                                  "calibrate and vkf read a capture file"),
    (["calibrate", "logdir", "--out", "site.yaml"], USAGE, "logdir: a directory of MCAP logs"),
    (["summary", "capture.bin"], USAGE, "cmsensord: capture.bin: a capture of the board's serial stream, not an "
                                        "MCAP log: `cmsensord replay capture.bin --out DIR` processes it into the "
                                        "logs that summary and report read"),
    (["report", "capture.bin", "--out", "r.html"], USAGE, "cmsensord: capture.bin: a capture of the board's "
                                                          "serial stream, not an MCAP log: `cmsensord replay"),
    (["summary", "notmcap.mcap"], USAGE, "notmcap.mcap: not an MCAP file"),
    (["summary", "missing.mcap"], USAGE, "missing.mcap: file not found"),
    (["record", "--port", "/dev/nonexistent-tty", "--out", "x.bin", "--duration", "1"], USAGE,
     "/dev/nonexistent-tty: no such device (is the board plugged in?"),
    (["record", "--port", "/dev/null", "--out", "x.bin", "--duration", "1"], USAGE,
     "is it a serial port?"),
    (["import", "capture.bin", "--out", "x.bin"], USAGE,
     "cmsensord import: capture.bin: a capture of the board's serial stream already (cmsensord's input): "
     "replay, calibrate and vkf read it as it is (`cmsensord replay capture.bin --out DIR`)"),
    # an --out file where a directory is, or in one that is not there; a directory as the port
    (["record", "--port", "capdir", "--out", "x.bin", "--duration", "1"], USAGE,
     "cmsensord: capdir: is a directory, not a serial port: give the board's tty, e.g. /dev/ttyACM0"),
    (["record", "--port", "/dev/nonexistent-tty", "--out", "capdir", "--duration", "1"], USAGE,
     "cmsensord: capdir: is a directory; give --out a file name, e.g. capdir/capture.bin"),
    (["record", "--port", "/dev/nonexistent-tty", "--out", "nodir/x.bin", "--duration", "1"], USAGE,
     "cmsensord: nodir/x.bin: no directory nodir: give --out a file in a directory that exists"),
    (["report", "logdir", "--out", "capdir"], USAGE,
     "cmsensord: capdir: is a directory; give --out a file name, e.g. capdir/report.html"),
    (["report", "logdir", "--out", "nodir/r.html"], USAGE,
     "cmsensord: nodir/r.html: no directory nodir: give --out a file in a directory that exists"),
    # a symlink that leads nowhere: a loop is said as one, not as a file or device not there
    (["summary", "loop.mcap"], USAGE, "cmsensord: loop.mcap: a symlink loop (too many levels of symbolic links): "
                                      "point it at the real file"),
    (["report", "loop.mcap", "--out", "r.html"], USAGE, "cmsensord: loop.mcap: a symlink loop (too many levels"),
    (["summary", "dangling.mcap"], USAGE, "cmsensord: dangling.mcap: a symlink to gone.mcap, which is not there"),
    (["record", "--port", "loop.tty", "--out", "x.bin", "--duration", "1"], USAGE,
     "cmsensord: loop.tty: a symlink loop (too many levels of symbolic links): point it at the board's tty, "
     "e.g. /dev/ttyACM0"),
    (["import", "loop.mcap", "--out", "x.bin"], USAGE, "cmsensord import: loop.mcap: a symlink loop (too many "
                                                       "levels of symbolic links): point it at the recording"),
    (["replay", "loop.mcap"], USAGE, "cmsensord: loop.mcap: a symlink loop (too many levels of symbolic links): "
                                     "point it at the capture"),
    (["vkf", "capture.bin"], USAGE, "capture.bin: the board is in RMS mode (its first STATUS): the batch VKF "
                                    "needs a capture in RAW mode"),
    (["vkf", "degrading.bin"], USAGE, "degrading.bin: the board is in RMS mode (its first STATUS)"),
    (["--simulate", "--scenario", "nosuch"], USAGE, "unknown scenario; choose from healthy"),
    (["--simulate", "--speed", "-1"], USAGE, "expected a positive number"),
    (["replay", "capture.bin", "--speed", "0"], USAGE, "expected a positive number"),
    ([], USAGE, "nothing to do: give --simulate, --config FILE or a subcommand"),
]


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    d = tmp_path_factory.mktemp("errors")
    (d / "bad.yaml").write_text("monitor:\n  r_max: 0.001\n")
    (d / "typo.yaml").write_text("monitor:\n  r_mx: 0.2\n")
    (d / "broken.yaml").write_text("link: [1, 2\n")
    (d / "unit.yaml").write_text("channels:\n  - name: acc\n  - name: mic\n    unit: Pa\n")
    (d / "nocal.yaml").write_text("channels:\n  - name: mic\n    kind: microphone\n")
    (d / "port.yaml").write_text("link:\n  port: /dev/nonexistent-tty\noutput:\n  dir: logs\n")
    (d / "notmcap.mcap").write_text("not an mcap file\n")
    (d / "capdir").mkdir()
    (d / "logdir").mkdir()
    (d / "logdir" / "cmsensord-20261201T120000Z.mcap").write_bytes(b"\x89MCAP0\r\n")
    (d / "afile").write_text("")
    (d / "loop.mcap").symlink_to("loop.mcap")
    (d / "loop.tty").symlink_to("loop.tty")
    (d / "dangling.mcap").symlink_to("gone.mcap")
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    Board(make_scenario("healthy", duration_s=2.0), BoardConfig()).write_capture(d / "capture.bin", 2.0)
    # an RMS capture whose replay warns (a failure): vkf says RMS mode before replaying it
    Board(make_scenario("degrading", duration_s=20.0), BoardConfig()).write_capture(d / "degrading.bin", 20.0)
    return d


@pytest.mark.parametrize("args, code, text", CASES, ids=[" ".join(c[0]) or "(none)" for c in CASES])
def test_user_error_is_one_line_with_its_exit_status(scratch, args, code, text):
    p = cmsensord(*args, cwd=scratch)
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == code, p.stderr
    assert "Traceback" not in p.stderr
    assert len(lines) == 1, p.stderr
    assert text in lines[0], lines[0]


def test_a_refused_capture_makes_no_output_directory(scratch):
    """A daemon's --capture naming its own configuration is refused before output.dir is made:
    the directory and its lock file were left behind by a daemon that never ran."""
    (scratch / "own.yaml").write_text("link:\n  port: /dev/nonexistent-tty\noutput:\n  dir: never_made\n")
    p = cmsensord("--config", "own.yaml", "--capture", "own.yaml", cwd=scratch)
    assert (p.returncode, p.stderr) == (CONFIG, "cmsensord: own.yaml: is the input own.yaml: writing it would "
                                                "destroy it; give --capture another file name\n")
    assert not (scratch / "never_made").exists()


def test_summary_into_a_closed_pipe_is_quiet(scratch):
    """`cmsensord summary FILE | head -1`: the reader closes the pipe early; no traceback."""
    import subprocess
    import sys

    from processes import ENV

    out = scratch / "logs"
    r = cmsensord("replay", "capture.bin", "--out", str(out), cwd=scratch)
    assert r.returncode == 0, r.stderr
    mcap = next(out.glob("*.mcap"))
    p = spawn([sys.executable, "-m", "cmsensord", "summary", "--json", str(mcap)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV)
    p.stdout.read(10)
    p.stdout.close()                    # like head: stop reading
    err = p.stderr.read().decode()
    assert p.wait(timeout=30) == 0
    assert "Traceback" not in err and "BrokenPipe" not in err


def test_an_empty_config_file_is_said(scratch):
    """A site file emptied by mistake would run every setting at its default (its calibration
    gone): one warning line says so, and the run goes on."""
    (scratch / "empty.yaml").write_text("# emptied\n")
    p = cmsensord("replay", "capture.bin", "--config", "empty.yaml", "--out", str(scratch / "empty_logs"), cwd=scratch)
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines()[0] == ("WARNING config: empty.yaml holds no settings (empty, or comments only): "
                                        "every setting is its default")


def test_import_of_a_fifo_or_a_device_is_one_line_not_a_wait(tmp_path):
    # a FIFO was opened to be read as a text table (and as a capture): the import waited for a
    # writer, without end
    import os

    os.mkfifo(tmp_path / "fifo")
    for name, kind in ((str(tmp_path / "fifo"), "FIFO"), ("/dev/zero", "character device")):
        p = cmsensord("import", name, "--out", str(tmp_path / "x.bin"), timeout=20)
        assert (p.returncode, p.stderr) == (2, f"cmsensord import: {name}: not a regular file (a {kind}): import "
                                               "reads the files of a recording (.wav, .csv, .tsv, .txt, .lvm, .npy, "
                                               ".npz, .mat, .tdms, or text tables of numbers)\n")
