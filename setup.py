"""Build the `wenv` C extension (sources in csrc/, one folder per layer: docs/ARCHITECTURE.md).

System libraries (Debian names): libopenexr-dev (OpenEXRCore), zlib1g-dev, libcubature-dev, libembree-dev
(Embree 3: the ray casts of occlusion).
scripts/setup.sh installs them.  Flags stay portable: no -march=native; hot loops dispatch on
CPU features at run time instead.
"""
import glob
import os
import shlex
import subprocess

from setuptools import Extension, setup


def pkg_config(*args):
    try:
        out = subprocess.run(["pkg-config", *args], check=True, capture_output=True, text=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return []
    return shlex.split(out)


exr_cflags = pkg_config("--cflags", "OpenEXR") or ["-I/usr/include/OpenEXR"]
include_dirs = [f[2:] for f in exr_cflags if f.startswith("-I")]
# Only the C library (OpenEXRCore) is used; the C++ libraries OpenEXR's .pc lists are not needed.
exr_libs = [f[2:] for f in pkg_config("--libs", "OpenEXR") if f.startswith("-lOpenEXRCore")] or ["OpenEXRCore"]

# WENV_DEBUG=1: unoptimised, with AddressSanitizer and UndefinedBehaviorSanitizer, for a debugger.
# WENV_SANITIZE=1: the same sanitizers at -O1, fast enough for the whole test suite
# (scripts/sanitize_tests.sh).  Either build needs libasan preloaded into python.
debug = os.environ.get("WENV_DEBUG") == "1"
sanitize = os.environ.get("WENV_SANITIZE") == "1"
# -fno-trapping-math: nothing here reads floating-point exception flags, and without it GCC may not
# compute both arms of a select in a vector loop (a division might trap), which kept the float BRDF
# loops scalar on AVX2.  It changes no value (-ffast-math would; -std=c11 keeps FMA contraction off).
extra_compile_args = ["-std=c11", "-D_DEFAULT_SOURCE", "-Wall", "-Wextra", "-fopenmp", "-fno-math-errno",
                      "-fno-trapping-math"]
if debug:
    extra_compile_args += ["-O0", "-g", "-fsanitize=address,undefined"]
elif sanitize:
    extra_compile_args += ["-O1", "-g", "-fno-omit-frame-pointer", "-fsanitize=address,undefined"]
else:
    extra_compile_args += ["-O3"]
extra_link_args = ["-fopenmp"] + (["-fsanitize=address,undefined"] if debug or sanitize else [])

setup(
    name="wenv",
    version="0.1.0",
    description="Wavelet-rotation environment shading and a virtual glossmeter",
    # sweeps of many jobs on any executor (Dask's among them): pure Python, importing neither bpy nor wenv
    py_modules=["wenv_sweep"],
    ext_modules=[
        Extension(
            "wenv",
            sources=sorted(glob.glob("csrc/**/*.c", recursive=True)),
            # a changed header (or the lobe's terms, included twice) rebuilds the sources, which
            # setuptools otherwise would not see as changed
            depends=sorted(glob.glob("csrc/**/*.h", recursive=True) + glob.glob("csrc/**/*.inc", recursive=True)),
            include_dirs=["csrc"] + include_dirs,
            libraries=exr_libs + ["cubature", "embree3", "z", "m"],
            extra_compile_args=extra_compile_args,
            extra_link_args=extra_link_args,
        )
    ],
    python_requires=">=3.11",
    install_requires=["numpy"],
)
