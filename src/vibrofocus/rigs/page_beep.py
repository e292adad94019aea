"""Can the participant page's beep reach a JACK rig's actuators? (``vibrofocus serve``'s check)

The page beeps through the browser, which plays through the desktop's sound server
(PulseAudio, or PipeWire's), never through PortAudio. On Linux PortAudio's default output
is often JACK's ``system``, the very device a lab's rig uses, so comparing the rig with
PortAudio's default (what :func:`vibrofocus.rigs.audio.default_output_risk` does on the
other host APIs) says nothing there. What can carry the browser's sound into a JACK rig's
outputs is a JACK connection to the rig's playback ports (PulseAudio's JACK sink, a
bridge): :func:`check_page_beep_on_jack` looks at those connections, as the rig's own
guard does before and during each play (:mod:`.jack_guard`), and warns where the desktop's
sound server is PipeWire, which can route the browser to the same device inside itself.
docs/hardware.md, "The participant page's beep".
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Sequence

from ..errors import ValidationError

__all__ = ["check_page_beep_on_jack", "desktop_sound_server"]


def desktop_sound_server(timeout_s: float = 2.0) -> str | None:
    """The desktop's sound server as ``pactl info`` names it (``"PulseAudio (on PipeWire 1.0.5)"``); None if none answers."""
    pactl = shutil.which("pactl")
    if pactl is None:
        return None
    try:
        out = subprocess.run([pactl, "info"], capture_output=True, text=True, timeout=timeout_s).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    for line in out.splitlines():
        if line.startswith("Server Name:"):
            return line.split(":", 1)[1].strip() or None
    return None


def check_page_beep_on_jack(device_name: str, channels: Sequence[int]) -> str | None:
    """Refuse a JACK rig whose outputs another program feeds; a warning where PipeWire may route the beep there.

    Parameters
    ----------
    device_name : str
        The rig's JACK client (PortAudio device), e.g. ``"system"``.
    channels : sequence of int
        Its actuator outputs, 1-based.

    Returns
    -------
    str or None
        A warning to print, or None.

    Raises
    ------
    ValidationError
        A port of another program is connected to an actuator output now: the page's
        beep (or anything else) would be added to the drives.
    """
    from .jack_guard import JackOutputGuard

    guard = JackOutputGuard(device_name, channels)
    try:
        feeds = guard.feeds()
    finally:
        guard.close()
    if feeds:
        shown = ", ".join(f"{f.source} -> {f.target}" for f in feeds[:4]) + (" ..." if len(feeds) > 4 else "")
        raise ValidationError(
            f"another program feeds the actuator outputs on JACK ({shown}): the participant page's beep, or any "
            "sound, would be added to the drives. Disconnect it (and the desktop's JACK sink or bridge from those "
            "ports), then start again (docs/hardware.md)")
    server = desktop_sound_server()
    if server is not None and "pipewire" in server.lower():
        return (f"the desktop's sound server is {server}, which also serves JACK and may play the browser on the "
                f"actuator interface ({device_name}) without a JACK connection: make the participant's headphones "
                "its default output (docs/hardware.md)")
    return None
