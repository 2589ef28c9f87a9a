"""The installable extension's zip, built as a user builds it, once a session."""
import functools
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@functools.lru_cache(maxsize=None)
def build_extension_zip():
    """The zip scripts/build_extension.sh builds, by the main environment's tools (the zip is one for
    every Blender, and tests/test_addon_install.py and tests/test_blender_versions.py install the same
    one: it is built once)."""
    main = os.path.join(ROOT, ".venv", "bin", "python")
    proc = subprocess.run(["bash", os.path.join(ROOT, "scripts", "build_extension.sh")], cwd=ROOT,
                          capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, PYTHON=main if os.path.exists(main) else sys.executable))
    assert proc.returncode == 0, proc.stderr + proc.stdout
    path = os.path.join(ROOT, proc.stdout.split()[0])
    assert os.path.isfile(path)
    return path
