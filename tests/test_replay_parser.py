"""`cmsensord replay ...` is parsed by a parser of the replay subcommand alone (no other
subcommand built or imported at every replay): the same namespace, the same errors."""

from __future__ import annotations

import pytest

from cmsensord.cli import build_parser, replay_parser

ARGV = [
    ["replay", "cap.bin"],
    ["replay", "cap.bin", "--config", "site.yaml", "--out", "logs", "--akf-trace"],
    ["replay", "cap.bin", "--realtime"],
    ["replay", "--speed", "2.5", "cap.bin"],
]


@pytest.mark.parametrize("argv", ARGV)
def test_the_replay_parser_gives_the_full_parsers_namespace(argv):
    full = vars(build_parser(with_scenarios=False).parse_args(argv))
    alone = vars(replay_parser().parse_args(argv))
    assert {"command", "verbose", "capture", "sub_config", "sub_out", "sub_trace", "sub_speed"} <= alone.keys()
    assert alone == {k: full[k] for k in alone}


@pytest.mark.parametrize("argv", [["replay"], ["replay", "cap.bin", "--bogus"], ["replay", "x", "--speed", "-1"],
                                  ["replay", "x", "--realtime", "--speed", "2"]])
def test_the_replay_parser_refuses_what_the_full_parser_refuses_with_the_same_line(argv, capsys):
    lines = []
    for parser in (build_parser(with_scenarios=False), replay_parser()):
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(argv)
        assert exc.value.code == 2
        lines.append(capsys.readouterr().err)
    assert lines[0] == lines[1] and lines[0].startswith("cmsensord")
