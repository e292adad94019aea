#!/usr/bin/env bash
# The whole test suite on a fresh machine with Python 3.11 and apt: installs Debian's
# chromium (browser tests), jackd2 and libportaudio2 (the audio rig against a real JACK
# server on its dummy driver), a virtual environment with vibrofocus and its test extras,
# then runs the suite in phases, each timed ("phase unit: 312 s"):
#
#   unit     the tests that are neither slow, browser nor docs, in parallel (pytest-xdist,
#            two workers per core)
#   slow     the slow (> ~10 s) and integration tests, in parallel
#   browser  the browser tests, in two processes (their pages keep real time)
#   docs     the Sphinx site with its executed gallery, built outside pytest, then checked
#            (scripts/build_docs.sh)
#   lowest   the smoke test at the lowest versions pyproject.toml allows (scripts/test_lowest.sh)
#
# Asked with browser, the docs and lowest phases run beside it (at a lower CPU priority: the
# browser phase mostly waits on its pages' real time, the smoke test on installs); the output
# of each follows, in its place, when it ends. BESIDE_BROWSER names the phases that do
# (default "docs lowest"; "slow docs lowest" starts the slow phase there too, "" none).
# The slow phase is not beside it by default: with one browser process, on 2 cores slow,
# browser and docs took 857 s beside against 883 s one after the other, and a JACK test of
# the slow phase lost samples at nice 19 (measured 2026-12-03).
#
#   bash scripts/test.sh                  unit, slow, browser and docs: every test
#   bash scripts/test.sh unit browser -x  only those phases; other arguments go to pytest
#   PYTHON=/path/to/python bash scripts/test.sh unit   in an environment of yours: installs nothing
#
# Every phase runs even when an earlier one failed; the exit status is the first failure's.
# A phase that selects no test (pytest's exit code 5, e.g. with -k) passes and says so.
# To choose tests by marker, call pytest yourself (DEVELOPING.md).
set -euo pipefail
cd "$(dirname "$0")/.."

phases=()
pytest_args=()
for arg in "$@"; do
    case "$arg" in
        unit|slow|browser|docs|lowest) phases+=("$arg") ;;
        *) pytest_args+=("$arg") ;;
    esac
