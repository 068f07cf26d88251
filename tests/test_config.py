"""Configuration: YAML -> frozen dataclasses; every bad input is one ConfigError line."""

from __future__ import annotations

import copy
import dataclasses
import re
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cmsensord.config import (
    ChannelConfig,
    Config,
    LinkConfig,
    MonitorConfig,
    OutputConfig,
    config_from_dict,
    config_to_dict,
    default_config,
    load_config,
)
from cmsensord.errors import EXIT_CONFIG, EXIT_USAGE, CmsensordError, ConfigError
from fuzz import examples

DEFAULT_YAML = Path(__file__).resolve().parents[1] / "config" / "default.yaml"


def write(tmp_path: Path, text: str, name: str = "cfg.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# --- defaults -----------------------------------------------------------------


def test_seed_000_defaults():
    m = MonitorConfig()
    assert (m.n, m.r_min, m.r_max, m.z_c, m.c, m.f_r) == (10, 4e-3, 0.13, 2.8, 0.4, 28.66)


@pytest.mark.parametrize("n", [1, 3, 8])
def test_default_config_round_trips(n):
    cfg = default_config(n)
    assert [ch.name for ch in cfg.channels] == [f"ch{i}" for i in range(n)]
    assert [ch.index for ch in cfg.channels] == list(range(n))
    assert all(ch.monitor == cfg.monitor for ch in cfg.channels)
    assert config_from_dict(config_to_dict(cfg)) == cfg
    # through YAML text too: what config_to_dict logs can be used as a config file
    assert config_from_dict(yaml.safe_load(yaml.safe_dump(config_to_dict(cfg)))) == cfg


def test_default_yaml_equals_default_config():
    cfg = load_config(DEFAULT_YAML)
    ref = default_config(1)
    for section in ("link", "output", "monitor"):
        got, want = getattr(cfg, section), getattr(ref, section)
        for f in dataclasses.fields(want):
            assert getattr(got, f.name) == getattr(want, f.name), f"{section}.{f.name}"
    assert cfg == ref


def test_default_yaml_lists_every_key():
    data = yaml.safe_load(DEFAULT_YAML.read_text(encoding="utf-8"))
    for section, cls in (("link", LinkConfig), ("output", OutputConfig), ("monitor", MonitorConfig)):
        assert set(data[section]) == {f.name for f in dataclasses.fields(cls)}, section


def test_no_file_and_empty_file_give_defaults(tmp_path):
    assert load_config(None) == default_config(1)
    assert load_config(None, n_channels=4) == default_config(4)
    assert load_config(write(tmp_path, "# only a comment\n")) == default_config(1)


def test_n_channels_used_only_without_channels_list(tmp_path):
    assert [c.name for c in load_config(DEFAULT_YAML, n_channels=3).channels] == ["ch0", "ch1", "ch2"]
    path = write(tmp_path, "channels:\n  - name: a\n")
    assert [c.name for c in load_config(path, n_channels=3).channels] == ["a"]


def test_exponent_without_dot_is_a_float(tmp_path):
    # PyYAML (YAML 1.1) would read 4e-3 as a string; the paper writes R_min = 4e-3.
    cfg = load_config(write(tmp_path, "monitor:\n  r_min: 4e-3\n  r_max: 13E-2\n  q0: 1e+0\n"))
    assert (cfg.monitor.r_min, cfg.monitor.r_max, cfg.monitor.q0) == (4e-3, 0.13, 1.0)


def test_frozen():
    cfg = default_config()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.monitor.n = 3  # type: ignore[misc]


def test_int_accepted_for_float_and_stored_as_float():
    cfg = config_from_dict({"monitor": {"f_r": 30, "q0": 0}})
    assert cfg.monitor.f_r == 30.0 and type(cfg.monitor.f_r) is float
    assert type(cfg.monitor.q0) is float


def test_objects_built_in_code_are_validated_too():
    with pytest.raises(ConfigError, match=r"^<code>: r_max: must be greater than r_min"):
        MonitorConfig(r_min=0.5, r_max=0.1)
    with pytest.raises(ConfigError, match=r"n: expected an integer \(got 2.5\)"):
        dataclasses.replace(MonitorConfig(), n=2.5)


# --- per-channel overrides ----------------------------------------------------


def test_per_channel_override_applied_and_others_inherit(tmp_path):
    path = write(
        tmp_path,
        """
monitor:
  z_c: 3.0
  f_r: 25
channels:
  - name: motor_de
    r_max: 0.2
  - name: motor_nde
    scale: 0.0125
    offset: 2048
  - name: fan
    index: 5
    f_r: 12.5
""",
    )
    cfg = load_config(path)
    de, nde, fan = cfg.channels
    assert (de.name, de.index, nde.index, fan.index) == ("motor_de", 0, 1, 5)
    assert de.monitor == dataclasses.replace(cfg.monitor, r_max=0.2)
    assert nde.monitor == cfg.monitor
    assert (nde.scale, nde.offset, de.scale, de.offset) == (0.0125, 2048.0, None, None)
    assert fan.monitor.f_r == 12.5 and fan.monitor.z_c == 3.0 and fan.monitor.r_max == 0.13
    assert cfg.monitor.z_c == 3.0 and cfg.monitor.f_r == 25.0
    assert cfg.channel("fan") is fan
    assert config_from_dict(config_to_dict(cfg)) == cfg
    assert config_to_dict(cfg)["channels"][0] == {
        "name": "motor_de", "index": 0, "scale": None, "offset": None, "r_max": 0.2,
    }


def test_channel_name_defaults_to_its_index():
    cfg = config_from_dict({"channels": [{"index": 2}, {}]})
    assert [(c.name, c.index) for c in cfg.channels] == [("ch2", 2), ("ch1", 1)]


# --- bad input -> one line naming file, key path, reason ------------------------

BAD_DICTS = [
    ({"monitor": {"r_mx": 0.2}}, "cfg.yaml: monitor.r_mx: unknown key 'r_mx' (did you mean 'r_max'?)"),
    ({"monitr": {}}, "cfg.yaml: monitr: unknown key 'monitr' (did you mean 'monitor'?)"),
    ({"link": {"xyz": 1}}, "link.xyz: unknown key 'xyz' (known keys: port, baud,"),
    ({"channels": [{"name": "a", "z_cc": 3}]}, "channels[0].z_cc: unknown key 'z_cc' (did you mean 'z_c'?)"),
    ({"monitor": {"n": "ten"}}, "cfg.yaml: monitor.n: expected an integer (got 'ten')"),
    ({"monitor": {"n": True}}, "monitor.n: expected an integer (got True)"),
    ({"monitor": {"n": 2.0}}, "monitor.n: expected an integer (got 2.0)"),
    ({"monitor": {"f_r": True}}, "monitor.f_r: expected a number (got True)"),
    ({"monitor": {"f_r": ".nan"}}, "monitor.f_r: expected a number (got '.nan')"),
    ({"monitor": {"f_r": float("inf")}}, "monitor.f_r: expected a finite number (got inf)"),
    ({"output": {"akf_trace": "yes please"}}, "output.akf_trace: expected true or false (got 'yes please')"),
    ({"link": {"port": 5}}, "link.port: expected a string (got 5)"),
    ({"monitor": {"n": 0}}, "monitor.n: must be >= 1 and <= 64 (got 0)"),
    ({"monitor": {"n": 65}}, "monitor.n: must be >= 1 and <= 64 (got 65)"),
    ({"monitor": {"c": 1}}, "monitor.c: must be > 0 and < 1 (got 1)"),
    ({"monitor": {"r_min": -1e-3}}, "monitor.r_min: must be > 0 (got -0.001)"),
    ({"monitor": {"window": 1}}, "monitor.window: must be >= 2 and <= 1000 (got 1)"),
    ({"link": {"queue_frames": 8}}, "link.queue_frames: must be >= 16 and <= 1000000 (got 8)"),
    ({"output": {"compression": "gzip"}}, "output.compression: must be one of zstd, lz4, none (got 'gzip')"),
    ({"output": {"compression": "zst"}}, "must be one of zstd, lz4, none (did you mean 'zstd'?) (got 'zst')"),
    ({"output": {"prefix": "a/b"}}, "output.prefix: must contain only letters, digits, _ . and - (got 'a/b')"),
    ({"monitor": {"r_min": 0.2, "r_max": 0.1}}, "cfg.yaml: monitor.r_max: must be greater than r_min = 0.2 (got 0.1)"),
    ({"monitor": {"r_max": 0.13, "r_min": 0.13}}, "monitor.r_max: must be greater than r_min = 0.13 (got 0.13)"),
    ({"channels": [{"name": "a", "r_max": 0.001}]}, "channels[0].r_max: must be greater than r_min = 0.004 (got 0.001)"),
    ({"link": {"reconnect_min_s": 9}}, "link.reconnect_min_s: must be <= reconnect_max_s = 5.0 (got 9.0)"),
    ({"output": {"akf_trace": True, "akf_trace_filter": 11}},
     "output.akf_trace_filter: must be <= monitor.n = 10 (got 11)"),
    (
        {"output": {"akf_trace": True, "akf_trace_filter": 5}, "channels": [{"name": "a", "n": 4}, {"name": "b", "n": 4}]},
        "output.akf_trace_filter: must be <= channels[0].n = 4 (got 5)",
    ),
    (
        {"channels": [{"name": "a"}, {"name": "b", "n": 4}]},
        "channels[1].n: every channel needs the same bank size n (channels[0] has 10)",
    ),
    ({"channels": [{"name": "a"}, {"name": "a"}]}, "cfg.yaml: channels[1].name: duplicate channel name (also channels[0]) (got 'a')"),
    ({"channels": [{"name": "a", "index": 1}, {"name": "b"}]}, "channels[1].index: duplicate channel index (also channels[0]) (got 1)"),
    ({"channels": [{"name": "motor-de"}]}, "channels[0].name: must contain only letters, digits and _ (got 'motor-de')"),
    ({"channels": [{"name": "a", "index": 8}]}, "channels[0].index: must be >= 0 and <= 7 (got 8)"),
    ({"channels": [{"name": "a", "scale": 0}]}, "channels[0].scale: must not be 0 (got 0)"),
    ({"channels": []}, "cfg.yaml: channels: must list at least one channel (got [])"),
    ({"channels": {"name": "a"}}, "channels: expected a list of channel entries (got {'name': 'a'})"),
    ({"channels": ["a"]}, "channels[0]: expected a mapping (name: ..., index: ...) (got 'a')"),
    ({"monitor": [1, 2]}, "cfg.yaml: monitor: expected a mapping of keys to values (got [1, 2])"),
    ([1, 2], "cfg.yaml: top level must be a mapping of the sections link, output, monitor, channels, tacho, orders, "
             "acoustic, indicators, bearings, capture, mqtt, alarms, commissioned (got [1, 2])"),
    ("text", "cfg.yaml: top level must be a mapping"),
]


@pytest.mark.parametrize("data, expected", BAD_DICTS, ids=[e for _, e in BAD_DICTS])
def test_bad_input_from_file(tmp_path, data, expected):
    path = write(tmp_path, yaml.safe_dump(data))
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    assert expected.replace("cfg.yaml", str(path)) in message


BAD_FILES = [
    ("monitor:\n  n: 3\n  r_max: [0.1\n", "YAML syntax error at line 4, column 1"),
    ("monitor:\n  n: 3\n    z_c: 2\n", "YAML syntax error at line 3, column 8: mapping values are not allowed here"),
    ("monitor:\n  r_max: 0.1\n  r_max: 0.2\n", "YAML syntax error at line 3, column 3: found duplicate key 'r_max'"),
    ("- monitor\n- link\n", "top level must be a mapping of the sections link, output, monitor, channels, tacho, "
                            "orders, acoustic, indicators, bearings, capture, mqtt, alarms, commissioned (got ['monitor', 'link'])"),
    ("monitor:\n\tn: 3\n", "YAML syntax error at line 2, column 1: found character '\\t' that cannot start any token: "
                          "indent with spaces, not tabs"),
    ("42\n", "top level must be a mapping"),
    ("monitor:\n  f_r: 1e999\n", "monitor.f_r: expected a finite number (got inf)"),
    ("monitor: !!python/object:os.system {}\n", "YAML syntax error at line 1, column 10: could not determine a constructor"),
]


@pytest.mark.parametrize("text, expected", BAD_FILES, ids=[e for _, e in BAD_FILES])
def test_bad_file_content(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    assert expected in message


def test_missing_file(tmp_path):
    path = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == f"{path}: file not found (`cmsensord config --default > FILE` writes one with every setting)"
    assert info.value.path == str(path)


def test_directory_and_non_utf8(tmp_path):
    with pytest.raises(ConfigError, match="is a directory, not a file"):
        load_config(tmp_path)
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes(b"monitor:\n  n: 3 # \xe9\n")
    with pytest.raises(ConfigError, match=r"latin1.yaml: not UTF-8 text \(byte offset 18\)"):
        load_config(bad)


@pytest.mark.parametrize("name", ["a\0b", Path("a\0b")], ids=["str", "Path"])
def test_file_name_with_a_nul_byte(name):
    """The OS cannot take the name: one ConfigError line with the NUL shown escaped, not a ValueError."""
    with pytest.raises(ConfigError) as info:
        load_config(name)
    assert str(info.value) == "a\\0b: not a usable file name: it contains a NUL byte"
    assert "\0" not in str(info.value) and "\n" not in str(info.value)


def test_error_attributes_and_exit_codes(tmp_path):
    path = write(tmp_path, "channels:\n  - name: a\n  - name: b\n    r_max: 0.001\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    err = info.value
    assert isinstance(err, CmsensordError)
    assert (err.source, err.path, err.value) == (str(path), "channels[1].r_max", 0.001)
    assert err.reason == "must be greater than r_min = 0.004"
    assert (EXIT_USAGE, EXIT_CONFIG) == (2, 78)


def test_bad_n_channels():
    with pytest.raises(ConfigError, match=r"n_channels: must be an integer in 1..8 \(got 9\)"):
        config_from_dict({}, n_channels=9)
    with pytest.raises(ConfigError, match=r"n_channels: must be an integer in 1..8 \(got 0\)"):
        default_config(0)


# --- hypothesis: any mutation loads or raises ConfigError, nothing else ----------

VALID = {
    "link": {"port": "/dev/ttyUSB0", "baud": 115200, "stall_s": 3},
    "output": {"compression": "lz4", "akf_trace": True, "akf_trace_filter": 3},
    "monitor": {"n": 5, "r_min": 0.01, "r_max": 0.2, "c": 0.5},
    "channels": [
        {"name": "a", "r_max": 0.3},
        {"name": "b", "index": 3, "scale": 0.5, "offset": 2048, "window": 4},
    ],
}
KEYS = sorted(
    {f.name for cls in (LinkConfig, OutputConfig, MonitorConfig, ChannelConfig, Config) for f in dataclasses.fields(cls)}
)

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.integers(min_value=-3, max_value=70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-2, max_value=2),
    st.text(max_size=8),
    st.sampled_from(["zstd", "lz4", "none", "a", "ch0", "", "/dev/x"]),
)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.sampled_from(KEYS) | st.text(max_size=4), inner, max_size=3)
    ),
    max_leaves=6,
)
key_choice = st.sampled_from(KEYS) | st.text(max_size=6) | st.integers(-2, 2)


