"""Interactive rates: the time a view change costs on a sphere of about 126k vertices under each of
the eight bundled HDRIs, 2 threads, one-lobe Cook-Torrance (and Lambert), for the presets, with the
viewport's culling (cull=True: back faces cost nothing) and without.  Medians over an orbit of views
seen once before (every table row made), side by side in one run.  Then what a lighting change
costs on the same sphere: a new World rotation (the held image turned: methods/lighting_frame.h)
and a new image (everything made from the lighting remade), each shaded once.  Prints the figures
and writes out/bench_interactive.json; the accuracy of the same settings is benchmarks/accuracy.py's.

    .venv/bin/python benchmarks/bench_interactive.py [--repeats 3] [--presets high,default] [--hdris all]
"""
import argparse
import json
import math
import os
import statistics
import time

import numpy as np

import wenv
from measure import OUT
from tests.helpers.measure import bundled_hdri
from accuracy import HDRIS

MATERIALS = {
    "lambert": lambda: wenv.Lambert((0.8, 0.8, 0.8)),
    "m0.1": lambda: wenv.CookTorrance(diffuse=0.0, lobes=[{"specular": 1.0, "alpha": 0.1, "ior": 1.5}]),
    "m0.2": lambda: wenv.CookTorrance(diffuse=0.0, lobes=[{"specular": 1.0, "alpha": 0.2, "ior": 1.5}]),
}
METHOD = {"draft": "rotation", "default": "slicing", "high": "slicing"}
ORBIT = 8


def uv_sphere(n_lat=251, n_lon=502):
    """Unit sphere of n_lat x n_lon vertices (126,002 by default): positions equal normals."""
    t = (np.arange(n_lat) + 0.5) / n_lat * math.pi
    p = np.arange(n_lon) / n_lon * 2 * math.pi
    tt, pp = np.meshgrid(t, p, indexing="ij")
    pos = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1).reshape(-1, 3)
    return pos.astype(np.float32)


def eye(i, radius=4.0):
    a = 2 * math.pi * i / ORBIT + 0.3
    return (radius * math.cos(a), radius * math.sin(a), 0.8 * math.sin(1.7 * a))


def view_changes(shader, pos, cull, repeats):
    """Median wall time (ms) of a view change, after one pass over the orbit."""
    for i in range(ORBIT):
        shader.shade_mesh(pos, pos, eye(i), cull=cull)
    times = []
    for _ in range(repeats):
        for i in range(ORBIT):
            t0 = time.perf_counter()
            shader.shade_mesh(pos, pos, eye(i), cull=cull)
            times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def lighting_changes(shader, env, other, pos, repeats):
    """Median wall time (ms) of a new World rotation -- at angles not seen before (a first sweep of
    the slider: normals turned onto normal samples whose table rows are not made yet) and at angles
    seen before -- and of a new image, each shaded once from the same eye."""
    shader.shade_mesh(pos, pos, eye(0), cull=True)
    worlds = [env.with_transform(rotation=0.35 * (k + 1)) for k in range(2 * repeats + 1)]
    first, again, images = [], [], []
    for times in (first, again):
        for world in worlds:
            t0 = time.perf_counter()
            shader.set_environment(world)
            shader.shade_mesh(pos, pos, eye(0), cull=True)
            times.append((time.perf_counter() - t0) * 1e3)
    for k in range(repeats):
        for image in (other, env):
            t0 = time.perf_counter()
            shader.set_environment(image)
            shader.shade_mesh(pos, pos, eye(0), cull=True)
            images.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(first), statistics.median(again), statistics.median(images)


