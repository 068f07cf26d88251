"""Configuration: one YAML file -> typed, frozen dataclasses.

The file has these sections (see ``config/default.yaml``, which lists every key
with its default)::

    link:     serial port and reader settings          -> LinkConfig
    output:   MCAP directory, compression, rotation    -> OutputConfig
    monitor:  Kim et al. 2023 AKF bank and decisions   -> MonitorConfig
    channels: optional list; per channel name, index, scale/offset, kind and
              any monitor key overriding the global monitor block -> ChannelConfig
    tacho:    the shaft tacho                          -> TachoConfig
    orders:   the order tracker and its components     -> OrdersConfig
    acoustic: microphone channels                      -> AcousticConfig
    indicators, bearings: vibration indicators         -> IndicatorsConfig, BearingConfig
    mqtt:     optional: publishing to an MQTT broker   -> MqttConfig (absent: None)

Modules: :mod:`.validation` (the generic checks, :class:`ConfigError`),
:mod:`.settings` (the dataclasses), :mod:`.loading` (YAML and dicts -> Config,
channel overlays, defaults, and back to a dict). Every failure raises
:class:`~cmsensord.errors.ConfigError` whose ``str()`` is one line naming the
file, the key path and the reason.
"""

from __future__ import annotations

from .loading import as_written, config_from_dict, config_to_dict, default_config, load_config
from .settings import (
    MAX_CHANNELS,
    NOMINAL_RATE_HZ,
    AcousticConfig,
    ChannelConfig,
    CommissionedConfig,
    ComponentConfig,
    Config,
    LinkConfig,
    MonitorConfig,
    OrdersConfig,
    OutputConfig,
    TachoConfig,
    default_channels,
)
from .validation import ConfigError

__all__ = [
    "MonitorConfig",
    "ChannelConfig",
    "LinkConfig",
    "OutputConfig",
    "TachoConfig",
    "OrdersConfig",
    "ComponentConfig",
    "AcousticConfig",
    "CommissionedConfig",
    "Config",
    "ConfigError",
    "as_written",
    "MAX_CHANNELS",
    "NOMINAL_RATE_HZ",
    "load_config",
    "config_from_dict",
    "default_config",
    "default_channels",
    "config_to_dict",
]
