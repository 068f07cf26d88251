"""Shared fixtures, and the ``process`` marker for tests that start processes or ptys.

    python -m pytest -m "not process"                # the unit tests
    python -m pytest -m "not process and not slow"   # the quick loop: without the long simulations
    python -m pytest -m process                      # daemon/board processes, ptys, shell tools

A test is marked ``process`` when its module is in PROCESS_MODULES (every test there
starts ``python -m cmsensord`` or ``python -m firmware_sim``), when it is named in
PROCESS_TESTS (such tests in modules of fast unit tests), or when it uses a fixture in
PROCESS_FIXTURES.  A new test that starts a process or opens a pty goes into a process
module, is added here, or carries ``@pytest.mark.process`` itself.

    CMSENSORD_CHECK_PROCESS_MARKS=1 python -m pytest -m "not process"

fails every unmarked test that starts a process or opens a pty (the check of these lists).
"""

from __future__ import annotations

import os
import pty
import subprocess

import pytest

import cmsensord.blas_threads  # noqa: F401  (first: the test processes' numpy runs one BLAS thread too)
import processes
from fakes import FakeClock

#: Modules whose every test starts processes or opens ptys.
PROCESS_MODULES = frozenset({
    "test_test_processes.py",
    "test_report.py",
    "test_capture.py",
    "test_capture_triggers.py",
    "test_alarms_daemon.py",
    "test_calibrate.py",
    "test_cli.py",
    "test_crash.py",
    "test_errors.py",
    "test_link_faults.py",
    "test_output_trust.py",
    "test_replay.py",
    "test_orders_latency.py",
    "test_replay_one_pass.py",
    "test_systemd.py",
    "test_traps.py",
    "test_stream_random.py",
    "test_realdata.py",
    "test_import.py",
    "test_import_memory.py",
    "test_import_text_tables.py",
    "test_report_recording_time.py",
    "test_stream_time.py",
    "test_config_hostile.py",
    "test_reader_thread.py",
    "test_stream_events.py",
    "test_live_batching.py",
    "test_no_compiler.py",
    "test_journal.py",
    "test_foxglove.py",
    "test_package.py",
    "test_vkf_command.py",
    "test_simulate_scenarios.py",
    "test_acoustic_calib_command.py",
    "test_indicators_daemon.py",
    "test_mqtt.py",
    "test_mqtt_config.py",
    "test_mqtt_runs.py",
    "test_retention_process.py",
    "test_output_dir_held.py",
    "test_short_logs.py",
    "test_dir_fsync.py",
    "test_fsync_noise.py",
    "test_output_unmounted.py",
    "test_report_link_totals.py",
    "test_log_times.py",
    "test_replay_log_times.py",
    "test_outage_stamps.py",
    "test_config_never_fires.py",
    "test_capture_not_mcap.py",
    "test_interrupted.py",
    "test_cli_options.py",
    "test_operator_answers.py",
})

#: Tests that start processes or open ptys, in modules of fast unit tests ("module::function").
PROCESS_TESTS = frozenset({
    "test_disk_full.py::test_the_daemon_keeps_running_on_a_full_disk_and_resumes_logging",
    "test_event_kinds.py::test_replays_write_only_events_the_stored_schema_allows",
    "test_firmware_sim.py::test_pty_stream_is_paced_and_decodes_contiguously",
    "test_firmware_sim.py::test_pty_without_reader_drops_bytes_and_never_blocks",
    "test_firmware_sim.py::test_pty_with_flow_control_waits_for_a_slow_reader_and_drops_nothing",
    "test_firmware_sim.py::test_pty_board_with_hold_stops_at_sigterm_whenever_it_lands",
    "test_firmware_sim.py::test_pty_board_with_start_on_stdin_sends_nothing_before_its_stdin_ends",
    "test_firmware_sim_raw.py::test_cli_warns_when_the_uart_cannot_carry_the_stream",
    "test_link.py::test_reader_thread_decodes_a_pty_and_tees_the_capture",
    "test_link.py::test_a_stalled_loop_loses_raw_blocks_but_no_rms_frame_and_memory_stays_bounded",
    "test_order_tracker.py::test_the_tracker_does_not_load_scipy_signal",
    "test_salvage.py::test_summary_of_truncated_files_and_of_a_file_that_is_not_mcap",
    "test_systemd_unit.py::test_systemd_analyze_verify_prints_nothing",
    "test_systemd_unit.py::test_systemd_analyze_verify_does_complain_here",
    "test_systemd_unit.py::test_systemd_analyze_security_exposure_is_at_most_2",
    "test_systemd_unit.py::test_systemd_analyze_with_the_mqtt_drop_in_verifies_and_stays_at_most_2",
})

#: Fixtures that start a process (``small_fs`` runs mount and umount).
PROCESS_FIXTURES = frozenset({"small_fs"})

#: Unit tests that simulate a long run (a simulated hour, tens of seconds each): also ``slow``.
SLOW_TESTS = frozenset({
    "test_scenarios.py::test_healthy_gives_no_anomaly_in_a_simulated_hour",
    "test_scenarios.py::test_degrading_rises_through_levels_fails_and_eases",
})


def pytest_collection_modifyitems(config, items):
    for item in items:
        module = item.path.name
        name = f"{module}::{item.originalname}"
        if (module in PROCESS_MODULES or name in PROCESS_TESTS
                or PROCESS_FIXTURES.intersection(getattr(item, "fixturenames", ()))):
            item.add_marker(pytest.mark.process)
        if name in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)


@pytest.fixture
def small_fs(tmp_path):
    """A 512 KiB tmpfs (root in a container that allows mounts; else the test skips)."""
    mnt = tmp_path / "fs"
    mnt.mkdir()
    try:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=512k", "tmpfs", str(mnt)],
                           capture_output=True, text=True, timeout=10)
    except FileNotFoundError:
        pytest.skip("no mount command")
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True, timeout=10)


@pytest.fixture(autouse=True)
def _process_mark_check(request, monkeypatch):
    """With CMSENSORD_CHECK_PROCESS_MARKS set: an unmarked test that starts a process fails."""
    if not os.environ.get("CMSENSORD_CHECK_PROCESS_MARKS") or request.node.get_closest_marker("process"):
        return

    def refuse(*args, **kwargs):
        raise AssertionError(f"{request.node.nodeid} starts a process or opens a pty: mark it "
                             "'process' (tests/conftest.py)")

    monkeypatch.setattr(subprocess.Popen, "__init__", refuse)
    monkeypatch.setattr(os, "openpty", refuse)
    monkeypatch.setattr(pty, "openpty", refuse)


@pytest.fixture(autouse=True)
def _stop_what_the_test_left():
    """After each test: no daemon or board of start_daemon/start_board is left running, even
    when the test failed before stopping it."""
    yield
    processes.stop_left_running()


@pytest.fixture
def clock() -> FakeClock:
    """A hand-set clock at t = 100.0 s, for the ``clock=`` of sinks and the notifier."""
    return FakeClock()
