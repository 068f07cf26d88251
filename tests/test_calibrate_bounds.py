"""`cmsensord calibrate --from/--to` at the edges: bounds far past any capture are one line
(or the period ends at the capture's end), and a healthy period too short at the capture's end
is given advice that can be followed (an earlier --from), or told the capture is too short."""

from __future__ import annotations

import pytest

from processes import cmsensord, run_module

pytestmark = pytest.mark.process

SHORT = ("cmsensord: calibrate: channel ch0: the healthy period holds {n} observation(s) ({s} s), fewer than the 2 "
         "decision periods learning needs (200, 2 s: the first is the filters' transient); {fix}\n")


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """Healthy captures of 10 s and 1.5 s."""
    tmp = tmp_path_factory.mktemp("bounds")
    for name, seconds in (("h10", "10"), ("h1", "1.5")):
        p = run_module("firmware_sim", "--scenario", "healthy", "--duration", seconds,
                       "--out", str(tmp / f"{name}.bin"))
        assert p.returncode == 0, p.stderr
    return tmp


def calibrate(captures, name, *args):
    return cmsensord("calibrate", str(captures / f"{name}.bin"), *args, "--out", str(captures / "site.yaml"))


def test_from_far_past_the_end_is_one_line(captures):
    p = calibrate(captures, "h10", "--from", "1e308")
    assert (p.returncode, p.stdout) == (2, "")
    assert p.stderr == (f"cmsensord: calibrate: {captures / 'h10.bin'}: no observations between 1e+308 and the end "
                        "(board seconds, or % of the capture; it holds 10.0 s)\n")


def test_to_far_past_the_end_ends_the_period_at_the_capture_end(captures):
    p = calibrate(captures, "h10", "--to", "1e308")
    assert p.returncode == 0, p.stderr
    assert "note: --to 1e+308 is past the capture's end (10.0 board s): the healthy period ends there" \
        in p.stdout.splitlines()
    assert p.stdout.startswith("healthy period: 0.0-10.0 board s")


@pytest.mark.parametrize("args", [("--from", "9.5"), ("--from", "9.5", "--to", "11.5")])
def test_a_period_too_short_at_the_end_advises_an_earlier_from_that_works(captures, args):
    p = calibrate(captures, "h10", *args)
    assert (p.returncode, p.stdout) == (2, "")
    assert p.stderr == SHORT.format(n=50, s="0.5", fix="give a longer one (--from 8 or earlier)")
    assert calibrate(captures, "h10", "--from", "8").returncode == 0


def test_a_capture_shorter_than_learning_needs_is_said_so(captures):
    p = calibrate(captures, "h1")
    assert (p.returncode, p.stdout) == (2, "")
    assert p.stderr == SHORT.format(n=150, s="1.5", fix="the capture holds only 1.5 s: record a longer one")
