"""
Live taps over Open Sound Control
=================================

``vibrofocus serve-osc`` plays taps that another program asks for over OSC: here a
python-osc client in the same script moves a tap across the grid, one ``/tap_xy`` message
every 2 mm from x = -12 mm to 12 mm, on the simulated rig (a model of an arm, not data).
For each played drive the simulated arm's peak displacement along the line y = 0 shows
where the focus landed; a malformed message is answered ``/error`` and plays nothing.
Needs ``pip install 'vibrofocus[osc]'``.
"""

import threading

import matplotlib.pyplot as plt
import numpy as np
from pythonosc.osc_message import OscMessage
from pythonosc.udp_client import SimpleUDPClient

from vibrofocus.realtime import OscTapServer, TapDesigner
from vibrofocus.rendering import TransferMatrix
from vibrofocus.rigs import make_rig

rig = make_rig("simulated", seed=0)
tm = TransferMatrix.from_model(rig, rig.layout, rig.fs)
# What `vibrofocus serve-osc` does: location designs now, the model on a grid for taps anywhere.
designer = TapDesigner(tm, rig, method="inverse", limit_v=rig.limits.peak_v, grid_pitch_m=5e-3)
designer.prepare_grid()
server = OscTapServer(rig, designer, port=0)
thread = threading.Thread(target=server.serve, daemon=True)
thread.start()
client = SimpleUDPClient(*server.address)

line = np.column_stack([np.linspace(-15e-3, 15e-3, 61), np.zeros(61)])
targets_mm = np.arange(-12.0, 12.1, 2.0)
fields = []
for x in targets_mm:
    client.send_message("/tap_xy", [float(x), 0.0])
    reply = OscMessage(client.receive(30))
    assert reply.address == "/played", reply.params
    fields.append(np.abs(rig.respond(rig.last_drive, line)).max(axis=1))

client.send_message("/tap_xy", [float("nan"), 0.0])
print("a NaN coordinate:", OscMessage(client.receive(30)).params[0])
client.send_message("/stop", [])
print("stop:", OscMessage(client.receive(30)).address, "- outputs", rig.outputs_v)
thread.join(10)
server.close()

fields = np.array(fields) * 1e6
fig, ax = plt.subplots(figsize=(6, 3.6), layout="constrained")
im = ax.imshow(fields, aspect="auto", origin="lower", cmap="magma",
               extent=(line[0, 0] * 1e3, line[-1, 0] * 1e3, targets_mm[0] - 1, targets_mm[-1] + 1))
ax.plot(targets_mm, targets_mm, "c.", label="asked (/tap_xy)")
ax.set_xlabel("position on the skin along y = 0 (mm)")
ax.set_ylabel("tap asked at x (mm)")
ax.legend(loc="upper left", fontsize=8)
fig.colorbar(im, label="peak displacement (µm)")
plt.show()
