"""Speed of tabulated BRDFs against the Cook-Torrance materials they tabulate, side by side in one run:
time per view change (a new view of Suzanne at 126k vertices, 2 threads, the median of the views) at
each preset, for Cook-Torrance (Beckmann, index 1.5, over diffuse 0.2) at m = 0.05, 0.2, 0.5 and the
90 x 90 x 180 table of the same material, the shaders of a preset timed in turn view by view so that
the machine's load falls on all alike.  A retro-reflective table (no Cook-Torrance lobe, reflecting at
every half vector, so the exact lights cannot skip any) is timed beside them for comparison.  Also the
time to set each material on a shader (precomputation: BRDF slices, albedo tables, grazing rules),
and to load MERL files: a full 90 x 90 x 180 measurement (35 MB) and a 4096 x 2 x 64 table measured
at its first theta_h only, whose unmeasured columns are all filled from it.

    .venv/bin/python benchmarks/bench_tabulated.py [--views 7] [--presets draft,default,high]

Prints the table and writes out/bench_tabulated.json."""
import argparse
import json
import os
import statistics
import tempfile
import time

import numpy as np

import wenv
from bench_shade import orbit_eye, suzanne
from measure import OUT
from tests.helpers import merl_files
from tests.helpers.measure import bundled_hdri

ROUGHNESS = (0.05, 0.2, 0.5)
DIFFUSE = 0.2


def materials():
    """{name: material}: each Cook-Torrance material, its table, and the retro-reflective table."""
    out = {}
    for m in ROUGHNESS:
        out[f"ct m={m}"] = wenv.CookTorrance(diffuse=DIFFUSE, lobes=[{"alpha": m, "ior": 1.5}],
                                            distribution="beckmann")
        out[f"table m={m}"] = wenv.Tabulated(merl_files.table_of(
            {"brdf": "cook_torrance", "roughness": m, "diffuse": [DIFFUSE] * 3}))
    out["table retro"] = wenv.Tabulated(merl_files.table_of({"brdf": "retro", "width": 0.5}))
    return out


def loading(repeats=5):
    """{case: median seconds of wenv.load_brdf} for MERL files written to a temporary folder."""
    rng = np.random.default_rng(8)
    sparse = rng.uniform(0.001, 0.05, size=(4096, 2, 64, 3))
    unmeasured = np.ones(sparse.shape[:3], bool)
    unmeasured[0] = False
    cases = {"full 90x90x180": (merl_files.table_of({"brdf": "cook_torrance", "roughness": 0.08}), None),
             "4096x2x64 measured at one theta_h": (sparse, unmeasured)}
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, (table, mask)) in enumerate(cases.items()):
            path = merl_files.write_merl(os.path.join(tmp, f"{k}.binary"), table, mask)
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                wenv.load_brdf(path)
                times.append(time.perf_counter() - t0)
            out[name] = statistics.median(times)
            print(f"load_brdf, {name}: {out[name]:.3f} s (median of {repeats})", flush=True)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--views", type=int, default=7)
    ap.add_argument("--presets", default="draft,default,high")
    ap.add_argument("--hdri", default="sunset")
    args = ap.parse_args()
    wenv.set_num_threads(2)
    pos, nrm = suzanne(4)
    env = wenv.load_environment(bundled_hdri(args.hdri))
    mats = materials()
    results = {"vertices": len(pos), "threads": wenv.get_num_threads(), "hdri": args.hdri,
               "load_seconds": loading(), "presets": {}}
    for preset in args.presets.split(","):
        method = "rotation" if preset == "draft" else "slicing"
        shaders, set_s = {}, {}
        base = wenv.Shader(env, wenv.Lambert(0.5), quality=preset, method=method)  # matrices built or loaded once
        for name, mat in mats.items():
            t0 = time.perf_counter()
            base.set_material(mat)
            set_s[name] = time.perf_counter() - t0
            shaders[name] = wenv.Shader(env, mat, quality=preset, method=method)
            shaders[name].shade_mesh(pos, nrm, orbit_eye(0))  # untimed first view
        times = {name: [] for name in mats}
        for i in range(1, args.views + 1):
            for name, sh in shaders.items():
                t0 = time.perf_counter()
                sh.shade_mesh(pos, nrm, orbit_eye(i))
                times[name].append(1e3 * (time.perf_counter() - t0))
        row = {name: {"view_ms": statistics.median(t), "set_material_s": set_s[name]} for name, t in times.items()}
        for m in ROUGHNESS:
            row[f"table m={m}"]["ratio_to_ct"] = row[f"table m={m}"]["view_ms"] / row[f"ct m={m}"]["view_ms"]
        results["presets"][preset] = row
        print(f"\n{preset} ({method}): new view of {len(pos)} vertices, median of {args.views}")
        print(f"{'material':<16}{'view':>10}{'ratio':>8}{'set_material':>14}")
        for name, r in row.items():
            ratio = f"{r['ratio_to_ct']:.2f}x" if "ratio_to_ct" in r else ""
            print(f"{name:<16}{r['view_ms']:>8.1f} ms{ratio:>8}{r['set_material_s']:>12.2f} s", flush=True)
        del shaders, base
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "bench_tabulated.json"), "w") as fp:
        json.dump(results, fp, indent=2)


if __name__ == "__main__":
    main()
