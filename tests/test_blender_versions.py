"""The add-on on every Blender the manifest names: its tests (tests/test_addon.py: register, shade,
the panels, live mode, undo, save and reload; tests/test_addon_install.py: install from the built
zip into a fresh user folder; the node, texture, bump and shader-node comparisons against that
release's Cycles) run on each LTS release in its own environment, made by
scripts/blender_versions.sh (scripts/setup.sh runs it).  The newest Blender runs the whole suite in
.venv.  The zip is built once, by the main environment (it is one for every Blender), and the
releases run at the same time, each in its own process."""
import os
import re
import subprocess

import pytest

from tests.helpers.blender_versions import exits_cleanly
from tests.helpers.extension_zip import build_extension_zip

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# and what differs from release to release against each one's Cycles (the Voronoi's cells hashed
# otherwise before 5.0, the bump terminator before 4.5).  (tests/test_closures_cycles.py, a minute a
# release, passes on each too -- a rough Diffuse BSDF is the classic Oren-Nayar before 4.3 --, run by hand
# to keep CI short.)
ADDON_TESTS = ["tests/test_addon.py", "tests/test_addon_install.py", "tests/test_procedural_textures.py",
               "tests/test_attributes.py", "tests/test_ngons_cycles.py", "tests/test_bump_cycles.py"]
SERIES = ["4.2", "4.5"]


def environment_python(series):
    python = os.path.join(ROOT, f".venv-blender-{series}", "bin", "python")
    assert os.path.exists(python), f"no Blender {series} environment: run scripts/setup.sh"
    return python


@pytest.fixture(scope="module")
def lts_runs(tmp_path_factory):
    """{series: the running pytest of the add-on's tests on that release, its output files}."""
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", WENV_EXTENSION_ZIP=build_extension_zip())
    env.pop("PYTEST_ADDOPTS", None)
    folder = tmp_path_factory.mktemp("lts")
    runs = {}
    for series in SERIES:
        out, err = open(folder / f"{series}.out", "w+"), open(folder / f"{series}.err", "w+")
        proc = subprocess.Popen([environment_python(series), "-m", "pytest", "-q", "-p", "no:cacheprovider",
                                 *ADDON_TESTS], cwd=ROOT, stdout=out, stderr=err, text=True, env=env)
        runs[series] = (proc, out, err)
    yield runs
    for proc, out, err in runs.values():
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        out.close()
        err.close()


@pytest.mark.parametrize("series", SERIES)
def test_the_addon_tests_pass_on_each_lts_release(series, lts_runs):
    version = subprocess.run([environment_python(series), "-c", "import bpy; print('%d.%d' % bpy.app.version[:2])"],
                             capture_output=True, text=True, timeout=120)
    assert version.stdout.strip() == series, version.stdout + version.stderr
    proc, out, err = lts_runs[series]
    returncode = proc.wait(timeout=1200)
    out.seek(0)
    err.seek(0)
    stdout, stderr = out.read(), err.read()
    summary = stdout.strip().splitlines()[-1] if stdout.strip() else ""
    # every test passed, none failed, errored or was skipped ...
    assert re.fullmatch(r"\d+ passed in [\d.]+s( \([\d:]+\))?", summary), stdout[-6000:] + stderr[-3000:]
    # ... and the process exited cleanly, bar bpy 4.2's own crash at exit (tests/helpers/blender_versions.py)
    clean = exits_cleanly(tuple(int(x) for x in series.split(".")))
    assert returncode == 0 or (not clean and returncode == -11), stdout[-3000:] + stderr[-3000:]