def refinement(hdri, material, pos, step=0.05):
    """The live mode's refinement on the sphere: `default` shown, then `high` in steps of `step`
    seconds, after a view change (high's table rows already made for these normals), a new World
    rotation (the same, turned) and a new image (its lighting slices remade as the steps need them).
    The fraction of the visible vertices refined after 0.1, 0.5 and 2 s of rest, and the time to
    refine them all."""
    env = wenv.load_environment(bundled_hdri(hdri))
    other = wenv.load_environment(bundled_hdri("city" if hdri != "city" else "night"))
    mat = MATERIALS[material]()
    accurate = wenv.Shader(env, mat, quality="high", method="slicing")
    accurate.shade_mesh(pos, pos, eye(0), cull=True)  # an earlier rest refined this view
    out = {}
    for case, change in (("view change", lambda: None),
                         ("World rotation", lambda: accurate.set_environment(env.with_transform(rotation=0.7))),
                         ("new image", lambda: accurate.set_environment(other))):
        change()
        rgb = np.zeros((len(pos), 3), np.float32)
        t0, first, marks = time.perf_counter(), 0, {}
        while True:
            accurate.shade_mesh(pos, pos, eye(3), cull=True, out=rgb, first=first, budget=step)
            first, total = accurate.stats["next_vertex"], accurate.stats["visible_vertices"]
            t = time.perf_counter() - t0
            for mark in (0.1, 0.5, 2.0):
                if t <= mark:
                    marks[mark] = first / total
            if first >= total:
                break
        out[case] = {"after_0.1s": marks.get(0.1, 0.0), "after_0.5s": marks.get(0.5, 0.0),
                     "after_2s": marks.get(2.0, 0.0), "all_s": t, "visible": total}
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=3, help="orbits timed per setting (8 views each)")
    ap.add_argument("--presets", default="high,default")
    ap.add_argument("--hdris", default="all", help="comma-separated, or all")
    args = ap.parse_args()
    wenv.set_num_threads(2)
    pos = uv_sphere()
    hdris = HDRIS if args.hdris == "all" else args.hdris.split(",")
    results = {"vertices": len(pos), "threads": 2, "views_per_orbit": ORBIT, "settings": []}
    print(f"{len(pos)} vertices, 2 threads, median view change over {args.repeats} orbits of {ORBIT} views (ms)")
    for preset in args.presets.split(","):
        for hdri in hdris:
            env = wenv.load_environment(bundled_hdri(hdri))
            row = f"{preset:8s} {hdri:10s}"
            for name, make in MATERIALS.items():
                shader = wenv.Shader(env, make(), quality=preset, method=METHOD[preset])
                culled = view_changes(shader, pos, True, args.repeats)
                visible = shader.stats["visible_vertices"]
                entry = {"preset": preset, "hdri": hdri, "material": name, "culled_ms": culled,
                         "visible_vertices": visible}
                if hdri == hdris[0]:  # shading every vertex, as for a render or a bake
                    entry["all_ms"] = view_changes(shader, pos, False, args.repeats)
                results["settings"].append(entry)
                row += f"  {name} {culled:7.1f}" + (f" (all {entry['all_ms']:.1f})" if "all_ms" in entry else "")
            print(row, flush=True)
    for preset in args.presets.split(","):
        mine = [e["culled_ms"] for e in results["settings"] if e["preset"] == preset]
        print(f"{preset}: worst {max(mine):.1f} ms, median {statistics.median(mine):.1f} ms over "
              f"{len(hdris)} HDRIs x {len(MATERIALS)} materials")
    results["lighting_changes"] = []
    print("lighting changes, median ms: a World rotation at new angles / at angles seen before / a new image "
          "(the next HDRI and back)")
    for preset in args.presets.split(","):
        for i, hdri in enumerate(hdris):
            env = wenv.load_environment(bundled_hdri(hdri))
            other = wenv.load_environment(bundled_hdri(hdris[(i + 1) % len(hdris)]))
            row = f"{preset:8s} {hdri:10s}"
            for name, make in MATERIALS.items():
                shader = wenv.Shader(env, make(), quality=preset, method=METHOD[preset])
                turn, again, image = lighting_changes(shader, env, other, pos, 1 if preset == "high" else args.repeats)
                results["lighting_changes"].append({"preset": preset, "hdri": hdri, "material": name,
                                                    "rotation_new_angle_ms": turn, "rotation_seen_angle_ms": again,
                                                    "new_image_ms": image})
                row += f"  {name} {turn:5.1f} / {again:5.1f} / {image:4.0f}"
            print(row, flush=True)
        mine = [e for e in results["lighting_changes"] if e["preset"] == preset]
        print(f"{preset}: World rotation worst {max(e['rotation_new_angle_ms'] for e in mine):.1f} ms at new angles, "
              f"{max(e['rotation_seen_angle_ms'] for e in mine):.1f} ms at angles seen before; new image worst "
              f"{max(e['new_image_ms'] for e in mine):.0f} ms, median {statistics.median(e['new_image_ms'] for e in mine):.0f} ms")
    results["refinement"] = {}
    for hdri, material in (("forest", "m0.1"), ("studio", "m0.2")):
        r = refinement(hdri, material, pos)
        results["refinement"][f"{hdri}/{material}"] = r
        for case, f in r.items():
            print(f"refining to high, {hdri} {material}, after {case}: {100 * f['after_0.1s']:.0f} % of "
                  f"{f['visible']} vertices after 0.1 s, {100 * f['after_0.5s']:.0f} % after 0.5 s, "
                  f"{100 * f['after_2s']:.0f} % after 2 s, all after {f['all_s']:.2f} s", flush=True)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "bench_interactive.json"), "w") as fp:
        json.dump(results, fp, indent=1)


if __name__ == "__main__":
    main()
