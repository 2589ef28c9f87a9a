"""Peak memory of one shading setting, measured in a fresh process so that nothing earlier in the
caller (other shaders, freed buffers the allocator kept) hides or inflates it.

The child loads a bundled HDRI, the material and the mesh (handed over as .npy files, so it does not
import bpy), then takes its baseline: resident memory after a garbage collection and malloc_trim,
with the kernel's peak-RSS mark reset to it (/proc/self/clear_refs).  It then builds
wenv.Shader(env, material, quality, method) and shades the mesh for one view (or `views` views
along an orbit: rotation and slicing fill their tables as new views and normals are seen).

Reported, in MB: peak_mb (the child's whole peak, baseline included), baseline_mb, increment_mb (the
peak during the build and shade over the baseline: the setting's cost, build-time temporaries
included), held_mb (what is still resident after the shade, over the baseline, once the allocator
has returned its free pages) and model_mb (the shader's own accounting: the sum of the *_bytes
entries of shader.stats, which held_mb should match up to the output and small buffers).  Rotation
matrices come from the usual cache folder unless cache_dir says otherwise; `cache` says whether
they were loaded, built or not used.

Linux only (reads /proc/self/status).  Without /proc/self/clear_refs the increment is the growth of
the process's peak, which understates a setting whose memory fits under the peak the set-up already
reached (`exact` False)."""
import ctypes
import gc
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

MB = 2.0 ** 20


def sphere_mesh(n):
    """n points of a Fibonacci lattice on the unit sphere with their normals, float32: a stand-in
    for Suzanne that needs no bpy."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    a = np.pi * (3 - np.sqrt(5)) * i
    pos = np.stack([r * np.cos(a), r * np.sin(a), z], axis=1).astype(np.float32)
    return pos, pos.copy()


# The material measured unless told otherwise: a specular Cook-Torrance lobe, m = 0.2 (the "m0.2" of
# benchmarks/accuracy.py's MATERIALS).
GLOSSY = {"diffuse": [0.0, 0.0, 0.0], "lobes": [{"specular": [1.0, 1.0, 1.0], "alpha": 0.2, "ior": 1.5}]}


def peak_memory(method, quality, positions, normals, hdri="sunset", material=GLOSSY,
                eye=(0.0, -4.0, 1.0), views=1, cache_dir=None, threads=2, timeout=1800):
    """Memory of one setting (see the module's docstring): a dict with peak_mb, baseline_mb,
    increment_mb, held_mb, model_mb, stats, cache, vertices and exact.  The first view is seen
    from eye, the others from eye turned about +Z by 20 degrees each.  material: {"diffuse": rgb,
    "lobes": [...]} as benchmarks/accuracy.py's MATERIALS (wenv.CookTorrance's keywords; a
    wenv.Lambert when lobes is empty).  cache_dir as wenv.Shader's: None for the usual folder, False
    for none, or a folder."""
    import wenv

    wenv_dir = os.path.dirname(os.path.abspath(wenv.__file__))
    with tempfile.TemporaryDirectory() as tmp:
        np.save(os.path.join(tmp, "positions.npy"), np.ascontiguousarray(positions, np.float32))
        np.save(os.path.join(tmp, "normals.npy"), np.ascontiguousarray(normals, np.float32))
        spec = {"method": method, "quality": quality, "hdri": hdri, "material": material,
                "eye": [float(c) for c in eye], "views": views, "cache_dir": cache_dir, "threads": threads,
                "folder": tmp}
        # The child imports the same wenv as this process, whichever build that is.
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [wenv_dir, os.environ.get("PYTHONPATH")])))
        proc = subprocess.run([sys.executable, os.path.abspath(__file__), json.dumps(spec)], env=env,
                              capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"memory measurement of {method} {quality} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _status_mb():
    """Current and peak resident memory of this process (VmRSS, VmHWM), MB."""
    got = {}
    with open("/proc/self/status") as fp:
        for line in fp:
            key = line.split(":")[0]
            if key in ("VmRSS", "VmHWM"):
                got[key] = int(line.split()[1]) / 1024
    return got["VmRSS"], got["VmHWM"]


def _reset_peak():
    """Sets the peak-RSS mark to the current RSS; False where the kernel does not offer it."""
    try:
        with open("/proc/self/clear_refs", "w") as fp:
            fp.write("5")
    except OSError:
        return False
    rss, hwm = _status_mb()
    return hwm <= rss + 1.0


def _release_free_memory():
    """Returns the pages glibc's allocator keeps after frees (a no-op elsewhere)."""
    gc.collect()
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _child(spec):
    # Run as a script, so tests/helpers/ is sys.path[0] and its measure.py imports by plain name.
    import wenv
    from measure import bundled_hdri

    wenv.set_num_threads(spec["threads"])
    env = wenv.load_environment(bundled_hdri(spec["hdri"]))
    m = spec["material"]
    if m["lobes"]:
        mat = wenv.CookTorrance(diffuse=tuple(m["diffuse"]), lobes=m["lobes"])
    else:
        mat = wenv.Lambert(tuple(m["diffuse"]))
    pos = np.load(os.path.join(spec["folder"], "positions.npy"))
    nrm = np.load(os.path.join(spec["folder"], "normals.npy"))
    # Freed memory the allocator still holds would be reused by the shader unseen: give it back.
    _release_free_memory()
    whole_peak_before = _status_mb()[1]
    exact = _reset_peak()
    baseline = _status_mb()[0]

    kwargs = {} if spec["cache_dir"] is None else {"cache_dir": spec["cache_dir"]}
    if spec["method"] == "rotation":
        kwargs["memory_budget_mb"] = 4096  # rotation at 64/32/64 holds 2.1 GB of matrices
    shader = wenv.Shader(env, mat, quality=spec["quality"], method=spec["method"], **kwargs)
    x, y, z = spec["eye"]
    for a in np.radians(20.0) * np.arange(spec["views"]):
        shader.shade_mesh(pos, nrm, (x * np.cos(a) - y * np.sin(a), x * np.sin(a) + y * np.cos(a), z))
    peak = _status_mb()[1]
    _release_free_memory()
    rss = _status_mb()[0]
    increment = peak - baseline if exact else max(peak - whole_peak_before, 0.0)
    stats = shader.stats
    model = sum(v for k, v in stats.items() if k.endswith("_bytes"))
    print(json.dumps({
        "method": spec["method"], "quality": shader.quality, "vertices": len(pos),
        "peak_mb": max(whole_peak_before, peak), "baseline_mb": baseline,
        "increment_mb": increment,
        "held_mb": rss - baseline, "model_mb": model / MB, "cache": stats.get("cache", "none"),
        "stats": stats, "exact": exact}))


if __name__ == "__main__":
    _child(json.loads(sys.argv[1]))
