"""Benchmark of the shading engine (medians, 2 threads): Suzanne subdivided to about 31k and 126k
vertices under a bundled HDRI at `default` quality.  Prints the figures and writes
out/bench_shade.json.

    .venv/bin/python benchmarks/bench_shade.py [--repeats 9] [--largest]

--largest also builds the thesis's largest matrices (4096 global, 1024 local, 4096 normals) and
reports their time and cache size (minutes)."""
import argparse
import json
import math
import os
import statistics
import tempfile
import time

import numpy as np

import wenv
from measure import OUT
from tests.helpers.measure import bundled_hdri


def suzanne(levels):
    """Vertex positions and smooth normals of Suzanne under a Subdivision Surface modifier."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.active_object
    mod = obj.modifiers.new("subd", "SUBSURF")
    mod.levels = levels
    bpy.ops.object.shade_smooth()
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    n = len(mesh.vertices)
    pos = np.empty(n * 3, np.float32)
    nrm = np.empty(n * 3, np.float32)
    mesh.vertices.foreach_get("co", pos)
    mesh.vertex_normals.foreach_get("vector", nrm)
    return pos.reshape(n, 3), nrm.reshape(n, 3)


CPU_MS = {}
# The thesis's matrices: 4096 global and 1024 local texels, 1024 normals (`default` before it moved to
# high's local resolution through slicing); --largest takes 4096 normals.
ROTATION_64 = {"global": 64, "local": 32, "normals": 32, "views": 16, "coefficients": 128, "light_coefficients": 1024,
               "matrix_epsilon": 1e-3, "lights": 128, "light_threshold": 256, "light_tolerance": 0.003, "grazing": 0,
               "grazing_slopes": 0}


def median_ms(fn, repeats, key=None):
    """Median wall time; the median process CPU time (all threads) goes to CPU_MS[key], a figure
    that other jobs on a shared machine disturb far less than the wall time."""
    times, cpu = [], []
    for i in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn(i)
        times.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
    if key:
        CPU_MS[key] = statistics.median(cpu)
    return statistics.median(times)


def orbit_eye(i, radius=4.0):
    a = 0.35 * i
    return (radius * math.sin(a), -radius * math.cos(a), 1.0 + 0.3 * math.sin(2 * a))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--hdri", default="sunset")
    ap.add_argument("--largest", action="store_true")
    args = ap.parse_args()
    wenv.set_num_threads(2)
    env = wenv.load_environment(bundled_hdri(args.hdri))
    material = wenv.CookTorrance(diffuse=(0.2, 0.2, 0.2), lobes=[{"specular": (1, 1, 1), "alpha": 0.2, "ior": 1.5}])
    results = {"threads": wenv.get_num_threads(), "hdri": args.hdri, "quality": wenv.QUALITY_PRESETS["default"]}

    t0 = time.perf_counter()
    wenv.Shader(env, material, quality=ROTATION_64, method="rotation", cache_dir=False)
    results["precompute_64_32_32_s"] = time.perf_counter() - t0
    print(f"matrices 64x64 global, 32x32 local, 32x32 normals (no cache): {results['precompute_64_32_32_s']:.2f} s")

    shader = wenv.Shader(env, material, quality="default")
    for levels in (3, 4):
        pos, nrm = suzanne(levels)
        key = f"suzanne_{len(pos) // 1000}k"
        shader.set_environment(env)  # leaves every entry but the latest view's stale
        for i in range(args.repeats):  # an orbit seen once: its table entries are made
            shader.shade_mesh(pos, nrm, orbit_eye(i))
        view = median_ms(lambda i: shader.shade_mesh(pos, nrm, orbit_eye(i)), args.repeats, "view")
        # views never seen: table entries made on the way (the first minutes of an orbit)
        new_view = median_ms(lambda i: shader.shade_mesh(pos, nrm, orbit_eye(0.5 + 40 * levels + i)),
                             args.repeats, "new_view")
        def lighting(i):
            shader.set_environment(env.with_transform(rotation=0.1 * (i + 1), strength=1.0))
            shader.shade_mesh(pos, nrm, orbit_eye(0))

        light = median_ms(lighting, args.repeats, "light")
        shader.set_environment(env)
        results[key] = {"vertices": len(pos), "view_change_ms": view, "new_view_ms": new_view,
                        "new_view_cpu_ms": CPU_MS["new_view"],
                        "lighting_change_ms": light, "view_change_cpu_ms": CPU_MS["view"],
                        "lighting_change_cpu_ms": CPU_MS["light"]}
        print(f"{key}: {len(pos)} vertices  view change {view:.1f} ms (median of {args.repeats}; "
              f"CPU {CPU_MS['view']:.1f} ms), new view {new_view:.1f} ms (CPU {CPU_MS['new_view']:.1f} ms), "
              f"lighting change {light:.1f} ms (CPU {CPU_MS['light']:.1f} ms)")

    if args.largest:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            big = wenv.Shader(env, material, quality=dict(ROTATION_64, normals=64), method="rotation", cache_dir=tmp,
                              memory_budget_mb=4096)
            secs = time.perf_counter() - t0
            size = sum(os.path.getsize(os.path.join(tmp, f)) for f in os.listdir(tmp))
            results["largest"] = {"seconds": secs, "cache_mb": size / 2**20, "nnz": big.stats["rotation_nnz"]}
            print(f"largest (4096 global, 1024 local, 4096 normals): {secs:.1f} s, cache {size / 2**20:.0f} MB")

    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "bench_shade.json"), "w") as fp:
        json.dump(results, fp, indent=2)
    print("wrote out/bench_shade.json")


if __name__ == "__main__":
    main()
