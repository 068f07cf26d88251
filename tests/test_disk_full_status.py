"""The daemon on a full disk says so where an operator looks: the status line names the outage,
and a capture that went to no file is not logged as captured. (A capture taken into a new
file that the retry opened, whose chunk then fails, is in the outage's count of lost messages.)"""

from __future__ import annotations

import pytest

from test_disk_full import daemon_filling


@pytest.mark.slow
def test_full_disk_on_the_status_line_and_captures_not_written_are_said(small_fs, tmp_path):
    err = daemon_filling(small_fs, tmp_path, "output:\n  retry_s: 1.0\n  retain_mb: 0\n  min_free_mb: 0\n"
                         "  akf_trace: true\ncapture:\n  every_s: 3\n  pre_s: 1\n  post_s: 1\n"
                         "  min_interval_s: 0\n", settle_s=2.0, full_s=5.0)   # 25 s of board time full
    lines = err.splitlines()
    start = next(i for i, ln in enumerate(lines) if "disk_error" in ln and "No space left" in ln)
    end = next(i for i, ln in enumerate(lines) if "logging resumed" in ln)
    outage = lines[start:end]
    assert any("| disk: not logging for " in ln and "No space left on device" in ln
               and "message(s) dropped" in ln for ln in outage), "\n".join(outage)[-3000:]
    assert any("capture on periodic not written: the log is not being written (disk error)" in ln
               for ln in outage), "\n".join(outage)[-3000:]
    assert not [ln for ln in lines[end + 2:] if "| disk: not logging" in ln]
    assert any(": captured " in ln for ln in lines[:start])
