"""``cmsensord --simulate``: firmware_sim on a pty, and the daemon's live loop on that pty.

Each scenario runs with its own defaults (:data:`SCENARIO_RUNS`: length, speed, channels,
mode, microphone channels) unless the command line says otherwise; the board's pty has flow
control, so a daemon that falls behind slows the board down and no byte is dropped.  A
simulated board is not the machine: its alarms are neither restored from nor kept in the
output directory's alarm state file (:mod:`cmsensord.service.alarm_store`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import subprocess
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import serial

from cmsensord.config import as_written, config_from_dict, default_config, load_config
from cmsensord.config.indicators import zones_assumed
from cmsensord.errors import ConfigError, SinkError
from cmsensord.serial_port import open_serial
from cmsensord.service.live import run_live
from cmsensord.service.sim_microphone import microphone_config

log = logging.getLogger("cmsensord")

#: order-tracker settings for the run-up scenarios of Yeh, Pan & Le (section 4.1): their
#: components, a -3 dB bandwidth of 20 Hz (r about 50 at the tracker rate) and the 0.1 s
#: smoother, which keeps the close orders within the paper's error bounds
#: (tests/test_order_tracker.py)
RUNUP_ORDERS = {
    "close_orders": {"max_rpm": 3000.0, "smoother_lag_s": 0.1, "components": [
        {"name": "o1", "order": 1.0, "bandwidth_hz": 20.0},
        {"name": "o4", "order": 4.0, "bandwidth_hz": 20.0},
        {"name": "o4_2", "order": 4.2, "bandwidth_hz": 20.0}]},
    "whirl": {"max_rpm": 7000.0, "smoother_lag_s": 0.1, "components": [
        {"name": "o1", "order": 1.0, "bandwidth_hz": 5.0},
        {"name": "whirl", "order": 0.47, "bandwidth_hz": 5.0, "alarm_rms": 0.7},
        {"name": "whip", "freq_hz": 47.0, "bandwidth_hz": 5.0}]},
}


@dataclass(frozen=True)
class ScenarioRun:
    """How ``--simulate`` runs a scenario when the command line does not say: its natural
    length, a speed this project's 2-core machine sustains with the simulator, the daemon and
    other work on it (measured: README, Using it), the board's channels and mode, and which
    channels carry a microphone (Pa) rather than an accelerometer (m/s²)."""

    duration_s: float = 600.0
    speed: float = 20.0
    channels: int = 1
    mode: str = "rms"
    microphones: tuple[int, ...] = ()


#: every scenario's defaults under --simulate (the others: ScenarioRun())
SCENARIO_RUNS = {
    "whirl": ScenarioRun(duration_s=180.0, speed=10.0, mode="raw"),
    "close_orders": ScenarioRun(duration_s=5.0, speed=1.0, mode="raw"),
    "healthy_mic": ScenarioRun(channels=2, microphones=(1,)),
    "faulty_mic": ScenarioRun(channels=2, microphones=(1,)),
    "degrading_mic": ScenarioRun(channels=2, microphones=(1,)),
    "degrading_mic_only": ScenarioRun(channels=1, microphones=(0,)),
}


def scenario_run(name: str) -> ScenarioRun:
    """The --simulate defaults of scenario ``name``."""
    return SCENARIO_RUNS.get(name, ScenarioRun())


@dataclass(frozen=True)
class SimulateOptions:
    """What ``--simulate`` runs: the scenario and board settings, and where the output goes.
    None: the scenario's default (:data:`SCENARIO_RUNS`)."""

    scenario: str = "degrading"
    duration: float | None = None
    speed: float | None = None
    seed: int = 0
    channels: int | None = None
    mode: str | None = None         # rms | raw
    tacho: bool = False
    config: str | None = None
    out: str | None = None
    capture: str | None = None
    akf_trace: bool = False
    publish: bool = False           # publish to the config's mqtt broker (as its client_id)


