"""What the benchmark scripts share: the checkout's out/ folder and how a sphere is drawn (its normals
per pixel, the thesis's tone map).  What they measure with (bundled HDRIs, random pairs, relative
RMSE) is the tests' too and lives in tests/helpers/measure.py.

The scripts run as scripts (benchmarks/ first on sys.path) and import the tests' helpers as
tests.helpers: importing this module puts the checkout on sys.path, last, so that a wenv named by
PYTHONPATH (another build, a sanitized one) is still the one imported."""
import os
import platform
import statistics
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "out")
if ROOT not in sys.path:
    sys.path.append(ROOT)


def cpu():
    """The CPU's model name and its widest vector extension the hot loops dispatch on ("AMD EPYC,
    avx2"): timings differ by both, and wenv picks its loops by the second at run time."""
    name, flags = platform.processor() or platform.machine(), set()
    try:
        with open("/proc/cpuinfo") as fp:
            for line in fp:
                key, _, value = line.partition(":")
                if key.strip() == "model name":
                    name = value.strip()
                elif key.strip() == "flags":
                    flags = set(value.split())
                    break
    except OSError:
        pass
    widest = next((f for f in ("avx512f", "avx2") if f in flags), "baseline")
    return f"{name}, {widest}"


def sphere_image(size):
    """Normals of a unit sphere seen orthographically from -Y (looking along +Y), one per pixel
    inside the disk: (mask, normals, view) with the view pointing back at the camera."""
    t = (np.arange(size) + 0.5) / size * 2 - 1
    x, z = np.meshgrid(t, -t)
    r2 = x * x + z * z
    mask = r2 < 1
    n = np.stack([x[mask], -np.sqrt(1 - r2[mask]), z[mask]], axis=1).astype(np.float32)
    return mask, n, np.array([0.0, -1.0, 0.0], np.float32)


def tone_map(rgb, l_max):
    """The thesis's global logarithmic operator: Ld = log10(1 + Lw) / log10(1 + Lmax)."""
    lw = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    ld = np.log10(1 + lw) / np.log10(1 + l_max)
    scale = np.where(lw > 0, ld / np.maximum(lw, 1e-12), 0)
    return np.clip(rgb * scale[..., None], 0, 1)


def side_by_side(first, second, repeat):
    """Median times (seconds) of two calls made in turn, round by round, so that a busy spell of a
    shared machine falls on both."""
    times = ([], [])
    for _ in range(repeat):
        for fn, out in zip((first, second), times):
            start = time.perf_counter()
            fn()
            out.append(time.perf_counter() - start)
    return statistics.median(times[0]), statistics.median(times[1])


def gather_limit_data(vertices, terms=128, coefficients=128 * 128, run=64, seed=0):
    """Inputs of the gather limit: each vertex keeps `terms` of the lighting's `coefficients` Haar
    coefficients (u16 indices and a float weight each, the thesis's per-vertex transport vectors),
    coherent as a mesh's are: every run of `run` vertices in mesh order keeps the same terms, with
    weights of its own.  (index (vertices, terms), weight, lighting rgb (coefficients, 3))."""
    rng = np.random.default_rng(seed)
    groups = -(-vertices // run)
    kept = np.sort(np.stack([rng.choice(coefficients, terms, replace=False) for _ in range(groups)]), axis=1)
    index = np.ascontiguousarray(np.repeat(kept.astype(np.uint16), run, axis=0)[:vertices])
    weight = rng.standard_normal((vertices, terms)).astype(np.float32)
    return index, weight, rng.random((coefficients, 3), dtype=np.float32)


def gather_limit_ms(data):
    """One pass of the gather limit over `data` (gather_limit_data), in ms: every vertex's sparse dot
    product with the lighting, RGB, on wenv's threads (wenv._sparse_rows_dot).  A view of a mesh
    cannot cost less than reading each vertex's own coefficients once: the floor the shading's
    view change is measured against."""
    import wenv
    t0 = time.perf_counter()
    wenv._sparse_rows_dot(*data)
    return 1e3 * (time.perf_counter() - t0)