done
((${#phases[@]})) || phases=(unit slow browser docs)

declare -A took=()
order=()
status=0
# phase NAME COMMAND...: runs the command, prints "phase NAME: N s" and keeps the first failure.
phase() {
    local name=$1; shift
    local start=${phase_start:-$SECONDS} rc=0
    phase_start=""
    echo "=== phase $name"
    "$@" || rc=$?
    if [ "$rc" = 5 ] && [ "$1" = "$python" ]; then
        echo "phase $name: no test selected"
        rc=0
    fi
    took[$name]=$((SECONDS - start))
    order+=("$name")
    echo "phase $name: ${took[$name]} s$([ "$rc" = 0 ] || echo " (FAILED, exit $rc)")"
    [ "$rc" = 0 ] || [ "$status" != 0 ] || status=$rc
}

setup() {
    local apt_packages=(chromium jackd2 libportaudio2) missing=() pkg
    for pkg in "${apt_packages[@]}"; do
        dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
    done
    if ((${#missing[@]})); then
        local SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
        echo "installing Debian packages: ${missing[*]}"
        $SUDO apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
    fi
    [ -x .venv/bin/python ] || python3 -m venv .venv
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -e '.[test]'
    # PsychoPy's own wheel without its dependencies (PyQt6, psychtoolbox, opencv, MeshPy... too
    # heavy for CI), in a folder of its own: enough for its Builder compiler and psychopy.data,
    # which tests/psychopy run in child processes (docs/psychopy.md). Not importable from the venv.
    [ -d "$psychopy_dir/psychopy" ] || .venv/bin/python -m pip install -q --no-deps --target "$psychopy_dir" \
        'psychopy==2026.2.5' 'six>=1.16' 'json-tricks>=3.17' 'i18next>=0.0.3' 'astunparse>=1.6' 'esprima>=4.0'
}

python=.venv/bin/python
psychopy_dir=.venv/psychopy-nodeps
if [ -n "${PYTHON:-}" ]; then
    # An environment of the caller's (PYTHON=/path/to/python): nothing is installed, and
    # VIBROFOCUS_TEST_PSYCHOPY is the caller's too.
    python=$PYTHON
else
    needs_setup=0
    for p in "${phases[@]}"; do [ "$p" = lowest ] || needs_setup=1; done
    if ((needs_setup)); then phase setup setup; fi
    export VIBROFOCUS_TEST_PSYCHOPY="$PWD/$psychopy_dir"
fi

# No bytecode or pytest cache in the checkout: the suite writes only to temporary folders
# (tests/conftest.py checks it). Python's bytecode (with pytest's rewritten test modules) and
# hypothesis' constants go to one temporary folder of this run instead, so that each of the
# suite's processes (every phase, every xdist worker, every command a test runs) compiles and
# parses nothing that an earlier one did: without it, collecting the suite took 24 s of CPU per
# process, and each command a test ran compiled the package again. The 25 slowest tests of
# each phase are listed at its end.
cache_dir=$(mktemp -d "${TMPDIR:-/tmp}/vibrofocus-test-cache.XXXXXX")
unset PYTHONDONTWRITEBYTECODE
export PYTHONPYCACHEPREFIX="$cache_dir/pycache" HYPOTHESIS_STORAGE_DIRECTORY="$cache_dir/hypothesis"
# One BLAS thread per process: the parallel phases run a process per core already, and a
# BLAS call that hands off to a second thread waits for a core the other worker holds (a
# dot product of 16384 samples took 24 ms with two threads on a busy 2-core machine, 45 us
# with one). Subprocesses (the served apps, simulate-study) inherit it. A caller's own
# setting is kept.
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1} OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} \
    MKL_NUM_THREADS=${MKL_NUM_THREADS:-1}
pytest=("$python" -m pytest -p no:cacheprovider --durations=25)
# The unit phase runs two workers per core: its tests wait on real time as much as they
# compute (a served app's start, a JACK play, a rig's close waiting out its graph round, a
# command's subprocess), and a second worker computes while the first waits. On 2 cores:
# 316 s against 412 s with one worker per core, CPU 187 % against about 145 % (2026-12-04).
# The slow phase keeps one per core: its tests compute, and four workers took as long
# (316 s against 322 s; that run also showed a lost LSL marker, a bug since fixed in
# MarkerOutlet.close).
# (At most 16: a worker holds the collected suite, 370 MB, and the heaviest tests reached
# 1.25 GB in one process.)
unit_workers=$((2 * $(nproc)))
((unit_workers <= 16)) || unit_workers=16
# The unit phase hands out whole modules (--dist loadscope), so a module's shared fixture (a
# calibration, a served app) is made by one worker, not by each; the slow phase's tests take
# seconds to minutes each, so an idle worker takes tests from a busy one (--dist worksteal).
# The lowest-versions smoke test spends most of its time installing, and the browser phase
# waiting on its pages: asked with browser, the phases of BESIDE_BROWSER (the smoke test and
# the docs build) start beside the browser phase, each in a background process of its own (its
# own temporary folders) at nice 19, so that the pages' real time comes first (the scheduler
# gives a nice-19 process about 1.5 % of a core that a nice-0 one wants: the background phases
# take what the browser phase leaves idle). The phase, where it comes (or right after browser,
# for one asked before it), waits for its process and shows its output. Its time counts from
# its start.
declare -A bg_pid=() bg_log=() bg_started=() bg_pytest=()
# start_beside NAME COMMAND...: starts a phase's command in the background.
start_beside() {
    local name=$1; shift
    bg_log[$name]=$(mktemp)
    bg_started[$name]=$SECONDS
    echo "=== phase $name: started beside the next phase; its output follows when it ends"
    bg_pytest[$name]=0
    [ "$1" != "$python" ] || bg_pytest[$name]=1
    nice -n 19 "$@" >"${bg_log[$name]}" 2>&1 &
    bg_pid[$name]=$!
}
# finish_beside NAME: waits for a phase started beside, shows its output, returns its status.
finish_beside() {
    local name=$1 rc=0
    wait "${bg_pid[$name]}" || rc=$?
    unset "bg_pid[$name]"
    cat "${bg_log[$name]}"
    rm -f "${bg_log[$name]}"
    if [ "$rc" = 5 ] && [ "${bg_pytest[$name]}" = 1 ]; then
        echo "phase $name: no test selected"
        rc=0
    fi
    return "$rc"
}
cleanup() {
    local name
    for name in "${!bg_pid[@]}"; do kill "${bg_pid[$name]}" 2>/dev/null || true; done
    for name in "${!bg_log[@]}"; do rm -f "${bg_log[$name]}"; done
    rm -rf "$cache_dir"
}
trap cleanup EXIT
# phase_cmd NAME: the command of a phase, in the array run_cmd.
phase_cmd() {
    case "$1" in
        unit) run_cmd=("${pytest[@]}" -n "$unit_workers" --dist loadscope -m "not slow and not browser and not docs") ;;
        slow) run_cmd=("${pytest[@]}" -n auto --dist worksteal -m "slow and not browser and not docs") ;;
        # Two processes, whole modules each: the pages keep real time (timeouts, pauses), and
        # one process left a core idle (CPU 98 % of 200 %, docs beside); two took 250 s
        # against 329 s, CPU 136 % (2026-12-04).
        browser) run_cmd=("${pytest[@]}" -n 2 --dist loadscope -m "browser and not docs") ;;
        docs) run_cmd=(env PYTHON="$python" bash scripts/build_docs.sh) ;;
        lowest) run_cmd=(bash scripts/test_lowest.sh); return ;;
    esac
    run_cmd+=(${pytest_args[@]+"${pytest_args[@]}"})
}
beside=" ${BESIDE_BROWSER-docs lowest} "
wants_browser=0
for p in "${phases[@]}"; do [ "$p" != browser ] || wants_browser=1; done
suite_start=$SECONDS
for p in "${phases[@]}"; do
    if ((wants_browser)) && [ "$p" != browser ] && [[ $beside == *" $p "* ]]; then
        # Runs beside the browser phase: started with it, finished after it, in its place.
        if [ -n "${bg_pid[$p]:-}" ]; then
            phase_start=${bg_started[$p]} phase "$p" finish_beside "$p"
        fi
        continue
    fi
    if [ "$p" = browser ]; then
        for q in "${phases[@]}"; do
            if [ "$q" != browser ] && [[ $beside == *" $q "* ]] && [ -z "${bg_started[$q]:-}" ]; then
                phase_cmd "$q"
                start_beside "$q" "${run_cmd[@]}"
            fi
        done
    fi
    phase_cmd "$p"
    phase "$p" "${run_cmd[@]}"
    if [ "$p" = browser ]; then
        # Those asked before browser (slow, in .ci/run's order) end here.
        for q in "${phases[@]}"; do
            [ "$q" != browser ] || break
            if [ -n "${bg_pid[$q]:-}" ]; then phase_start=${bg_started[$q]} phase "$q" finish_beside "$q"; fi
        done
    fi
done

echo "=== phase times"
total=0
for name in "${order[@]}"; do
    printf 'phase %-8s %5d s\n' "$name:" "${took[$name]}"
    total=$((total + took[$name]))
done
printf 'total          %5d s\n' "$total"
((${#bg_started[@]} == 0)) || printf 'wall clock     %5d s (%s beside browser)\n' "$((SECONDS - suite_start))" "${!bg_started[*]}"
exit "$status"
