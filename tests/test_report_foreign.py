"""`cmsensord report` of MCAP files that are not (all) cmsensord's: a ROS 2 bag, cmsensord's
topics holding messages that are not its JSON objects, and a log with such messages among its
own: what it could not read is counted and said in one line; with nothing of cmsensord's to
read, no page and exit status 2."""

from __future__ import annotations

import json

import pytest
from mcap.writer import Writer

from processes import cmsensord

pytestmark = pytest.mark.process

S = 1_000_000_000
EVENT = {"timestamp": {"sec": 0, "nsec": 0}, "kind": "start", "level": 0, "message": "started"}


def write(path, messages) -> None:
    """An MCAP of ``messages``: (topic, data) at one a second."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="test")
        schema = w.register_schema(name="x", encoding="jsonschema", data=b"{}")
        channels: dict[str, int] = {}
        for i, (topic, data) in enumerate(messages):
            if topic not in channels:
                channels[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=schema)
            w.add_message(channels[topic], log_time=i * S, data=data, publish_time=i * S)
        w.finish()


def test_a_ros_bag_is_one_line_and_no_page(tmp_path):
    bag = tmp_path / "ros.mcap"
    write(bag, [("/chatter", b"\x00\x01\x00\x00hello")] * 100 + [("/tf", b"\x00\x01")] * 5)
    p = cmsensord("report", str(bag), "--out", str(tmp_path / "r.html"))
    assert (p.returncode, p.stdout) == (2, "")
    assert p.stderr == (f"cmsensord: {bag}: no cmsensord message in it to report: of its 105 message(s), "
                        "105 on topics not cmsensord's (/chatter, /tf)\n")
    assert not (tmp_path / "r.html").exists()


def test_cmsensord_topics_holding_no_json_object_are_one_line_and_no_page(tmp_path):
    junk = tmp_path / "junk.mcap"
    write(junk, [("/cm/events", b"not json")] * 50 + [("/cm/events", b"[1]"), ("/cm/ch0/orders", b'"x"'),
                                                       ("/cm/ch0/severity", b"\x00\x01")])
    p = cmsensord("report", str(junk), "--out", str(tmp_path / "r.html"))
    assert (p.returncode, p.stdout) == (2, "")
    assert p.stderr == (f"cmsensord: {junk}: no cmsensord message in it to report: of its 53 message(s), "
                        "53 on cmsensord's topics that are not its JSON objects\n")
    assert not (tmp_path / "r.html").exists()


def test_messages_not_read_among_a_logs_own_are_counted(tmp_path):
    log = tmp_path / "mixed.mcap"
    write(log, [("/cm/events", json.dumps({**EVENT, "timestamp": {"sec": i, "nsec": 0}}).encode()) for i in range(10)]
          + [("/cm/events", b"not json")] * 5 + [("/chatter", b"\x00")] * 3)
    p = cmsensord("report", str(log), "--out", str(tmp_path / "r.html"))
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines() == [
        f"cmsensord: report: {log}: of its 18 message(s), 3 on topics not cmsensord's (/chatter); 5 on cmsensord's "
        "topics that are not its JSON objects: left out",
        f"report: {tmp_path / 'r.html'} (0 figures, 18 messages from 1 file(s))"]
    page = (tmp_path / "r.html").read_text()
    assert ("messages left out: 3 on topics not cmsensord&#x27;s (/chatter); 5 on cmsensord&#x27;s topics that "
            "are not its JSON objects; complete") in page
