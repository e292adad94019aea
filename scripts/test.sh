#!/usr/bin/env bash
# The whole test suite on a fresh machine with Python 3.11 and apt: installs Debian's
# chromium (browser tests), jackd2 and libportaudio2 (the audio rig against a real JACK
# server on its dummy driver), a virtual environment with vibrofocus and its test extras,
# then runs pytest: in parallel, then the browser tests in one process. Extra arguments go to
# both runs of pytest (e.g. -q, -x); to choose tests by marker, call pytest yourself
# (DEVELOPING.md).
set -euo pipefail
cd "$(dirname "$0")/.."

apt_packages=(chromium jackd2 libportaudio2)
missing=()
for pkg in "${apt_packages[@]}"; do
    dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if ((${#missing[@]})); then
    SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
    echo "installing Debian packages: ${missing[*]}"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e '.[test]'
# PsychoPy's own wheel without its dependencies (PyQt6, psychtoolbox, opencv, MeshPy... too heavy
# for CI), in a folder of its own: enough for its Builder compiler and psychopy.data, which
# tests/psychopy run in child processes (docs/psychopy.md). Not importable from the venv itself.
psychopy_dir=.venv/psychopy-nodeps
[ -d "$psychopy_dir/psychopy" ] || .venv/bin/python -m pip install -q --no-deps --target "$psychopy_dir" \
    'psychopy==2026.2.5' 'six>=1.16' 'json-tricks>=3.17' 'i18next>=0.0.3' 'astunparse>=1.6' 'esprima>=4.0'
export VIBROFOCUS_TEST_PSYCHOPY="$PWD/$psychopy_dir"

# Everything but the browser tests in parallel on every core (pytest-xdist), then the
# browser tests in one process: their pages keep real time (timeouts, pauses), which two
# chromiums beside a loaded machine would stretch. No bytecode or pytest cache in the
# checkout: the suite writes only to temporary folders (tests/conftest.py checks it).
export PYTHONDONTWRITEBYTECODE=1
status=0
.venv/bin/python -m pytest -n auto -p no:cacheprovider -m "not browser" "$@" || status=$?
.venv/bin/python -m pytest -p no:cacheprovider -m browser "$@" || status=$?
exit "$status"
