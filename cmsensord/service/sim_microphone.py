"""The microphone channels of ``cmsensord --simulate``: their configuration and the acoustic
calibration of the simulated motor, made from the simulator the documented way and cached.

The calibration is what a user makes on a real machine (README, Acoustic channels), with the
simulated board in place of the machine::

    python -m firmware_sim --scenario degrading_mic --channels 2 --mode raw --seed 1000 \\
        --duration 300 --out pair.bin                                 # accelerometer + microphone
    python -m firmware_sim --scenario degrading_mic --channels 2 --mode raw --seed 1001 \\
        --duration 60 --param machine_off=1 --out bg.bin              # the background alone
    python -m cmsensord.acoustic_calib --paired pair.bin --background bg.bin --accel 0 --mic 1 \\
        --out mic.json

:func:`simulator_calibration` runs the same steps (the board's capture writer and
:func:`cmsensord.acoustic_calib.fit_captures`) once and keeps the file in the user's cache
directory (``$XDG_CACHE_HOME/cmsensord``, else ``~/.cache/cmsensord``), named for the recipe
and the package version, so every microphone scenario (healthy, faulty, degrading: one motor)
uses it from then on.  Other seeds than the runs' (0 by default) keep calibration and test apart.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from cmsensord import __version__
from cmsensord.config import Config
from cmsensord.errors import ConfigError

#: the calibration recipe: scenario, seeds and seconds of the paired and background captures
RECIPE: dict[str, Any] = {"scenario": "degrading_mic", "paired_seed": 1000, "paired_s": 300.0,
          "background_seed": 1001, "background_s": 60.0, "mode": "raw", "accel": 0, "mic": 1}


#: how long making the calibration takes, said before it starts (3.9-6.1 s measured on a 2-core
#: x86 machine, longer with other work on it)
MAKING_S = "about 4-30 s, longer on a small board"


def cache_dir() -> Path:
    """Where the simulator's calibration is kept: $XDG_CACHE_HOME/cmsensord or ~/.cache/cmsensord."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "cmsensord"


def simulator_calibration(fallback_dir: Path | None = None) -> Path:
    """The acoustic calibration of the simulated motor: the cached file, made first if missing
    (:data:`MAKING_S`), with a line on stderr before (what it is made from, how long it takes)
    and one after (the time it took, where it is kept); a cached one is one line.  Where the
    cache directory cannot be made, the file goes into ``fallback_dir`` (the run's output
    directory)."""
    key = hashlib.sha256(repr((sorted(RECIPE.items()), __version__)).encode()).hexdigest()[:12]
    path = cache_dir() / f"acoustic-simulated-motor-{key}.json"
    if path.is_file():
        print(f"acoustic calibration of the simulated motor: {path} (cached)", file=sys.stderr)
        return path
    t = time.monotonic()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError:
        if fallback_dir is None:
            raise
        path = fallback_dir / path.name
    r = RECIPE
    print(f"acoustic calibration of the simulated motor: none cached yet: making it once ({MAKING_S}) from "
          f"{r['paired_s']:g} s of {r['scenario']} (seed {r['paired_seed']}) and {r['background_s']:g} s of its "
          f"background (seed {r['background_seed']}), as python -m cmsensord.acoustic_calib does",
          file=sys.stderr, flush=True)
    with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
        cal = _fit(Path(tmp))
        from cmsensord.acoustic_calib import save_calibration
        part = Path(tmp) / "mic.json"
        save_calibration(cal, str(part))
        os.replace(part, path)                     # complete or absent, also for a parallel run
    print(f"acoustic calibration of the simulated motor: made in {time.monotonic() - t:.1f} s; kept in {path}",
          file=sys.stderr)
    return path


def _fit(tmp: Path):
    """The captures of :data:`RECIPE` written into ``tmp`` and the calibration fitted from them."""
    from cmsensord.acoustic_calib import fit_captures
    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    r = RECIPE
    caps = []
    for name, seed, seconds, params in (("pair", r["paired_seed"], r["paired_s"], {}),
                                        ("bg", r["background_seed"], r["background_s"], {"machine_off": True})):
        sc = make_scenario(str(r["scenario"]), n_channels=2, seed=int(seed), duration_s=float(seconds), **params)
        board = Board(sc, BoardConfig(mode=str(r["mode"]), n_channels=2, fs=sc.fs,
                                          scale=getattr(sc, "board_scale", None)))
        cap = tmp / f"{name}.bin"
        board.write_capture(cap, float(seconds))
        caps.append(cap)
    return fit_captures(caps[0], caps[1], accel=int(r["accel"]), mic=int(r["mic"]))


def microphone_config(cfg: Config, scenario: str, microphones: tuple[int, ...], *,
                      from_file: str | None, fallback_dir: Path | None = None) -> Config:
    """``cfg`` for a scenario whose channels ``microphones`` carry sound (Pa).

    Without a configuration file: those channels become ``kind: microphone`` with the
    simulator's calibration (:func:`simulator_calibration`) unless ``acoustic.calibration``
    is set.  With one (``from_file``): its channels must fit the board's units, a microphone
    channel configured as an accelerometer (or the reverse) is a ConfigError naming the key."""
    if from_file is not None:
        for i, ch in enumerate(cfg.channels):
            sends = "Pa (a microphone)" if ch.index in microphones else "m/s^2 (an accelerometer)"
            if (ch.kind == "microphone") != (ch.index in microphones):
                raise ConfigError(from_file, f"channels[{i}].kind", f"the simulated board ({scenario}) "
                                  f"sends {sends} on channel {ch.index}, which a channel of kind "
                                  f"{ch.kind} cannot take", ch.kind)
        return cfg
    cal = cfg.acoustic.calibration or str(simulator_calibration(fallback_dir))
    channels = tuple(dataclasses.replace(ch, kind="microphone", calibration=cal, unit="Pa")
                     if ch.index in microphones else ch for ch in cfg.channels)
    return dataclasses.replace(cfg, channels=channels)
