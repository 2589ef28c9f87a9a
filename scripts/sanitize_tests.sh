#!/usr/bin/env bash
# Runs the Python test suite against wenv built with AddressSanitizer and UndefinedBehaviorSanitizer
# at -O1 (WENV_SANITIZE=1 in setup.py), gcc's libasan and libubsan preloaded into python.  The
# sanitized extension goes to build/sanitize/ with its own objects, so the in-place build is left
# as it was, and comes first on PYTHONPATH.  A sanitizer report stops the run (one pytest process).
#
#   bash scripts/sanitize_tests.sh                        # the whole suite
#   bash scripts/sanitize_tests.sh tests/test_envmap.py   # some files (any pytest arguments)
#
# Only wenv is instrumented: reports come from its code (or from memory it was handed).  Leaks are
# not checked here: every allocation's stack runs through the interpreter, so leak suppressions for
# CPython, numpy or bpy would hide wenv's own too.  wenv's leaks are checked where the stacks are
# its own: tests/test_core_c.py (the C core under ASan with leak detection) and the fuzz targets
# (libFuzzer checks every input).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
out=build/sanitize

WENV_SANITIZE=1 "$PY" setup.py -q build_ext --build-lib "$out/lib" --build-temp "$out/tmp" >/dev/null

export LD_PRELOAD="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libubsan.so)"
# allocator_may_return_null: a failed allocation returns NULL, as without the sanitizer, so the
# MemoryError paths the tests take stay what they are; suppressions: see the file
export ASAN_OPTIONS="detect_leaks=0:halt_on_error=1:allocator_may_return_null=1:suppressions=$PWD/scripts/sanitize.supp"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:suppressions=$PWD/scripts/sanitize.supp"
if [ $# -eq 0 ]; then
    set -- tests
fi
# Left to the ordinary run: these compare the resident memory a setting takes with the shader's
# count of its arrays, which AddressSanitizer's shadow memory, redzones and quarantine inflate
set -- "$@" --deselect tests/test_memory.py::test_rotation_memory_grows_with_the_setting \
    --deselect tests/test_memory.py::test_split_sum_counts_its_source_pyramid
# The sanitized build goes first on this process's sys.path only, and is imported before pytest
# starts, so every later import gets it (tests that put the checkout, with its in-place build, on
# sys.path for benchmarks/ included); -P keeps the current folder off sys.path.  Child processes
# that load wenv are given its folder by the tests (dirname(wenv.__file__)); PYTHONPATH is left
# alone, as tests/test_addon_install.py checks that a fresh process sees no development copy.
exec "$PY" -P -c '
import sys
sys.path.insert(0, sys.argv[1])
import pytest, wenv
if not wenv.__file__.startswith(sys.argv[1]):
    sys.exit("not the sanitized build: " + wenv.__file__)
print("wenv:", wenv.__file__)
sys.exit(pytest.main(["-q", *sys.argv[2:]]))' "$PWD/$out/lib/" "$@"
