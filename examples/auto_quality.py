"""quality="auto": which setting it picks, whether it meets its target, and how its time compares
with the cheapest fixed setting that meets the same target.

For every bundled HDRI and several materials, every setting auto chooses from is measured (the
slicing ladder wenv.AUTO_LADDER, and for the Lambertian material also the SH orders
wenv.AUTO_SH_ORDERS): relative RMSE against the stored reference on the fixed pairs of
examples/accuracy.py, and the time from nothing to a first shaded view of Suzanne at ~126k vertices (2 threads; later
views cost about the same at every level, 16 table reads per vertex).  Then, per
target, auto's choice is compared with the cheapest setting that met the target.  Prints the table
and writes out/auto_quality.json.

    .venv/bin/python examples/auto_quality.py [--pairs 2000] [--targets 0.01,0.02,0.05] [--repeats 5]
    .venv/bin/python examples/auto_quality.py --calibrate   # the error table auto's model is built on
"""
import argparse
import json
import os
import statistics
import time

import numpy as np

import wenv
from _common import OUT, bundled_hdri, relative_rmse
from accuracy import DATA, HDRIS, MATERIALS, material
from bench_shade import orbit_eye, suzanne


def first_view_ms(env, mat, quality, pos, nrm, repeats, method="slicing"):
    """Median time from nothing to a shaded mesh: the shader made for this environment and material
    (slicing: no matrices) and one view of the mesh shaded.  Later views read the same table at a
    cost that hardly depends on the setting; what a setting costs is this, and its memory."""
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        wenv.Shader(env, mat, quality=quality, method=method).shade_mesh(pos, nrm, orbit_eye(i))
        times.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(times)


def new_view_ms(env, mat, quality, pos, nrm, repeats, method="slicing"):
    """Median time of a view change to a view not seen before (after an untimed first view), as
    examples/speed_vs_accuracy.py times it."""
    sh = wenv.Shader(env, mat, quality=quality, method=method)
    sh.shade_mesh(pos, nrm, orbit_eye(-1))
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        sh.shade_mesh(pos, nrm, orbit_eye(0.5 + 3 * i))
        times.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(times)


