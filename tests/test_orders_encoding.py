"""The /orders messages' JSON made from the tracker's arrays in one pass: the bytes
of the plain encoder, byte for byte, message for message.

The order chain lays a call's numbers out in one array and fills a template of each
channel's message shape (:class:`~cmsensord.sinks.orders_encoding.OrdersTemplate`) with
them in one formatting call; the message dict carries the text
(:class:`~cmsensord.sinks.encoded.EncodedMessage`) and the sink writes it instead of
encoding the dict.  Held to the plain encoder of the same dict: numbers at the edges of a
float's text (negative zero, subnormal, huge, tiny, integral, 17 digits), invalid blocks,
NaN and infinity (left out by the plain encoder: those messages go the plain way), names
with quotes, percent signs, line breaks and non-ASCII characters, a fixed-frequency
component, several channels; and a whole `cmsensord replay` against the same replay with
the texts off, record for record in the MCAP files."""

from __future__ import annotations

import copy
import math
import pickle
import subprocess
import sys

import numpy as np
import pytest

from cmsensord.monitor import messages
from cmsensord.sinks.encoded import EncodedMessage
from cmsensord.sinks.mcap_encoding import encode_message
from cmsensord.sinks.orders_encoding import OrdersTemplate
from processes import ENV, cmsensord

#: numbers whose text is at an edge of float.__repr__ (and so of the JSON encoder)
EDGES = [-0.0, 0.0, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, 1e16, 9007199254740993.0,
         1e-7, 0.0001, 123456789.0, 0.1, 1 / 3, -2.5, 1e22, 1e21, 1.5e-5, 28.659950959417447]


class Comp:
    """A tracked component's name and order (TrackedComponent's fields that messages read)."""

    def __init__(self, name, order):
        self.name, self.order = name, order


def plain(channel, method, comps, numbers):
    """The message dict of the numbers (speed, each component's f, rms, amplitude, fraction),
    as the order chain makes it, valid."""
    K = len(comps)
    f, r, a = numbers[1:1 + 3 * K:3], numbers[2:2 + 3 * K:3], numbers[3:3 + 3 * K:3]
    return messages.orders(7, channel, numbers[0], True, method,
                           messages.order_entries(comps, f, r, a, True), numbers[-1]).msg


@pytest.mark.parametrize("names,channel", [
    (["1x", "2x", "3x", "4x"], "ch0"),
    (['q"uote', "per%cent%s", "line\nbreak", "ünï€"], "chan %r \"0\""),
    (["null", "o2", "whip"], "null"),
])
def test_a_template_filled_with_edge_numbers_is_the_plain_encoders_text(names, channel):
    comps = [Comp(n, None if n == "whip" else float(i + 1)) for i, n in enumerate(names)]
    t = OrdersTemplate(channel, "smoothed", [(c.name, c.order) for c in comps])
    assert t.text is not None
    rng = np.random.default_rng(1)
    cases = [EDGES[i:i + t.n_numbers] for i in range(len(EDGES) - t.n_numbers + 1)]
    cases += [rng.choice(EDGES, t.n_numbers).tolist() for _ in range(200)]
    cases += [(rng.standard_normal(t.n_numbers) * 10.0 ** rng.integers(-300, 300, t.n_numbers)).tolist()
              for _ in range(200)]
    for numbers in cases:
        msg = plain(channel, "smoothed", comps, numbers)
        want = encode_message("/cm/x/orders", 1_795_752_402_800_443_149, msg)
        got = encode_message("/cm/x/orders", 1_795_752_402_800_443_149, EncodedMessage(msg, t.fill(numbers)))
        assert got == want


def test_a_name_made_of_the_markers_characters_has_no_template():
    assert OrdersTemplate("ch0", "recursive", [("\x000\x00", 1.0), ("b", 2.0)]).text is None


def test_a_changed_message_drops_its_text_and_copies_keep_it():
    comps = [Comp("1x", 1.0)]
    numbers = [1719.5, 28.6, 0.5, 0.7, 0.0]
    msg = plain("ch0", "recursive", comps, numbers)
    text = OrdersTemplate("ch0", "recursive", [("1x", 1.0)]).fill(numbers)
    for keep in (copy.copy, copy.deepcopy, lambda m: pickle.loads(pickle.dumps(m))):
        m = keep(EncodedMessage(msg, text))
        assert type(m) is EncodedMessage and m.text == text and m == msg
    changes = [lambda m: m.__setitem__("speed_rpm", 1.0), lambda m: m.__delitem__("speed_rpm"),
               lambda m: m.update(valid=False), lambda m: m.pop("missing_fraction"), lambda m: m.popitem(),
               lambda m: m.setdefault("extra", 1), lambda m: m.clear(), lambda m: m.__ior__({"valid": False})]
    for change in changes:
        m = EncodedMessage(msg, text)
        change(m)
        assert m.text is None
        assert encode_message("/t", 5, m) == encode_message("/t", 5, dict(m))


