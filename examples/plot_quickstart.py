"""
Quick start: calibrate, render a tap, play it, measure it
=========================================================

The README's first Python snippet. A simulated participant's forearm is calibrated
(exponential sweeps, H1 estimate), a tap is rendered at location 5 with the default
inverse filter, played on the arm (with vibrometer noise) and judged with the focus
metrics.
"""

import matplotlib.pyplot as plt
import numpy as np

import vibrofocus as vf

rig = vf.SimulatedForearm(seed=3)  # a model of a forearm, not a person
cal = vf.calibrate(rig, participant_id="P03")  # H: (n_freqs, n_points, n_actuators), m/V
H = cal.transfer_for(4096)  # on numpy.fft.rfftfreq(4096, 1 / fs)
r = vf.render("inverse", H, cal.fs, cal.layout, location=5)  # drives (4, 4096) V at the 10 V limit
recorded = rig.play_and_record(r.drives)
while np.isnan(recorded).any():  # a vibrometer dropout: repeat, never patch
    recorded = rig.play_and_record(r.drives)
metrics = vf.focus_metrics(recorded, r.target_index, r.desired, cal.fs, drives=r.drives,
                           compare_indices=range(cal.layout.n_locations))
print({k: round(float(metrics[k]), 3) for k in ("fidelity", "contrast_db", "target_peak_m", "peak_drive_v")})

# %%
# What the nine locations recorded; the target (location 5) in colour.
t_ms = (np.arange(recorded.shape[1]) / cal.fs - r.t0) * 1e3
view = (t_ms > -10) & (t_ms < 20)
fig, ax = plt.subplots(figsize=(7, 3.5))
for i in range(cal.layout.n_locations):
    target = i == r.target_index
    ax.plot(t_ms[view], recorded[i, view] * 1e6, color="#0072B2" if target else "0.75", lw=1.6 if target else 0.8)
ax.set_xlabel("time from the asked tap (ms)")
ax.set_ylabel("displacement (µm)")
ax.set_title("Simulated forearm: the tap at location 5 and the other locations")
fig.tight_layout()
