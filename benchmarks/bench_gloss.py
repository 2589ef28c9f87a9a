"""Benchmark: one 3-angle gloss measurement (20, 60, 85 degrees) of two-lobe Cook-Torrance materials.

Times wenv.gloss(material, (20, 60, 85)) at the default tolerance (0.05 GU) for a grid of two-lobe
materials (Beckmann and GGX; a sharp clear-coat lobe over a broader base lobe, coloured, with a
diffuse part), with the module's default threads and with one thread.  Prints median timings and
writes them to out/bench_gloss.json.  Timing is not part of the test suite.

    python benchmarks/bench_gloss.py [--repeat 31] [--out out/bench_gloss.json]
"""
import argparse
import json
import os
import platform
import statistics
import time

import wenv

GEOMETRIES = (20, 60, 85)
# (sharp lobe roughness, base lobe roughness): clear coats from near-mirror to satin.
PAIRS = [(1e-4, 0.1), (1e-3, 0.05), (3e-3, 0.3), (0.01, 0.1), (0.02, 0.2), (0.05, 0.5)]


def material(dist, m1, m2):
    return wenv.CookTorrance(
        diffuse=(0.35, 0.12, 0.05),
        lobes=[dict(alpha=m1, ior=1.5), dict(alpha=m2, specular=(0.6, 0.5, 0.4), ior=1.8)],
        distribution=dist,
    )


def time_one(mat, repeat):
    wenv.gloss(mat, GEOMETRIES)  # warm-up
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        wenv.gloss(mat, GEOMETRIES)
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts) * 1e3, min(ts) * 1e3


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=31)
    ap.add_argument("--out", default=os.path.join("out", "bench_gloss.json"))
    args = ap.parse_args()

    default_threads = wenv.get_num_threads()
    results = []
    for threads in (default_threads, 1):
        wenv.set_num_threads(threads)
        for dist in ("beckmann", "ggx"):
            for m1, m2 in PAIRS:
                mat = material(dist, m1, m2)
                med, best = time_one(mat, args.repeat)
                evals = [wenv.Glossmeter(angle=g).reading(mat)["evaluations"] for g in GEOMETRIES]
                gu = wenv.gloss(mat, GEOMETRIES)
                results.append(dict(threads=threads, distribution=dist, roughness=[m1, m2], median_ms=med,
                                    min_ms=best, evaluations=evals, gloss=list(gu)))
                print(f"threads={threads} {dist:8s} m=({m1:g}, {m2:g}): median {med:6.2f} ms  min {best:6.2f} ms  "
                      f"evals {evals}  GU {gu[0]:.2f} / {gu[1]:.2f} / {gu[2]:.2f}")
    wenv.set_num_threads(default_threads)

    summary = {}
    for threads in sorted({r["threads"] for r in results}):
        meds = [r["median_ms"] for r in results if r["threads"] == threads]
        summary[f"threads={threads}"] = dict(median_of_medians_ms=statistics.median(meds), worst_median_ms=max(meds))
        print(f"threads={threads}: median over materials {statistics.median(meds):.2f} ms, "
              f"worst material {max(meds):.2f} ms (target <= 20 ms)")
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/bench_gloss.py", repeat=args.repeat, machine=platform.machine(),
                       processor=platform.processor(), cpus=os.cpu_count(), load_average=os.getloadavg(),
                       summary=summary, results=results), f, indent=1)
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
