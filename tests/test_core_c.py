"""The C core below the bindings stands on its own: csrc/ without csrc/python/ builds into a plain
program (tests/c/core_check.c) that checks the material interface and every registered shading
method against closed forms, and no numerical file includes Python.h."""
import functools
import glob
import os
import re
import shlex
import subprocess
import tempfile
from concurrent.futures import ThreadPoolExecutor

import pytest

import wenv

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CSRC = os.path.join(ROOT, "csrc")


def numerical_sources():
    return sorted(p for p in glob.glob(os.path.join(CSRC, "**", "*.c"), recursive=True)
                  if os.sep + "python" + os.sep not in p)


def test_numerical_code_never_includes_python():
    files = [p for p in glob.glob(os.path.join(CSRC, "**", "*.[ch]"), recursive=True)
             if os.sep + "python" + os.sep not in p]
    assert len(files) > 40
    offenders = [p for p in files if re.search(r'#include\s*[<"]Python\.h[">]|#include\s*"python/', open(p).read())]
    assert offenders == []


def test_layers_include_only_layers_below():
    """base <- math <- scene, bake <- methods, reference, glossmeter <- auto <- python (docs/ARCHITECTURE.md §1)."""
    rank = {"base": 0, "math": 1, "scene": 2, "bake": 2, "methods": 3, "reference": 3, "glossmeter": 3, "auto": 4,
            "python": 5}
    wrong = []
    for path in glob.glob(os.path.join(CSRC, "**", "*.[ch]"), recursive=True):
        layer = os.path.relpath(path, CSRC).split(os.sep)[0]
        for inc in re.findall(r'#include "([a-z_]+)/', open(path).read()):
            if rank[inc] > rank[layer] or (rank[inc] == rank[layer] and inc != layer):
                wrong.append((os.path.relpath(path, CSRC), inc))
    assert wrong == []


def pkg_config(*args):
    try:
        return shlex.split(subprocess.run(["pkg-config", *args], check=True, capture_output=True, text=True).stdout)
    except (OSError, subprocess.CalledProcessError):
        return []


@pytest.mark.parametrize("sanitized", [False, True], ids=["plain", "asan-ubsan"])
def test_core_without_python(tmp_path, sanitized):
    """With sanitized, AddressSanitizer (leaks included) and UndefinedBehaviorSanitizer watch the run."""
    exe = tmp_path / "core_check"
    exr = [f for f in pkg_config("--cflags", "OpenEXR") if f.startswith("-I")] or ["-I/usr/include/OpenEXR"]
    sanitize = ["-g", "-fsanitize=address,undefined", "-fno-sanitize-recover=undefined",
                "-fno-omit-frame-pointer"] if sanitized else []
    flags = ["-std=c11", "-D_DEFAULT_SOURCE", "-O1", *sanitize, "-fopenmp", "-Wall", "-Wextra", "-Werror", "-I" + CSRC,
             *exr]
    sources = [os.path.join(ROOT, "tests", "c", "core_check.c"), *numerical_sources()]
    objects = [str(tmp_path / f"{i}.o") for i in range(len(sources))]

    def compile_one(source, obj):
        return subprocess.run(["gcc", *flags, "-c", source, "-o", obj], capture_output=True, text=True)

    with ThreadPoolExecutor(os.cpu_count() or 1) as pool:  # one compiler per core
        for build in pool.map(compile_one, sources, objects):
            assert build.returncode == 0, build.stderr[-4000:]
    link = subprocess.run(["gcc", *sanitize, "-fopenmp", *objects, "-o", str(exe), "-lOpenEXRCore", "-lcubature",
                           "-lembree3", "-lz", "-lm"], capture_output=True, text=True)
    assert link.returncode == 0, link.stderr[-4000:]
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=300,
                         env=dict(os.environ, OMP_NUM_THREADS="2", ASAN_OPTIONS="detect_leaks=1"))
    assert "Sanitizer" not in run.stderr and "runtime error" not in run.stderr, run.stderr[-4000:]
    assert "FAIL" not in run.stdout, run.stdout
    assert run.returncode == 0, run.stdout + run.stderr
    summary = re.search(r"^(\d+) passed, (\d+) failed$", run.stdout, re.M)
    assert summary and summary.group(2) == "0"
    # Cycles' bump terminator (2), a GGX lobe cut in two (6), a lamp (1), the bake's texels and margin (3), the grazing pyramid's halves
    # and the node loops and single reads this CPU runs (5), materials (9), each model's accelerators against the
    # defaults derived from its lobe_value (35), then a white furnace, the Lambertian part's light given apart and
    # stats per method, the registry and the reference
    assert int(summary.group(1)) == 2 + 6 + 1 + 3 + 5 + 9 + 35 + 3 * len(wenv.METHODS) + 2
    assert run.stdout.count("is lobe_value's") == 9 and "its cone for the exact lights is its shape's" in run.stdout
    assert "ok   a single pyramid read is the portable one's to the bit" in run.stdout
    for method in wenv.METHODS:
        assert f"ok   {method}: a white environment reflects the albedo" in run.stdout
        assert f"ok   {method}: the Lambertian part's light apart, coloured, is the whole" in run.stdout


def setup_compile_args():
    """The C flags setup.py builds the module with (its extra_compile_args for an optimised build)."""
    import ast
    tree = ast.parse(open(os.path.join(ROOT, "setup.py")).read())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "extra_compile_args" for t in node.targets):
            return ast.literal_eval(node.value) + ["-O3"]
    raise AssertionError("setup.py has no extra_compile_args")


@functools.lru_cache(maxsize=None)
def vectoriser_report(source, arch):
    """GCC's run compiling csrc/<source> with setup.py's flags for `arch`, reporting the loops it
    vectorised (once per source and CPU: principled.c holds two of the loops)."""
    with tempfile.TemporaryDirectory() as folder:
        return subprocess.run(["gcc", *setup_compile_args(), "-march=" + arch, "-fPIC", "-I" + CSRC, "-c",
                               os.path.join(CSRC, source), "-o", os.path.join(folder, "o.o"),
                               "-fopt-info-vec-optimized"], capture_output=True, text=True)


@pytest.mark.skipif(os.uname().machine != "x86_64", reason="the vector clones are built for x86-64 only")
@pytest.mark.parametrize("arch", ["x86-64-v3", "x86-64-v4"])
@pytest.mark.parametrize("source, loop_in", [("scene/cook_torrance.c", "ct_lobe_lanes"),
                                             ("scene/principled.c", "ggx_lanes"),
                                             ("scene/principled.c", "sheen_lanes")])
def test_float_brdf_loops_run_in_vector_lanes(arch, source, loop_in):
    """The exact lights' BRDF evaluations are written for the vectoriser; GCC once left them scalar
    (a branch in the loop, an aliasing read, a trapping select) and a view took 1.4-2x as long.  Compiled
    with setup.py's flags for each clone's CPU, the loop over directions must be reported vectorised."""
    path = os.path.join(CSRC, source)
    lines = open(path).read().split("\n")
    start = next(i for i, l in enumerate(lines) if re.search(r"\b" + loop_in + r"\(", l))
    loop = next(i for i in range(start, len(lines)) if re.match(r"\s*for \(size_t k = 0; k < ", lines[i])) + 1
    build = vectoriser_report(source, arch)
    assert build.returncode == 0, build.stderr[-4000:]
    assert re.search(rf"{re.escape(source)}:{loop}:\d+: optimized: loop vectorized", build.stderr), \
        f"{source}:{loop} ({loop_in}) not vectorised for {arch}"
