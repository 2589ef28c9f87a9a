"""Where a view change's time goes at `default`: per class of vertex (facing the eye, oblique, near
grazing, back-facing), and per part of the method (the exact lights, the grazing path), per material
and HDRI.  The set-up is the speed target's: a UV sphere of 126,002 vertices, the camera 4.2 units
away, every vertex shaded, 2 threads.

A class's time is a shade_mesh of its vertices alone, per vertex; a part's share is the time it
saves when turned off (`lights` 0: the suns and bright features left in the wavelet maps; `grazing`
0: no grazing path), measured in the same run.  Medians of --repeat calls after one to warm the
tables.  Writes out/speed_breakdown.json.

    python benchmarks/speed_breakdown.py [--hdris forest studio] [--repeat 5]

benchmarks/compare_builds.py runs it against two builds side by side (`--benchmarks speed_breakdown`).
"""
import argparse
import json
import os
import platform
import sys
import time

import numpy as np

from measure import OUT, cpu  # puts the checkout on sys.path, after a build that PYTHONPATH names
import wenv
from tests.conftest import hdri_path

EYE = (0.0, -4.2, 0.0)
MATERIALS = {
    "Lambert": lambda: wenv.Lambert((0.8, 0.8, 0.8)),
    "Beckmann m=0.2": lambda: wenv.CookTorrance(lobes=[{"specular": 1.0, "alpha": 0.2, "ior": 1.5}],
                                                distribution="beckmann"),
    "Principled paint": lambda: wenv.Principled(base_color=(0.6, 0.15, 0.08), roughness=0.3),
    "Principled metal": lambda: wenv.Principled(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.3),
}
# cos of the angle between normal and view
CLASSES = {"facing (cos > 0.5)": (0.5, 1.01), "oblique (0.2-0.5)": (0.2, 0.5), "near grazing (0-0.2)": (0.0, 0.2),
           "back-facing": (-1.01, 0.0)}


def sphere(rings=251, segments=502):
    th = np.linspace(0, np.pi, rings + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    n = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    return np.vstack([n, [[0, 0, 1], [0, 0, -1]]]).astype(np.float32)


def median_time(shader, positions, normals, repeat):
    shader.shade_mesh(positions, normals, EYE)
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        shader.shade_mesh(positions, normals, EYE)
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hdris", nargs="*", default=["forest", "studio"])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", default=os.path.join(OUT, "speed_breakdown.json"))
    args = ap.parse_args()
    wenv.set_num_threads(2)
    normals = sphere()
    view = np.asarray(EYE, np.float32) - normals
    cos_v = np.einsum("ij,ij->i", view / np.linalg.norm(view, axis=1, keepdims=True), normals)
    default = dict(wenv.QUALITY_PRESETS["default"])
    variants = {"default": default, "no exact lights": dict(default, lights=0),
                "no grazing path": dict(default, grazing=0.0)}
    rows = []
    print(f"{len(normals)} vertices: " + ", ".join(f"{k} {int(((cos_v > lo) & (cos_v <= hi)).sum())}"
                                                     for k, (lo, hi) in CLASSES.items()))
    for hdri in args.hdris:
        env = wenv.load_environment(hdri_path(hdri))
        for name, make in MATERIALS.items():
            row = dict(hdri=hdri, material=name)
            shaders = {k: wenv.Shader(env, make(), quality=q) for k, q in variants.items()}
            for k, shader in shaders.items():
                row[k] = median_time(shader, normals, normals, args.repeat)
            for k, (lo, hi) in CLASSES.items():
                sel = (cos_v > lo) & (cos_v <= hi)
                t = median_time(shaders["default"], np.ascontiguousarray(normals[sel]),
                                np.ascontiguousarray(normals[sel]), args.repeat)
                row[k] = dict(vertices=int(sel.sum()), seconds=t, ns_per_vertex=1e9 * t / max(int(sel.sum()), 1))
            rows.append(row)
            print(f"{hdri:8s} {name:18s} default {1e3 * row['default']:6.1f} ms | lights "
                  f"{1e3 * (row['default'] - row['no exact lights']):6.1f} ms | grazing path "
                  f"{1e3 * (row['default'] - row['no grazing path']):6.1f} ms | per vertex: "
                  + ", ".join(f"{k.split(' (')[0]} {row[k]['ns_per_vertex']:.0f} ns" for k in CLASSES), flush=True)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/speed_breakdown.py " + " ".join(sys.argv[1:]),
                       machine=platform.machine(), cpu=cpu(), vertices=len(normals), rows=rows), f, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
