"""A colour per vertex (Shader.shade(..., base_color=)): a view change with a colour per vertex
against one with the material's own, same shader and preset, side by side, per method, on a sphere
of 125,502 vertices under forest, 2 threads.  Prints a table and writes out/bench_vertex_colour.json.
Timing is not part of the test suite.

    python benchmarks/bench_vertex_colour.py [--repeat 7] [--hdri forest]
"""
import argparse
import json
import os
import platform
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import wenv  # noqa: E402
from measure import side_by_side  # noqa: E402
from tests.conftest import hdri_path  # noqa: E402
from tests.helpers.meshes import uv_sphere  # noqa: E402

# (method, quality): the wavelet methods at `default` (slicing: rotation's matrices at `default`
# exceed the 1 GB budget here), the peers at theirs
SETTINGS = (("slicing", "default"), ("split_sum", "default"), ("sh", "default"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--hdri", default="forest")
    ap.add_argument("--out", default=os.path.join("out", "bench_vertex_colour.json"))
    args = ap.parse_args()
    v, _ = uv_sphere(252, 500)
    eye = np.float32([0.0, -4.2, 0.0])
    views = ((eye - v) / np.linalg.norm(eye - v, axis=1)[:, None]).astype(np.float32)
    colours = np.random.default_rng(0).uniform(0.0, 1.0, (len(v), 3)).astype(np.float32)
    env = wenv.load_environment(hdri_path(args.hdri))
    material = wenv.Principled(base_color=(0.6, 0.15, 0.08), roughness=0.3)
    rows = []
    print(f"{len(v)} vertices, {wenv.get_num_threads()} threads, {args.hdri}, Principled paint")
    print(f"{'method':10s} {'quality':8s} {'own ms':>8s} {'per vertex ms':>14s} {'ratio':>6s}")
    for method, quality in SETTINGS:
        shader = wenv.Shader(env, material, quality=quality, method=method)
        shader.shade(v, views)
        shader.shade(v, views, base_color=colours)
        own, per_vertex = side_by_side(lambda: shader.shade(v, views),
                                       lambda: shader.shade(v, views, base_color=colours), args.repeat)
        row = dict(method=method, quality=quality, own_ms=1e3 * own, per_vertex_ms=1e3 * per_vertex)
        row["ratio"] = row["per_vertex_ms"] / row["own_ms"]
        rows.append(row)
        print(f"{method:10s} {quality:8s} {row['own_ms']:8.1f} {row['per_vertex_ms']:14.1f} {row['ratio']:6.2f}")
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/bench_vertex_colour.py " + " ".join(sys.argv[1:]),
                       machine=platform.machine(), threads=wenv.get_num_threads(), vertices=len(v), hdri=args.hdri,
                       rows=rows), f, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
