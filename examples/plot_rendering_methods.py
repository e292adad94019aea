"""
Rendering methods at equal peak drive
=====================================

Every rendering method of :func:`vibrofocus.render`, designed from the simulated
forearm's exact transfer for location 5, scaled to the same 10 V peak drive and shown as
the skin's displacement at the instant each method's tap is largest at the target. The
energy contrast stands beside the array's bound (the most any drive that gives the tap
reaches).
"""

import matplotlib.pyplot as plt
import numpy as np

import vibrofocus as vf
from vibrofocus.analysis import method_colors
from vibrofocus.defaults import METHODS

rig = vf.SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0)
layout, n = rig.layout, 4096
H = rig.transfer(layout.points_xy, np.fft.rfftfreq(n, 1 / rig.fs))
axis = np.linspace(-0.035, 0.035, 25)
grid = np.column_stack([a.ravel() for a in np.meshgrid(axis, axis)])

fig, axes = plt.subplots(2, 3, figsize=(10, 6.6), sharex=True, sharey=True)
colors = method_colors(METHODS)
for ax, method in zip(axes.flat, METHODS):
    r = vf.render(method, H, rig.fs, layout, 5)
    m = r.metrics()
    t_focus = np.argmax(np.abs(r.predicted[r.target_index])) / rig.fs
    u = rig.field(r.drives, grid, times=[t_focus])[:, 0].reshape(len(axis), len(axis)) * 1e6
    top = 1.2 * np.abs(r.predicted[r.target_index]).max() * 1e6
    ax.imshow(u, origin="lower", cmap="RdBu_r", vmin=-top, vmax=top, extent=[-35, 35, -35, 35])
    ax.plot(*(layout.actuators_xy.T * 1e3), "ks", mfc="none")
    ax.plot(*(layout.locations_xy.T * 1e3), "k.", ms=3)
    ax.set_title(f"{method}\nenergy contrast {m['energy_contrast_db']:.1f} dB (bound {m['bound_db']:.1f})",
                 fontsize=9, color=colors[method])
for ax in axes[-1]:
    ax.set_xlabel("x (mm)")
for ax in axes[:, 0]:
    ax.set_ylabel("y (mm, to wrist)")
fig.suptitle("Each method at 10 V peak, at its focus instant (colour scale: 1.2 x its target peak)")
fig.tight_layout()