def _containers(node, out):
    """Every dict and list inside node (node included)."""
    if isinstance(node, (dict, list)):
        out.append(node)
        children = node.values() if isinstance(node, dict) else node
        for child in children:
            _containers(child, out)
    return out


@st.composite
def mutated(draw):
    d = copy.deepcopy(VALID)
    for _ in range(draw(st.integers(1, 4))):
        containers = _containers(d, [])
        target = draw(st.sampled_from(containers))
        action = draw(st.sampled_from(["set", "add", "delete"]))
        if isinstance(target, dict):
            if action == "add" or not target:
                target[draw(key_choice)] = draw(values)
            elif action == "set":
                target[draw(st.sampled_from(sorted(target, key=repr)))] = draw(values)
            else:
                del target[draw(st.sampled_from(sorted(target, key=repr)))]
        else:
            if action == "add" or not target:
                target.append(draw(values))
            elif action == "set":
                target[draw(st.integers(0, len(target) - 1))] = draw(values)
            else:
                del target[draw(st.integers(0, len(target) - 1))]
    if draw(st.integers(0, 20)) == 0:
        d = draw(values)  # sometimes the whole document is replaced
    return d


def test_valid_base_document_loads():
    cfg = config_from_dict(VALID)
    assert cfg.channels[1].monitor.window == 4 and cfg.channels[1].index == 3


