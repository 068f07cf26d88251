"""``systemctl reload`` (SIGHUP) after editing the configuration: the daemon starts a new log
file and applies no setting, and says so in one warning line naming what changed and how to apply
it, or that the edited file does not load (a restart would stop the daemon on it)."""

from __future__ import annotations

import json
import signal
import threading
import time

import numpy as np
import pytest

from processes import start_board, start_daemon

pytestmark = pytest.mark.process

RULES = "alarms:\n  rules:\n    - name: rms\n      indicator: accel_rms\n      alert: 3.0\n      danger: 6.0\n"


class _Lines:
    """The daemon's stderr lines as they come (a reader thread)."""

    def __init__(self, proc):
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._read, args=(proc.stderr,), daemon=True)
        self._thread.start()

    def _read(self, pipe) -> None:
        for line in pipe:
            self.lines.append(line.rstrip("\n"))

    def count(self, prefix: str) -> int:
        return sum(line.startswith(prefix) for line in self.lines)

    def wait(self, prefix: str, n: int, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while self.count(prefix) < n:
            assert time.monotonic() < deadline, f"no {n}th {prefix!r} line:\n" + "\n".join(self.lines)
            time.sleep(0.02)

    def join(self) -> None:
        self._thread.join(timeout=10)


def reloads(d, edits, out: _Lines | None = None) -> list[str]:
    """SIGHUP the daemon ``d`` once after each of ``edits`` (callables changing its files), then
    stop it: its stderr lines (the reopen of each reload waited for, and the line after it;
    ``out``: the reader of its stderr already started)."""
    out = out or _Lines(d)
    try:
        out.wait("INFO effective settings:", 1)
        for n, edit in enumerate(edits, 1):
            edit()
            d.send_signal(signal.SIGHUP)
            out.wait("INFO reopen:", n)
            time.sleep(0.1)                 # the line after the reopen's, if one comes
        d.send_signal(signal.SIGTERM)
        assert d.wait(timeout=10) == 0
    finally:
        if d.poll() is None:
            d.kill()
        out.join()
    return out.lines


def test_a_reload_says_the_edited_configuration_is_not_applied(tmp_path):
    """Three reloads of a daemon (its board unplugged: the loop turns all the same): the file as
    it started, no config line; a level edited, one warning naming it and the restart that applies
    it; the file broken, one warning with its error, before a restart stops the daemon on it."""
    d = start_daemon(tmp_path, tmp_path / "no-board", config=RULES)
    cfg = tmp_path / "cmsensord.yaml"

    def edit(old: str, new: str):
        return lambda: cfg.write_text(cfg.read_text().replace(old, new))
    lines = reloads(d, (lambda: None, edit("alert: 3.0", "alert: 4.0"), edit("alert: 4.0", "alert: four")))
    said = [line for line in lines if line.startswith(("INFO reopen:", "WARNING config:"))]
    assert [line.split(":")[0] for line in said] == ["INFO reopen", "INFO reopen", "WARNING config",
                                                     "INFO reopen", "WARNING config"], lines
    assert said[2] == (f"WARNING config: {cfg} changed since the daemon started (alarms.rules[0].alert 3.0 -> 4.0): "
                       "not applied, a reload only starts a new log file; restart the daemon to apply it "
                       "(systemctl restart cmsensord: alarm latches and acknowledgements are kept)")
    assert said[4] == (f"WARNING config: {cfg} changed since the daemon started and does not load: "
                       "alarms.rules[0].alert: expected a number (got 'four'); a reload applies no setting, "
                       "and a restart would stop the daemon (exit 78): fix the file first")
    assert not any("Traceback" in line for line in lines)


def test_a_reload_of_an_unchanged_configuration_whose_named_file_broke_does_not_call_it_changed(tmp_path):
    """The configuration file as it started, the MQTT password file it names removed: the warning
    says the file is unchanged and what no longer loads (the file it names), not that it changed;
    the file put back, a reload says nothing again."""
    pw = tmp_path / "password"
    pw.write_text("secret\n")
    d = start_daemon(tmp_path, tmp_path / "no-board", config=(
        f"mqtt:\n  host: 127.0.0.1\n  port: 9\n  username: rig\n  password_file: {pw}\n"))
    cfg = tmp_path / "cmsensord.yaml"
    lines = reloads(d, (pw.unlink, lambda: pw.write_text("secret\n")))
    said = [line for line in lines if line.startswith(("INFO reopen:", "WARNING config:"))]
    assert [line.split(":")[0] for line in said] == ["INFO reopen", "WARNING config", "INFO reopen"], lines
    assert said[1].startswith(f"WARNING config: {cfg} is unchanged since the daemon started but no longer loads: "
                              "mqtt.password_file: cannot read: No such file or directory (got '"), said[1]
    assert said[1].endswith("); a reload applies no setting, and a restart would stop the daemon (exit 78): put "
                            "back or fix the file it names first"), said[1]


def _calibration(path) -> None:
    """A microphone calibration of a made-up machine (sound energy 2 x the vibration's) at ``path``."""
    from cmsensord.acoustic_calib import fit_model, save_calibration

    r = np.random.default_rng(0)
    x = 0.1 * np.exp(r.normal(0.0, 0.5, 3000))
    save_calibration(fit_model(x, 2 * x + 0.05 + 0.01 * r.standard_normal(3000) ** 2,
                               0.05 + 0.01 * r.standard_normal(1000) ** 2), path)


def test_a_reload_says_an_edited_microphone_calibration_is_not_applied(tmp_path):
    """A daemon watching a microphone (a board sending it): the calibration file's note edited, no
    line (the model it runs on is the same); its model edited, one warning naming the file, as an
    edited setting is (guards against a silent reload that leaves the old model running)."""
    mic = tmp_path / "mic.json"
    _calibration(mic)
    link = tmp_path / "ttyBOARD"
    board = start_board("--scenario", "healthy_mic", "--channels", "2", "--speed", "5", "--link", str(link))
    try:
        d = start_daemon(tmp_path, link, config=(
            f"channels:\n  - {{name: acc, index: 0}}\n  - {{name: mic, index: 1, kind: microphone}}\n"
            f"acoustic:\n  calibration: {mic}\n"))

        def edit(key: str, change):
            def do() -> None:
                doc = json.loads(mic.read_text())
                doc[key] = change(doc[key])
                mic.write_text(json.dumps(doc))
            return do
        out = _Lines(d)
        out.wait("INFO config: board firmware", 1, timeout=20)
        time.sleep(1.0)                         # the first data: the microphone's chain reads its calibration
        lines = reloads(d, (edit("info", lambda i: {**i, "note": "edited"}),
                            edit("model", lambda m: {**m, "F": m["F"] * 0.9})), out)
    finally:
        board.terminate()
        board.wait(timeout=5)
    said = [line for line in lines if line.startswith("INFO reopen:") or "since the daemon" in line]
    assert [line.split(":")[0] for line in said] == ["INFO reopen", "INFO reopen", "WARNING config"], lines
    assert said[2] == (f"WARNING config: the microphone calibration {mic} changed since the daemon read it: not "
                       "applied, a reload only starts a new log file; restart the daemon to apply it (systemctl "
                       "restart cmsensord: alarm latches and acknowledgements are kept)"), lines
    assert not any("Traceback" in line for line in lines)
