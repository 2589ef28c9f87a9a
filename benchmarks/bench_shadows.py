"""Shadows on Suzanne: the occlusion's cost per mesh state, a view change with shadows against one
without (same shader, same preset, side by side), and the error against the ray-cast reference with
the same bounce, under Blender's bundled HDRIs.  Prints a table and writes out/bench_shadows.json.
Timing is not part of the test suite.

    python benchmarks/bench_shadows.py [--levels 4] [--resolution 8] [--repeat 5] [--sample 300]
"""
import argparse
import json
import os
import platform
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import wenv  # noqa: E402
from measure import side_by_side  # noqa: E402
from tests.conftest import HDRI_NAMES, hdri_path  # noqa: E402

MATERIALS = {
    "paint": dict(base_color=(0.6, 0.15, 0.08), roughness=0.3),
    "metal": dict(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.3),
    "gloss": dict(base_color=(0.1, 0.3, 0.6), roughness=0.1),
}


def suzanne(levels):
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_monkey_add()
    ob = bpy.context.object
    ob.modifiers.new("subdivision", "SUBSURF").levels = levels
    mesh = ob.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    mesh.calc_loop_triangles()
    p = np.empty(len(mesh.vertices) * 3, np.float32)
    n = np.empty_like(p)
    t = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.vertices.foreach_get("co", p)
    mesh.vertices.foreach_get("normal", n)
    mesh.loop_triangles.foreach_get("vertices", t)
    return p.reshape(-1, 3), n.reshape(-1, 3), t.reshape(-1, 3)


def moved_blocker(positions, normals, triangles, resolution):
    """A ball (radius 0.3, 1,106 vertices) beside Suzanne's cheek, then moved 0.4 up: her
    occlusion cast anew against the scene after, and made from the one before (only the vertices
    whose rays met the ball or meet it now cast again).  Medians of 3."""
    from tests.helpers.meshes import merged, uv_sphere
    ball, ball_faces = uv_sphere(24, 48, 0.3)
    scenes = [wenv.Occluders(*merged((positions, triangles), (ball + np.float32(at), ball_faces)))
              for at in ((1.1, -0.6, 0.0), (1.1, -0.6, 0.4))]
    before = scenes[0].occlusion(positions, normals, resolution=resolution)
    changed = (len(triangles), len(ball_faces))
    new_cast = median_time(lambda: scenes[1].occlusion(positions, normals, resolution=resolution), 3)
    refresh = median_time(lambda: scenes[1].occlusion(positions, normals, previous=before, changed=changed), 3)
    refreshed = scenes[1].occlusion(positions, normals, previous=before, changed=changed)
    return dict(new_cast_seconds=new_cast, refresh_seconds=refresh, cast_vertices=refreshed.cast_vertices)


def median_time(fn, repeat):
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, default=4, help="Suzanne's subdivision levels (4: 126,290 vertices)")
    ap.add_argument("--resolution", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sample", type=int, default=300, help="front-facing vertices the reference shades")
    ap.add_argument("--hdris", nargs="*", default=HDRI_NAMES)
    ap.add_argument("--out", default=os.path.join("out", "bench_shadows.json"))
    args = ap.parse_args()
    positions, normals, triangles = suzanne(args.levels)
    build = median_time(lambda: wenv.Occluders(positions, triangles), 3)
    occluders = wenv.Occluders(positions, triangles)
    made = []
    for _ in range(3):
        start = time.perf_counter()
        occlusion = occluders.occlusion(positions, normals, resolution=args.resolution)
        made.append(time.perf_counter() - start)
    print(f"{len(positions)} vertices, {len(triangles)} triangles, {wenv.get_num_threads()} threads: Embree scene "
          f"{build:.3f} s, occlusion {statistics.median(made):.3f} s at {args.resolution}x{args.resolution} "
          f"({occlusion.blocked_vertices} vertices blocked, {occlusion.nbytes / 2**20:.1f} MB)")
    moved = moved_blocker(positions, normals, triangles, args.resolution)
    print(f"a ball moved beside her cheek: a new cast {moved['new_cast_seconds']:.3f} s, from the one before "
          f"{moved['refresh_seconds']:.3f} s ({moved['cast_vertices']} of {len(positions)} vertices cast again)")
    eye = np.array([0.0, -4.0, 1.0], np.float32)
    views = (eye - positions) / np.linalg.norm(eye - positions, axis=1)[:, None]
    front = np.flatnonzero(np.einsum("ij,ij->i", normals, views) > 0)
    pick = np.sort(np.random.default_rng(1).choice(front, min(args.sample, len(front)), replace=False))
    rows = []
    print(f"{'HDRI':10s} {'material':8s} {'plain ms':>9s} {'shadowed ms':>12s} {'ratio':>6s} {'error':>7s} "
          f"{'unshadowed':>10s}")
    for hdri in args.hdris:
        env = wenv.load_environment(hdri_path(hdri))
        for name, inputs in MATERIALS.items():
            mat = wenv.Principled(**inputs)
            shader = wenv.Shader(env, mat, quality="default")
            plain = shader.shade(normals, views)
            shaded = shader.shade(normals, views, occlusion=occlusion)
            t_plain, t_shadow = side_by_side(lambda: shader.shade(normals, views),
                                             lambda: shader.shade(normals, views, occlusion=occlusion), args.repeat)
            light = shader.diffuse_light(normals, occlusion=occlusion)
            truth = wenv.reference(env, mat, normals[pick], views[pick], positions=positions[pick],
                                   occluders=occluders, bounce=light)

            def rel(a):
                return float(np.sqrt(np.mean((a[pick] - truth) ** 2)) / np.mean(truth))

            row = dict(hdri=hdri, material=name, plain_ms=1e3 * t_plain, shadowed_ms=1e3 * t_shadow,
                       ratio=t_shadow / t_plain, error=rel(shaded), unshadowed_error=rel(plain))
            rows.append(row)
            print(f"{hdri:10s} {name:8s} {row['plain_ms']:9.1f} {row['shadowed_ms']:12.1f} {row['ratio']:6.2f} "
                  f"{100 * row['error']:6.1f}% {100 * row['unshadowed_error']:9.1f}%")
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/bench_shadows.py " + " ".join(sys.argv[1:]),
                       machine=platform.machine(), threads=wenv.get_num_threads(), vertices=len(positions),
                       triangles=len(triangles), resolution=args.resolution, embree_seconds=build,
                       occlusion_seconds=statistics.median(made), occlusion_bytes=occlusion.nbytes,
                       moved_blocker=moved, rows=rows), f,
                  indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
