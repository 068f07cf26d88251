"""Options of the command line that apply beyond the mode they are listed with: ``--out`` and
``--akf-trace`` of the live daemon, ``-v`` after a subcommand, and the one warning line of an
empty configuration file in every command that reads one."""

from __future__ import annotations

from cmsensord.sinks.mcap_sink import read_messages
from processes import cmsensord, daemon_on_short_board, run_module


def test_the_daemon_writes_to_out_and_traces_with_akf_trace(tmp_path):
    """`cmsensord --config FILE --out DIR --akf-trace`: its logs in DIR (not output.dir), with
    /cm/<ch>/akf, as --simulate and replay do with the same options."""
    _, err = daemon_on_short_board(tmp_path, "--out", str(tmp_path / "out"), "--akf-trace")
    assert not (tmp_path / "logs").exists()                                 # the config's output.dir
    (log,) = (tmp_path / "out").glob("*.mcap")
    assert f"MCAP log: {log}" in err.splitlines()
    topics = {t for t, _, _ in read_messages(log)}
    assert "/cm/ch0/akf" in topics


def test_verbose_is_taken_after_the_subcommand_as_before_it(tmp_path):
    cap = tmp_path / "h.bin"
    assert run_module("firmware_sim", "--out", str(cap), "--scenario", "healthy", "--duration", "5").returncode == 0
    info = "INFO config: board firmware 1.0: RMS mode, 1 channel(s), fs 25000 Hz, block 250"
    for args in (["replay", str(cap), "-v"], ["-v", "replay", str(cap)], ["replay", "-v", str(cap)]):
        p = cmsensord(*args, "--out", str(tmp_path / "logs"))
        assert p.returncode == 0, p.stderr
        assert info in p.stderr.splitlines(), args
    quiet = cmsensord("replay", str(cap), "--out", str(tmp_path / "logs"))
    assert quiet.returncode == 0 and info not in quiet.stderr.splitlines()
    for sub in ("replay", "summary", "calibrate", "import", "status"):
        text = " ".join(cmsensord(sub, "--help").stdout.split())         # as wrapped to any width
        assert " -v, --verbose log more: -v info, -vv debug (default: warnings and up) " in text + " ", sub


EMPTY = "WARNING config: empty.yaml holds no settings (empty, or comments only): every setting is its default"


def test_an_empty_config_is_said_by_simulate(tmp_path):
    """As by the daemon and replay (tests/test_errors.py): a site file emptied by mistake would run
    every setting at its default."""
    (tmp_path / "empty.yaml").write_text("# emptied\n")
    p = cmsensord("--simulate", "--config", "empty.yaml", "--duration", "3", "--speed", "10",
                  "--out", str(tmp_path / "sim"), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines()[0] == EMPTY
    assert p.stderr.splitlines().count(EMPTY) == 1


def test_an_empty_config_is_said_by_calibrate(tmp_path):
    (tmp_path / "empty.yaml").write_text("# emptied\n")
    assert run_module("firmware_sim", "--out", str(tmp_path / "cap.bin"), "--scenario", "healthy",
                      "--duration", "5").returncode == 0
    p = cmsensord("calibrate", "cap.bin", "--config", "empty.yaml", "--out", "site.yaml", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines()[0] == EMPTY
    assert p.stderr.splitlines().count(EMPTY) == 1


def test_a_baud_rate_out_of_range_is_a_usage_line(tmp_path):
    """`record --baud -5` ends in a usage line, exit 2, not in pyserial's ValueError's traceback."""
    p = cmsensord("record", "--port", "/dev/null", "--out", str(tmp_path / "r.bin"), "--baud", "-5")
    assert p.returncode == 2
    assert p.stderr.splitlines() == ["cmsensord record: error: argument --baud: expected an integer 1..12000000, "
                                     "got -5 (see cmsensord record --help)"]
    assert not (tmp_path / "r.bin").exists()


def test_an_unknown_option_whose_value_reads_as_the_subcommand_is_named():
    """`cmsensord --simulate --seconds 5`: argparse took 5 for the subcommand ("invalid choice:
    '5'"); the one line names the option and the one meant, exit 2."""
    for args, meant in ((("--simulate", "--seconds", "5"), "--duration"),
                        (("--simulate", "--duraton", "5"), "--duration")):
        p = cmsensord(*args)
        assert p.returncode == 2, p.stderr
        assert p.stderr == (f"cmsensord: error: unrecognized argument {args[1].split('=')[0]} (did you mean "
                            f"{meant}?) (see cmsensord --help)\n"), p.stderr
    p = cmsensord("frobnicate")                         # a subcommand mistyped is still said as one
    assert p.returncode == 2 and "invalid choice: 'frobnicate'" in p.stderr, p.stderr


def test_arguments_left_over_after_a_subcommand_point_at_its_help():
    """`replay a.bin b.bin`, `calibrate x.bin --to 20 %`: the arguments argparse could not place
    are on the subcommand's line, so its --help is the one named (it named `cmsensord --help`);
    without a subcommand, the command's."""
    for args, command, extra in ((("replay", "a.bin", "b.bin"), "cmsensord replay", "b.bin"),
                                 (("calibrate", "x.bin", "--to", "20", "%", "--out", "s.yaml"),
                                  "cmsensord calibrate", "%"),
                                 (("-v", "vkf", "x.bin", "--bogus"), "cmsensord vkf", "--bogus"),
                                 (("--verbose", "--bogus"), "cmsensord", "--bogus")):
        p = cmsensord(*args)
        assert (p.returncode, p.stdout) == (2, ""), p.stderr
        assert p.stderr == f"{command}: error: unrecognized arguments: {extra} (see {command} --help)\n"


def test_replay_and_vkf_help_give_the_out_default_they_use(tmp_path):
    """`--out` left out writes where the help says: cmsensord-logs in the current directory (that
    of --simulate too), or output.dir of --config."""
    said = ("--out DIR MCAP output directory (default: output.dir of --config, else cmsensord-logs here, "
            "where --simulate writes too: give each run its own)")
    for sub in ("replay", "vkf"):
        assert said in " ".join(cmsensord(sub, "--help").stdout.split()), sub
    cap = tmp_path / "h.bin"
    assert run_module("firmware_sim", "--out", str(cap), "--scenario", "healthy", "--duration", "2").returncode == 0
    p = cmsensord("replay", "h.bin", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert len(list((tmp_path / "cmsensord-logs").glob("cmsensord-*.mcap"))) == 1
    (tmp_path / "site.yaml").write_text("output:\n  dir: site-logs\n")
    p = cmsensord("replay", "h.bin", "--config", "site.yaml", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert len(list((tmp_path / "site-logs").glob("cmsensord-*.mcap"))) == 1
