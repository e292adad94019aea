"""
A calibration as a SOFA file, opened with pyfar
===============================================

:func:`vibrofocus.calibration.export_sofa` writes a calibration's transfer matrix
(skin displacement per actuator voltage, m/V) to a SOFA ``GeneralTF-E`` file: the
receivers are the skin points, the emitters the actuators, with their positions. sofar
verifies it and pyfar reads it as ``FrequencyData`` of shape (emitters, measurements,
receivers). The calibration is of the simulated forearm (a model). Needs ``pip install
'vibrofocus[sofa]' pyfar``.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import pyfar as pf
import sofar as sf

from vibrofocus.calibration import calibrate, export_sofa
from vibrofocus.rigs import make_rig

cal = calibrate(make_rig("simulated", seed=0), participant_id="S00", sweep_s=1.0, repeats=4)
with tempfile.TemporaryDirectory() as tmp:
    path = export_sofa(cal, Path(tmp) / "S00.sofa")
    sofa = sf.read_sofa(str(path), verbose=False)
    sofa.verify(issue_handling="raise")
    data, sources, receivers = pf.io.convert_sofa(sofa)

print(sofa.GLOBAL_SOFAConventions, data)
print("receivers (skin points), x y in mm:\n", (receivers.cartesian[:, :2] * 1e3).round(1))

fig, ax = plt.subplots(figsize=(7, 4))
labels = cal.layout.point_labels
for r in (0, 4, 8):  # locations 1, 5 and 9, from actuator 1
    pf.plot.freq(data[0, 0, r], ax=ax, dB=True, label=f"actuator {cal.layout.actuator_names[0]} -> point {labels[r]}")
ax.set_xlim(10, 1000)
ax.set_title("Transfer functions read by pyfar (simulated forearm, a model)")
ax.legend()
