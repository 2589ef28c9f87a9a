"""How a view change's cost grows with the mesh: UV spheres of about 8k, 31k, 126k and 500k
vertices (mesh order, positions equal normals), the camera 4.2 units from the centre, every vertex
shaded (no culling), 2 threads, `default`, each material under forest and studio.  Two kinds of view
change, each the median of --repeat after untimed warm-up views, the sizes interleaved round by round
so that the machine's drift falls on all of them alike:
- **seen**: views of an orbit of 8 shaded once before, what orbiting back and forth costs: the
  normal samples' lighting slices and table rows exist, so this is the per-vertex work;
- **new**: views further along the orbit each time, turning parts of the sphere never seen into view:
  their normal samples' slices and rows are made on the way.  Every sphere has the same normals,
  so that work is the same at every size and shows as a fixed cost (it is the normals', not the
  view's: a mesh with fewer distinct normals makes fewer).

Prints, per material, HDRI and kind, the time per view and per vertex, the ratio of the time per
vertex at 500k to that at 126k (the target: at most 1.3), and the fixed per-view cost: the intercept
of a least-squares line through (vertices, time) over the four sizes, and the measured time of a
100-vertex sphere (the target: at most 1 ms).  Writes out/view_scaling.json.

    python benchmarks/view_scaling.py [--hdris forest studio] [--repeat 7]
"""
import argparse
import json
import math
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))
import wenv  # noqa: E402

from conftest import hdri_path  # noqa: E402
from bench_interactive import uv_sphere  # noqa: E402

# rings x segments: 7,938, 31,752, 126,002 and 501,264 vertices, and a 100-vertex mesh
SIZES = {"8k": (63, 126), "31k": (126, 252), "126k": (251, 502), "500k": (501, 1001)}
TINY = (10, 10)
MATERIALS = {
    "Lambert": lambda: wenv.Lambert((0.8, 0.8, 0.8)),
    "Beckmann m=0.2": lambda: wenv.CookTorrance(lobes=[{"specular": 1.0, "alpha": 0.2, "ior": 1.5}],
                                                distribution="beckmann"),
    "Principled paint": lambda: wenv.Principled(base_color=(0.6, 0.15, 0.08), roughness=0.3),
}


def eye(a, radius=4.2):
    return (radius * math.cos(a), radius * math.sin(a), 0.8 * math.sin(1.7 * a))


def seen_eye(i):
    """View i of an orbit of 8, shaded before."""
    return eye(2 * math.pi * (i % 8) / 8 + 0.3)


def new_eye(i):
    """A view not seen before: 0.37 radians further along each time."""
    return eye(2 * math.pi + 0.3 + 0.37 * (i + 1))


def measure(shaders, meshes, eyes, repeat):
    times = {name: [] for name in meshes}
    for i in range(repeat):
        for name, pos in meshes.items():
            t0 = time.perf_counter()
            shaders[name].shade_mesh(pos, pos, eyes(i))
            times[name].append(time.perf_counter() - t0)
    return {name: 1e3 * float(np.median(t)) for name, t in times.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hdris", nargs="+", default=["forest", "studio"])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    meshes = {name: uv_sphere(*shape) for name, shape in SIZES.items()}
    meshes["tiny"] = uv_sphere(*TINY)
    results = []
    for hdri in args.hdris:
        env = wenv.load_environment(hdri_path(hdri))
        for label, make in MATERIALS.items():
            shaders = {name: wenv.Shader(env, make(), quality="default") for name in meshes}
            for name, pos in meshes.items():  # the orbit's views, once
                for i in range(8):
                    shaders[name].shade_mesh(pos, pos, seen_eye(i))
            n = {name: len(pos) for name, pos in meshes.items()}
            sizes = list(SIZES)
            for kind, eyes in (("seen", seen_eye), ("new", new_eye)):
                ms = measure(shaders, meshes, eyes, args.repeat)
                slope, intercept = np.polyfit([n[s] for s in sizes], [ms[s] for s in sizes], 1)
                per_vertex = {s: 1e6 * ms[s] / n[s] for s in sizes}  # ns
                row = {"hdri": hdri, "material": label, "views": kind, "vertices": n, "ms": ms,
                       "ns_per_vertex": per_vertex, "ratio_500k_126k": per_vertex["500k"] / per_vertex["126k"],
                       "fixed_ms_fit": float(intercept), "tiny_ms": ms["tiny"]}
                results.append(row)
                print(f"{hdri:8s} {label:17s} {kind:4s} "
                      + "  ".join(f"{s} {ms[s]:6.2f} ms ({per_vertex[s]:4.0f} ns)" for s in sizes)
                      + f" | 500k/126k {row['ratio_500k_126k']:.2f}  fixed (fit) {intercept:+.2f} ms"
                      + f"  {n['tiny']} vertices {ms['tiny']:.3f} ms", flush=True)
    out = os.path.join(ROOT, "out")
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "view_scaling.json"), "w") as fp:
        json.dump({"machine": platform.processor() or platform.machine(), "threads": wenv._work_threads(),
                   "results": results}, fp, indent=2)


if __name__ == "__main__":
    main()
