#!/usr/bin/env bash
# The PsychoPy component with all of PsychoPy (not part of CI: about 5 minutes to install).
#
# Installs PsychoPy 2026.2.5 with all its dependencies and vibrofocus in a virtual
# environment of their own (.venv-psychopy), and xvfb; compiles the shipped Builder
# experiment with `vibrofocus psychopy compile` (PsychoPy's plugins loaded) and runs the
# compiled staircase under Xvfb with a real PsychoPy window, its taps on the simulated rig;
# then checks the data file PsychoPy wrote (docs/psychopy.md, "How it is tested").
#
#   bash scripts/test_psychopy_full.sh
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

if ! command -v xvfb-run >/dev/null; then
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    $SUDO apt-get install -y -q xvfb xauth
fi
venv=.venv-psychopy
[ -x "$venv/bin/python" ] || python3.11 -m venv "$venv"
"$venv/bin/python" -m pip install -q 'psychopy==2026.2.5' -e .

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp examples/psychopy/tap_staircase.psyexp "$work/"
cd "$work"
export HOME=$work MPLBACKEND=Agg
"$root/$venv/bin/vibrofocus" psychopy compile tap_staircase.psyexp
grep -q "from vibrofocus.psychopy import TapStimulus" tap_staircase.py
timeout 600 xvfb-run -a -s "-screen 0 1280x1024x24" "$root/$venv/bin/python" tap_staircase.py
"$root/$venv/bin/python" - <<'PY'
import csv, glob
(path,) = glob.glob("data/*.csv")
rows = [r for r in csv.DictReader(open(path, encoding="utf-8-sig")) if r.get("tap.tap_id")]
levels = [float(r["tap.level_db"]) for r in rows]
assert len(rows) >= 5 and len(set(levels)) >= 3, (len(rows), levels)
assert all(r["tap.error"] == "" and r["tap.onset_device_s"] for r in rows)
print(f"PsychoPy ran the compiled staircase under Xvfb: {len(rows)} taps, levels {sorted(set(levels))} dB")
PY
