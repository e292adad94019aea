"""Defaults of the reference setup (docs/method.md), in SI units.

Everything here is a default, not a constant: each is a parameter of the object that
uses it.
"""

from __future__ import annotations

#: Sample rate of drives and recordings, Hz.
FS_HZ = 10_000.0
#: Calibrated band, Hz.
BAND_HZ = (10.0, 1000.0)
#: Drive limit at the actuator, V peak (1 V DAQ output through a 20 dB amplifier).
DRIVE_LIMIT_V = 10.0
#: Largest plausible transfer magnitude ``|H|`` of a calibration, m/V: 1 mm of skin displacement per volt
#: at the actuator (exciters on skin give micrometres per volt; the simulated forearm at
#: most 0.3 um/V). A larger value is a corrupt or edited file, not a measurement.
H_MAX_M_PER_V = 1e-3
#: Smallest plausible in-band peak of ``|H|`` over the whole array, m/V (1 pm per volt): below,
#: no actuator moved the skin measurably and every design would ask for absurd drives.
H_MIN_PEAK_M_PER_V = 1e-12
#: Ricker spread sigma of the base stimulus, s.
SIGMA_S = 1e-3
#: Peak displacement asked of the target point by the inverse filter, m.
TARGET_PEAK_M = 2e-6
#: Funneling amplitude A, V.
FUNNELING_AMPLITUDE_V = 10.0
#: Length of a rendering window, samples (0.4096 s at 10 kHz).
N_SAMPLES = 4096
#: Where the target waveform sits in the window, as a fraction of its length: late enough
#: that the acausal part of an inverse-filter drive (its pre-ringing) fits before it.
TARGET_FRACTION = 0.5
#: Rendering methods of docs/method.md, rendering methods.
METHODS = ("funneling", "inverse", "combination", "time_reversal", "contrast", "constrained")
#: Methods compared in the localization studies (docs/file-formats.md, trials file).
STUDY_METHODS = ("funneling", "inverse", "combination")


def participant_seed(participant_id: str) -> int:
    """Seed of a simulated forearm derived from a participant id (stable across runs and machines).

    ``vibrofocus calibrate --rig simulated`` uses it when no ``--seed`` is given, so two
    participants never share a bit-identical simulated arm.

    Parameters
    ----------
    participant_id : str

    Returns
    -------
    int
        In ``[0, 2**31)``: the first four bytes of SHA-256 of the UTF-8 id.
    """
    import hashlib

    digest = hashlib.sha256(str(participant_id).encode("utf-8")).digest()
    return int.from_bytes(digest[:4], "big") & 0x7FFFFFFF
