"""A FIFO, a device or a directory given where a command reads a file (an MCAP log to
``summary`` and ``report``, a capture to ``replay``, ``calibrate`` and ``vkf``) is refused in
one line saying what it is, at once: a FIFO is never opened to wait for a writer (none of these
commands reads one: the README names no such use)."""

from __future__ import annotations

import os

import pytest

from processes import cmsensord

CAPTURE = "replay, calibrate and vkf read a capture file (`--capture`, `cmsensord record`, `cmsensord import`)"


@pytest.mark.parametrize("command", [["summary"], ["report", "--out", "r.html"]])
def test_a_fifo_given_as_a_log_is_said_to_be_one(tmp_path, command):
    os.mkfifo(tmp_path / "x.mcap")
    p = cmsensord(*command, "x.mcap", timeout=20, cwd=tmp_path)
    assert (p.returncode, p.stderr) == (2, "cmsensord: x.mcap: not a regular file (a FIFO): give an MCAP log or a "
                                           "directory of them\n")


@pytest.mark.parametrize("command", [["replay", "--out", "o"], ["calibrate", "--out", "site.yaml"],
                                     ["vkf", "--out", "o"]])
def test_a_fifo_given_as_a_capture_is_refused_not_waited_on(tmp_path, command):
    os.mkfifo(tmp_path / "x.bin")
    p = cmsensord(*command, "x.bin", timeout=20, cwd=tmp_path)
    assert (p.returncode, p.stderr) == (2, f"cmsensord: x.bin: not a regular file (a FIFO): {CAPTURE}\n")
    assert sorted(os.listdir(tmp_path)) == ["x.bin"]         # nothing written


def test_a_device_or_a_directory_given_as_a_capture_is_said_to_be_one(tmp_path):
    p = cmsensord("replay", "/dev/zero", "--out", "o", timeout=20, cwd=tmp_path)
    assert (p.returncode, p.stderr) == (2, f"cmsensord: /dev/zero: not a regular file (a character device): "
                                           f"{CAPTURE}\n")
    p = cmsensord("replay", ".", "--out", "o", timeout=20, cwd=tmp_path)
    assert (p.returncode, p.stderr) == (2, f"cmsensord: .: is a directory, not a capture file: {CAPTURE}\n")
