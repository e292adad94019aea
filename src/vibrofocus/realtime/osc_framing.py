"""The framing of an OSC datagram, walked before python-osc parses it.

python-osc (1.10.2) trusts a bundle element's size: a negative one moves its read
position backwards and its parser loops for ever, logging a warning on every pass. This
walk refuses such a datagram first. It reads every size, checks that each element lies
inside its bundle and is a message or a bundle, caps how deep bundles nest and how many
elements a datagram holds, and checks each message's address and type tags, so that
python-osc only parses datagrams it can parse in one pass, without logging.

The walk moves forward only: each step passes at least 4 bytes, so it ends after at most
``len(data) / 4`` steps whatever the bytes are, and it stops at the first element past
:data:`MAX_ELEMENTS`. That cap is small on purpose: a datagram is handled as one piece
(python-osc takes about 0.1 ms per message), so a bundle of thousands of taps would hold
the server's receiving thread, and a ``/stop`` behind it, for a tenth of a second or more.
"""

from __future__ import annotations

__all__ = ["FramingError", "TooManyElements", "check_framing", "parse_datagram", "MAX_BUNDLE_DEPTH",
           "MAX_ELEMENTS"]

#: Deepest nesting of bundles accepted (a bundle in a bundle is depth 2).
MAX_BUNDLE_DEPTH = 8
#: Most messages and bundles one datagram may hold (a bundle of a few taps, a method and
#: a tap, is what a client needs; each tap may also go in a datagram of its own).
MAX_ELEMENTS = 16

_BUNDLE = b"#bundle\x00"
#: The argument types python-osc parses (OSC 1.0 and 1.1): any other would be logged and skipped.
_TYPE_TAGS = frozenset(b"ihfdsbrmtTFN[]")


class FramingError(ValueError):
    """A datagram whose framing is not OSC's; its message says where."""


class TooManyElements(FramingError):
    """A datagram of valid framing that holds more than :data:`MAX_ELEMENTS` messages and bundles."""


def check_framing(data: bytes) -> int:
    """Check the framing of one datagram before it is parsed.

    Parameters
    ----------
    data : bytes
        The datagram.

    Returns
    -------
    int
        The number of messages it holds.

    Raises
    ------
    FramingError
        A bundle element whose size is negative, zero, not a multiple of 4 or past the end
        of its bundle; a bundle shorter than its header; bundles nested deeper than
        :data:`MAX_BUNDLE_DEPTH`; an element
        that is neither a message nor a bundle; a message without a terminated address,
        or with a type tag python-osc does not parse.
    TooManyElements
        More than :data:`MAX_ELEMENTS` elements (a subclass of FramingError).
    """
    data = bytes(data)
    if data.startswith(b"/"):
        _check_message(data, 0, len(data))
        return 1
    if not data.startswith(_BUNDLE):
        raise FramingError("neither an OSC message (starts with '/') nor a bundle (starts with '#bundle')")
    n_messages = n_elements = 0
    # (end of the bundle, position of its next element, depth), innermost last.
    stack = [(len(data), _bundle_start(data, 0, len(data)), 1)]
    while stack:
        end, pos, depth = stack.pop()
        if pos >= end:
            continue
        if pos + 4 > end:
            raise FramingError(f"bundle element at byte {pos}: {end - pos} byte(s) left, too few for its size")
        size = int.from_bytes(data[pos:pos + 4], "big", signed=True)
        start = pos + 4
        if size <= 0 or size % 4 or start + size > end:
            reason = ("is not positive" if size <= 0 else "is not a multiple of 4" if size % 4
                      else f"runs past the end of its bundle (byte {end})")
            raise FramingError(f"bundle element at byte {pos}: its size {size} {reason}")
        n_elements += 1
        if n_elements > MAX_ELEMENTS:
            raise TooManyElements(f"more than {MAX_ELEMENTS} elements (messages and bundles) in one datagram")
        stack.append((end, start + size, depth))  # the rest of this bundle, after this element
        if data.startswith(_BUNDLE, start):
            if depth >= MAX_BUNDLE_DEPTH:
                raise FramingError(f"bundles nested deeper than {MAX_BUNDLE_DEPTH}")
            stack.append((start + size, _bundle_start(data, start, start + size), depth + 1))
        elif data.startswith(b"/", start):
            _check_message(data, start, start + size)
            n_messages += 1
        else:
            raise FramingError(f"bundle element at byte {pos} is neither a message nor a bundle")
    return n_messages


def parse_datagram(data: bytes) -> list:
    """The messages of one datagram, in python-osc's order, once its framing passed.

    Parameters
    ----------
    data : bytes
        The datagram.

    Returns
    -------
    list of pythonosc.osc_message.OscMessage

    Raises
    ------
    FramingError
        From :func:`check_framing`.
    Exception
        Whatever python-osc raises for a datagram it cannot parse (its ``ParseError``,
        a ``UnicodeDecodeError`` of a string argument).
    """
    from pythonosc.osc_packet import OscPacket

    check_framing(data)
    return [timed.message for timed in OscPacket(bytes(data)).messages]


def _bundle_start(data: bytes, start: int, end: int) -> int:
    """Where a bundle's first element is: after '#bundle', NUL and the 8-byte time tag."""
    if end - start < 16:
        raise FramingError(f"bundle at byte {start} has {end - start} bytes, fewer than its 16-byte header")
    return start + 16


def _string_end(data: bytes, start: int, end: int, what: str) -> int:
    """The position after an OSC string (NUL-terminated, padded to 4 bytes) in ``data[start:end]``."""
    nul = data.find(b"\x00", start, end)
    if nul < 0:
        raise FramingError(f"{what} at byte {start} has no terminating NUL")
    after = start + ((nul - start) // 4 + 1) * 4
    if after > end:
        raise FramingError(f"{what} at byte {start} is not padded to 4 bytes")
    try:
        data[start:nul].decode("ascii")
    except UnicodeDecodeError:
        raise FramingError(f"{what} at byte {start} is not ASCII") from None
    return after


def _check_message(data: bytes, start: int, end: int) -> None:
    """The address and the type tags of one message in ``data[start:end]`` (its arguments python-osc checks)."""
    pos = _string_end(data, start, end, "address")
    if pos >= end:
        return  # no type tags: a message without arguments
    if data[pos:pos + 1] != b",":
        raise FramingError(f"type tags at byte {pos} do not start with ','")
    _string_end(data, pos, end, "type tags")
    tags = data[pos + 1:data.index(b"\x00", pos)]
    unknown = set(tags) - _TYPE_TAGS
    if unknown:
        raise FramingError(f"type tag(s) {''.join(sorted(map(chr, unknown)))!r} at byte {pos} are not supported")
