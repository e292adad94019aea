"""The PsychoPy Builder component of a vibrofocus tap: :class:`VibrofocusTapComponent`.

PsychoPy finds it through the ``psychopy.experiment.components`` entry point of
vibrofocus's ``pyproject.toml`` (PsychoPy's plugin mechanism), so it appears in Builder's
component panel under *Stimuli* and *Tactile* once vibrofocus is installed in PsychoPy's
Python. It writes code that uses :class:`vibrofocus.psychopy.TapStimulus`:

- at the start of the experiment, the stimulus through ``serve-osc`` or in-process;
- at each routine's start, the tap's location (or point), level and method, so that a
  loop's variable (``$level``, a staircase's ``$level``) sets them;
- when the component starts, ``win.callOnFlip(<name>.play)`` (with *sync to screen
  refresh*), or the play at once;
- at the routine's end, the tap's onsets in the data file (``thisExp.addData``, columns
  ``<name>.tap_id``, ``<name>.onset_host_s``, ``<name>.onset_device_s``, ...).

This module imports PsychoPy; nothing else in vibrofocus imports this module.
"""

from __future__ import annotations

from pathlib import Path

from psychopy.experiment.components import BaseComponent, Param, _translate

__all__ = ["VibrofocusTapComponent"]

_METHODS = ["inverse", "funneling", "combination", "time_reversal", "contrast", "constrained", "minimax"]


