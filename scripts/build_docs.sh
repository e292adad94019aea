#!/usr/bin/env bash
# Builds the documentation site as CI does, outside pytest: Sphinx with -W (a warning fails
# the build), executing the gallery's examples; then checks the built site
# (tests/test_docs.py -m docs: the API and gallery pages, the command-line reference, and the
# navigation bar on one row in a real chromium).
#
#   bash scripts/build_docs.sh                  build into a temporary folder, check, remove it
#   DOCS_OUT=DIR bash scripts/build_docs.sh     keep the site in DIR/html (DIR must not exist)
#
# Extra arguments go to the check's pytest (e.g. -q). Built from a copy of docs/, examples/
# and CHANGELOG.md: the build writes pages (api/, auto_examples/) beside its sources, and
# nothing is written into the checkout. PYTHON is the interpreter (default .venv/bin/python).
set -euo pipefail
if [ -n "${DOCS_OUT:-}" ]; then
    mkdir "$DOCS_OUT"  # refuses an existing folder: nothing of another build is mixed in
    DOCS_OUT=$(cd "$DOCS_OUT" && pwd)
fi
cd "$(dirname "$0")/.."
root=$(pwd)
python=${PYTHON:-.venv/bin/python}
case "$python" in /*) ;; */*) python="$root/$python" ;; esac
if ! "$python" -c "import sphinx, sphinx_gallery, numpydoc, myst_parser, pydata_sphinx_theme" 2>/dev/null; then
    echo "error: building the docs needs the docs extra: $python -m pip install -e '.[docs]'" >&2
    exit 2
fi
if [ -n "${DOCS_OUT:-}" ]; then
    work=$DOCS_OUT
else
    work=$(mktemp -d)
    trap 'rm -rf "$work"' EXIT
fi

mkdir "$work/source"
cp -r "$root/docs" "$work/source/docs"
rm -rf "$work/source/docs/_build" "$work/source/docs/api" "$work/source/docs/auto_examples"
cp -r "$root/examples" "$work/source/examples"
cp "$root/CHANGELOG.md" "$work/source/CHANGELOG.md"

# No bytecode in the checkout: none at all, unless the caller keeps it elsewhere
# (PYTHONPYCACHEPREFIX, as scripts/test.sh does).
[ -n "${PYTHONPYCACHEPREFIX:-}" ] || export PYTHONDONTWRITEBYTECODE=1
export MPLBACKEND=Agg
# liblsl (the LSL examples) logs every reconnection to stderr; as in the tests, only fatal
# errors (an example that fails still fails the build). A configuration of the caller's wins.
if [ -z "${LSLAPICFG:-}" ]; then
    printf '[log]\nlevel = -3\n' > "$work/lsl_api.cfg"
    export LSLAPICFG="$work/lsl_api.cfg"
fi
start=$SECONDS
(cd "$work" && "$python" -m sphinx -W --keep-going -q -b html "$work/source/docs" "$work/html")
echo "sphinx build: $((SECONDS - start)) s"

rc=0
VIBROFOCUS_DOCS_HTML="$work/html" "$python" -m pytest -p no:cacheprovider --durations=25 -m docs \
    tests/test_docs.py "$@" || rc=$?
[ "$rc" != 5 ] || { echo "the docs check selected no test"; rc=0; }
exit "$rc"
