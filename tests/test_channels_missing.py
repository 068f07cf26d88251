"""A configuration whose channels the board does not send (an index counted from 1 on a
1-channel board): one WARNING saying nothing is monitored, on a live pty and in a replay, not
one a batch (the daemon said it ~200 times a second, 1,409 config events in 7 s)."""

from __future__ import annotations

import re

import pytest

from processes import cmsensord, daemon_on_short_board, run_module

NONE = ("WARNING config: board sends 1 channel(s) (index 0); none of the configured channels is among "
        "them (de (index 1)): nothing is monitored until it sends them")


def test_a_daemon_on_a_board_without_the_configured_channel_says_so_once(tmp_path):
    _, err = daemon_on_short_board(tmp_path, config="channels:\n  - {name: de, index: 1}\n")
    assert [ln for ln in err.splitlines() if "config:" in ln and "configured" in ln] == [NONE], err


@pytest.mark.parametrize("indexes, said", [
    ((0, 1, 2), "WARNING config: board sends 2 channel(s); configured channel(s) fan (index 2) not in the stream: "
                "not monitored, their alarm rules and bearings see no value"),
    ((2, 3), "WARNING config: board sends 2 channel(s) (index 0 to 1); none of the configured channels is among "
             "them (de (index 2), nde (index 3)): nothing is monitored until it sends them"),
], ids=["some", "none"])
def test_a_replay_says_once_which_configured_channels_the_capture_lacks(tmp_path, indexes, said):
    cap = tmp_path / "cap.bin"
    sim = run_module("firmware_sim", "--scenario", "healthy", "--channels", "2", "--duration", "20", "--out", cap)
    assert sim.returncode == 0, sim.stderr
    cfg = tmp_path / "site.yaml"
    cfg.write_text("channels:\n" + "".join(f"  - {{name: {name}, index: {i}}}\n"
                                           for name, i in zip(("de", "nde", "fan"), indexes)))
    p = cmsensord("replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "out"))
    assert p.returncode == 0, p.stderr
    assert [ln for ln in p.stderr.splitlines() if "config:" in ln and "configured" in ln] == [said], p.stderr
    assert re.search(r"events: .*\bconfig 2\b", p.stderr), p.stderr        # and the run's configuration