def args_ref(data, h, name, n):
    return data[f"{h}/{name}"][:n]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pairs", type=int, default=2000)
    ap.add_argument("--targets", default="0.01,0.03,0.1")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--materials", default="lambert,m0.1,m0.2,m0.5")
    ap.add_argument("--calibrate", action="store_true", help="print the per-level error table (medians)")
    args = ap.parse_args()
    wenv.set_num_threads(2)
    data = np.load(DATA)
    nrm, vw = data["normals"][:args.pairs], data["views"][:args.pairs]
    names = args.materials.split(",")
    targets = [float(t) for t in args.targets.split(",")]
    ladder = wenv.AUTO_LADDER
    pos, mesh_nrm = suzanne(4)

    # Fixed settings: the ladder's levels (method "slicing") for every material, and for a material
    # without lobes also the SH orders auto may pick instead (method "sh"), keyed "sh<order>".
    def settings(name):
        out = {level: ("slicing", q) for level, q in enumerate(ladder)}
        if not MATERIALS[name]["lobes"]:
            out.update({f"sh{o}": ("sh", {"order": o, "views": 2}) for o in wenv.AUTO_SH_ORDERS})
        return out

    errors, times, view_times, chosen = {}, {}, {}, {}
    for level, q in enumerate(ladder):
        # one shader per level: new lighting and materials through set_environment / set_material
        sh = None
        for h in HDRIS:
            env = wenv.load_environment(bundled_hdri(h))
            for name in names:
                mat = material(MATERIALS[name])
                if sh is None:
                    sh = wenv.Shader(env, mat, quality=q, method="slicing")
                else:
                    if sh.environment is not env:
                        sh.set_environment(env)
                    sh.set_material(mat)
                errors[h, name, level] = relative_rmse(sh.shade(nrm, vw), args_ref(data, h, name, args.pairs))
        print(f"level {level}: median error (%) " + " ".join(
            f"{n} {100 * float(np.median([errors[h, n, level] for h in HDRIS])):.2f}" for n in names), flush=True)
    for name in names:
        for sid, (method, q) in settings(name).items():
            if method == "sh":
                for h in HDRIS:
                    sh = wenv.Shader(wenv.load_environment(bundled_hdri(h)), material(MATERIALS[name]), quality=q,
                                     method=method)
                    errors[h, name, sid] = relative_rmse(sh.shade(nrm, vw), args_ref(data, h, name, args.pairs))
    sunset = wenv.load_environment(bundled_hdri("sunset"))
    for name in names:
        for sid, (method, q) in settings(name).items():
            times[name, sid] = first_view_ms(sunset, material(MATERIALS[name]), q, pos, mesh_nrm, args.repeats, method)
            view_times[name, sid] = new_view_ms(sunset, material(MATERIALS[name]), q, pos, mesh_nrm,
                                                2 * args.repeats + 1, method)
        print(name, "ms to the first shaded view by setting:", {sid: round(times[name, sid], 1) for sid in settings(name)},
              "; per new view:", {sid: round(view_times[name, sid], 1) for sid in settings(name)}, flush=True)
    for h in HDRIS:
        env = wenv.load_environment(bundled_hdri(h))
        for name in names:
            for t in targets:
                chosen[h, name, t] = wenv.Shader(env, material(MATERIALS[name]), quality="auto",
                                                 target_error=t).stats["auto"]

    if args.calibrate:
        print("median relative RMSE (%) over the HDRIs, per ladder level:")
        for name in names:
            print(name, [round(100 * float(np.median([errors[h, name, lv] for h in HDRIS])), 3)
                         for lv in range(len(ladder))])

    rows = []
    for t in targets:
        for name in names:
            for h in HDRIS:
                a = chosen[h, name, t]
                sid = f"sh{a['sh_order']}" if a["method"] == "sh" else a["level"]
                met = [k for k in settings(name) if errors[h, name, k] <= t]
                cheapest = min(met, key=lambda k: times[name, k]) if met else None
                rows.append({"target": t, "material": name, "hdri": h, "auto_level": sid,
                             "auto_method": a["method"], "predicted": a["predicted_error"], "reachable": a["met"],
                             "auto_error": errors[h, name, sid], "met": errors[h, name, sid] <= t,
                             "auto_ms": times[name, sid], "cheapest_level": cheapest,
                             "cheapest_ms": times[name, cheapest] if cheapest is not None else None,
                             "ratio": times[name, sid] / times[name, cheapest] if cheapest is not None else None,
                             "auto_view_ms": view_times[name, sid],
                             "view_ratio": (view_times[name, sid] / min(view_times[name, k] for k in met)
                                            if met else None)})
    print(f"{'target':>7} {'material':>8} {'hdri':>10} {'auto':>5} {'error %':>8} {'met':>4} "
          f"{'ms':>6} {'cheapest':>8} {'ms':>6} {'ratio':>6}")
    for r in rows:
        ch = "-" if r["cheapest_level"] is None else str(r["cheapest_level"])
        cms = "-" if r["cheapest_ms"] is None else f"{r['cheapest_ms']:.1f}"
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.2f}"
        print(f"{100 * r['target']:>6.0f}% {r['material']:>8} {r['hdri']:>10} {str(r['auto_level']):>5} "
              f"{100 * r['auto_error']:>8.2f} {'yes' if r['met'] else 'no':>4} {r['auto_ms']:>6.1f} {ch:>8} {cms:>6} {ratio:>6}")
    print("summary: target, cases, reachable by some level, auto met (where reachable), "
          "within 1.25x of the cheapest that met it: first view | per new view")
    for t in targets:
        r = [x for x in rows if x["target"] == t]
        reach = [x for x in r if x["cheapest_level"] is not None]
        print(f"{100 * t:.0f}%  {len(r)}  {len(reach)}  {sum(x['met'] for x in r)} ({sum(x['met'] for x in reach)})  "
              f"{sum(1 for x in reach if x['met'] and x['ratio'] <= 1.25)} | "
              f"{sum(1 for x in reach if x['met'] and x['view_ratio'] <= 1.25)}")
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "auto_quality.json"), "w") as fp:
        json.dump({"ladder": ladder, "rows": rows,
                   "errors": {f"{h}/{n}/{lv}": e for (h, n, lv), e in errors.items()},
                   "times_ms": {f"{n}/{lv}": t for (n, lv), t in times.items()},
                   "view_times_ms": {f"{n}/{lv}": t for (n, lv), t in view_times.items()}}, fp, indent=1)
    print("wrote out/auto_quality.json")


if __name__ == "__main__":
    main()
