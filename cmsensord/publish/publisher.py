"""The MQTT publisher: paho-mqtt in its own thread, fed by a bounded in-memory hand-over queue.

The processing loop calls :meth:`Publisher.offer`, which only appends to a bounded deque (the
oldest entry is dropped and counted when it is full): it never waits for the network or the
disk. The thread moves offered messages into the :class:`~.disk_queue.DiskQueue` (numbering
them), sends from the queue while connected (at most ``MAX_INFLIGHT`` unacknowledged; the
backlog, what was queued before the connection, at most ``resend_per_s``), and moves the
queue's cursor with each PUBACK. A lost connection rewinds the send cursor to the first
unacknowledged message; reconnection backs off from ``reconnect_min_s`` doubling to
``reconnect_max_s``. The latest message of each retained topic is kept in memory (one per
topic) and published again at each connection once the broker has acknowledged it, so a broker
that restarted without persistence has the retained state again. State changes and losses
become events (:attr:`Publisher.events`, drained by the caller's thread into /cm/events).
"""

from __future__ import annotations

import collections
import contextlib
import json
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from cmsensord.config.mqtt import MqttConfig
from cmsensord.config.mqtt_tls import tls_context
from cmsensord.publish.discovery import WorstAlarms, discovery_messages
from cmsensord.publish.disk_queue import HOLD_BYTES, DiskQueue
from cmsensord.publish.topics import TopicMap, payload
from cmsensord.sinks.alarm_schema import TOPIC_ALARMS
from cmsensord.sinks.mcap_encoding import ns_to_stamp

#: messages sent and not yet acknowledged (paho's own default window)
MAX_INFLIGHT = 20
#: the thread's poll period [s]: how long an offered message waits at most before it is queued
#: (0.05 s costs 0.8 % of a core more at the default rate; bench/bench_mqtt.py)
POLL_S = 0.2
#: a broker that accepted TCP but sent no CONNACK for this long is given up and retried
CONNACK_S = 10.0


def _password(path: str | None) -> str | None:
    """The password: the file's first line (the file is read at each connection)."""
    if path is None:
        return None
    with open(path, encoding="utf-8") as f:
        return f.readline().rstrip("\r\n")


