"""The procedural textures' cost: wenv.noise_texture, wenv.voronoi_texture, wenv.wave_texture,
wenv.white_noise_texture and wenv.gabor_texture at a million random points (what a bake of a million texels reads), 2 threads, the median of --repeat
calls each, at the node's defaults and at the heavier settings users pick (more detail, distortion,
Smooth F1, colour).  Prints a table and writes out/bench_textures.json.  Timing is not part of the
test suite.

    python benchmarks/bench_textures.py [--points 1000000] [--repeat 5]
"""
import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import wenv  # noqa: E402
from measure import OUT, cpu  # noqa: E402

CASES = [
    ("Noise, Fac (defaults: 3D fBM, detail 2)", wenv.noise_texture, dict(color=False)),
    ("Noise, Color", wenv.noise_texture, dict()),
    ("Noise, Color, detail 8, distortion 0.5", wenv.noise_texture, dict(detail=8.0, distortion=0.5)),
    ("Noise, 4D Fac, detail 15", wenv.noise_texture, dict(dimensions=4, detail=15.0, color=False)),
    ("Voronoi F1, Distance (defaults)", wenv.voronoi_texture, dict(color=False)),
    ("Voronoi F1, Color", wenv.voronoi_texture, dict()),
    ("Voronoi Smooth F1, Distance", wenv.voronoi_texture, dict(feature="SMOOTH_F1", color=False)),
    ("Voronoi distance to edge, detail 2", wenv.voronoi_texture, dict(feature="DISTANCE_TO_EDGE", detail=2.0)),
    ("Wave, bands (defaults)", wenv.wave_texture, dict()),
    ("Wave, rings, distortion 2, detail 4", wenv.wave_texture, dict(wave_type="RINGS", direction="SPHERICAL",
                                                                   distortion=2.0, detail=4.0)),
    ("White Noise, Color", wenv.white_noise_texture, dict()),
    ("Gabor, 2D (defaults)", wenv.gabor_texture, dict()),
    ("Gabor, 3D", wenv.gabor_texture, dict(dimensions=3)),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    wenv.set_num_threads(2)
    points = np.random.default_rng(0).random((args.points, 3)).astype(np.float32) * 4.0
    rows = []
    for name, call, kw in CASES:
        call(points[:1000], **kw)  # warm
        times = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            call(points, **kw)
            times.append(time.perf_counter() - t)
        ms = 1e3 * statistics.median(times)
        rows.append(dict(case=name, ms=ms, settings=kw))
        print(f"{name:45s} {ms:8.1f} ms")
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "bench_textures.json"), "w") as fp:
        json.dump(dict(cpu=cpu(), points=args.points, repeat=args.repeat, rows=rows), fp, indent=1)


if __name__ == "__main__":
    main()
