"""Who else feeds the audio rig's outputs on a JACK server (JACK, or PipeWire's JACK).

JACK adds up every client connected to a playback port. A media player, a browser
through pipewire-jack or a DAW connected to the port an actuator hangs on adds its signal
to the rig's drive, past every limit the rig enforces: two signals at half of full scale
make full scale. The device lock keeps other vibrofocus rigs off the interface; this
guard looks at the connections themselves, through the JACK-Client package (a thin
binding of libjack, the library PortAudio's JACK host API uses too).

How PortAudio maps onto JACK
----------------------------
PortAudio's JACK host API lists each JACK client as a device, and output channel ``k``
of a device as the ``k``-th audio input port of that client (``system:playback_k``, or
``loopback:playback_k`` on a server with loopback ports). Each stream registers output
ports of its own on the process's PortAudio client (``PortAudio:out_n``) when it is
opened, and connects its ``k``-th port to the device's ``k``-th when it starts.

The audio rig runs one stream from its opening to its closing, so on the playback ports
it uses only that stream's own port for each channel may be connected, before a play and
while it plays. Any other port connected there is another program's signal (or another
stream of this process), summed with the drive by JACK.
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass
from typing import Mapping, Sequence

from .devices import DeviceError

__all__ = ["ForeignFeed", "JackOutputGuard", "shared_output_message", "CLIENT_NAME"]

#: The name of the guard's own JACK client (it has no ports; JACK may append a number).
CLIENT_NAME = "vibrofocus-guard"
# The characters POSIX extended regular expressions (jack_get_ports' patterns) give a meaning.
_ERE_SPECIAL = re.compile(r"([\\^$.|?*+()\[\]{}])")
# A port PortAudio's JACK host API registers for a stream's output channel.
_STREAM_OUT = re.compile(r"^(?P<client>.+):out_(?P<n>[0-9]+)$")


@dataclass(frozen=True)
class ForeignFeed:
    """One port of another JACK client connected to a playback port the rig uses.

    Attributes
    ----------
    source : str
        The other port, ``"client:port"``.
    target : str
        The rig's playback port it feeds, ``"client:port"``.
    channel : int
        The rig's output channel (1-based) that port is.
    """

    source: str
    target: str
    channel: int

    @property
    def client(self) -> str:
        """The JACK client (program) the source port belongs to."""
        return self.source.split(":", 1)[0]


class JackOutputGuard:
    """Watches the connections of the JACK playback ports behind a PortAudio JACK device.

    Parameters
    ----------
    device_name : str
        The PortAudio device name: a JACK client (``"system"``, ``"loopback"``, ...).
    channels : sequence of int
        The rig's output channels (1-based) to watch.

    Raises
    ------
    DeviceError
        JACK-Client cannot load, the JACK server does not answer, or the device has fewer
        playback ports than the highest channel.

    Notes
    -----
    Every method may be called from any thread; after :meth:`close` they raise
    :class:`~vibrofocus.rigs.DeviceError`.
    """

    def __init__(self, device_name: str, channels: Sequence[int]):
        try:
            import jack
        except (ImportError, OSError) as exc:
            raise DeviceError(
                f"the audio rig checks on JACK that no other program feeds its outputs, through the JACK-Client "
                f"package, which could not load ({exc}); install it (pip install JACK-Client)") from None
        self._jack = jack
        self._lock = threading.Lock()
        self.channels = tuple(int(c) for c in channels)
        try:
            client = jack.Client(CLIENT_NAME, no_start_server=True)
        except jack.JackError as exc:
            raise DeviceError(f"could not open a JACK client to watch who feeds the rig's outputs ({exc}); is the "
                              "JACK server still running?") from None
        try:
            pattern = "^" + _ERE_SPECIAL.sub(r"\\\1", device_name) + ":"
            ports = client.get_ports(pattern, is_audio=True, is_input=True)
            if len(ports) < max(self.channels):
                raise DeviceError(
                    f"the JACK client {device_name!r} has {len(ports)} playback port(s), but the rig uses output "
                    f"channels up to {max(self.channels)}")
        except BaseException:
            client.close()
            raise
        self._client = client
        self._targets = {c: ports[c - 1] for c in self.channels}

    @property
    def targets(self) -> dict[int, str]:
        """The playback port of each watched channel, ``{channel: "client:port"}``."""
        return {c: p.name for c, p in self._targets.items()}

    def _call(self, func, *args):
        with self._lock:
            if self._client is None:
                raise DeviceError("the rig is closed: its JACK connections are no longer watched")
            try:
                return func(self._client, *args)
            except self._jack.JackError as exc:
                raise DeviceError(f"JACK did not answer about the rig's output connections ({exc}); is the "
                                  "JACK server still running?") from None

    def output_ports(self) -> frozenset[str]:
        """The names of every audio output port on the server now."""
        return self._call(lambda c: frozenset(p.name for p in c.get_ports(is_audio=True, is_output=True)))

    def own_ports(self, before: frozenset[str], n_out: int) -> dict[int, str]:
        """The ports of the stream opened since ``before`` was listed, by watched channel.

        Parameters
        ----------
        before : frozenset of str
            :meth:`output_ports` just before the stream was opened.
        n_out : int
            How many output channels the stream has.

        Returns
        -------
        dict
            ``{channel: "client:out_n"}`` for every watched channel.

        Raises
        ------
        DeviceError
            When the new ports are not one PortAudio stream's ``n_out`` consecutive ports
            (another program registered ports at the same moment): the rig cannot tell
            its own connections from others', so it does not play.
        """
        new = self.output_ports() - before
        by_client: dict[str, list[tuple[int, str]]] = {}
        for name in new:
            m = _STREAM_OUT.match(name)
            if m:
                by_client.setdefault(m["client"], []).append((int(m["n"]), name))
        found = next(iter(by_client.values())) if len(by_client) == 1 else []
        numbers = sorted(n for n, _ in found)
        if len(numbers) != n_out or numbers != list(range(numbers[0], numbers[0] + n_out)):
            listing = ", ".join(sorted(new)) or "none"
            raise DeviceError(
                f"the rig could not tell its own stream's JACK ports among the new ones ({listing}; expected "
                f"{n_out} ports out_n of one client), so it cannot check who else feeds its outputs; nothing was "
                "played: try again")
        ordered = [name for _, name in sorted(found)]
        return {c: ordered[c - 1] for c in self.channels}

    def feeds(self, own: Mapping[int, str] | None = None) -> list[ForeignFeed]:
        """Every port connected to a watched playback port other than the rig's own.

        Parameters
        ----------
        own : dict, optional
            The rig's own stream ports (:meth:`own_ports`) once it has started; None
            before the stream starts, when any connection is another's.

        Returns
        -------
        list of ForeignFeed
        """
        def listing(client):
            out = []
            for channel, port in self._targets.items():
                mine = own.get(channel) if own else None
                out.extend(ForeignFeed(p.name, port.name, channel) for p in client.get_all_connections(port)
                           if p.name != mine)
            return out

        return self._call(listing)

    def check_routing(self, own: Mapping[int, str]) -> None:
        """Check that the stream's own port of each channel reaches that channel's playback port.

        Raises
        ------
        DeviceError
            When PortAudio connected a channel elsewhere than the port the guard watches.
        """
        def missing(client):
            return [c for c, port in self._targets.items()
                    if own[c] not in {p.name for p in client.get_all_connections(port)}]

        wrong = self._call(missing)
        if wrong:
            raise DeviceError(
                "PortAudio did not connect the rig's output(s) " + ", ".join(map(str, wrong)) + " to "
                + ", ".join(self._targets[c].name for c in wrong) + ", the ports whose other connections the rig "
                "watches; the play was stopped: tell the vibrofocus developers the device's JACK port names")

    def disconnect(self, feeds: Sequence[ForeignFeed]) -> list[str]:
        """Disconnect other programs' ports from the rig's playback ports.

        Returns
        -------
        list of str
            One line per connection that could not be removed (empty when all were).
        """
        failed = []
        for feed in feeds:
            try:
                self._call(lambda c: c.disconnect(feed.source, feed.target))
            except DeviceError as exc:
                failed.append(f"{feed.source} -> {feed.target}: {exc}")
        return failed

    def close(self) -> None:
        """Close the guard's JACK client (idempotent)."""
        with self._lock:
            client, self._client = self._client, None
        if client is not None:
            try:
                client.close()
            except Exception:  # noqa: BLE001 - a dead server: the client is gone with it
                pass


