"""quality="auto": which setting it picks, whether it meets its target, and how its time compares
with the cheapest fixed setting that meets the same target.

For every bundled HDRI and several materials, every setting auto chooses from is measured (the
slicing ladder wenv.AUTO_LADDER, and for the Lambertian material also the SH orders
wenv.AUTO_SH_ORDERS): relative RMSE over normals uniform on the sphere and views uniform on their
hemisphere, the time from nothing to a first shaded view of Suzanne at ~126k vertices, and the time
of a new view (2 threads).

The error is estimated with the ladder's last level (`high`) as a control variate: its difference
from each setting on many pairs drawn about the lighting's brightest reflections (weighted back to
the uniform law: measure.mirror_weighted_pairs), plus the reference's correction on 8000 stored
pairs (the 2000 of benchmarks/accuracy.py and the 6000 of its --make-extra-reference).  Over those
8000 alone a narrow lobe's error moves several-fold with the sun hits the sample happens to hold.
Then, per target, auto's choice is compared with the cheapest setting that met the target.  Prints
the table and writes out/auto_quality.json.

    .venv/bin/python benchmarks/auto_quality.py [--pairs 8000] [--targets 0.01,0.02,0.05] [--repeats 5]
    .venv/bin/python benchmarks/auto_quality.py --calibrate   # the error table auto's model is built on
    .venv/bin/python benchmarks/auto_quality.py --fit         # the environment factor's constants, from the JSON
    .venv/bin/python benchmarks/auto_quality.py --calibrate-ggx   # GGX_*: a GGX lobe's error over a Beckmann one's
"""
import argparse
import json
import math
import os
import statistics
import time

import itertools

import numpy as np

