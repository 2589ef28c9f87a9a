"""The add-on on every Blender the manifest names: its tests (tests/test_addon.py: register, shade,
the panels, live mode, undo, save and reload; tests/test_addon_install.py: install from the built
zip into a fresh user folder) run on each LTS release in its own environment, made by
scripts/blender_versions.sh (scripts/setup.sh runs it).  The newest Blender runs the whole suite in
.venv."""
import os
import re
import subprocess

import pytest

from tests.helpers.blender_versions import exits_cleanly

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ADDON_TESTS = ["tests/test_addon.py", "tests/test_addon_install.py"]


@pytest.mark.parametrize("series", ["4.2", "4.5"])
def test_the_addon_tests_pass_on_each_lts_release(series):
    python = os.path.join(ROOT, f".venv-blender-{series}", "bin", "python")
    assert os.path.exists(python), f"no Blender {series} environment: run scripts/setup.sh"
    version = subprocess.run([python, "-c", "import bpy; print('%d.%d' % bpy.app.version[:2])"],
                             capture_output=True, text=True, timeout=120)
    assert version.stdout.strip() == series, version.stdout + version.stderr
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    env.pop("PYTEST_ADDOPTS", None)
    proc = subprocess.run([python, "-m", "pytest", "-q", "-p", "no:cacheprovider", *ADDON_TESTS], cwd=ROOT,
                          capture_output=True, text=True, timeout=1200, env=env)
    summary = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else ""
    # every test passed, none failed, errored or was skipped ...
    assert re.fullmatch(r"\d+ passed in [\d.]+s( \([\d:]+\))?", summary), proc.stdout[-6000:] + proc.stderr[-3000:]
    # ... and the process exited cleanly, bar bpy 4.2's own crash at exit (tests/helpers/blender_versions.py)
    clean = exits_cleanly(tuple(int(x) for x in series.split(".")))
    assert proc.returncode == 0 or (not clean and proc.returncode == -11), proc.stdout[-3000:] + proc.stderr[-3000:]