def simulate(opt: SimulateOptions) -> int:
    """Start firmware_sim on a pty (with flow control: a slow reader slows the board down, no
    byte is dropped) and the daemon on that pty."""
    from firmware_sim.scenarios import SCENARIOS

    if opt.scenario not in SCENARIOS:
        raise ConfigError("--scenario", None, f"unknown scenario; choose from {', '.join(SCENARIOS)}",
                          opt.scenario)
    run = scenario_run(opt.scenario)
    opt = dataclasses.replace(
        opt, duration=opt.duration or run.duration_s, speed=opt.speed or run.speed,
        channels=opt.channels or run.channels, mode=opt.mode or run.mode)
    assert opt.channels is not None and opt.mode is not None and opt.duration and opt.speed
    if run.microphones and max(run.microphones) >= opt.channels:
        raise ConfigError("--channels", None, f"{opt.scenario} sends its microphone on channel "
                          f"{max(run.microphones)}: give at least {max(run.microphones) + 1} channels",
                          opt.channels)
    cfg = load_config(opt.config, n_channels=opt.channels) if opt.config else default_config(opt.channels)
    note = zones_assumed(cfg.indicators, as_written(opt.config).get("indicators"))
    if note and opt.mode == "raw":          # an RMS-mode board's records carry no zone
        print(note, file=sys.stderr)
    if cfg.mqtt is not None and not opt.publish:
        log.warning("mqtt: the mqtt section is ignored: a simulated board would publish as client_id %s "
                    "under %s/, the live daemon's (its retained alarms, its dashboards); give --publish "
                    "to publish it", cfg.mqtt.client, cfg.mqtt.prefix)
        cfg = dataclasses.replace(cfg, mqtt=None)
    runup = opt.scenario in RUNUP_ORDERS
    mode = opt.mode
    tacho = opt.tacho or runup
    if runup and "orders" not in as_written(opt.config):
        # the paper's validation signals: track their components (Yeh, Pan & Le, section 4.1),
        # unless the configuration file gives orders of its own
        cfg = dataclasses.replace(cfg, orders=config_from_dict(
            {"orders": RUNUP_ORDERS[opt.scenario]}, source="--scenario").orders)
    out_dir = opt.out or cfg.output.dir
    try:                                # before the simulator starts: a clear error first
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SinkError(f"{out_dir}: cannot create the output directory: {exc.strerror or exc}") from None
    if run.microphones:
        cfg = microphone_config(cfg, opt.scenario, run.microphones, from_file=opt.config,
                                fallback_dir=Path(out_dir))
    cfg = dataclasses.replace(cfg, output=dataclasses.replace(cfg.output, dir=out_dir,
                                                              akf_trace=cfg.output.akf_trace or opt.akf_trace))
    cmd = [sys.executable, "-P", "-m", "firmware_sim", "--pty", "--scenario", opt.scenario,
           "--duration", str(opt.duration), "--speed", str(opt.speed), "--seed", str(opt.seed),
           "--channels", str(opt.channels), "--mode", mode, "--hold", "--flow-control",
           "--start-on-stdin"] + (["--tacho"] if tacho else [])
    sim = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True, start_new_session=True, env=_sim_env())
    assert sim.stdout is not None and sim.stderr is not None    # both piped above
    try:
        line = sim.stdout.readline().strip()
        if not line.startswith("/dev/"):
            err = sim.stderr.read() if sim.poll() is not None else ""
            print(f"cmsensord: the simulator did not start: {line or err.strip()}", file=sys.stderr)
            return 1
        print(f"simulated board ({opt.scenario}, {mode.upper()} mode{' + tacho' if tacho else ''}, "
              f"{opt.channels} channel(s), seed {opt.seed}) on "
              f"{line}; {opt.duration:g} s at {opt.speed:g}x real time", file=sys.stderr)
        cfg = dataclasses.replace(cfg, link=dataclasses.replace(cfg.link, port=line))
        return run_live(cfg, auto_channels=False, duration_s=opt.duration, sim_done=_watch(sim),
                        capture_path=opt.capture, open_port=_start_on_open(sim, line, cfg.link.baud),
                        metadata={"scenario": opt.scenario, "seed": str(opt.seed),
                                  "duration_s": str(opt.duration)}, simulated=True,
                        inputs=[opt.config] if opt.config else [])
    finally:
        _end(sim)


def _sim_env() -> dict[str, str]:
    """The simulator's environment: PYTHONPATH without its empty or relative entries,
    which would put the working directory (and a ``numpy.py`` there) on sys.path; with
    ``python -P`` the simulator imports only from installed and absolute paths."""
    env = dict(os.environ)
    path = [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if os.path.isabs(p)]
    if path:
        env["PYTHONPATH"] = os.pathsep.join(path)
    else:
        env.pop("PYTHONPATH", None)
    return env


def _start_on_open(sim: subprocess.Popen, port: str, baud: int) -> Callable[[], serial.Serial]:
    """How the reader opens the simulator's pty (exclusively, as every port): then the
    simulator starts its stream (``--start-on-stdin``: EOF on its stdin), so none of it is
    written before pyserial's open, which discards what waits in the port, and a simulated
    run is whole from its first block."""
    def open_port() -> serial.Serial:
        ser = open_serial(port, baud, timeout=0.05)
        if sim.stdin is not None and not sim.stdin.closed:
            with contextlib.suppress(OSError):      # the simulator has gone: the reader sees it
                sim.stdin.close()
        return ser

    return open_port


def _watch(sim: subprocess.Popen) -> threading.Event:
    """Set when the simulator has sent everything (it prints its stats then) or ended."""
    done = threading.Event()

    def watch_sim() -> None:
        assert sim.stdout is not None                   # piped by simulate()
        for out_line in sim.stdout:
            if out_line.startswith("{"):
                done.set()
        done.set()

    threading.Thread(target=watch_sim, name="sim-watch", daemon=True).start()
    return done


def _end(sim: subprocess.Popen) -> None:
    if sim.poll() is None:
        sim.terminate()
    try:
        sim.wait(timeout=3)
    except subprocess.TimeoutExpired:
        sim.kill()
