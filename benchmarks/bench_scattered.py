"""Benchmark: the first and second shade of a few thousand scattered (normal, view) pairs.

A new Shader (forest, slicing) shades random pairs twice, as the accuracy tests and a small mesh's
first views do: the first call makes the lighting slices and, where it is cheaper than whole table
rows, reads each vertex's 16 table entries made for it alone; the second makes the rows its pairs
ask for again.  Medians over rounds, each with a new Shader.  Prints the figures and writes
out/bench_scattered.json; with benchmarks/compare_builds.py it times two builds side by side.

    python benchmarks/bench_scattered.py [--pairs 2000] [--rounds 5]
"""
import argparse
import json
import os
import statistics
import time

from measure import OUT, cpu
from tests.helpers.measure import bundled_hdri, random_pairs

import wenv

MATERIALS = {
    "cook-torrance m=0.2": lambda: wenv.CookTorrance(0.3, lobes=[{"alpha": 0.2}]),
    "principled metal": lambda: wenv.Principled(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.3),
}
PRESETS = ("default", "high")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    env = wenv.load_environment(bundled_hdri("forest"))
    nrm, v = random_pairs(args.pairs, 3)
    figures = {}
    for name, make in MATERIALS.items():
        for preset in PRESETS:
            first, second = [], []
            for _ in range(args.rounds):
                shader = wenv.Shader(env, make(), quality=preset, method="slicing")
                t0 = time.perf_counter()
                shader.shade(nrm, v)
                t1 = time.perf_counter()
                shader.shade(nrm, v)
                first.append(t1 - t0)
                second.append(time.perf_counter() - t1)
            row = {"first_ms": 1e3 * statistics.median(first), "second_ms": 1e3 * statistics.median(second)}
            figures[f"{name}/{preset}"] = row
            print(f"{name:22s} {preset:8s} first {row['first_ms']:8.1f} ms   second {row['second_ms']:8.1f} ms",
                  flush=True)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "bench_scattered.json"), "w") as fp:
        json.dump({"cpu": cpu(), "threads": wenv.get_num_threads(), "pairs": args.pairs, "rounds": args.rounds,
                   "hdri": "forest", "method": "slicing", "figures": figures}, fp, indent=1)


if __name__ == "__main__":
    main()