@settings(max_examples=examples(400), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated(), st.sampled_from([None, 1, 4]))
def test_fuzz_mutations_load_or_raise_config_error(d, n_channels):
    try:
        cfg = config_from_dict(d, source="fuzz.yaml", n_channels=n_channels)
    except ConfigError as err:
        message = str(err)
        assert message.startswith("fuzz.yaml: ")
        assert "\n" not in message
        return
    # whatever loads is a consistent Config that round-trips
    assert isinstance(cfg, Config)
    assert config_from_dict(config_to_dict(cfg)) == cfg


@settings(max_examples=examples(200), deadline=None)
@given(st.text(alphabet=st.sampled_from(list("monitor:n_cr- []{}\n\t'\"#!&*,.0123456789")), max_size=60))
def test_fuzz_random_yaml_text_loads_or_raises_config_error(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("y") / "fuzz.yaml"
    path.write_text(text, encoding="utf-8")
    try:
        load_config(path)
    except ConfigError as err:
        assert str(err).startswith(f"{path}: ")
        assert "\n" not in str(err)


def test_default_yaml_holds_the_tacho_and_orders_defaults():
    cfg = load_config(Path(__file__).resolve().parents[1] / "config" / "default.yaml")
    assert cfg.tacho == default_config(1).tacho
    assert cfg.orders == default_config(1).orders
    assert [c.order for c in cfg.orders.components] == [1.0, 2.0, 3.0, 4.0]


@pytest.mark.parametrize("orders, message", [
    ({"components": [{"name": "a"}]}, "orders.components[0].order: give exactly one of order"),
    ({"components": [{"name": "a", "order": 1, "freq_hz": 3}]}, "give exactly one of order"),
    ({"components": [{"name": "a", "order": 1, "r": 3, "bandwidth_hz": 2}]},
     "orders.components[0].bandwidth_hz: give at most one of r, bandwidth_hz, bandwidth_pct"),
    ({"components": [{"name": "a", "order": 1}, {"name": "a", "order": 2}]},
     "orders.components[1].name: duplicate component name"),
    ({"components": []}, "orders.components: expected a non-empty list"),
    ({"components": [{"name": "a", "order": 1, "ordr": 2}]}, "unknown key 'ordr' (did you mean 'order'?)"),
    ({"smoother_lag_s": 0.5}, "orders.smoother_lag_s: must be >= 0 and <= 0.2"),
    ({"components": [{"name": "a", "order": 1}, {"order": 2}]}, "orders.components[1].name: missing (required)"),
])
def test_bad_orders_sections(orders, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        config_from_dict({"orders": orders}, source="x.yaml")


def test_orders_round_trip():
    d = {"orders": {"components": [{"name": "whirl", "order": 0.47, "alarm_rms": 1.0},
                                   {"name": "whip", "freq_hz": 47, "bandwidth_hz": 2}]},
         "tacho": {"ppr": 4}}
    cfg = config_from_dict(d)
    assert config_from_dict(config_to_dict(cfg)) == cfg
    assert cfg.orders.components[1].freq_hz == 47.0 and cfg.tacho.ppr == 4


# --- the ranges `cmsensord config --default` states are the ones loading enforces --------------

_NUMBER = re.compile(r"(?<![\w])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")
#: a bound of 0 said by a relation to another key (``> r_min``: r_min is > 0 itself)
_RELATIVE = {"monitor.r_max": "> r_min", "orders.max_rpm": "> min_rpm", "commissioned.to_s": "> from_s"}


def _key_comment(lines: list[str], section: str, key: str) -> str:
    """The comment of ``key`` in ``section`` of the default file: its line's and the comment lines
    after it (the mqtt section is commented out: its keys' lines start with ``#``)."""
    start = next(i for i, ln in enumerate(lines) if re.match(rf"#? ?{section}:", ln))
    for i in range(start + 1, len(lines)):
        m = re.match(rf"#?\s+{key}:[^#]*#?(.*)", lines[i])
        if m:
            more = []
            for ln in lines[i + 1:]:
                cont = re.match(r"#?\s+#(.*)", ln)
                if not cont:
                    break
                more.append(cont.group(1))
            return " ".join([m.group(1), *more])
    raise AssertionError(f"{section}.{key}: no line in the default file")


def test_default_file_states_every_bound_loading_enforces():
    """Each numeric range of a setting (gt/ge/lt/le of its field) is written in its comment in
    what `cmsensord config --default` prints, so a user editing a site file from it meets no
    refusal the file did not state (an integer's ``> 0`` may read ``1..``)."""
    from cmsensord.config.capture import CaptureConfig
    from cmsensord.config.indicators import IndicatorsConfig
    from cmsensord.config.mqtt import MqttConfig
    from cmsensord.config.settings import AcousticConfig, CommissionedConfig, OrdersConfig, TachoConfig
    from processes import cmsensord

    p = cmsensord("config", "--default")
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    sections = {"link": LinkConfig, "output": OutputConfig, "monitor": MonitorConfig, "tacho": TachoConfig,
                "orders": OrdersConfig, "acoustic": AcousticConfig, "indicators": IndicatorsConfig,
                "capture": CaptureConfig, "mqtt": MqttConfig, "commissioned": CommissionedConfig}
    unstated = []
    for section, cls in sections.items():
        for f in dataclasses.fields(cls):
            comment = _key_comment(lines, section, f.name)
            stated = {float(x) for x in _NUMBER.findall(comment)}
            integer = f.type in ("int", "int | None")
            for rule in ("gt", "ge", "lt", "le"):
                if rule not in f.metadata:
                    continue
                bound = float(f.metadata[rule])
                said = {bound} | ({bound + 1} if integer and rule == "gt" else set())
                if f"{section}.{f.name}" in _RELATIVE and bound == 0 and _RELATIVE[f"{section}.{f.name}"] in comment:
                    continue
                if not said & stated:
                    unstated.append(f"{section}.{f.name} {rule} {bound:g}")
    assert unstated == []