import wenv
from accuracy import HDRIS, MATERIALS, PRINCIPLED, load_reference, material
from bench_shade import orbit_eye, suzanne
from measure import OUT, ROOT
from tests.helpers.measure import bundled_hdri, estimated_error, mirror_weighted_pairs, relative_rmse


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
    benchmarks/speed_vs_accuracy.py times it."""
    sh = wenv.Shader(env, mat, quality=quality, method=method)
    sh.shade_mesh(pos, nrm, orbit_eye(-1))
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        sh.shade_mesh(pos, nrm, orbit_eye(0.5 + 3 * i))
        times.append(1e3 * (time.perf_counter() - t0))
    return statistics.median(times)


def setting_of(choice):
    """The key of the setting auto chose (stats["auto"]): its ladder level, or "sh<order>"."""
    return f"sh{choice['sh_order']}" if choice["method"] == "sh" else choice["level"]


# The estimate's floor: the control variate's two terms, read on different pairs, can sum below 0
# where a setting errs far less than the stored pairs resolve (estimated_error then gives 0).
RESOLVED_ERROR = 1e-4
SUBSET = 2000  # pairs in benchmarks/accuracy.py's table: the metric's noise is read off subsets this size


def errors_of(out, ref):
    """Relative RMSE over all the pairs, and over each run of SUBSET of them."""
    parts = [relative_rmse(out[i:i + SUBSET], ref[i:i + SUBSET]) for i in range(0, len(ref) - SUBSET + 1, SUBSET)]
    return relative_rmse(out, ref), parts


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pairs", type=int, default=8000, help="stored reference pairs")
    ap.add_argument("--control-pairs", type=int, default=50000, help="weighted pairs the control is read on")
    ap.add_argument("--targets", default="0.01,0.03,0.1")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--materials", default="lambert,m0.05,m0.1,m0.2,m0.5")
    ap.add_argument("--calibrate", action="store_true", help="print the per-level median error table from out/auto_quality.json")
    ap.add_argument("--fit", action="store_true", help="fit the environment factor's constants to out/auto_quality.json")
    ap.add_argument("--max-misses", type=int, default=0, help="--fit: cases auto may miss its target in")
    ap.add_argument("--calibrate-ggx", action="store_true",
                    help="GGX_* of csrc/auto/autoquality.c from the Principled paint's and metal's stored reference")
    args = ap.parse_args()
    if args.fit:
        return fit(args.max_misses)
    if args.calibrate_ggx:
        return calibrate_ggx()
    if args.calibrate:
        return calibrate()
    wenv.set_num_threads(2)
    data = load_reference(args.pairs)
    nrm, vw = data["normals"], data["views"]
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

    errors, plain_errors, subset_errors, times, view_times, chosen = {}, {}, {}, {}, {}, {}
    many = {}  # per HDRI and material: weighted pairs drawn about the narrowest lobe's bright reflections
    for i, h in enumerate(HDRIS):
        env = wenv.load_environment(bundled_hdri(h))
        for j, name in enumerate(names):
            lobes = MATERIALS[name]["lobes"]
            m = min(lobe["alpha"] for lobe in lobes) if lobes else 1.0
            many[h, name] = mirror_weighted_pairs(env, m, args.control_pairs, 1000 + 100 * i + j,
                                                  share=0.5 if lobes else 0.0)
    out, out_many = {}, {}
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
                out[h, name, level] = sh.shade(nrm, vw)
                out_many[h, name, level] = sh.shade(*many[h, name][:2])
        print(f"level {level} shaded", flush=True)
    for name in names:
        for sid, (method, q) in settings(name).items():
            if method == "sh":
                for h in HDRIS:
                    sh = wenv.Shader(wenv.load_environment(bundled_hdri(h)), material(MATERIALS[name]), quality=q,
                                     method=method)
                    out[h, name, sid] = sh.shade(nrm, vw)
                    out_many[h, name, sid] = sh.shade(*many[h, name][:2])
    control = len(ladder) - 1
    spread = []  # the estimate over one half of the weighted pairs against the other
    for (h, name, sid), o in out.items():
        ref, w = data[f"{h}/{name}"], many[h, name][2]
        c, c_many, o_many = out[h, name, control], out_many[h, name, control], out_many[h, name, sid]
        errors[h, name, sid] = estimated_error(o, ref, c, o_many, c_many, w)
        plain_errors[h, name, sid], subset_errors[h, name, sid] = errors_of(o, ref)
        half = len(w) // 2
        a, b = (estimated_error(o, ref, c, o_many[s], c_many[s], w[s]) for s in (slice(0, half), slice(half, None)))
        if sid != control and a > 0 and b > 0:
            spread.append((name == "lambert", math.log(a / b)))
    for level in range(len(ladder)):
        print(f"level {level}: median error (%) " + " ".join(
            f"{n} {100 * float(np.median([errors[h, n, level] for h in HDRIS])):.2f}" for n in names), flush=True)
    sunset = wenv.load_environment(bundled_hdri("sunset"))
    for name in names:
        for sid, (method, q) in settings(name).items():
            times[name, sid] = first_view_ms(sunset, material(MATERIALS[name]), q, pos, mesh_nrm, args.repeats, method)
            view_times[name, sid] = new_view_ms(sunset, material(MATERIALS[name]), q, pos, mesh_nrm,
                                                2 * args.repeats + 1, method)
        print(name, "ms to the first shaded view by setting:", {sid: round(times[name, sid], 1) for sid in settings(name)},
              "; per new view:", {sid: round(view_times[name, sid], 1) for sid in settings(name)}, flush=True)
    # Auto as the add-on runs it: given the mesh's normals, on an environment it has analysed before.
    # The analysis is made once per environment, part by part as materials need them (the lights and
    # pyramid for lobes, the SH spectrum without): each part is timed apart, on fresh copies.
    features, analysis_ms = {}, {}
    glossy = {"diffuse": [0.1] * 3, "lobes": [{"specular": 1.0, "alpha": 0.2, "ior": 1.5}]}
    for h in HDRIS:
        env = wenv.load_environment(bundled_hdri(h))
        analysis_ms[h] = {part: statistics.median(
            1e3 * wenv.Shader(env.with_transform(), material(spec), quality="auto").stats["auto"]["analysis_seconds"]
            for _ in range(args.repeats)) for part, spec in (("spectrum", MATERIALS["lambert"]), ("lights", glossy))}
        for name in names:
            for t in targets:
                chosen[h, name, t] = wenv.Shader(env, material(MATERIALS[name]), quality="auto", target_error=t,
                                                 normals=mesh_nrm).stats["auto"]
            if MATERIALS[name]["lobes"]:  # every level's estimate (the same at every target)
                features[f"{h}/{name}"] = chosen[h, name, targets[0]]["levels"]
    # what choosing itself costs (stats["auto"]["seconds"] less the analysis it made: reading the
    # analysis and the mesh's normals, before any shading setting is built)
    choose_ms = {f"{h}/{n}/{t}": 1e3 * (a["seconds"] - a["analysis_seconds"]) for (h, n, t), a in chosen.items()}
    for kind in ("lambert", "lobes"):
        v = [ms for k, ms in choose_ms.items() if (k.split("/")[1] == "lambert") == (kind == "lambert")]
        print(f"ms auto spends choosing, {kind}: median {statistics.median(v):.2f}, max {max(v):.2f}", flush=True)
    print("ms analysing each environment (once per environment and part):",
          {h: {part: round(ms, 1) for part, ms in a.items()} for h, a in analysis_ms.items()}, flush=True)
    # Auto timed end to end under sunset beside the sum the table uses (the chosen setting's time
    # plus choosing): on the analysed environment, and on a fresh one (the analysis included).
    end_to_end = {}
    for spec in (MATERIALS["lambert"], glossy):  # analyses sunset (both parts), untimed
        wenv.Shader(sunset, material(spec), quality="auto")
    for name in names:
        for t in targets:
            mat = material(MATERIALS[name])
            warm, fresh = [], []
            for i in range(args.repeats):
                t0 = time.perf_counter()
                wenv.Shader(sunset, mat, quality="auto", target_error=t, normals=mesh_nrm).shade_mesh(pos, mesh_nrm, orbit_eye(i))
                warm.append(1e3 * (time.perf_counter() - t0))
                new_env = sunset.with_transform()  # a copy: not analysed yet
                t0 = time.perf_counter()
                wenv.Shader(new_env, mat, quality="auto", target_error=t, normals=mesh_nrm).shade_mesh(pos, mesh_nrm, orbit_eye(i))
                fresh.append(1e3 * (time.perf_counter() - t0))
            a = chosen["sunset", name, t]
            sid = setting_of(a)
            end_to_end[f"{name}/{t}"] = {"setting": sid, "auto_ms": statistics.median(warm),
                                         "auto_fresh_ms": statistics.median(fresh),
                                         "setting_plus_choosing_ms": times[name, sid] + choose_ms[f"sunset/{name}/{t}"]}
            e = end_to_end[f"{name}/{t}"]
            print(f"sunset {name} {100 * t:.0f}%: auto ({sid}) {e['auto_ms']:.1f} ms end to end, "
                  f"{e['auto_fresh_ms']:.1f} ms on a fresh environment; the setting's time plus choosing "
                  f"{e['setting_plus_choosing_ms']:.1f} ms", flush=True)

    rows = []
    for t in targets:
        for name in names:
            for h in HDRIS:
                a = chosen[h, name, t]
                sid = setting_of(a)
                met = [k for k in settings(name) if errors[h, name, k] <= t]
                cheapest = min(met, key=lambda k: times[name, k]) if met else None
                # auto's time: its setting's, plus choosing (on an analysed environment), plus for a
                # first choice on this environment the parts of its analysis this choice needed
                auto_ms = times[name, sid] + choose_ms[f"{h}/{name}/{t}"]
                fresh_ms = auto_ms + sum(analysis_ms[h][part] for part, needed in (
                    ("spectrum", not MATERIALS[name]["lobes"]), ("lights", a["method"] == "slicing")) if needed)
                rows.append({"target": t, "material": name, "hdri": h, "auto_level": sid,
                             "auto_method": a["method"], "predicted": a["predicted_error"], "reachable": a["met"],
                             "auto_error": errors[h, name, sid], "met": errors[h, name, sid] <= t,
                             "auto_ms": auto_ms, "auto_fresh_ms": fresh_ms, "cheapest_level": cheapest,
                             "cheapest_ms": times[name, cheapest] if cheapest is not None else None,
                             "ratio": auto_ms / times[name, cheapest] if cheapest is not None else None,
                             "fresh_ratio": fresh_ms / times[name, cheapest] if cheapest is not None else None,
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
              f"{sum(1 for x in reach if x['met'] and x['view_ratio'] <= 1.25)}; first choice on a fresh environment "
              f"(its analysis counted): {sum(1 for x in reach if x['met'] and x['fresh_ratio'] <= 1.25)}")
    for kind in ("lambert", "lobes"):
        r = [x for x in rows if x["cheapest_level"] is not None and (x["material"] == "lambert") == (kind == "lambert")]
        within = sum(1 for x in r if x["met"] and x["ratio"] <= 1.25)
        print(f"{kind}: met {sum(x['met'] for x in r)} of {len(r)}, within 1.25x {within} (fresh environment "
              f"{sum(1 for x in r if x['met'] and x['fresh_ratio'] <= 1.25)}); summed time ratio "
              f"{sum(x['auto_ms'] for x in r) / sum(x['cheapest_ms'] for x in r):.2f}, median "
              f"{statistics.median(x['ratio'] for x in r):.2f}")
    # How far the measure itself moves: the error over one run of SUBSET pairs against another.
    noise = {}
    for kind in ("lambert", "lobes"):
        logs = [np.log(p[i] / p[j]) for (h, n, lv), p in subset_errors.items() if (n == "lambert") == (kind == "lambert")
                for i in range(len(p)) for j in range(i + 1, len(p))]
        if logs:
            noise[kind] = {"rms_log_ratio": float(np.sqrt(np.mean(np.square(logs)))), "max_ratio": float(np.exp(np.max(np.abs(logs))))}
            print(f"{kind}: error over {SUBSET} pairs against another {SUBSET}: rms ratio "
                  f"{np.exp(noise[kind]['rms_log_ratio']):.2f}x, at most {noise[kind]['max_ratio']:.1f}x", flush=True)
    for kind, lam in (("lambert", True), ("lobes", False)):
        logs = [x for is_lam, x in spread if is_lam == lam]
        if logs:
            noise.setdefault(kind, {})["estimate_halves_rms_ratio"] = float(np.exp(np.sqrt(np.mean(np.square(logs)))))
            noise[kind]["estimate_halves_max_ratio"] = float(np.exp(np.max(np.abs(logs))))
            print(f"{kind}: the estimate from one half of the {args.control_pairs} weighted pairs against "
                  f"the other: rms ratio {noise[kind]['estimate_halves_rms_ratio']:.3f}x, at most "
                  f"{noise[kind]['estimate_halves_max_ratio']:.2f}x", flush=True)
    # (an estimate of 0 is an error below what the measure resolves: no ratio to take)
    logs = [math.log(plain_errors[k] / errors[k]) for k in errors
            if k[2] != control and k[1] != "lambert" and errors[k] > 0]
    noise.setdefault("lobes", {})["stored_pairs_alone_rms_ratio"] = float(np.exp(np.sqrt(np.mean(np.square(logs)))))
    noise["lobes"]["stored_pairs_alone_max_ratio"] = float(np.exp(np.max(np.abs(logs))))
    print(f"lobes: the error over the {len(nrm)} stored pairs alone against the estimate: rms ratio "
          f"{noise['lobes']['stored_pairs_alone_rms_ratio']:.2f}x, at most {noise['lobes']['stored_pairs_alone_max_ratio']:.1f}x")
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "auto_quality.json"), "w") as fp:
        json.dump({"ladder": ladder, "rows": rows, "features": features, "choose_ms": choose_ms, "targets": targets,
                   "analysis_ms": analysis_ms, "end_to_end_sunset": end_to_end,
                   "pairs": len(nrm), "control_pairs": args.control_pairs, "noise": noise,
                   "plain_errors": {f"{h}/{n}/{lv}": e for (h, n, lv), e in plain_errors.items()},
                   "subset_errors": {f"{h}/{n}/{lv}": e for (h, n, lv), e in subset_errors.items()},
                   "errors": {f"{h}/{n}/{lv}": e for (h, n, lv), e in errors.items()},
                   "times_ms": {f"{n}/{lv}": t for (n, lv), t in times.items()},
                   "view_times_ms": {f"{n}/{lv}": t for (n, lv), t in view_times.items()}}, fp, indent=1)
    print("wrote out/auto_quality.json")


def calibrate():
    """MEDIAN_ERROR of csrc/auto/autoquality.c: per ladder level, the median over the HDRIs of the
    estimated error, at roughness 0.05, 0.1, 0.2, 0.5 and for Lambert, from out/auto_quality.json."""
    with open(os.path.join(OUT, "auto_quality.json")) as fp:
        d = json.load(fp)
    errors = d["errors"]
    hdris = sorted({k.split("/")[0] for k in errors})
    for lv in range(len(d["ladder"])):
        row = [statistics.median(errors[f"{h}/{n}/{lv}"] for h in hdris) for n in ("m0.05", "m0.1", "m0.2", "m0.5", "lambert")]
        print("    {" + ", ".join(f"{e:.5f}" for e in row) + "},")


def calibrate_ggx():
    """GGX_DIELECTRIC, GGX_METAL, HEAD_ON_* and NARROW_FACTOR of csrc/auto/autoquality.c.  GGX_*: per
    ladder level, how much more a GGX lobe errs than the Beckmann lobe of the same width that
    MEDIAN_ERROR was measured on (a dielectric, index 1.5) -- the Principled paint (a dielectric GGX
    lobe over a diffuse base) and the Principled metal of benchmarks/accuracy.py (alpha 0.09 both)
    against Cook-Torrance at m = 0.09 (the errors at m = 0.05 and 0.1 interpolated in log m, as auto
    interpolates MEDIAN_ERROR): the largest ratio over the HDRIs, so that a target said to be met
    is.  HEAD_ON_*: the two's lobes' albedo head-on over theirs at 80 degrees, which auto
    interpolates the factor by.  NARROW_FACTOR: how much more a lobe narrower than the calibrated
    range errs than its prediction at m = 0.05 -- the coated paint (a clear coat of Coat Roughness
    0.1, alpha 0.01, over a base of roughness 0.5) against Cook-Torrance at m = 0.05 times its GGX
    factor; the median over the HDRIs.  Each over the 2000 stored pairs under each bundled HDRI."""
    beckmann, ggx = np.load(os.path.join(ROOT, "tests", "data", "accuracy_reference.npz")), \
        np.load(os.path.join(ROOT, "tests", "data", "accuracy_reference_principled.npz"))
    alpha = 0.09
    t = math.log(alpha / 0.05) / math.log(0.1 / 0.05)
    env0 = wenv.load_environment(bundled_hdri(HDRIS[0]))
    head_on = {name: wenv.Shader(env0, wenv.Principled(**PRINCIPLED[name]["principled"]), quality="auto",
                                 target_error=0.01).stats["auto"]["head_on"] for name in ("paint", "metal", "coated")}
    metal_like = min(1.0, max(0.0, (head_on["coated"] - head_on["paint"]) / (head_on["metal"] - head_on["paint"])))
    rows = {"paint": [], "metal": [], "narrow": []}
    for level, q in enumerate(wenv.AUTO_LADDER):
        ratios = {"paint": [], "metal": []}
        narrow = []
        for h in HDRIS:
            env = wenv.load_environment(bundled_hdri(h))
            sh = wenv.Shader(env, material(MATERIALS["m0.05"]), quality=q, method="slicing")
            e = {}
            for name in ("m0.05", "m0.1"):
                sh.set_material(material(MATERIALS[name]))
                e[name] = relative_rmse(sh.shade(beckmann["normals"], beckmann["views"]), beckmann[f"{h}/{name}"])
            for name in ("paint", "metal", "coated"):
                sh.set_material(wenv.Principled(**PRINCIPLED[name]["principled"]))
                e[name] = relative_rmse(sh.shade(ggx["normals"], ggx["views"]), ggx[f"{h}/{name}"])
            beck = math.exp((1 - t) * math.log(e["m0.05"]) + t * math.log(e["m0.1"]))
            for name in ratios:
                ratios[name].append(e[name] / beck)
            narrow.append(e["coated"] / e["m0.05"])
        for name in ratios:
            rows[name].append(max(ratios[name]))
        factor = (1 - metal_like) * rows["paint"][-1] + metal_like * rows["metal"][-1]
        rows["narrow"].append(statistics.median(narrow) / factor)
        print(f"level {level}: GGX over Beckmann at m = {alpha}, largest over the HDRIs: paint "
              f"{rows['paint'][-1]:.2f} (median {statistics.median(ratios['paint']):.2f}), metal "
              f"{rows['metal'][-1]:.2f} (median {statistics.median(ratios['metal']):.2f}); a coat of alpha 0.01 "
              f"over its prediction at m = 0.05 {rows['narrow'][-1]:.2f}", flush=True)
    print("GGX_DIELECTRIC " + ", ".join(f"{r:.2f}" for r in rows["paint"]))
    print("GGX_METAL      " + ", ".join(f"{r:.2f}" for r in rows["metal"]))
    print(f"HEAD_ON_DIELECTRIC {head_on['paint']:.3f}  HEAD_ON_METAL {head_on['metal']:.3f}")
    print("NARROW_FACTOR  " + ", ".join(f"{r:.2f}" for r in rows["narrow"]))


def fit(max_misses):
    """Grid-fit auto's environment factor, SCALE ((1 - l) + SLOPE c) / (1 + d)^POWER (csrc/auto/autoquality.c),
    to the measured errors and every level's estimates in out/auto_quality.json: among the constants
    that miss the target in at most `max_misses` reachable cases, those within 1.25x of the cheapest
    sufficient level in the most.  Then the same fit leaving each HDRI out, scored on that HDRI."""
    with open(os.path.join(OUT, "auto_quality.json")) as fp:
        d = json.load(fp)
    errors, times, feats = d["errors"], d["times_ms"], d["features"]
    levels = range(len(d["ladder"]))
    cases = sorted({tuple(k.split("/")) for k in feats})
    hdris = sorted({h for h, _ in cases})
    median = {(n, lv): statistics.median(errors[f"{h}/{n}/{lv}"] for h in hdris) for _, n in cases for lv in levels}

    def score(env_factor, only):
        """(reachable, met, within 1.25x, summed time over the cheapest, claims of a target missed)."""
        met = within = reach = false_claims = 0
        picked_ms = cheapest_ms = 0.0
        for (h, n), t in itertools.product(cases, d["targets"]):
            if h not in only:
                continue
            pred = [median[n, lv] * env_factor(h, n, lv) for lv in levels]
            pick = next((lv for lv in levels if pred[lv] <= t), levels[-1])
            false_claims += pred[pick] <= t < errors[f"{h}/{n}/{pick}"]
            ok = [lv for lv in levels if errors[f"{h}/{n}/{lv}"] <= t]
            if not ok:
                continue
            reach += 1
            cheapest = min(ok, key=lambda lv: times[f"{n}/{lv}"])
            picked_ms += times[f"{n}/{pick}"]
            cheapest_ms += times[f"{n}/{cheapest}"]
            if errors[f"{h}/{n}/{pick}"] <= t:
                met += 1
                within += times[f"{n}/{pick}"] <= 1.25 * times[f"{n}/{cheapest}"]
        return reach, met, within, picked_ms / cheapest_ms if cheapest_ms else 1.0, false_claims

    # The top level (high) is taken when nothing cheaper is predicted to meet the target: its factor
    # only says whether it does, a least-squares fit.  A grazing level below it (default) is picked
    # on its prediction, so its constants are fitted as the other levels' are: every target some
    # level meets met, then as few levels picked too high as that allows.
    top = levels[-1]
    high = fit_grazing(errors, feats, cases, median, top)
    middle = [lv for lv in levels if lv != top and d["ladder"][lv]["grazing"] > 0]
    # the middle levels' contrast power at m <= 0.2 and from 0.5 up (GRAZING_FACTOR's wide power;
    # equal: one power for every width)
    middle_grid = [(round(k, 2), p, q, w) for k in np.arange(0.5, 4.01, 0.05) for p in (0.25, 0.5, 0.75, 1.0)
                   for q in (0, 0.0625, 0.125, 0.25) for w in (0.25, 0.375, 0.5, 0.625, 0.75, 1.0) if w <= p]

    def contrast_power_at(contrast_power, wide_power, n):
        """autoquality.c's contrast_power_at for material n (m0.05 ... m0.5)."""
        m = float(n[1:])
        if m <= 0.2:
            return contrast_power
        t = min(1.0, math.log(m / 0.2) / math.log(0.5 / 0.2))
        return contrast_power + t * (wide_power - contrast_power)

    def grazing_factor(f, constants, n):
        scale, contrast_power, dominance_power, *wide = constants
        power = contrast_power_at(contrast_power, wide[0], n) if wide else contrast_power
        return (scale * ((1 - f["lights_share"]) + 10 * f["sun_contrast"]) ** power /
                (1 + f["light_dominance"]) ** dominance_power)

    def model(scale, slope, power, middle_constants):
        def env_factor(h, n, lv):
            f = feats[f"{h}/{n}"][lv]
            if lv == top:
                factor = grazing_factor(f, high, n)
            elif lv in middle:
                factor = grazing_factor(f, middle_constants, n)
            else:
                factor = scale * ((1 - f["lights_share"]) + slope * f["contrast"]) / (1 + f["light_dominance"]) ** power
            return min(8.0, max(0.15, factor))  # ENV_FACTOR_MAX, ENV_FACTOR_MIN
        return env_factor

    grid = [(round(k, 2), s, p) for k in np.arange(0.5, 2.51, 0.05) for s in (0, 1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 20)
            for p in (0, 0.0625, 0.125, 0.1875, 0.25, 0.375, 0.5)]

    def choose(candidates, only):
        """Among constants missing at most max_misses reachable cases and claiming no missed target
        (an unreachable one included): the most within 1.25x, then the most met, the least summed
        time, the scale nearest 1."""
        scored = [(score(model(*g), only), g) for g in candidates]
        ok = [(r, g) for r, g in scored if r[0] - r[1] <= max_misses and not r[4]] or scored
        return max(ok, key=lambda x: (x[0][2], x[0][1], -x[0][3], -abs(x[1][0] - 1)))

    def best(only):
        """The levels' constants and the middle grazing level's, each fitted with the other held
        (twice over), from the most cautious middle constants: a start from which no level's miss
        hides another's."""
        g = (1.0, 10, 0.0625, (4.0, 0.25, 0.0, 0.25))
        for _ in range(2):
            _, g = choose([(*c, g[3]) for c in grid], only)
            r, g = choose([(*g[:3], c) for c in middle_grid], only)
        return r, g

    (reach, met, within, ratio, _), g = best(hdris)
    print(f"ERROR_SCALE {g[0]}  CONTRAST_SLOPE {g[1]}  DOMINANCE_POWER {g[2]}; levels {middle}: GRAZING_FACTOR "
          f"{{{g[3][0]}, {g[3][1]}, {g[3][2]}, {g[3][3]}}}: of {reach} reachable cases met {met}, within 1.25x {within}, "
          f"summed time {ratio:.2f}x the cheapest sufficient")
    # auto's `met` flag: does the picked level's prediction say the target is met where it is?
    right = wrong_yes = wrong_no = 0
    for (h, n), t in itertools.product(cases, d["targets"]):
        pred = [median[n, lv] * model(*g)(h, n, lv) for lv in levels]
        pick = next((lv for lv in levels if pred[lv] <= t), top)
        claim, true = pred[pick] <= t, errors[f"{h}/{n}/{pick}"] <= t
        right += claim == true
        wrong_yes += claim and not true
        wrong_no += true and not claim
    print(f"auto's met flag: right in {right} of {right + wrong_yes + wrong_no} cases; says met where the "
          f"target is missed in {wrong_yes}, not met where it is met in {wrong_no}")
    # What an exact measure of the environment would give if it were one number per HDRI and roughness
    # (its true factor at level 0, carried to the other levels by the medians' shape): the levels'
    # shape varies between environments, which a factor the same for every level cannot follow.
    oracle = max((score(lambda h, n, lv, k=k: k * errors[f"{h}/{n}/0"] / median[n, 0], hdris)[1:3], k)
                 for k in np.arange(1.0, 3.0, 0.01))
    print(f"with each HDRI and roughness's exact level-0 factor at every level (times {oracle[1]:.2f}): met "
          f"{oracle[0][0]}, within 1.25x {oracle[0][1]}")
    # Better still: the model's own per-level shape, times each HDRI and roughness's exact factor
    # (the geometric mean of measured over predicted on the levels without the grazing path), with
    # the smallest margin that meets every target.  No measure of the environment can do better than
    # one exact factor per HDRI and roughness, and the levels' own deviations from it are what remain.
    plain = [lv for lv in levels if not d["ladder"][lv]["grazing"]]
    exact = {}
    for h, n in cases:
        pred = [lv["predicted_error"] for lv in feats[f"{h}/{n}"]]
        g = math.exp(statistics.fmean(math.log(max(errors[f"{h}/{n}/{lv}"], RESOLVED_ERROR) / pred[lv])
                                      for lv in plain))
        exact[h, n] = [p * (g if lv in plain else 1.0) for lv, p in enumerate(pred)]
    for margin in np.arange(1.0, 2.0, 0.01):
        r = score(lambda h, n, lv, k=margin: k * exact[h, n][lv] / median[n, lv], hdris)
        if r[0] == r[1]:
            print(f"with the model's shape and each HDRI and roughness's exact factor (margin {margin:.2f}): "
                  f"met {r[1]}, within 1.25x {r[2]}")
            break
    tot = np.zeros(3, int)
    for h in hdris:
        _, g = best([x for x in hdris if x != h])
        r = score(model(*g), [h])[:3]
        tot += r
        print(f"  fitted without {h}: {g} -> on {h}: reachable {r[0]}, met {r[1]}, within {r[2]}")
    print(f"leave one HDRI out: reachable {tot[0]}, met {tot[1]}, within 1.25x {tot[2]}")