def chain_and_blocks(n_channels: int):
    """An order chain (2 orders, a fixed-frequency component) and tracker blocks of crafted
    numbers: edges of a float's text, an invalid block, NaN and infinity in places."""
    from cmsensord.config import config_from_dict
    from cmsensord.dsp.order_tracker.state import BlockStats
    from cmsensord.dsp.tacho import TachoTracker
    from cmsensord.monitor.clock import BlockClock
    from cmsensord.monitor.orders import OrderChain

    cfg = config_from_dict({"orders": {"components": [
        {"name": "1x", "order": 1.0}, {"name": "2x", "order": 2.0}, {"name": "whip", "freq_hz": 47.0}]}},
        n_channels=n_channels)
    clock = BlockClock()
    clock.set_rate(25000, 250)
    clock.anchor(0, 10**18)
    chain = OrderChain(cfg, cfg.channels, TachoTracker(25000.0, 1, block_len=250), fs=25000, clock=clock)
    chain.sample0 = 0
    rng = np.random.default_rng(4)
    E, C, K = 40, n_channels, 3
    edges = np.array(EDGES)
    rms = rng.choice(edges, (E, C, K)) * rng.choice([1.0, -1.0], (E, C, K))
    amp = np.abs(rng.standard_normal((E, C, K))) * 10.0 ** rng.integers(-20, 20, (E, C, K))
    rpm = rng.uniform(0.0, 3000.0, E)
    rpm[3] = -0.0
    rpm[4] = 1.7e308                             # 2x's frequency beyond the float range: infinity
    valid = np.ones(E, bool)
    valid[5] = False
    rms[6, 0, 1] = np.nan
    amp[7, -1, 2] = np.inf
    rpm[8] = np.nan
    missing = rng.integers(0, chain.tracker.block + 1, (E, C))
    blocks = BlockStats(np.arange(E) * 10, np.arange(E) * 250 + 249, rpm, rms, amp, valid, missing)
    return chain, blocks


@pytest.mark.parametrize("n_channels", [1, 3])
def test_the_chains_messages_carry_the_plain_encoders_bytes(monkeypatch, n_channels):
    import cmsensord.monitor.orders as orders

    chain, blocks = chain_and_blocks(n_channels)
    with np.errstate(over="ignore"):            # 2 x 1.7e308 rpm: infinity, on purpose
        got = chain._blocks(blocks, "recursive")
        monkeypatch.setattr(orders, "PRE_ENCODED", False)
        want = chain._blocks(blocks, "recursive")
    assert len(got) == len(want) == 40 * n_channels
    texts = 0
    for g, w in zip(got, want):
        assert repr(g) == repr(w) and type(w.msg) is dict  # the same fields and values (NaN too)
        assert encode_message(g.topic, g.stamp_ns, g.msg) == encode_message(w.topic, w.stamp_ns, w.msg)
        texts += type(g.msg) is EncodedMessage
    plain_ones = [w for w in want if not w.msg["valid"] or any(v is None or not math.isfinite(v)
                                                              for v in numbers(w.msg))]
    assert texts == len(got) - len(plain_ones) and len(plain_ones) >= 4


def numbers(msg) -> list:
    """An /orders message's numbers (None where left out)."""
    return [msg["speed_rpm"], msg["missing_fraction"]] + [o.get(k) for o in msg["orders"]
                                                          for k in ("freq_hz", "rms", "amplitude")]


@pytest.mark.process
def test_replay_writes_the_bytes_of_the_plain_encoder(tmp_path):
    """`cmsensord replay` of a RAW capture with a tacho (orders 1x-4x, recursive and smoothed,
    lost bytes in it) and the same replay with the texts off: the same records, byte for byte."""
    from mcap.reader import make_reader

    from firmware_sim.board import Board, BoardConfig
    from firmware_sim.scenarios import make_scenario

    cap = tmp_path / "cap.bin"
    sc = make_scenario("faulty", n_channels=2, duration_s=12.0, seed=5)
    Board(sc, BoardConfig(n_channels=2, mode="raw", tacho=True)).write_capture(cap, 12.0)
    data = bytearray(cap.read_bytes())
    del data[len(data) // 3:len(data) // 3 + 4000]               # a few lost frames
    cap.write_bytes(bytes(data))
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("orders:\n  smoother_lag_s: 0.2\n")
    got = cmsensord("replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "got"))
    off = ("import sys\nimport cmsensord.monitor.orders as o\no.PRE_ENCODED = False\n"
           "from cmsensord.cli import main\nsys.exit(main(sys.argv[1:]))\n")
    ref = subprocess.run([sys.executable, "-c", off, "replay", str(cap), "--config", str(cfg),
                          "--out", str(tmp_path / "ref")], capture_output=True, text=True, env=ENV, timeout=300)
    assert got.returncode == ref.returncode == 0, got.stderr + ref.stderr

    def records(out):
        """(topic, log and publish time from the first message's, the JSON after its timestamp):
        a replay's clock is anchored at the wall clock's time of its start."""
        rows = []
        for f in sorted(out.glob("*.mcap")):
            with open(f, "rb") as fh:
                for _, ch, m in make_reader(fh).iter_messages():
                    if ch.topic != "/cm/diagnostics":      # its uptime is the wall clock's
                        rows.append((ch.topic, m.log_time, m.publish_time, m.data[m.data.index(b"},") + 2:]))
        t0 = rows[0][1]
        return [(topic, lt - t0, pt - t0, data) for topic, lt, pt, data in rows]

    a, b = records(tmp_path / "got"), records(tmp_path / "ref")
    orders_rows = [r for r in a if r[0].endswith("/orders")]
    assert len(orders_rows) > 300 and {r[0] for r in orders_rows} == {"/cm/ch0/orders", "/cm/ch1/orders"}
    assert any(b'"method":"smoothed"' in r[3] for r in orders_rows)
    assert any(b'"valid":false' in r[3] for r in orders_rows)
    assert len(a) == len(b) and a == b
