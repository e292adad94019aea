#!/usr/bin/env bash
# Smoke test at the LOWEST versions pyproject.toml allows (uv --resolution lowest-direct):
# import, --help, the demo, one render and one analysis, in a throw-away virtual environment.
# Every minimum in pyproject.toml is one this run installed. Run by .ci/run after the suite.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

python3 -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q uv
# Built from a copy: setuptools writes its build/ folder beside the sources.
mkdir "$work/pkg"
cp -r "$root/src" "$root/tools" "$root/pyproject.toml" "$root/README.md" "$root/LICENSE" "$work/pkg/"
# The test extra's file readers (pybids, pyfar) at their minimums too: pyproject states them.
"$work/venv/bin/uv" pip install -q --python "$work/venv/bin/python" --resolution lowest-direct "$work/pkg[lsl,sofa,osc,minimax]" \
    "pybids==$(grep -oP '"pybids>=\K[0-9.]+' "$root/pyproject.toml")" "pyfar==$(grep -oP '"pyfar>=\K[0-9.]+' "$root/pyproject.toml")"
"$work/venv/bin/uv" pip list -q --python "$work/venv/bin/python" --format freeze > "$work/versions.txt" 2>/dev/null || true

export PYTHONDONTWRITEBYTECODE=1 MPLBACKEND=Agg
cd "$work"  # nothing is written into the checkout
vf="$work/venv/bin/vibrofocus"
"$work/venv/bin/python" -c "import vibrofocus; print('vibrofocus', vibrofocus.__version__)"
"$vf" --help > /dev/null
# The optional extras at their minimums: pylsl loads its bundled liblsl, sofar knows GeneralTF-E,
# python-osc's client reads replies (serve-osc's tests use it).
"$work/venv/bin/python" -c "import pylsl, sofar; pylsl.local_clock(); sofar.Sofa('GeneralTF-E'); from pythonosc.udp_client import SimpleUDPClient; SimpleUDPClient.receive"
"$vf" serve-osc --help > /dev/null
# A small peak-contrast design (CVXOPT's cone solver at its minimum); cvxpy and Clarabel at
# their minimums import (the reference formulation of the tests and the benchmark).
"$work/venv/bin/python" -c "
import cvxpy, clarabel
import numpy as np
from vibrofocus.rendering import minimax_filter
rng = np.random.default_rng(0)
h = rng.standard_normal((3, 2, 24)) * np.exp(-np.arange(24) / 6.0)
H = np.fft.rfft(h, 256, axis=-1).transpose(2, 0, 1)
t = (np.arange(256) / 2000.0 - 0.064) / 4e-3
targets = np.zeros((3, 256)); targets[0] = (1 - t**2) * np.exp(-t**2 / 2)
_, rep = minimax_filter(H, targets, 2000.0, band=(20.0, 300.0), min_fidelity=0.9, support_s=(0.02, 0.01), full_output=True)
assert rep.fidelity >= 0.9 - 1e-3, rep.fidelity
assert rep.status == 'optimal' and rep.solver == 'cvxopt.conelp', (rep.status, rep.solver)"
"$vf" latency --count 3 --spacing 0 --json > "$work/latency.json"
"$vf" serve --help > /dev/null
"$work/venv/bin/python" -c "
import sys
from vibrofocus.web.app import create_app
create_app(sys.argv[1], token='t' * 32)" "$work/s.sqlite"
"$vf" demo --json --no-figures --out "$work/demo" > "$work/demo.json"
"$work/venv/bin/python" -c "import json, sys; d = json.load(open(sys.argv[1])); assert len(d['results']) == 54" "$work/demo.json"
"$vf" render --calibration "$work/demo/calibration.nc" --method inverse --location 5 --out "$work/tap.npz" > /dev/null
# pyfar at its minimum reads a calibration exported as SOFA; pybids at its minimum imports.
"$work/venv/bin/python" -c "
import sys, bids, pyfar
from vibrofocus.calibration import export_sofa, load_calibration
export_sofa(load_calibration(sys.argv[1]), sys.argv[2])
pyfar.io.read_sofa(sys.argv[2])" "$work/demo/calibration.nc" "$work/cal.sofa"
# The synthetic trials of the analysis tests, imported as the package tests.analysis from the
# checkout's root (the current folder of a -c command is first on its path; nothing is written).
(cd "$root" && "$work/venv/bin/python" -c "
import sys
from tests.analysis.synthetic import make_trials
make_trials(8, seed=3).to_csv(sys.argv[1], index=False)" "$work/trials.csv")
"$vf" analyze "$work/trials.csv" --out "$work/report" > /dev/null
test -s "$work/report/report.json"
echo "lowest-versions smoke test passed with:"
grep -iE '^(click|numpy|scipy|xarray|h5netcdf|h5py|pandas|pingouin|matplotlib|fastapi|jinja2|uvicorn|typer|rich|pydantic|sounddevice|nidaqmx|dask|distributed|threadpoolctl|pylsl|sofar|python-osc|cvxpy|clarabel|cvxopt|pybids|pyfar)==' "$work/versions.txt" | tr '\n' ' '
echo
