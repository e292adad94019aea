"""
A rendering method of your own
===============================

A lab adds a method without touching vibrofocus: a frozen dataclass that subclasses
:class:`vibrofocus.rendering.Method` holds its options, its ``solve`` returns the drives,
and :func:`vibrofocus.register_method` gives it a name. From then on it runs wherever a
built-in method does: in :func:`vibrofocus.render`, in the demo, in the study engine and
in the web app's preview. (An installed package registers its methods through the
entry-point group ``vibrofocus.methods`` instead.)

The method here is time reversal with a window: each actuator plays its impulse response
to the target, cut to the first ``window_ms`` milliseconds with a half-Hann fade, time
reversed and convolved with the tap. It is then compared, on the simulated forearm, with
the built-in time reversal (the whole response) and the inverse filter.
"""

from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np

import vibrofocus as vf
from vibrofocus.demo import run_demo
from vibrofocus.rendering import Method


@vf.register_method("windowed_time_reversal")
@dataclass(frozen=True, kw_only=True)
class WindowedTimeReversal(Method):
    """Time reversal of the target's impulse responses, cut to a window.

    Parameters
    ----------
    window_ms : float
        Length of the impulse responses kept, ms (> 0).
    """

    window_ms: float = 15.0

    def __post_init__(self):
        super().__post_init__()  # the options every method shares
        if not self.window_ms > 0:
            raise ValueError(f"window_ms must be > 0, got {self.window_ms!r}")

    def solve(self, problem):
        tm, n = problem.tm, problem.n
        # Impulse responses from every actuator to the target, shape (n_actuators, n).
        h = np.fft.irfft(tm.H[:, problem.target_index, :], n, axis=0).T
        keep = min(n // 2, int(self.window_ms * 1e-3 * tm.fs))
        fade = np.ones(n)
        fade[keep // 2:keep] = np.hanning(2 * (keep - keep // 2))[keep - keep // 2:]
        fade[keep:] = 0.0
        # Reversal in time is conjugation in frequency; times the tap's spectrum centres
        # the focus at the tap's time.
        spectra = np.conj(np.fft.rfft(h * fade, axis=1)) * np.fft.rfft(problem.reference)
        return np.fft.irfft(spectra, n, axis=1)


# %%
# Rendered through ``render`` by its name, like a built-in method
# ---------------------------------------------------------------
rig = vf.SimulatedForearm(seed=0, noise_m=0.0, dropout_rate=0.0)
tm = rig.transfer_matrix()  # the arm's true transfer, with its window and provenance
methods = ["inverse", "time_reversal", "windowed_time_reversal"]
designs = {m: vf.render(m, tm, rig.fs, rig.layout, 5) for m in methods}
print(vf.available_methods())

fig, axes = plt.subplots(1, 3, figsize=(10, 3.2), sharey=True)
for ax, (method, design) in zip(axes, designs.items()):
    t_ms = (design.time - design.t0) * 1e3
    for i in range(design.predicted.shape[0]):
        target = i == design.target_index
        ax.plot(t_ms, design.predicted[i] * 1e6, color="C3" if target else "0.75", lw=1.5 if target else 0.7,
                zorder=3 if target else 1)
    m = design.metrics()
    ax.set_title(f"{method}\nfidelity {m['fidelity']:.2f}, energy contrast {m['energy_contrast_db']:.1f} dB",
                 fontsize=9)
    ax.set_xlim(-30, 30)
    ax.set_xlabel("time from the tap (ms)")
axes[0].set_ylabel("predicted displacement (µm)")
fig.suptitle("Location 5 at 10 V peak: the target (red) and every other point (grey)")
fig.tight_layout()

# %%
# Played in the demo
# ------------------
# The demo lists the registry's methods, so the new one is designed, played on the
# simulated forearm and measured beside the others.
result = run_demo(rig, methods=methods, locations=[5])
for row in result.rows:
    print(f"{row['method']:>24s}: measured fidelity {row['fidelity']:.2f}, "
          f"energy contrast {row['energy_contrast_db']:.1f} dB")
