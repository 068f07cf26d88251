"""Ctrl-C during ``cmsensord import`` and ``cmsensord vkf`` (real processes sent SIGINT mid-run):
one line saying the command was interrupted and what it left on disk, exit 130 (both exited
130 in silence)."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from processes import run_module, spawn


def _interrupt_when(args, ready, timeout=60.0) -> tuple[int, str]:
    """``python -m cmsensord ARGS`` sent SIGINT once ``ready()``; (exit status, stderr)."""
    proc = spawn([sys.executable, "-m", "cmsensord", *args], stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + timeout
    while not ready():
        assert proc.poll() is None and time.monotonic() < end, "the run ended before it could be interrupted"
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """200 s of 2 channels at 25.6 kHz (a few seconds to import)."""
    path = tmp_path_factory.mktemp("rec") / "rec.npy"
    np.save(path, np.random.default_rng(0).normal(size=(25600 * 200, 2)).astype(np.float32))
    return path


@pytest.mark.parametrize("before", [False, True])
def test_ctrl_c_during_an_import_says_nothing_was_written(recording, tmp_path, before):
    out = tmp_path / "rec.bin"
    if before:                          # an earlier import's capture and sidecar, kept as they were
        out.write_bytes(b"old capture")
        (tmp_path / "rec.bin.json").write_text("{}\n")
    status, err = _interrupt_when(["import", str(recording), "--fs", "25600", "--unit", "g", "--out", str(out)],
                                  lambda: (tmp_path / "rec.bin.part").exists())
    assert status == 130, err
    left = f"{out} left as it was" if before else f"{out} not made"
    assert err == f"cmsensord import: interrupted (Ctrl-C): nothing written ({left})\n"
    if before:
        assert out.read_bytes() == b"old capture" and (tmp_path / "rec.bin.json").read_text() == "{}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == (["rec.bin", "rec.bin.json"] if before else [])


def test_ctrl_c_during_a_vkf_says_how_far_it_got_and_leaves_nothing(tmp_path):
    cap = tmp_path / "co.bin"
    sim = run_module("firmware_sim", "--scenario", "close_orders", "--mode", "raw", "--tacho", "--duration", "150",
                     "--out", str(cap))
    assert sim.returncode == 0, sim.stderr
    out = tmp_path / "out"

    def replaying() -> bool:            # its log open: the replay under way
        if not any(out.glob("*.mcap.part")):
            return False
        time.sleep(0.3)
        return True

    status, err = _interrupt_when(["vkf", str(cap), "--out", str(out)], replaying)
    assert status == 130, err
    last = err.splitlines()[-1]
    assert re.fullmatch(rf"cmsensord: vkf: interrupted \(Ctrl-C\) at \d+% of the replay of {re.escape(str(cap))}: "
                        r"nothing written \(the batch orders need the whole record\)", last), err
    assert not out.exists()
