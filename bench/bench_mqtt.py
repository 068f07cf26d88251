#!/usr/bin/env python3
"""Benchmark of MQTT publishing (cmsensord/publish): what the publisher sustains, what it costs at
the default rate, and what an outage puts on disk.

1. sample messages: a simulated 4-channel board in RAW mode with a tacho (``cmsensord --simulate``),
   its MCAP messages of the default ``publish`` kinds (severity, indicators, alarms, events) per
   board second;
2. throughput: the Publisher (thread, disk queue, paho) against a Mosquitto on 127.0.0.1, N
   messages offered at once, until the broker acknowledged the last one (QoS 1), messages/s;
3. CPU: those messages offered at their real rate (4 channels) for ``--seconds``, the process's
   CPU time (the publisher thread and paho; the offering loop sleeps) as % of one core;
4. outage: an hour of those messages into the disk queue with no broker: bytes on disk.

    python bench/bench_mqtt.py [--seconds 30] [--messages 20000]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from cmsensord.config.mqtt import MqttConfig  # noqa: E402
from cmsensord.publish.disk_queue import DiskQueue  # noqa: E402
from cmsensord.publish.publisher import Publisher  # noqa: E402
from cmsensord.publish.topics import TopicMap, payload  # noqa: E402
from cmsensord.sinks.mcap_sink import read_messages  # noqa: E402
from mosquitto import Broker  # noqa: E402

KINDS = MqttConfig(host="h").publish


def sample(work: Path, seconds: float = 20.0) -> tuple[list[tuple[str, int, dict]], float]:
    """The published MCAP messages of a simulated 4-channel RAW run, and its board seconds."""
    subprocess.run([sys.executable, "-m", "cmsensord", "--simulate", "--scenario", "faulty", "--channels", "4",
                    "--mode", "raw", "--tacho", "--duration", str(seconds), "--speed", "4", "--out",
                    str(work / "logs")], check=True, capture_output=True, cwd=ROOT)
    msgs = [(t, s, m) for p in sorted((work / "logs").glob("*.mcap")) for t, s, m in read_messages(p)
            if t.strip("/").split("/")[-1] in KINDS]
    return msgs, seconds


def wait(test, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end and not test():
        time.sleep(0.005)
    return test()


def throughput(work: Path, port: int, msgs: list, n: int) -> float:
    pub = Publisher(MqttConfig(host="127.0.0.1", port=port, client_id="bench", resend_per_s=1e6,
                               handover_messages=n + 10), str(work / "q-throughput"))
    pub.start()
    assert wait(lambda: pub.state == "connected", 10)
    t0 = time.perf_counter()
    for i in range(n):
        t, s, m = msgs[i % len(msgs)]
        pub.offer(t, s, m)
    assert wait(lambda: pub.acked_total >= n, 300), pub.diagnostics()
    rate = n / (time.perf_counter() - t0)
    pub.close()
    return rate


def offering(pub, msgs: list, per_s: float, seconds: float) -> float:
    """Offer ``msgs`` at ``per_s`` for ``seconds`` (in bursts every 0.1 s, as decisions come):
    the process's CPU seconds per second."""
    c0, t0 = time.process_time(), time.perf_counter()
    i = 0
    while time.perf_counter() - t0 < seconds:
        due = int((time.perf_counter() - t0) * per_s)
        while i < due:
            t, s, m = msgs[i % len(msgs)]
            pub.offer(t, s, m)
            i += 1
        time.sleep(0.1)
    return (time.process_time() - c0) / (time.perf_counter() - t0)


class _Nothing:
    def offer(self, topic, stamp_ns, msg) -> None:
        pass


def cpu(work: Path, port: int, msgs: list, board_s: float, seconds: float) -> tuple[float, float]:
    """Messages/s and the publisher's CPU in % of one core: the offering loop's CPU with the
    publisher minus the same loop offering to nothing."""
    per_s = len(msgs) / board_s
    pub = Publisher(MqttConfig(host="127.0.0.1", port=port, client_id="bench-cpu"), str(work / "q-cpu"))
    pub.start()
    assert wait(lambda: pub.state == "connected", 10)
    used = offering(pub, msgs, per_s, seconds)
    pub.close()
    return per_s, 100 * (used - offering(_Nothing(), msgs, per_s, seconds))


def outage(work: Path, msgs: list, board_s: float) -> tuple[int, int]:
    topics = TopicMap(MqttConfig(host="h", client_id="bench"))
    q = DiskQueue(work / "q-outage", max_bytes=1 << 40)
    n = int(len(msgs) / board_s * 3600)
    for i in range(n):
        t, s, m = msgs[i % len(msgs)]
        route = topics.route(t)
        assert route is not None
        q.append(route[0], lambda seq, t=t, s=s, m=m: payload(t, s, m, seq), route[1])
    q.close()
    return n, q.size_bytes


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0, help="duration of the CPU measurement")
    ap.add_argument("--messages", type=int, default=20000, help="messages of the throughput measurement")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_mqtt_") as tmp:
        work = Path(tmp)
        msgs, board_s = sample(work)
        kinds: dict[str, list[int]] = {}
        for t, s, m in msgs:
            kinds.setdefault(t.strip("/").split("/")[-1], []).append(len(payload(t, s, m, 1)))
        broker = Broker(work / "broker").start()
        try:
            rate = throughput(work, broker.port, msgs, args.messages)
            per_s, pct = cpu(work, broker.port, msgs, board_s, args.seconds)
        finally:
            broker.stop()
        n, size = outage(work, msgs, board_s)
    print("| quantity | value |\n| --- | --- |")
    for kind, sizes in sorted(kinds.items()):
        print(f"| {kind}: messages per board second (4 channels), mean payload | "
              f"{len(sizes) / board_s:.2f} /s, {sum(sizes) / len(sizes):.0f} B |")
    print(f"| publisher throughput (QoS 1, acknowledged, 127.0.0.1) | {rate:,.0f} messages/s |")
    print(f"| CPU at the default publishing rate ({per_s:.1f} messages/s, 4 channels) | {pct:.2f} % of one core |")
    print(f"| disk queue after one hour of outage ({n:,} messages) | {size / 1e6:.1f} MB |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