def fit_grazing(errors, feats, cases, median, level):
    """The factor of a level with the grazing path, scale ((1 - l) + 10 c_s)^contrast_power /
    (1 + d)^dominance_power (GRAZING_FACTOR in csrc/auto/autoquality.c; c_s the bright extended share
    the suns alone leave): least squares in the logs over the cases whose error the estimate
    resolves; prints the constants and returns them rounded as the C source has them."""
    x, y = [], []
    for h, n in cases:
        f, e = feats[f"{h}/{n}"][level], errors[f"{h}/{n}/{level}"]
        if e < RESOLVED_ERROR:  # below what the estimate resolves: no shape to fit
            continue
        x.append([1.0, math.log((1 - f["lights_share"]) + 10 * f["sun_contrast"]), -math.log1p(f["light_dominance"])])
        y.append(math.log(e / median[n, level]))
    (a, p, q), *_ = np.linalg.lstsq(np.array(x), np.array(y), rcond=None)
    res = np.array(y) - np.array(x) @ np.array([a, p, q])
    constants = (round(math.exp(a), 2), round(4 * p) / 4, round(8 * q) / 8)
    print(f"level {level}: GRAZING_FACTOR {{{constants[0]}, {constants[1]}, {constants[2]}}} "
          f"(log residuals: rms {np.sqrt(np.mean(res ** 2)):.2f}, from {res.min():.2f} to {res.max():.2f})")
    return constants


if __name__ == "__main__":
    main()
