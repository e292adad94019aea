"""Live taps over Open Sound Control: the workflow under ``vibrofocus serve-osc``."""

from __future__ import annotations

import contextlib
from pathlib import Path

from .progress import Progress, QuietProgress

__all__ = ["serve_live_taps"]

#: Addresses a server may bind without a warning that anyone who reaches it can play taps.
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def serve_live_taps(*, port: int, host: str, rig: str, rig_config: Path | None, calibration: Path | None,
                    skin: str, method: str, seed: int | None, max_wait_ms: float, log: Path | None, lsl: bool,
                    lsl_source_id: str | None, progress: Progress | None = None) -> None:
    """Open the rig, design the taps, and serve ``/tap`` requests until ``/stop``, SIGINT or SIGTERM.

    Every line the server has for its user goes to ``progress.note`` (``err=True`` for the
    standard error's, ``warning=True`` or ``danger=True`` for a warning).

    Parameters
    ----------
    port, host : int, str
        The UDP port (0: any free one) and the address to bind.
    rig, rig_config : str, Path or None
        The rig (simulated, audio, nidaq) and a hardware rig's settings file.
    calibration : Path or None
        The calibration the taps are designed from (required on hardware; default on the
        simulated rig: the arm's own transfer).
    skin : str
        Skin preset of the simulated forearm.
    method : str
        Rendering method at start (``/method`` changes it).
    seed : int or None
        Participant seed of the simulated forearm.
    max_wait_ms : float
        A tap that waited longer than this behind others is answered ``/error stale``, ms.
    log : Path or None
        The tap log (.csv or SQLite) every played tap is kept in.
    lsl, lsl_source_id : bool, str or None
        Send onset markers over the Lab Streaming Layer, and their source id.
    progress : Progress, optional
        Where the server's lines go (docs/real-time.md gives what each says).

    Raises
    ------
    ValidationError
        A bad option or calibration, or python-osc (or pylsl with ``lsl``) missing.
    OutputError
        A played tap could not be written to the tap log (the server stops, outputs at zero).
    """
    progress = progress if progress is not None else QuietProgress()
    from ..errors import ValidationError

    try:
        import pythonosc  # noqa: F401 - the optional extra, checked before anything starts
    except ImportError:
        raise ValidationError("serve-osc needs python-osc: pip install 'vibrofocus[osc]'") from None
    from ..realtime import OscTapServer, TapDesigner, TapLog
    from ..realtime.limits import check_designs
    from ..rendering import TransferMatrix
    from ..rigs import make_rig
    from ..skin import skin_preset

    if calibration is None and rig != "simulated":
        raise ValidationError(f"the {rig} rig needs --calibration (a calibration measured on it)")
    skin_name = skin_preset(skin).name
    if lsl_source_id is not None and not lsl:
        raise ValidationError("--lsl-source-id needs --lsl")
    if lsl:
        from ..io.lsl import check_source_id, import_pylsl, stable_source_id

        # Checked before the rig opens; a log names the stream, so a restarted server keeps it.
        stream_id = (check_source_id(lsl_source_id) if lsl_source_id is not None
                     else stable_source_id(log) if log is not None else None)
        import_pylsl()  # before the rig opens: a missing pylsl is one line, nothing started
    # The start takes about a minute on the simulated rig (its transfer, the designs, the
    # /tap_xy grid): each stage is said as it begins, never a silent wait.
    progress.note(f"serve-osc: opening the {rig} rig ...", err=True)
    with contextlib.ExitStack() as stack:
        the_rig = stack.enter_context(make_rig(rig, config=rig_config, seed=seed,
                                               skin=skin_name if rig == "simulated" else None))
        if calibration is not None:
            from .._atomic import protect
            from ..calibration import load_calibration

            protect(calibration, "calibration")
            cal = load_calibration(calibration)
            if abs(cal.fs - the_rig.fs) > 1e-9 * the_rig.fs:
                raise ValidationError(f"--calibration {calibration} is at {cal.fs:g} Hz but the {rig} rig runs "
                                      f"at {the_rig.fs:g} Hz")
            if cal.layout.n_actuators != the_rig.layout.n_actuators:
                raise ValidationError(f"--calibration {calibration} has {cal.layout.n_actuators} actuators, the "
                                      f"{rig} rig {the_rig.layout.n_actuators}")
            from ..studies.engine import CalibrationRenderer

            # The window the method's designs fit on this calibration, found as the studies
            # find it (the calibration's own resolution, doubled while a design needs more).
            window = CalibrationRenderer(cal, limit_v=the_rig.limits.peak_v, levels="equal-peak",
                                         bounds=False).prepare([method], cal.layout.location_numbers)
            tm, model = TransferMatrix.from_calibration(cal, window), cal.fit
            source = f"calibration {calibration}"
        else:
            progress.note("serve-osc: computing the simulated arm's transfer at the locations ...", err=True)
            tm, model = TransferMatrix.from_model(the_rig, the_rig.layout, the_rig.fs), the_rig
            source = f"the simulated arm's own transfer (skin {skin_name})"
        # Opened before the designs (seconds): a log that cannot be written is said at once.
        tap_log = stack.enter_context(TapLog(log)) if log is not None else None
        outlet = None
        if lsl:
            from ..io.lsl import MarkerOutlet

            outlet = stack.enter_context(MarkerOutlet(source_id=stream_id))
        from ..rendering import available_methods, method_class

        if method in available_methods() and not method_class(method).live:
            progress.note(f"designing {method} at the {tm.layout.n_locations} locations ahead "
                              "(seconds each) ...", err=True)
        designer = TapDesigner(tm, model, method=method, limit_v=the_rig.limits.peak_v)
        refused = check_designs(designer, the_rig)  # a tap the limits refuse is said now, not at the tap
        if refused:
            progress.note(f"warning: {refused}", err=True, warning=True)
        if model is not None:
            progress.note("serve-osc: evaluating the skin model on the /tap_xy grid (up to a minute) ...", err=True)
            designer.prepare_grid(lambda done, total: progress.step(done, total, "rows of the /tap_xy grid"))
        if host not in LOCAL_HOSTS:
            progress.note(f"WARNING: binding to {host}: anyone who can reach it can play taps.", err=True, danger=True)
        server = OscTapServer(the_rig, designer, host=host, port=port, max_wait_s=max_wait_ms / 1e3,
                              tap_log=tap_log, marker_sink=None if outlet is None else outlet.push)
        shown_host, shown_port = server.address
        if ":" in str(shown_host):  # an IPv6 address goes in brackets in a URL: osc.udp://[::1]:9124
            shown_host = f"[{shown_host}]"
        progress.note(f"serve-osc: listening on osc.udp://{shown_host}:{shown_port} ({rig} rig, designs from "
                   f"{source}, method {designer.method}, drive limit {designer.limit_v:g} V)")
        progress.note(f"taps: /tap 1..{designer.layout.n_locations}"
                   + (f" (no /tap_xy with {designer.method}: a design takes seconds)"
                      if not designer.live else
                      f", /tap_xy in {designer.area.describe()}" if model is not None else
                      " (no /tap_xy: the calibration has no fitted skin model)")
                   + " (each with an optional level, dB re the design); /method <name>; /stop", )
        kept = ([f"taps logged to {log}" + (f" after tap {tap_log.last_tap_id}" if tap_log.last_tap_id else "")]
                if tap_log is not None else [])
        kept += [f"LSL markers on 'vibrofocus-markers' (source_id {outlet.source_id})"] if outlet is not None else []
        if kept:
            progress.note("recording: " + "; ".join(kept))
        try:
            who = server.serve()
        finally:
            server.close()
        if server.log_error is not None:
            from ..errors import OutputError

            raise OutputError(f"serve-osc stopped: tap {server.records[-1].tap_id} played but could not be "
                              f"written to {log} ({server.log_error}); all outputs at zero")
    progress.note(f"serve-osc stopped by {who}; all outputs at zero")
