"""StopFlag: the signals the daemon takes set their flag and wake the loop's wait at once."""

from __future__ import annotations

import os
import signal

import pytest

from cmsensord import hangup
from cmsensord.service.signals import StopFlag


@pytest.fixture
def restored_handlers():
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_each_signal_sets_its_flag_and_wakes_the_loop(restored_handlers, sig):
    stop, woken = StopFlag(), []
    stop.wake = lambda: woken.append(True)
    stop.install()
    stop.install_reopen()
    os.kill(os.getpid(), sig)            # the handler runs in this (the main) thread before kill returns
    assert woken == [True]
    if sig == signal.SIGHUP:
        assert stop.reopen and not stop.event.is_set()
    else:
        assert stop.event.is_set() and not stop.reopen and stop.signal == sig


def test_a_sighup_held_from_the_entry_point_is_a_reopen_once_the_loop_takes_it(restored_handlers):
    hangup.hold()
    os.kill(os.getpid(), signal.SIGHUP)  # before the loop's handler: held, not the end of the process
    stop = StopFlag()
    stop.install_reopen()
    assert stop.reopen and not stop.event.is_set()
    again = StopFlag()
    again.install_reopen()               # taken once
    assert not again.reopen
