"""The OSC framing walk: hostile datagrams are refused before python-osc parses them.

python-osc 1.10.2 loops for ever on a bundle element of a negative size (and logs a
warning on every pass); here such datagrams are answered ``/error`` and the server goes
on serving. The fuzz runs each datagram's parse in a worker thread with a generous
bound, so a parse that never returns fails the test instead of hanging it.
"""

from __future__ import annotations

import logging
import socket
import struct
import threading

import pytest

pytest.importorskip("pythonosc")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from pythonosc.osc_message import OscMessage  # noqa: E402

from vibrofocus.realtime import OscTapServer  # noqa: E402
from vibrofocus.realtime.osc_framing import (MAX_BUNDLE_DEPTH, MAX_ELEMENTS, FramingError,  # noqa: E402
                                             check_framing, parse_datagram)

from ._designer import simulated_designer  # noqa: E402

#: A parse that has not returned after this long never will (a few ms is the norm), s.
PARSE_BOUND_S = 10.0

HEADER = b"#bundle\x00" + b"\x00" * 7 + b"\x01"
TAP5 = b"/tap\x00\x00\x00\x00,i\x00\x00" + struct.pack(">i", 5)


def element(content: bytes, size: int | None = None) -> bytes:
    return struct.pack(">i", len(content) if size is None else size) + content


#: The datagram of the issue: 36 bytes, one element whose size is -4.
NEGATIVE = HEADER + element(TAP5, -4)


def _parse_within_bound(data: bytes):
    """``parse_datagram(data)`` in a worker thread: ('ok', messages) or ('refused', exc); fails if it hangs."""
    out = {}

    def work():
        try:
            out["ok"] = parse_datagram(data)
        except Exception as exc:  # noqa: BLE001 - any refusal is fine; only a hang is not
            out["refused"] = exc

    worker = threading.Thread(target=work, daemon=True)
    worker.start()
    worker.join(PARSE_BOUND_S)
    assert not worker.is_alive(), f"the parse of {data[:64]!r}... ({len(data)} bytes) did not return"
    return next(iter(out.items()))


def test_the_negative_size_datagram_of_the_issue_is_refused():
    assert len(NEGATIVE) == 36
    with pytest.raises(FramingError, match="size -4 is not positive"):
        check_framing(NEGATIVE)


@pytest.mark.parametrize("data, needle", [
    (HEADER + element(TAP5, 0), "size 0 is not positive"),
    (HEADER + element(TAP5, 14), "not a multiple of 4"),
    (HEADER + element(TAP5, 20), "runs past the end"),
    (HEADER + element(TAP5)[:-2], "runs past the end"),
    (HEADER + b"\x00\x00", "too few for its size"),
    (HEADER[:12], "fewer than its 16-byte header"),
    (HEADER + element(b"abcd"), "neither a message nor a bundle"),
    (HEADER + element(HEADER[:8]), "fewer than its 16-byte header"),
    (b"/tap\x00\x00\x00\x00,iZ\x00" + struct.pack(">i", 5), "type tag(s) 'Z'"),
    (b"/tap\x00\x00\x00\x00i\x00\x00\x00", "do not start with ','"),
    (b"/tap", "no terminating NUL"),
    (b"/tap\xff\x00\x00\x00", "not ASCII"),
    (b"junk", "neither an OSC message"),
    (b"", "neither an OSC message"),
])
def test_bad_framing_is_refused_and_says_where(data, needle):
    with pytest.raises(FramingError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        check_framing(data)


def _nested(depth: int) -> bytes:
    data = HEADER + element(TAP5)
    for _ in range(depth - 1):
        data = HEADER + element(data)
    return data


def test_nesting_and_element_count_are_capped():
    assert check_framing(_nested(MAX_BUNDLE_DEPTH)) == 1
    assert len(parse_datagram(_nested(MAX_BUNDLE_DEPTH))) == 1
    with pytest.raises(FramingError, match="nested deeper"):
        check_framing(_nested(MAX_BUNDLE_DEPTH + 1))
    many = HEADER + element(b"/s\x00\x00") * MAX_ELEMENTS
    assert check_framing(many) == MAX_ELEMENTS
    with pytest.raises(FramingError, match=f"more than {MAX_ELEMENTS} elements"):
        check_framing(many + element(b"/s\x00\x00"))


def test_valid_packets_pass_and_parse_as_python_osc_does():
    from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
    from pythonosc.osc_message_builder import OscMessageBuilder

    inner = OscBundleBuilder(IMMEDIATELY)
    outer = OscBundleBuilder(IMMEDIATELY)
    for address, args in (("/tap", [5]), ("/tap_xy", [1.5, -2.0]), ("/method", ["funneling"]), ("/stop", [])):
        builder = OscMessageBuilder(address=address)
        for arg in args:
            builder.add_arg(arg)
        inner.add_content(builder.build())
    outer.add_content(inner.build())
    data = outer.build().dgram
    assert check_framing(data) == 4
    assert [(m.address, m.params) for m in parse_datagram(data)] == [
        ("/tap", [5]), ("/tap_xy", [1.5, -2.0]), ("/method", ["funneling"]), ("/stop", [])]


# -- fuzz -------------------------------------------------------------------------------
_sizes = st.one_of(st.integers(-(2**31), 2**31 - 1), st.integers(-64, 64))
_contents = st.one_of(st.binary(max_size=48), st.just(TAP5), st.just(HEADER), st.just(b"/s\x00\x00"),
                      st.builds(lambda tags: b"/a\x00\x00," + tags + b"\x00" * (4 - (len(tags) + 1) % 4),
                                st.binary(max_size=11)))


@st.composite
def bundles(draw, depth=0):
    """Bundles of elements whose sizes are sometimes true, sometimes anything."""
    parts = [HEADER]
    for _ in range(draw(st.integers(0, 4))):
        if depth < 3 and draw(st.booleans()):
            content = draw(bundles(depth=depth + 1))
        else:
            content = draw(_contents)
        size = len(content) if draw(st.booleans()) else draw(_sizes)
        parts.append(element(content, size))
    return b"".join(parts)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(bundles(), st.binary(max_size=96), st.builds(lambda b: HEADER + b, st.binary(max_size=64))))
