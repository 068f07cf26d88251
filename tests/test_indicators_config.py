"""The ``indicators`` and ``bearings`` sections: defaults, documentation, one-line errors."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from cmsensord.config import ConfigError, config_from_dict, config_to_dict, load_config
from cmsensord.config.indicators import BandConfig, BearingConfig, IndicatorsConfig

DEFAULT_YAML = Path(__file__).resolve().parents[1] / "config" / "default.yaml"
ZA2115 = {"name": "de", "channel": "ch0", "elements": 16, "ball_diameter": 0.331,
          "pitch_diameter": 2.815, "contact_angle_deg": 15.17}


def test_default_yaml_lists_every_indicators_key_with_the_defaults():
    data = yaml.safe_load(DEFAULT_YAML.read_text(encoding="utf-8"))
    assert set(data["indicators"]) == {f.name for f in dataclasses.fields(IndicatorsConfig)}
    assert data["bearings"] == []
    text = DEFAULT_YAML.read_text(encoding="utf-8")
    for f in dataclasses.fields(BearingConfig) + dataclasses.fields(BandConfig):
        assert f.name in text, f.name
    assert load_config(DEFAULT_YAML).indicators == IndicatorsConfig()


def test_a_full_section_round_trips():
    cfg = config_from_dict({"indicators": {"interval_s": 2, "machine_group": 1, "foundation": "flexible",
                                           "rpm": 1480, "velocity_band_hz": [2, 1000],
                                           "bands": [{"name": "low", "lo_hz": 10, "hi_hz": 1000},
                                                     {"name": "1x", "lo_order": 0.8, "hi_order": 1.2}]},
                            "bearings": [ZA2115]})
    assert cfg.indicators.velocity_band_hz == (2.0, 1000.0) and cfg.bearings[0].elements == 16
    assert config_from_dict(yaml.safe_load(yaml.safe_dump(config_to_dict(cfg)))) == cfg


@pytest.mark.parametrize("data, expected", [
    ({"indicators": {"machine_group": 3}}, "f.yaml: indicators.machine_group: must be >= 1 and <= 2 (got 3)"),
    ({"indicators": {"foundation": "soft"}},
     "f.yaml: indicators.foundation: must be one of rigid, flexible (got 'soft')"),
    ({"indicators": {"velocity_band_hz": [1000, 10]}}, "f.yaml: indicators.velocity_band_hz: must be two "
     "frequencies [lo, hi] in Hz with 0 <= lo < hi (got [1000.0, 10.0])"),
    ({"indicators": {"bands": [{"name": "a", "lo_hz": 5}]}},
     "f.yaml: indicators.bands[0].hi_hz: give both ends of the band (got None)"),
    ({"indicators": {"bands": [{"name": "a", "lo_hz": 5, "hi_hz": 9, "lo_order": 1, "hi_order": 2}]}},
     "f.yaml: indicators.bands[0].lo_hz: give either lo_hz and hi_hz, or lo_order and hi_order (got 5.0)"),
    ({"indicators": {"intervall_s": 1}},
     "f.yaml: indicators.intervall_s: unknown key 'intervall_s' (did you mean 'interval_s'?)"),
    ({"channels": [{"name": "ch0"}], "bearings": [{**ZA2115, "channel": "motor"}]},
     "f.yaml: bearings[0].channel: bearing de names no channel (channels: ch0) (got 'motor')"),
    ({"bearings": [{**ZA2115, "ball_diameter": 3.0}]},
     "f.yaml: bearings[0].pitch_diameter: must be greater than ball_diameter = 3.0 (got 2.815)"),
    ({"bearings": [{k: v for k, v in ZA2115.items() if k != "elements"}]},
     "f.yaml: bearings[0].elements: missing (required)"),
    ({"bearings": [ZA2115, ZA2115]}, "f.yaml: bearings[1].name: duplicate bearing name (got 'de')"),
    ({"bearings": {"de": 1}}, "f.yaml: bearings: expected a list of entries (name: ..., channel: ..., "
     "elements: ...) (got {'de': 1})"),
])
def test_bad_sections_give_one_line_naming_the_key(data, expected):
    with pytest.raises(ConfigError) as err:
        config_from_dict(data, source="f.yaml")
    assert str(err.value) == expected
