#!/usr/bin/env bash
# Build the course book to HTML: book/_build/html/index.html
#
#   book/build.sh            (from anywhere; needs `pip install -e ".[book]"`)
#
# The book's source root is the repository root, so that it renders notebooks/ and exercises/ in
# place (Jupyter Book 1 only includes files below its source root); _config.yml and _toc.yml live
# here in book/ and are passed explicitly. Every notebook is executed afresh, in parallel (book/execute.py;
# in fast mode: shorter demos, same algorithms), unless the test suite just ran it with the same code,
# library and solver versions (book/kept_runs.py: pytest then book/build.sh runs each notebook once),
# and every Sphinx warning -- a broken cross-reference, a missing figure, a cell
# that raises -- fails the build (-W), after reporting all of them (--keep-going). Then the pages
# are read as a reader gets them (book/check_rendered.py): raw $$, \begin{, a pipe table or a
# Python repr on any page, or fewer equations than the source holds, fails the build too.
# With RACING_LAB_REPOSITORY=https://github.com/<owner>/<repo>, every chapter gets a launch-on-Binder
# button (book/launch_config.py); without it the book is the same, offline, without buttons.
# Extra arguments are passed on to jupyter-book (e.g. --all to rebuild every page).
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
cd "$repo"
export RACING_LIB_FAST="${RACING_LIB_FAST:-1}"
start=$(date +%s)
# Launch buttons (Binder) only when RACING_LAB_REPOSITORY names the published repository.
config="$(python "$repo/book/launch_config.py")"
# Every notebook executed, one per core (Jupyter Book alone runs them one at a time), or its fresh
# run from the test suite taken.
python "$repo/book/execute.py"
jupyter-book build . \
  --config "$config" \
  --toc book/_toc.yml \
  --path-output book \
  --warningiserror --keep-going \
  "$@"
python "$repo/book/check_rendered.py"
echo "book: built in $(( $(date +%s) - start )) s -> book/_build/html/index.html"
