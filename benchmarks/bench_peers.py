"""Accuracy and speed of the peer methods (split-sum, spherical harmonics) next to wavelet rotation,
side by side in one run: relative RMSE against wenv.reference on random (normal, view) pairs under a
bundled HDRI for Cook-Torrance lobes of several roughnesses, the precomputation time, and the median
shade_mesh time on Suzanne subdivided to ~126k vertices (2 threads).  Prints a table and writes
out/bench_peers.json.

    .venv/bin/python benchmarks/bench_peers.py [--pairs 500] [--repeats 3] [--hdri sunset]

The reference costs ~80 ns per pixel per pair (~40 ms per pair on a 1024 x 512 HDRI): 500 pairs at
three roughnesses take about a minute."""
import argparse
import json
import os
import statistics
import time

import numpy as np

import wenv
from bench_shade import orbit_eye, suzanne
from measure import OUT
from tests.helpers.measure import bundled_hdri, random_pairs, relative_rmse

CONFIGS = [
    ("rotation", "draft"), ("slicing", "default"),
    ("split_sum", "draft"), ("split_sum", "default"), ("split_sum", "high"),
    ("sh", {"order": 2}), ("sh", "draft"), ("sh", "default"), ("sh", "high"),
]


def label(method, quality):
    return f"{method} {quality if isinstance(quality, str) else ','.join(f'{k}={v}' for k, v in quality.items())}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--hdri", default="sunset")
    ap.add_argument("--roughness", type=float, nargs="+", default=[0.05, 0.2, 0.5])
    args = ap.parse_args()
    wenv.set_num_threads(2)
    env = wenv.load_environment(bundled_hdri(args.hdri))
    nrm, v = random_pairs(args.pairs, 7)
    pos, mesh_nrm = suzanne(4)
    results = {"hdri": args.hdri, "pairs": args.pairs, "vertices": len(pos), "threads": wenv.get_num_threads(),
               "rows": []}
    print(f"{args.hdri}, {args.pairs} random pairs, Suzanne {len(pos)} vertices, {results['threads']} threads")
    print(f"{'method':32s} {'m':>5s} {'rel RMSE':>9s} {'setup s':>8s} {'shade ms':>9s}")
    for m in args.roughness:
        mat = wenv.CookTorrance(diffuse=(0.2, 0.2, 0.2), lobes=[{"specular": (1, 1, 1), "alpha": m, "ior": 1.5}])
        t0 = time.perf_counter()
        ref = wenv.reference(env, mat, nrm, v)
        ref_s = time.perf_counter() - t0
        for method, quality in CONFIGS:
            t0 = time.perf_counter()
            shader = wenv.Shader(env, mat, quality=quality, method=method)
            setup = time.perf_counter() - t0
            err = relative_rmse(shader.shade(nrm, v), ref)
            shader.shade_mesh(pos, mesh_nrm, orbit_eye(100))  # first view: fills the wavelet tables
            times = []
            for i in range(args.repeats):
                t0 = time.perf_counter()
                shader.shade_mesh(pos, mesh_nrm, orbit_eye(i))
                times.append((time.perf_counter() - t0) * 1e3)
            row = {"method": method, "quality": shader.quality, "label": label(method, quality), "roughness": m,
                   "rel_rmse": err, "setup_s": setup, "shade_ms_median": statistics.median(times),
                   "reference_s": ref_s}
            results["rows"].append(row)
            print(f"{row['label']:32s} {m:5.2f} {err:9.4f} {setup:8.2f} {row['shade_ms_median']:9.1f}", flush=True)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "bench_peers.json"), "w") as fp:
        json.dump(results, fp, indent=1)


if __name__ == "__main__":
    main()