def shared_output_message(feeds: Sequence[ForeignFeed], labels: Mapping[int, str], *, when: str,
                          failed: Sequence[str] = ()) -> str:
    """The one-line message of a :class:`~vibrofocus.rigs.SharedOutputError`.

    Parameters
    ----------
    feeds : sequence of ForeignFeed
        What else feeds the rig's outputs.
    labels : dict
        ``{channel: "actuator 1"}``: what each output channel drives.
    when : {"before", "during", "check"}
        Refused before the stream started, stopped while it played, or found by
        ``vibrofocus devices --check`` (which plays and disconnects nothing).
    failed : sequence of str
        Connections the rig could not remove (it removes every one it finds).
    """
    clients = sorted({f.client for f in feeds})
    who = ", ".join(f"'{c}'" for c in clients)
    where = "; ".join(f"{f.source} into {f.target}, output {f.channel}, {labels.get(f.channel, 'unused')}"
                      for f in feeds)
    head = (f"another program feeds the rig's outputs: JACK client{'s' if len(clients) > 1 else ''} {who} ({where})"
            + (" connected while the rig was playing" if when == "during" else "")
            + ". JACK adds its signal to the drive, past the rig's limits")
    if when == "check":
        return head + ("; the rig would refuse to play and disconnect it: close that program or route it to "
                       "another interface")
    done = ("the play was refused before it started" if when == "before"
            else "the play was stopped and the rig's outputs are at zero")
    if failed:
        return (head + f"; {done}, but the rig could NOT disconnect it ({'; '.join(failed)}): switch the amplifier "
                "off, then close that program")
    return head + f"; {done} and the rig disconnected it: close that program or route it to another interface"
