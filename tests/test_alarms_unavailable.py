"""An indicator a record lists unavailable by name (a bearing line its envelope spectrum does
not resolve, :mod:`cmsensord.dsp.indicators.resolution`) is no reading for the alarms: they
hold their level through it, and what was measured before it does not count after it (a
pending delay starts again, a voting alarm counts no exceedance of that channel)."""

from __future__ import annotations

from cmsensord.config import config_from_dict
from cmsensord.monitor import messages
from cmsensord.monitor.alarms import Alarms

S = 1_000_000_000
BEARING = {"name": "tb", "elements": 13, "ball_diameter": 3.5, "pitch_diameter": 25.6}


def alarms(rule: dict, channels=("ch0",), indicator: str = "tb.bpfo") -> Alarms:
    """The alarms of one rule on ``indicator`` (tb.bpfo, tb on the first channel; or band.hi)."""
    cfg = config_from_dict({"channels": [{"name": c} for c in channels],
                            "bearings": [{**BEARING, "channel": channels[0]}],
                            "indicators": {"bands": [{"name": "hi", "lo_hz": 2000.0, "hi_hz": 4000.0}]},
                            "alarms": {"rules": [{"name": "r", "indicator": indicator, "alert": 1.0, **rule}]}})
    return Alarms(cfg, lambda: tuple(channels))


def record(second: int, channel: str, bpfo: float | None) -> messages.Message:
    """An indicators record with the line, or with it listed unavailable (None)."""
    lines = {} if bpfo is None else {"bpfo": {"amplitude": bpfo, "freq_hz": 170.0}}
    fields = {"mode": "raw", "interval_s": 1.0, "missing_fraction": 0.0, "speed_rpm": 1800.0,
              "bearings": [{"name": "tb", "lines": lines}], **({"unavailable": ["tb.bpfo"]} if bpfo is None else {})}
    return messages.indicators(second * S, channel, fields)


def band_record(second: int, channel: str, rms: float | None) -> messages.Message:
    """An indicators record with band hi, or with it listed unavailable (None)."""
    fields = {"mode": "raw", "interval_s": 1.0, "missing_fraction": 0.0, "speed_rpm": 1800.0,
              "bands": [] if rms is None else [{"name": "hi", "rms": rms}],
              **({"unavailable": ["band.hi"]} if rms is None else {})}
    return messages.indicators(second * S, channel, fields)


def changes(a: Alarms, series: list[tuple[str, float | None]], make=record) -> list[tuple[int, str]]:
    """One record a second (channel, value or None) by ``make``: the (second, kind) of each alarm event."""
    out = []
    for k, (ch, x) in enumerate(series):
        out += [(k, e.kind) for e in a.see(make(k, ch, x)) if getattr(e, "kind", "").startswith("alarm_")]
    return out


def test_an_on_delay_starts_again_after_the_line_was_unavailable():
    a = alarms({"on_delay_s": 3})
    got = changes(a, [("ch0", 2.0)] + [("ch0", None)] * 4 + [("ch0", 2.0)] * 4)
    assert got == [(8, "alarm_alert")]          # not at 5, the 2.0 at 0 counted across the gap


def test_an_off_delay_starts_again_and_the_alarm_holds_through_the_gap():
    a = alarms({"off_delay_s": 3})
    got = changes(a, [("ch0", 2.0), ("ch0", 0.5)] + [("ch0", None)] * 4 + [("ch0", 0.5)] * 4)
    assert got == [(0, "alarm_alert"), (9, "alarm_clear")]     # not cleared at 6


def test_a_voting_alarm_counts_no_exceedance_of_a_channel_whose_value_is_unavailable():
    """(A bearing's line is of its one channel: a voting rule over channels watches a band here.)"""
    a = alarms({"vote": 2}, channels=("ch0", "ch1"), indicator="band.hi")
    got = changes(a, [("ch0", 2.0), ("ch0", None), ("ch1", 2.0), ("ch1", 2.0), ("ch0", 2.0)], band_record)
    assert got == [(4, "alarm_alert")]          # not at 2, ch0's 2.0 of second 0 still voting