def test_fuzz_every_datagram_is_parsed_or_refused_in_bounded_time_and_silently(data):
    # The root logger is where python-osc 1.10.2 logs what it skips (through logging.warning).
    records = []
    handler = logging.Handler()
    handler.emit = records.append
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        outcome, value = _parse_within_bound(data)
    finally:
        root.removeHandler(handler)
    assert records == [], [r.getMessage() for r in records[:3]]
    if outcome == "ok":
        assert all(m.address.startswith("/") for m in value)


def test_a_server_answers_the_negative_size_datagram_error_and_the_next_tap_plays(caplog):
    rig, designer = simulated_designer()
    server = OscTapServer(rig, designer, port=0)
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    raw.settimeout(60)
    try:
        with caplog.at_level(logging.DEBUG):
            raw.sendto(NEGATIVE, server.address)
            reply = OscMessage(raw.recv(65536))
            assert reply.address == "/error" and "size -4 is not positive" in reply.params[0], reply.params
            raw.sendto(TAP5, server.address)
            reply = OscMessage(raw.recv(65536))
            assert reply.address == "/played" and reply.params[:1] == [5]
        assert caplog.records == []
        assert rig.n_played == 1 and server.n_errors == 1
    finally:
        server.stop()
        thread.join(30)
        server.close()
        raw.close()
    assert logging.getLogger("pythonosc").propagate is False


def test_a_bundle_of_more_than_a_few_messages_is_refused_whole_and_the_next_tap_plays():
    """The flood's 2000-message bundle held the receiving thread 0.1-0.2 s (and a /stop behind it)."""
    assert MAX_ELEMENTS <= 16
    rig, designer = simulated_designer()
    server = OscTapServer(rig, designer, port=0)
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    raw.settimeout(60)
    try:
        raw.sendto(HEADER + element(TAP5) * 2000, server.address)
        reply = OscMessage(raw.recv(65536))
        assert reply.address == "/error", reply.params
        assert reply.params[0].startswith(f"refused: more than {MAX_ELEMENTS} elements"), reply.params
        assert "nothing in it played" in reply.params[0]
        raw.sendto(HEADER + element(TAP5) * MAX_ELEMENTS, server.address)  # at the cap: every tap answered
        replies = [OscMessage(raw.recv(65536)) for _ in range(MAX_ELEMENTS)]
        assert all(r.address in ("/played", "/error") for r in replies)
        assert replies[0].address == "/played" and replies[0].params[:1] == [5]
        assert server.n_errors == 1 + sum(r.address == "/error" for r in replies)
    finally:
        server.stop()
        thread.join(30)
        server.close()
        raw.close()
