#!/usr/bin/env bash
# Makes a virtual environment per Blender LTS release the manifest names beside the newest (which
# .venv holds): .venv-blender-<major.minor> with that release's bpy module, numpy and pytest, the
# repository on its path (the in-place build of `wenv` and the add-on), for the add-on's tests on
# each (tests/test_blender_versions.py).  Safe to run again: it installs only what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
# The newest patch release of each LTS series (bpy wheels for Python 3.11); 4.2.0 crashes at exit
# once a script registers a class or handler.
for version in 4.2.23 4.5.15; do
    tuple=${version//./, }
    series=${version%.*}
    venv=.venv-blender-$series
    if [ ! -x "$venv/bin/python" ]; then
        echo "wenv setup: creating $venv (Blender $version)"
        "$PY" -m venv "$venv"
    fi
    if ! "$venv/bin/python" -c "import bpy, numpy, pytest, sys; sys.exit(tuple(bpy.app.version) != ($tuple))" \
            >/dev/null 2>&1; then
        echo "wenv setup: installing bpy==$version, numpy and pytest into $venv"
        "$venv/bin/python" -m pip install -q --upgrade pip >/dev/null
        "$venv/bin/python" -m pip install -q "bpy==$version" "numpy>=1.26" "pytest>=8"
    fi
    "$venv/bin/python" - <<'PY'
import os, site
with open(os.path.join(site.getsitepackages()[0], "wenv-dev.pth"), "w") as fp:
    fp.write(os.getcwd() + "\n")
PY
done