class Publisher:
    """Publishes what :meth:`offer` is given to the broker of ``cfg``; ``queue_dir`` holds the
    disk queue (OSError if it cannot be created; with ``wait_for_disk``, the daemon, not for a
    full, failing or read-only disk: messages are then held in memory and sent from there, as
    after a write error).
    ``alarm_rules``: alarms are evaluated, so with discovery and ``alarms`` published, each
    channel's worst alarm is derived, published and announced (without rules it would stay
    unknown)."""

    def __init__(self, cfg: MqttConfig, queue_dir: str, channels: tuple[str, ...] = (),
                 alarm_rules: bool = False, wait_when_full: bool = False, wait_for_disk: bool = False) -> None:
        self.cfg, self.topics, self.channels = cfg, TopicMap(cfg), channels
        self.wait_when_full = wait_when_full      # offer waits for room (a replay), not drops (the daemon)
        self.give_up = threading.Event()          # set: nothing waits for the broker or for room any more
        self.moved = 0                            # messages the thread took from the hand-over queue
        self.queue = DiskQueue(queue_dir, max_bytes=int(cfg.queue_mb * 1e6), fsync_s=cfg.fsync_s,
                               wait_for_disk=wait_for_disk)
        self.handover: collections.deque = collections.deque(maxlen=cfg.handover_messages)
        self.handover_drops = 0
        self.events: collections.deque = collections.deque(maxlen=1000)
        self.state = "connecting"
        self.sent = self.acked_total = 0
        self._stop = threading.Event()
        self._client: Any = None
        self._inflight: dict[int, int] = {}       # paho mid -> seq
        self._tokens = 0.0
        self._backlog_end = 1                     # seqs below it were queued before this connection
        self._refused: str | None = None          # the reason of the last refusal (one event each)
        self._down_reported = False               # this outage has had its event
        self._errors: dict[str, str] = {}        # the disk queue's conditions said (write, sync, read, lease): why
        self._dropped_seen = self._handover_seen = 0
        self._connecting_since = 0.0
        self._dialing: threading.Thread | None = None
        self._dialed: Any = None                  # the client the dialling thread connected
        self._dial_error = ""
        self._last_send = 0.0
        self._thread = threading.Thread(target=self._run, name="mqtt", daemon=True)
        self._discovered: tuple[str, ...] = ()     # the channels announced on this connection
        self._retained: dict[str, tuple[int, bytes]] = {}   # MQTT topic -> (seq, payload) of its latest
        self._worst: WorstAlarms | None = None    # each channel's worst alarm, for discovery
        if cfg.discovery and "alarms" in cfg.publish and alarm_rules:
            self._worst = WorstAlarms(channels)
        self._say_how_the_queue_opened()

    def _say_how_the_queue_opened(self) -> None:
        """The queue's state at start, as events: entries left alone, damaged records skipped
        and a torn tail cut off (one line), an unreadable acknowledgement cursor, or what an
        earlier run left to send."""
        q = self.queue
        for path, what in q.strays:
            self._event("mqtt_queue", f"store-and-forward queue: {path} is {what}, not one of its segment "
                        "files: left alone", logging.WARNING, action="skipped", details={"file": str(path)})
        said = []
        if q.damaged_bytes:
            said.append(f"skipped {q.damaged_bytes} damaged byte(s) in its segments ({q.damaged_records} "
                        "message(s) lost); the messages after them are kept")
        if q.truncated_bytes:
            said.append(f"cut {q.truncated_bytes} byte(s) of torn record(s) at its end (a crash or a power cut "
                        f"while writing; the {q.torn_seqs} seq(s) they could hold are not used again)")
        if said:
            self._event("mqtt_queue", "store-and-forward queue: " + "; ".join(said), logging.WARNING,
                        action="damaged" if q.damaged_bytes else "truncated",
                        bytes=q.damaged_bytes + q.truncated_bytes, count=q.damaged_records)
        if q.cursor_error is not None:
            cursor = q.dir / "acked"
            self._event("mqtt_queue", f"store-and-forward queue: the acknowledgement cursor {cursor} is "
                        f"unreadable ({q.cursor_error}): " + (
                            f"the {q.depth} queued message(s) are sent from the oldest kept, some perhaps a "
                            "second time (delivery is at least once)" if q.depth else
                            f"nothing is queued and seq numbering starts again at {q.next_seq}"),
                        logging.WARNING, action="cursor_unreadable", count=q.depth, reason=q.cursor_error,
                        details={"file": str(cursor)})
        elif q.depth:
            self._event("mqtt_queue", f"store-and-forward queue: {q.depth} message(s) from an earlier run "
                        "wait for the broker", logging.INFO, action="resumed", count=q.depth)

    # -- the caller's side ---------------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def offer(self, topic: str, stamp_ns: int, msg: dict) -> None:
        """Hand one MCAP message over (non-blocking); not published kinds are ignored here."""
        route = self.topics.route(topic)
        if route is None:
            return
        self._hand(route, topic, stamp_ns, msg)
        if self._worst is not None and topic == TOPIC_ALARMS:
            for ch, state in self._worst.changed(msg):
                self._hand((self.topics.worst_alarm(ch), True), f"/cm/{ch}/worst_alarm", stamp_ns, state)

    def set_channels(self, channels: tuple[str, ...]) -> None:
        """The monitored channels, once the board (or an import) says which: the worst alarm of
        each is derived from the next ``/cm/alarms`` tables, and the thread sends the discovery
        messages of those it has not sent yet."""
        self.channels = channels
        if self._worst is not None:
            self._worst.channels = channels

    def _hand(self, route: tuple[str, bool], topic: str, stamp_ns: int, msg: dict) -> None:
        if self.wait_when_full and len(self.handover) == self.handover.maxlen:
            self._wait_for_room()
        if len(self.handover) == self.handover.maxlen:
            self.handover_drops += 1
        self.handover.append((route, topic, stamp_ns, msg))

    def _wait_for_room(self) -> None:
        """Wait while the thread moves the hand-over queue on; give up for good (then drop the
        oldest, as the daemon does) once it has not moved for ``CONNACK_S`` (a queue that
        cannot be written) or :attr:`give_up` is set (Ctrl-C)."""
        seen, since = self.moved, time.monotonic()
        while len(self.handover) == self.handover.maxlen and self._thread.is_alive() and not self.give_up.is_set():
            if self.moved != seen:
                seen, since = self.moved, time.monotonic()
            elif time.monotonic() - since > CONNACK_S:
                self.give_up.set()
                self._event("mqtt_queue", f"the publisher has taken no message for {CONNACK_S:g} s: from here on "
                            "the oldest waiting in memory is dropped for each new one, as the daemon does",
                            logging.WARNING, action="dropping")
            self.give_up.wait(0.01)

    def left(self) -> int:
        """Offered messages the broker has not acknowledged yet."""
        return len(self.handover) + self.queue.depth

    def backlog(self) -> int | None:
        """While connected, the messages queued before this connection not sent yet (the only
        ones paced, at ``resend_per_s``; the rest go as fast as the broker takes them); None when
        not connected: what is queued is the next connection's backlog."""
        if self.state != "connected":
            return None
        return max(0, self._backlog_end - self.queue.send_seq)

    def drain(self, idle_s: float = CONNACK_S, progress: Callable[[int], None] | None = None) -> int:
        """Wait until the broker has acknowledged every offered message, until it has
        acknowledged none for ``idle_s`` (not connected, gone), refused the connection, or
        :attr:`give_up` is set; ``progress`` gets the count acknowledged so far. Returns the
        count left (still queued on disk)."""
        acked, since = self.acked_total, time.monotonic()
        while self._thread.is_alive() and self.left() and self.state != "refused" and not self.give_up.is_set():
            if progress is not None:
                progress(self.acked_total)
            now = time.monotonic()
            if self.acked_total != acked:
                acked, since = self.acked_total, now
            elif now - since > idle_s:
                break
            time.sleep(0.05)
        return self.left()

    def close(self, timeout: float = 3.0) -> None:
        """Stop the thread: offered messages are queued on disk, sent if connected, and the
        retained status becomes ``offline``."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def diagnostics(self) -> dict:
        """The link's state for /cm/diagnostics."""
        q = self.queue
        return {"state": self.state, "queued": q.depth, "queue_bytes": q.size_bytes,
                "dropped": q.dropped + self.handover_drops, "sent": self.sent, "acked": self.acked_total}

    def summary(self) -> str:
        """The exit summary's line (after :meth:`close`): what was sent, and what is left in the
        queue for the next run publishing from it (it sends them first)."""
        q, cfg = self.queue, self.cfg
        dropped = q.dropped + self.handover_drops
        line = (f"  mqtt: {self.sent} message(s) sent to {cfg.host}:{cfg.port} as client_id {cfg.client}, "
                f"{self.acked_total} acknowledged{f', {dropped} dropped' if dropped else ''}; {q.depth} left "
                f"unacknowledged in {q.dir}")
        held = q.held_unsent
        lost = f" ({held} of them lost: held in memory, the disk refused them)" if held else ""
        return line + lost + (": the next run publishing from this queue sends them first" if q.depth > held else "")

    def status(self) -> str:
        """The status line's part: ``mqtt connected q 0``."""
        return f"mqtt {self.state} q {self.queue.depth}"

    def _event(self, kind: str, message: str, level: int, **fields: Any) -> None:
        self.events.append((kind, message, level, fields))

    # -- the thread ----------------------------------------------------------------------------
    def _run(self) -> None:
        import paho.mqtt.client as mqtt

        backoff, next_try, last_beat = self.cfg.reconnect_min_s, 0.0, 0.0
        try:
            while not self._stop.is_set():
                self._to_disk()
                now = time.monotonic()
                if self._client is None and self._dialing is None and now >= next_try:
                    self._dialing = self._dial(mqtt)
                if self._dialing is not None and not self._dialing.is_alive():
                    self._dialing = None
                    if self._dialed is None:
                        self._down(self._dial_error, "disconnected")
                        next_try, backoff = now + backoff, min(backoff * 2, self.cfg.reconnect_max_s)
                    else:
                        self._client, self._connecting_since, self._dialed = self._dialed, now, None
                if self._client is not None:
                    self._client.loop(timeout=POLL_S)
                    if self.state == "connected":
                        backoff = self.cfg.reconnect_min_s
                        if self._discovered != self.channels:
                            self._discover()
                        self._send(now)
                        if now - last_beat >= self.cfg.heartbeat_s:
                            last_beat = now
                            self._heartbeat()
                    elif self.state != "connecting" or now - self._connecting_since > CONNACK_S:
                        if self.state == "connecting":
                            self._down(f"no answer from {self.cfg.host}:{self.cfg.port}", "disconnected")
                        self._drop_client()
                        next_try, backoff = now + backoff, min(backoff * 2, self.cfg.reconnect_max_s)
                else:
                    self._stop.wait(POLL_S)
                self._sync()
            self._finish()
        except Exception as exc:                    # noqa: BLE001 - reported, never a crash
            self.state = "failed"
            self._event("mqtt_link", f"the MQTT publisher stopped: {type(exc).__name__}: {exc}",
                        logging.ERROR, state="failed")

    def _dial(self, mqtt: Any) -> threading.Thread:
        """A new client connecting (TCP and TLS) in a short-lived thread, so that this thread
        keeps moving offered messages to disk meanwhile: ``_dialed`` is the client, or None
        on failure; CONNACK arrives in ``loop``."""
        cfg = self.cfg
        client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=cfg.client,
                             protocol=mqtt.MQTTv311, clean_session=True)
        client.max_inflight_messages_set(MAX_INFLIGHT)
        client.will_set(self.topics.status, "offline", qos=1, retain=True)
        client.on_connect, client.on_disconnect = self._on_connect, self._on_disconnect
        client.on_publish = self._on_publish
        self.state, self._dialed = "connecting", None

        def dial() -> None:
            try:
                if cfg.username is not None:
                    client.username_pw_set(cfg.username, _password(cfg.password_file))
                context = tls_context(cfg)
                if context is not None:
                    client.tls_set_context(context)
                client.connect(cfg.host, cfg.port, keepalive=cfg.keepalive_s)
            except Exception as err:                # noqa: BLE001 - refused, unreachable, TLS, files
                self._dial_error = f"cannot connect to {cfg.host}:{cfg.port}: {err}"
                return
            self._dialed = client

        self._dial_error = ""
        thread = threading.Thread(target=dial, name="mqtt-connect", daemon=True)
        thread.start()
        return thread

    def _down(self, reason: str, state: str) -> None:
        """The link is down: one event per outage (a retry failing alike is silent), and one per
        distinct refusal (a wrong password is reported even while the outage is)."""
        self.state = state
        if self._refused == reason or (state == "disconnected" and self._down_reported):
            return
        self._refused, self._down_reported = reason, True
        level = logging.ERROR if state == "refused" else logging.WARNING
        self._event("mqtt_link", f"{reason}; retrying with back-off up to {self.cfg.reconnect_max_s:g} s, "
                    f"{self.queue.depth} message(s) queued", level, state=state, queued=self.queue.depth)

    def _drop_client(self) -> None:
        client, self._client = self._client, None
        with contextlib.suppress(Exception):        # the socket may be gone already
            client.disconnect()
        self._inflight.clear()
        self.queue.rewind()

    def _on_connect(self, client: Any, userdata: Any, flags: Any, reason: Any, properties: Any) -> None:
        if reason.is_failure:
            self._down(f"broker {self.cfg.host}:{self.cfg.port} refused the connection: {reason}", "refused")
            return
        self.state, self._refused, self._down_reported = "connected", None, False
        self._inflight.clear()
        self.queue.rewind()
        self._backlog_end = self.queue.next_seq
        self._event("mqtt_link", f"connected to {self.cfg.host}:{self.cfg.port} as {self.cfg.client}; "
                    f"{self.queue.depth} message(s) queued", logging.INFO, state="connected",
                    queued=self.queue.depth)
        client.publish(self.topics.status, "online", qos=1, retain=True)
        self._discovered = ()
        self._discover()
        self._republish(client)

    def _discover(self) -> None:
        """The discovery messages of the channels not yet announced on this connection."""
        channels = self.channels
        new = tuple(ch for ch in channels if ch not in self._discovered)
        if self.cfg.discovery and new:
            for topic, body in discovery_messages(self.cfg, new, worst_alarm=self._worst is not None):
                self._client.publish(topic, body, qos=1, retain=True)
        self._discovered = channels

    def _republish(self, client: Any) -> None:
        """The latest message of each retained topic that the broker acknowledged, again (the
        broker may have lost it in a restart); one not yet acknowledged is sent from the queue."""
        for topic, (seq, body) in list(self._retained.items()):
            if seq <= self.queue.acked:
                client.publish(topic, body, qos=self.cfg.qos, retain=True)

    def _on_disconnect(self, client: Any, userdata: Any, flags: Any, reason: Any, properties: Any) -> None:
        if self.state not in ("connected", "connecting"):
            return
        connected = self.state == "connected"
        why = f"{reason}"
        if why == "Unspecified error" and not getattr(flags, "is_disconnect_packet_from_server", False):
            why += f" ({self._closed_causes(connected)})"
        if connected:
            self._down(f"lost the broker {self.cfg.host}:{self.cfg.port}: {why}", "disconnected")
        else:
            self._down(f"cannot connect to {self.cfg.host}:{self.cfg.port}: {why}", "disconnected")

    def _closed_causes(self, connected: bool) -> str:
        """The likely causes of a connection the broker closed without saying why (paho's
        "Unspecified error"): once connected, another client taking over the client id or
        the broker stopping; while connecting, plain MQTT spoken to a TLS port."""
        if connected:
            return (f"the broker closed the connection: another client using client_id {self.cfg.client}? "
                    "the broker stopping?")
        if self.cfg.ca_file is None and self.cfg.certfile is None:
            return "the broker closed the connection: a TLS port without mqtt.ca_file? the broker's log says why"
        return "the broker closed the connection: the broker's log says why"

    def _on_publish(self, client: Any, userdata: Any, mid: int, reason: Any, properties: Any) -> None:
        seq = self._inflight.pop(mid, None)
        if seq is not None:
            self.queue.ack(seq)
            self.acked_total += 1

    def _to_disk(self) -> None:
        """Offered messages -> the disk queue, numbered (held in memory and sent from there while
        the disk refuses them); a replay's messages wait while the queue is full, where the
        daemon's drop the oldest; a disk that refuses them is one event per outage."""
        q = self.queue
        q.write_held()
        hold_mb = min(HOLD_BYTES >> 20, self.cfg.queue_mb)
        waits = self.wait_when_full and not self.give_up.is_set()
        while self.handover and not (waits and q.full):                        # a replay waits for room
            (mqtt_topic, retain), topic, stamp_ns, msg = self.handover.popleft()
            try:
                body = payload(topic, stamp_ns, msg, q.next_seq)
            except Exception as err:                # noqa: BLE001 - a message JSON cannot carry
                self._event("mqtt_queue", f"{topic}: not published: {err}", logging.WARNING,
                            action="encode_error")
                continue
            seq = q.append(mqtt_topic, lambda _, body=body: body, retain, bound=not waits)
            if retain:
                self._retained[mqtt_topic] = (seq, body)
            self.moved += 1
        self._say("write", q.write_error, "cannot write ({}); new messages are sent from memory, up to "
                  f"{hold_mb:g} MB kept until it takes them", "writable again")
        self._say("lease", None if "write" in self._errors else q.lease.error,     # else the same outage
                  "cannot write its seq lease ({}): after a crash, seqs may be used again", "seq lease written again")
        if self.handover_drops != self._handover_seen:
            n, self._handover_seen = self.handover_drops - self._handover_seen, self.handover_drops
            self._event("mqtt_queue", f"the publisher fell behind: dropped the {n} oldest message(s) "
                        f"waiting in memory ({self.handover_drops} in all)", logging.WARNING,
                        action="handover_dropped", count=n, total=self.handover_drops)
        if self.queue.dropped != self._dropped_seen:
            n = self.queue.dropped - self._dropped_seen
            self._dropped_seen = self.queue.dropped
            where = f"over {self.cfg.queue_mb:g} MB" if q.write_error is None else \
                f"the disk refusing them, over {hold_mb:g} MB in memory"
            self._event("mqtt_queue", f"store-and-forward queue {where}: dropped "
                        f"the {n} oldest unsent message(s) ({self.queue.dropped} in all)",
                        logging.WARNING, action="dropped", count=n, total=self.queue.dropped)

    def _say(self, key: str, err: OSError | None, text: str, over: str | None = None) -> None:
        """Condition ``key`` of the disk queue as events: one ERROR (``text``, the reason in its
        ``{}``) when ``err`` starts it or changes its reason, one INFO (``over``) when it ends."""
        reason = None if err is None else err.strerror or str(err)
        if self._errors.get(key) == reason:
            return
        if reason is None:
            del self._errors[key]
            if over is not None:
                self._event("mqtt_queue", f"store-and-forward queue {over}", logging.INFO, action="resumed")
            return
        self._errors[key] = reason
        self._event("mqtt_queue", f"store-and-forward queue {self.queue.dir}: {text.format(reason)}", logging.ERROR,
                    action="read_error" if key == "read" else "write_error", reason=reason)

    def _sync(self, force: bool = False) -> None:
        """The queue's fsync and cursor, at most every ``fsync_s``; a failure is one event until
        a sync goes through again (none while its write error is said: the same outage)."""
        try:
            synced = self.queue.sync(force)
        except OSError as err:
            self._say("sync", None if "write" in self._errors else err, "cannot make it durable ({})")
            return
        if synced:
            self._say("sync", None, "")

    def _send(self, now: float) -> None:
        """From the queue's send cursor, at most ``MAX_INFLIGHT`` unacknowledged: the backlog
        (queued before this connection) at ``resend_per_s`` (a token bucket), what came since
        as it comes."""
        room = MAX_INFLIGHT - len(self._inflight)
        backlog = self._backlog_end - self.queue.send_seq
        if backlog > 0:
            rate = self.cfg.resend_per_s
            self._tokens = min(max(rate, 1.0), self._tokens + rate * (now - (self._last_send or now)))
            self._last_send = now
            room = min(room, int(self._tokens), backlog)
        if room <= 0:
            return
        try:
            batch = self.queue.next_batch(room)
        except OSError as err:                  # a segment that cannot be read: tried again at the next poll
            self._say("read", err, "cannot read ({}); sending waits until it can", "readable again")
            return
        self._say("read", None, "", "readable again")
        for rec in batch:
            info = self._client.publish(rec.topic, rec.payload, qos=self.cfg.qos, retain=rec.retain)
            self._inflight[info.mid] = rec.seq
            self._tokens -= rec.seq < self._backlog_end
            self.sent += 1

    def _heartbeat(self) -> None:
        q = self.queue
        beat = {"timestamp": ns_to_stamp(time.time_ns()), "state": self.state, "queued": q.depth,
                "dropped": q.dropped + self.handover_drops, "next_seq": q.next_seq}
        self._client.publish(self.topics.heartbeat, json.dumps(beat), qos=0, retain=False)

    def _finish(self) -> None:
        """At stop: queue what was offered (a replay's messages no longer wait for room: the
        queue's bounds drop the oldest, counted); send for up to a second; ``offline``; disconnect."""
        self.give_up.set()
        self._to_disk()
        end = time.monotonic() + 1.0
        while self._client is not None and self.state == "connected" and time.monotonic() < end \
                and (self.queue.send_seq < self.queue.next_seq or self._inflight):
            self._send(time.monotonic())
            self._client.loop(timeout=POLL_S)
        if self._client is not None and self.state == "connected":
            info = self._client.publish(self.topics.status, "offline", qos=1, retain=True)
            self.state = "stopping"             # the disconnection below is ours: no event
            for _ in range(10):
                if info.is_published():
                    break
                self._client.loop(timeout=POLL_S)
            self._client.disconnect()
        self.state = "stopped"
        self._sync(force=True)
        self.queue.close()