class VibrofocusTapComponent(BaseComponent):
    """A focused vibrotactile tap (vibrofocus), played through serve-osc or an in-process rig."""

    categories = ["Stimuli", "Tactile"]
    targets = ["PsychoPy"]
    iconFile = Path(__file__).parent / "tap.png"
    tooltip = _translate("vibrofocus tap: a focused vibrotactile tap at a location or point of the arm")
    plugin = "vibrofocus"

    def __init__(self, exp, parentName, name="tap", startType="time (s)", startVal=0.0, stopType="duration (s)",
                 stopVal=1.0, startEstim="", durationEstim="", location=5, x_mm="", y_mm="", level=0.0,
                 method="inverse", calibration="", backend="serve-osc", host="127.0.0.1", port=9000,
                 rig="simulated", rigConfig="", seed="", syncScreenRefresh=True):
        super().__init__(exp, parentName, name, startType=startType, startVal=startVal, stopType=stopType,
                         stopVal=stopVal, startEstim=startEstim, durationEstim=durationEstim,
                         syncScreenRefresh=syncScreenRefresh)
        self.type = "VibrofocusTap"
        self.url = "https://vibrofocus.readthedocs.io/en/latest/psychopy.html"
        self.order += ["location", "x_mm", "y_mm", "level", "method", "backend", "host", "port", "rig",
                       "calibration", "rigConfig", "seed"]
        self.params["location"] = Param(
            location, valType="code", inputType="single", categ="Basic", updates="set every repeat",
            allowedUpdates=["constant", "set every repeat"],
            hint=_translate("Layout location of the tap (1-based); ignored when x and y are given"),
            label=_translate("Location"))
        self.params["x_mm"] = Param(
            x_mm, valType="code", inputType="single", categ="Basic", updates="set every repeat",
            allowedUpdates=["constant", "set every repeat"],
            hint=_translate("x of a tap anywhere in the calibrated area, mm (blank: the location)"),
            label=_translate("x (mm)"))
        self.params["y_mm"] = Param(
            y_mm, valType="code", inputType="single", categ="Basic", updates="set every repeat",
            allowedUpdates=["constant", "set every repeat"],
            hint=_translate("y of a tap anywhere in the calibrated area, mm (blank: the location)"),
            label=_translate("y (mm)"))
        self.params["level"] = Param(
            level, valType="code", inputType="single", categ="Basic", updates="set every repeat",
            allowedUpdates=["constant", "set every repeat"],
            hint=_translate("Level in dB re the calibrated design (0: as designed, at the drive limit; -6: half "
                            "the amplitude); the safety layer refuses what breaks a limit"),
            label=_translate("Level (dB)"))
        self.params["method"] = Param(
            method, valType="str", inputType="choice", allowedVals=_METHODS, categ="Basic",
            updates="set every repeat", allowedUpdates=["constant", "set every repeat"],
            hint=_translate("Rendering method of the tap"), label=_translate("Method"))
        self.params["backend"] = Param(
            backend, valType="str", inputType="choice", allowedVals=["serve-osc", "in-process"], categ="Device",
            hint=_translate("serve-osc: a running 'vibrofocus serve-osc' plays the taps; in-process: this "
                            "experiment opens the rig"), label=_translate("Play through"))
        self.params["host"] = Param(
            host, valType="str", inputType="single", categ="Device",
            hint=_translate("Address of serve-osc"), label=_translate("serve-osc host"))
        self.params["port"] = Param(
            port, valType="int", inputType="single", categ="Device",
            hint=_translate("UDP port of serve-osc (its --port)"), label=_translate("serve-osc port"))
        self.params["rig"] = Param(
            rig, valType="str", inputType="choice", allowedVals=["simulated", "audio", "nidaq"], categ="Device",
            hint=_translate("In-process: the rig to open"), label=_translate("Rig"))
        self.params["calibration"] = Param(
            calibration, valType="file", inputType="file", categ="Device",
            hint=_translate("In-process: the calibration file (.nc) the taps are designed from (required for "
                            "audio/nidaq; blank on the simulated rig: the simulated arm's own transfer)"),
            label=_translate("Calibration file"))
        self.params["rigConfig"] = Param(
            rigConfig, valType="file", inputType="file", categ="Device",
            hint=_translate("In-process: the hardware settings file of an audio or nidaq rig"),
            label=_translate("Rig config"))
        self.params["seed"] = Param(
            seed, valType="code", inputType="single", categ="Device",
            hint=_translate("In-process, simulated rig: the simulated participant's seed (blank: none)"),
            label=_translate("Simulated seed"))
        for device in ("rig", "calibration", "rigConfig", "seed"):
            self.depends.append({"dependsOn": "backend", "condition": "=='in-process'", "param": device,
                                 "true": "show", "false": "hide"})
        for device in ("host", "port"):
            self.depends.append({"dependsOn": "backend", "condition": "=='serve-osc'", "param": device,
                                 "true": "show", "false": "hide"})

    # Every value goes into the code once, as PsychoPy writes it (``str(param)``), and the
    # code is never formatted again: a ``%`` in an expression (``$(trials.thisN % 9) + 1``)
    # or a path (``C:/lab/100%done/cal.nc``) stays as written.
    def writeInitCode(self, buff):
        p = self.params
        name = _code(p, "name")
        code = f"# the vibrofocus tap {name}\nfrom vibrofocus.psychopy import TapStimulus\n"
        if p["backend"].val == "in-process":
            # Blank settings are None (the simulated arm's own transfer, no hardware file, no seed).
            given = {k: _code(p, k) if str(p[k].val).strip() else "None" for k in ("calibration", "rigConfig", "seed")}
            # Taps at points need the skin model evaluated at start (seconds); locations do not.
            anywhere = bool(str(p["x_mm"].val).strip() and str(p["y_mm"].val).strip())
            code += (f"{name} = TapStimulus.in_process({_code(p, 'rig')}, calibration={given['calibration']}, "
                     f"rig_config={given['rigConfig']}, seed={given['seed']}, anywhere={anywhere}, name={name!r}, "
                     f"method={_code(p, 'method')})\n")
        else:
            code += (f"{name} = TapStimulus.osc(host={_code(p, 'host')}, port={_code(p, 'port')}, name={name!r}, "
                     f"method={_code(p, 'method')})\n")
        buff.writeIndentedLines(code)

    def writeRoutineStartCode(self, buff):
        p = self.params
        name = _code(p, "name")
        if str(p["x_mm"].val).strip() and str(p["y_mm"].val).strip():
            where = f"x_mm={_code(p, 'x_mm')}, y_mm={_code(p, 'y_mm')}"
        else:
            where = f"location={_code(p, 'location')}"
        buff.writeIndentedLines(f"{name}.set({where}, level_db={_code(p, 'level')}, method={_code(p, 'method')})\n")
        buff.writeIndentedLines(f"{name}.status = NOT_STARTED\n")

    def writeFrameCode(self, buff):
        name = _code(self.params, "name")
        buff.writeIndented(f"# *{name}* updates\n")
        indented = self.writeStartTestCode(buff)
        if indented:
            if self.params["syncScreenRefresh"].val:
                # On the flip that shows this frame, as a sound component starts.
                buff.writeIndented(f"win.callOnFlip({name}.play)\n")
            else:
                buff.writeIndented(f"{name}.play()\n")
            buff.setIndentLevel(-indented, relative=True)
        # The tap plays on by itself; its stop only lets the routine end (a drive lasts < 1 s).
        indented = self.writeStopTestCode(buff)
        if indented:
            buff.setIndentLevel(-indented, relative=True)

    def writeRoutineEndCode(self, buff):
        # The onsets on the host's and the device's clocks, in the data file.
        name = _code(self.params, "name")
        buff.writeIndentedLines(f"if {name}.status != NOT_STARTED:\n"
                                f"    {name}.store(thisExp)\n")
        super().writeRoutineEndCode(buff)

    def writeExperimentEndCode(self, buff):
        buff.writeIndented(f"{_code(self.params, 'name')}.close()\n")


def _code(params, key: str) -> str:
    """A parameter as PsychoPy writes it into a script (a literal, or a ``$`` expression as is)."""
    return str(params[key])
