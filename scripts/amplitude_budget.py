#!/usr/bin/env python
"""Write the amplitude budget of docs/simulated-arm-truth.md: how far a tap carries on the model.

One exciter plays 10 V of the base tap (the paper's Ricker, sigma = 1 ms) on the nominal
forearm of each layered preset (identical, fully coupled exciters; the study's geometry).
The table gives the peak displacement on the exciter and at 8, 16, 24 and 32 mm from it,
toward the array centre (location 5 lies 31.8 mm from every exciter), in µm and in dB re
the exciter. The decay is split, approximately, into geometric spreading (a surface wave's
amplitude falls as 1/sqrt(r) from the 7 mm contact radius), material loss (the law's
attenuation at the tap's peak frequency) and the rest (dispersion and the loss of the
tap's high frequencies, which lower its peak). Last, the drive each exciter would need for
2 µm at location 5 if all four added in phase there.

    .venv/bin/python scripts/amplitude_budget.py          # rewrite the table in the doc
    .venv/bin/python scripts/amplitude_budget.py --print  # only print it
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from vibrofocus.defaults import FS_HZ, SIGMA_S
from vibrofocus.rigs import SimulatedForearm
from vibrofocus.skin import ForearmParameters

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "simulated-arm-truth.md"
N = 8192
DISTANCES_MM = (8.0, 16.0, 24.0, 32.0)
PRESETS = ("nominal", "low", "high")
#: Contact radius of the exciter's cone, m: where geometric spreading is counted from (an assumption).
CONTACT_RADIUS_M = 7e-3
DRIVE_V = 10.0
TARGET_M = 2e-6


def tap(n: int = N) -> np.ndarray:
    """10 V of the zero-mean Ricker (sigma = 1 ms), centred at 0.1 s."""
    t = np.arange(n) / FS_HZ - 0.1
    return DRIVE_V * (1 - t**2 / SIGMA_S**2) * np.exp(-(t**2) / (2 * SIGMA_S**2))


def budget(skin: str) -> dict:
    """Peak displacements of one exciter's 10 V tap along the line to the array centre."""
    params = ForearmParameters.nominal(4, skin=skin)
    arm = SimulatedForearm(participant=params, skin=skin)
    actuator = np.asarray(arm.layout.actuators_xy[0], float)
    centre = np.asarray(arm.layout.actuators_xy, float).mean(axis=0)
    direction = (centre - actuator) / np.linalg.norm(centre - actuator)
    distances = np.array((0.0,) + DISTANCES_MM) * 1e-3
    points = actuator + distances[:, None] * direction
    freqs = np.fft.rfftfreq(N, 1 / FS_HZ)
    h = arm.transfer(points, freqs)[:, :, 0]  # (F, points) from exciter 1
    spectrum = np.fft.rfft(tap())
    peaks = np.abs(np.fft.irfft(spectrum[:, None] * h, N, axis=0)).max(axis=0)
    # The tap's peak frequency: where its spectrum is largest.
    f_peak = float(freqs[np.argmax(np.abs(spectrum))])
    alpha = float(params.law.attenuation(f_peak))  # Np/m
    r = np.maximum(distances, CONTACT_RADIUS_M)
    spreading_db = 10 * np.log10(r / CONTACT_RADIUS_M)
    loss_db = 20 * np.log10(np.e) * alpha * (r - CONTACT_RADIUS_M)
    total_db = 20 * np.log10(peaks[0] / peaks)
    centre_m = float(np.linalg.norm(centre - actuator))
    at_centre = float(np.abs(np.fft.irfft(spectrum * arm.transfer(centre[None], freqs)[:, 0, 0], N)).max())
    return {"skin": skin, "peaks_um": peaks * 1e6, "total_db": total_db, "spreading_db": spreading_db,
            "loss_db": loss_db, "f_peak": f_peak, "alpha": alpha, "centre_mm": centre_m * 1e3,
            "centre_um": at_centre * 1e6, "needed_v": DRIVE_V * (TARGET_M / 4) / at_centre}


def markdown(rows: list[dict]) -> str:
    head = "| preset | on the exciter µm | " + " | ".join(f"{d:g} mm: µm (dB)" for d in DISTANCES_MM) + \
        " | at 32 mm: spreading / loss / rest dB | location 5: one exciter µm | 2 µm at location 5, four in phase: V each |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        cells = " | ".join(f"{p:.2f} ({-t:.1f})" for p, t in zip(r["peaks_um"][1:], r["total_db"][1:]))
        rest = r["total_db"][-1] - r["spreading_db"][-1] - r["loss_db"][-1]
        lines.append(
            f"| {r['skin']} | {r['peaks_um'][0]:.2f} | {cells} | {r['spreading_db'][-1]:.1f} / {r['loss_db'][-1]:.1f} / "
            f"{rest:.1f} | {r['centre_um']:.3f} | {r['needed_v']:.0f} |")
    f = rows[0]
    alphas = ", ".join(f"{r['skin']} {r['alpha']:.0f}" for r in rows)
    lines.append("")
    lines.append(f"Tap peak frequency {f['f_peak']:.0f} Hz; location 5 lies {f['centre_mm']:.1f} mm from each "
                 f"exciter; loss counted at the law's attenuation there ({alphas} Np/m), "
                 f"spreading as 1/sqrt(r) from a {CONTACT_RADIUS_M * 1e3:g} mm contact radius; made by "
                 "`scripts/amplitude_budget.py`.")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--print", action="store_true", help="only print the table")
    args = parser.parse_args()
    table = markdown([budget(skin) for skin in PRESETS])
    print(table)
    if not args.print:
        from vibrofocus_tools.markers import write_between_markers

        write_between_markers(PAGE, "amplitude-budget", table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
