#!/usr/bin/env python
"""Fit the simulated forearm's wave law to published forearm measurements.

Prints every published point with the fitted law's value and the residual, the fitted
parameters with their standard errors beside the nominal ones in
``vibrofocus.skin.parameters.NOMINAL_LAW``, and the fitted speed, group speed and
attenuation over the calibrated band. With ``--figure PATH`` it also draws the data,
the curves and the residuals.

    .venv/bin/python scripts/fit_skin_model.py [--figure docs/figures/skin_fit.png]

The data and their sources: ``src/vibrofocus/skin/data/forearm_waves.csv`` and
``src/vibrofocus/skin/data/SOURCES.md``; the method: ``docs/skin-model.md``.
"""

from __future__ import annotations

import argparse

import numpy as np

import pandas as pd

from vibrofocus.skin.fit import fit_wave_law, load_forearm_data, points_from_published_fits
from vibrofocus.skin.parameters import NOMINAL_LAW

CURVE_FREQS = np.array([20.0, 50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 400.0, 600.0, 800.0, 1000.0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--figure", help="write a PNG of the fit to this path")
    args = parser.parse_args()

    data = load_forearm_data()
    fit = fit_wave_law(pd.concat([data, points_from_published_fits(data)], ignore_index=True))
    law = fit.law

    print("Published points and the fitted law (residual = model / published - 1)\n")
    print(f"{'source':<14} {'quantity':<18} {'f Hz':>6} {'published':>10} {'model':>10} {'resid %':>8}  how read")
    for row in fit.points.itertuples():
        print(f"{row.source_key:<14} {row.quantity:<18} {row.frequency_hz:>6.0f} {row.value:>10.4g} "
              f"{row.model:>10.4g} {row.residual_pct:>+8.2f}  {row.how_read}")
    print(f"\nrms log residual {fit.rms_log_residual:.3f}; largest |residual| {fit.max_abs_residual_pct:.1f} %")

    print("\nFitted parameters (standard errors from the Jacobian at the optimum)")
    print(f"  mu0   = {law.mu0_pa:10.4g} Pa     (x exp(+-{fit.relative_std['mu0_pa']:.2f}))   nominal {NOMINAL_LAW.mu0_pa:.4g}")
    print(f"  eta   = {law.eta_pa_sn:10.4g} Pa s^n (x exp(+-{fit.relative_std['eta_pa_sn']:.2f}))   "
          f"nominal {NOMINAL_LAW.eta_pa_sn:.4g}")
    print(f"  n     = {law.order:10.4f}          (+-{fit.relative_std['order']:.3f})            nominal {NOMINAL_LAW.order:.4f}")
    print(f"  rho   = {law.density_kg_m3:.0f} kg/m^3 and xi = {law.rayleigh_factor} held fixed")

    unused = data[~data["use"].astype(bool)]
    if len(unused):
        print("\nPoints kept for comparison, not fitted:")
        for row in unused.itertuples():
            print(f"  {row.source_key:<16} {row.quantity:<30} {row.value:>8g}  {row.body_site}")

    print("\nFitted law over the band")
    print(f"{'f Hz':>6} {'c m/s':>7} {'v_g m/s':>8} {'alpha Np/m':>11} {'dB over 30 mm':>14}")
    c, vg, a = law.phase_speed(CURVE_FREQS), law.group_speed(CURVE_FREQS), law.attenuation(CURVE_FREQS)
    for f, ci, gi, ai in zip(CURVE_FREQS, c, vg, a):
        print(f"{f:>6.0f} {ci:>7.2f} {gi:>8.2f} {ai:>11.1f} {20 * np.log10(np.e) * ai * 0.03:>14.1f}")

    if args.figure:
        _figure(fit, args.figure)
        print(f"\nwrote {args.figure}")


def _figure(fit, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vibrofocus.io import save_figure

    law = fit.law
    f = np.geomspace(20, 1000, 200)
    quantities = [q for q in ("phase_speed_m_s", "attenuation_np_m") if q in set(fit.points["quantity"])]
    curves = {"phase_speed_m_s": (law.phase_speed(f), "phase speed, m/s"),
              "attenuation_np_m": (law.attenuation(f), "attenuation, Np/m")}
    fig, axes = plt.subplots(2, len(quantities), figsize=(4.2 * len(quantities), 5.5), sharex=True,
                             gridspec_kw={"height_ratios": [3, 1]}, squeeze=False)
    kinds = fit.points["source_key"] + ", " + fit.points["how_read"].replace({"text": "measured", "table": "measured"})
    markers = dict(zip(sorted(kinds.unique()), "Dosv^<>"))
    for j, q in enumerate(quantities):
        top, bottom = axes[0, j], axes[1, j]
        top.plot(f, curves[q][0], color="k", lw=1.5, label="fitted law")
        pts = fit.points[fit.points["quantity"] == q]
        for key, sub in pts.groupby(kinds[pts.index]):
            err = sub["spread"].to_numpy(float)
            top.errorbar(sub["frequency_hz"], sub["value"], yerr=np.where(np.isfinite(err), err, 0),
                         fmt=markers.get(key, "o"), ms=5, capsize=2, label=key)
            bottom.plot(sub["frequency_hz"], sub["residual_pct"], markers.get(key, "o"), ms=5)
        if q == "phase_speed_m_s":
            top.axhline(7.0, color="0.5", ls="--", lw=1, label="plateau, fingertip (manfredi2012), not fitted")
        top.set_ylabel(curves[q][1])
        top.set_xscale("log")
        top.legend(fontsize=8)
        bottom.axhline(0, color="k", lw=0.8)
        bottom.set_ylabel("residual, %")
        bottom.set_xlabel("frequency, Hz")
    fig.suptitle("Forearm surface waves: published points and the fitted causal law", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=150)
    plt.close(fig)


if __name__ == "__main__":
    main()
