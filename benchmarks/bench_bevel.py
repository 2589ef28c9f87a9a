"""The Bevel node's cost (addon/bevel.py, wenv.Occluders.bevel): Suzanne subdivided 3 times (31,658
vertices, smooth, a Smart UV map) at three radii, 1.6, 4 and 8 times her triangles' median size, and
a cube of 2 m (flat, its 12 triangles the hard-surface case) at 0.05 m: the vertices, a bake's
texels (--size squared) reading their triangles' corners where the normal turns linearly, and the
same texels each its own integral; with how far apart those two are.  2 threads, the median of
--repeat calls.  Prints a table and writes out/bench_bevel.json.  Timing is not part of the test
suite.

    python benchmarks/bench_bevel.py [--size 1024] [--repeat 3]
"""
import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402

from addon import bake, bevel, meshes, textures  # noqa: E402
from measure import OUT, cpu  # noqa: E402


def unwrapped(obj):
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.uv.smart_project(island_margin=0.002)
    bpy.ops.object.mode_set(mode="OBJECT")
    return obj


def suzanne():
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.object
    obj.modifiers.new("subdivided", "SUBSURF").levels = 3
    bpy.ops.object.modifier_apply(modifier="subdivided")
    obj.data.shade_smooth()
    return unwrapped(obj)


def cube():
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(4.0, 0.0, 0.0))
    return unwrapped(bpy.context.object)


def median_seconds(call, repeat):
    times = []
    for _ in range(repeat):
        bevel._normals.clear()
        start = time.perf_counter()
        got = call()
        times.append(time.perf_counter() - start)
    return statistics.median(times), got


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    rows = []
    for make, radii in ((suzanne, (0.02, 0.05, 0.1)), (cube, (0.05,))):
        obj = make()
        depsgraph = bpy.context.evaluated_depsgraph_get()
        mesh = obj.data
        corner_vert = meshes.corner_vertices(mesh)
        data = meshes.read_mesh(obj, depsgraph)
        sites, _ = bake.texel_sites(textures.corner_uvs(mesh, mesh.uv_layers.active), textures.triangle_corners(mesh),
                                    args.size, args.size, 4096)
        co = textures.world_points(mesh, obj.matrix_world)[corner_vert]
        normals = np.empty(len(mesh.loops) * 3, np.float32)
        mesh.corner_normals.foreach_get("vector", normals)
        points, own = sites.at(co.astype(np.float32)), sites.at(normals.reshape(-1, 3))
        for radius in radii:
            at_vertices, _ = median_seconds(
                lambda: bevel.normals(obj, depsgraph, data.positions, data.normals, radius), args.repeat)
            linear, got = median_seconds(
                lambda: bevel.normals(obj, depsgraph, points, own, radius, sites=sites), args.repeat)
            each, direct = median_seconds(lambda: bevel.normals(obj, depsgraph, points, own, radius), args.repeat)
            apart = np.degrees(np.arccos(np.clip((got * direct).sum(axis=1), -1.0, 1.0)))
            rows.append({"mesh": obj.name, "vertices": len(mesh.vertices), "triangles": len(mesh.loop_triangles),
                         "radius": radius, "rows": data.count, "vertices_s": at_vertices, "texels": sites.count,
                         "texels_s": linear, "each_texel_s": each, "apart_p99_degrees": float(np.percentile(apart, 99)),
                         "apart_max_degrees": float(apart.max())})
            r = rows[-1]
            print(f"{r['mesh']:8s} radius {radius:<5}: {r['rows']:6d} rows {at_vertices:6.2f} s; {r['texels']} texels "
                  f"{linear:6.2f} s, each its own {each:6.2f} s ({each / r['texels'] * 1e6:.1f} us a texel); "
                  f"apart p99 {r['apart_p99_degrees']:.2f}, max {r['apart_max_degrees']:.2f} degrees")
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "bench_bevel.json"), "w") as f:
        json.dump({"cpu": cpu(), "threads": 2, "size": args.size, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
