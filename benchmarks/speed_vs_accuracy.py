"""Speed against accuracy of every shading method over its quality settings, in one run on the same
inputs: time per view change (shade_mesh on Suzanne subdivided to ~126k vertices, 2 threads, median
of interleaved runs) against relative RMSE versus wenv.reference, for specular-only Cook-Torrance
m = 0.05, 0.2 and 0.5 under two bundled HDRIs.  The error is over normals uniform on the sphere and
views uniform on their hemisphere, estimated as benchmarks/auto_quality.py does: `high` as a control
variate, its difference from each setting read on 50000 pairs drawn about the lighting's bright
reflections (weighted back to the uniform law), the reference's correction on the 8000 stored pairs
of benchmarks/accuracy.py.  Over the stored pairs alone a narrow lobe under a sun is a lottery.
Writes docs/speed_vs_accuracy.{json,csv,png}: a log-log chart with each method's Pareto front, and
the gather limit measured in the same rounds as the views (benchmarks/measure.py: every vertex's
128 kept RGB terms read once, the thesis's per-vertex sparse dot product), each setting's time over
it in the CSV.
Each setting's peak memory is measured too, in a fresh process (tests/helpers/memory.py: the growth of
peak resident memory while the shader is built and shades one view, under the first HDRI at m = 0.2,
rotation matrices loaded from the cache the timing run filled), and drawn against the time per view
change in docs/memory_vs_time.png.

    .venv/bin/python benchmarks/speed_vs_accuracy.py [--hdris sunset,city] [--repeats 5] [--pairs 8000]
                     [--control-pairs 50000] [--configs rotation,split_sum:default,3] [--no-memory] [--out DIR]
    .venv/bin/python benchmarks/speed_vs_accuracy.py --replot       # the charts again from the JSON
    .venv/bin/python benchmarks/speed_vs_accuracy.py --memory-only  # memory of the JSON's settings, added to it

Reference values come from tests/data/ (benchmarks/accuracy.py); keys missing there (an HDRI that is
not bundled) are computed (wenv.reference, ~20-40 ms per pair) and cached in out/.  `slicing` is
wavelet rotation with the resampling applied directly instead of through truncated matrices (the same
result when nothing is truncated), which is how resolutions whose matrices would not fit in memory
are shown."""
import argparse
import csv
import json
import math
import os
import statistics
import time

import numpy as np

import wenv
from accuracy import MATERIALS, load_reference, material
from bench_shade import orbit_eye, suzanne
from measure import OUT, ROOT, gather_limit_data, gather_limit_ms
from tests.helpers.measure import bundled_hdri, estimated_error, mirror_weighted_pairs, relative_rmse
from tests.helpers.memory import peak_memory

DOCS = os.path.join(ROOT, "docs")
ROUGHNESS = ["m0.05", "m0.2", "m0.5"]
# The thesis's 64/32/32 rotation setting (`default` until it moved to high's local resolution through
# slicing), spelled out: a partial dict takes its missing keys from `default`.
R64 = {"global": 64, "local": 32, "normals": 32, "views": 16, "coefficients": 128, "light_coefficients": 1024,
       "matrix_epsilon": 1e-3, "lights": 128, "light_threshold": 256.0, "light_tolerance": 0.003, "grazing": 0.0,
       "grazing_slopes": 0}
HIGH = wenv.QUALITY_PRESETS["high"]
CONFIGS = [
    ("rotation", "draft"),
    ("rotation", dict(R64, **{"global": 32, "local": 16, "normals": 16, "views": 8, "light_coefficients": 0})),
    ("rotation", R64),
    ("rotation", dict(R64, coefficients=512, light_coefficients=0)),
    ("rotation", dict(R64, normals=64, views=32, coefficients=512, light_coefficients=0)),
    ("slicing", dict(R64, coefficients=512, light_coefficients=0)),
    ("slicing", "default"),
    ("slicing", wenv.AUTO_LADDER[5]),  # auto's level 5: default's path, high's maps, bright features as lights
    ("slicing", "high"),
    ("slicing", dict(HIGH, coefficients=2048)),
    ("split_sum", {"prefilter": 32, "samples": 16, "lut": 16}),
    ("split_sum", "draft"),
    ("split_sum", "default"),
    ("split_sum", "high"),
    ("sh", {"order": 2}),
    ("sh", "draft"),
    ("sh", "default"),
    ("sh", {"order": 12, "views": 48}),
    ("sh", "high"),
]
COLOURS = {"rotation": "tab:blue", "slicing": "tab:cyan", "split_sum": "tab:red", "sh": "tab:green"}
MARKERS = {"rotation": "o", "slicing": "s", "split_sum": "^", "sh": "D"}


def short_label(method, q):
    """The settings that matter for each method, compactly."""
    if method in ("rotation", "slicing"):
        s = f"{q['global']}/{q['local']}/{q['normals']} v{q['views']} c{q['coefficients']}"
        s += f" lc{q['light_coefficients']}" if q["light_coefficients"] else ""
        # lights beyond the suns (threshold under 256x the mean) and the grazing path, as in `high`
        s += f" L{q['lights']}@{q['light_threshold']:g}" if q["light_threshold"] < 256 else ""
        s += f" tol{q['light_tolerance']:g}" if q["light_tolerance"] != 0.003 else ""
        return s + (f" g{q['grazing']:g}" if q.get("grazing") else "")
    if method == "split_sum":
        return f"p{q['prefilter']} s{q['samples']} t{q['lut']}"
    return f"L{q['order']} v{q['views']}"


def select_configs(spec):
    """CONFIGS picked by a comma-separated list of method names (all their settings), method:preset
    names or indices into CONFIGS; all of them for an empty spec."""
    if not spec:
        return list(CONFIGS)
    picked = []
    for token in spec.split(","):
        hits = [k for k, (method, q) in enumerate(CONFIGS)
                if token in (method, str(k)) or (isinstance(q, str) and token == f"{method}:{q}")]
        if not hits:
            raise SystemExit(f"--configs: {token!r} is no method, method:preset or index 0-{len(CONFIGS) - 1}")
        picked += [k for k in hits if k not in picked]
    return [CONFIGS[k] for k in sorted(picked)]


MEMORY_MATERIAL = "m0.2"
GATHER_TERMS = 128


def measure_memory(rows, hdri, pos, mesh_nrm):
    """Each row's peak memory in a fresh process (see tests/helpers/memory.py), stored as row["memory"]."""
    for row in rows:
        mem = peak_memory(row["method"], row["quality"], pos, mesh_nrm, hdri=hdri,
                          material=MATERIALS[MEMORY_MATERIAL], eye=orbit_eye(100))
        row["memory"] = {k: mem[k] for k in ("increment_mb", "peak_mb", "baseline_mb", "held_mb", "model_mb",
                                             "cache", "exact")}
        row.pop("memory_mb", None)  # an older, in-process estimate
        print(f"memory {row['method']:9s} {row['short']:28s} +{mem['increment_mb']:7.1f} MB "
              f"(peak {mem['peak_mb']:.0f} MB, shader's own count {mem['model_mb']:.1f} MB, matrices "
              f"{mem['cache']})", flush=True)


def load_references(hdris, pairs):
    stored = load_reference(pairs)
    nrm, v = stored["normals"], stored["views"]
    refs = {}
    for h in hdris:
        env = None
        for name in ROUGHNESS:
            key = f"{h}/{name}"
            if key in stored:
                refs[key] = stored[key]
                continue
            cache = os.path.join(OUT, "reference_cache", f"{h}_{name}_{pairs}.npy")
            if os.path.exists(cache):
                refs[key] = np.load(cache)
                continue
            env = env or wenv.load_environment(bundled_hdri(h))
            t0 = time.perf_counter()
            refs[key] = wenv.reference(env, material(MATERIALS[name]), nrm, v)
            print(f"reference {key}: {time.perf_counter() - t0:.0f} s", flush=True)
            os.makedirs(os.path.dirname(cache), exist_ok=True)
            np.save(cache, refs[key])
    return nrm, v, refs


def pareto(points):
    """Indices of the points no other point beats in both time and error, by time."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], float("inf")
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def chart(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hdris = results["hdris"]
    fig, axes = plt.subplots(len(hdris), len(ROUGHNESS), figsize=(5.2 * len(ROUGHNESS), 4.6 * len(hdris)),
                             squeeze=False, sharex=True)
    for r, h in enumerate(hdris):
        for c, name in enumerate(ROUGHNESS):
            ax = axes[r][c]
            for method in COLOURS:
                rows = [row for row in results["rows"] if row["method"] == method]
                if not rows:
                    continue
                pts = [(row["shade_ms"][name], row["rel_rmse"][f"{h}/{name}"]) for row in rows]
                ax.scatter(*zip(*pts), c=COLOURS[method], marker=MARKERS[method], s=28, zorder=3,
                           label={"slicing": "slicing (= rotation, untruncated matrices)"}.get(method, method))
                front = pareto(pts)
                ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], c=COLOURS[method], lw=1.2,
                        drawstyle="steps-post", alpha=0.8)
                for i in front:  # only the front is labelled: the rest would overlap it
                    ax.annotate(rows[i]["short"], pts[i], fontsize=6, xytext=(4, 3), textcoords="offset points",
                                color=COLOURS[method])
            if results.get("gather_limit_ms"):
                limit = results["gather_limit_ms"][name]
                ax.axvline(limit, c="0.3", ls="--", lw=1, zorder=1,
                           label=f"gather limit: {results['gather_terms']} RGB terms a vertex ({limit:.1f} ms)")
            ax.set_xscale("log")
            ax.set_yscale("log")
            percent = matplotlib.ticker.FuncFormatter(lambda y, _: f"{100 * y:.3g} %")
            ax.yaxis.set_major_formatter(percent)
            ax.yaxis.set_minor_formatter(percent)
            ax.tick_params(axis="y", which="minor", labelsize=6)
            ax.grid(True, which="both", alpha=0.25)
            ax.set_title(f"{h}, Cook-Torrance m = {name[1:]}", fontsize=10)
            if r == len(hdris) - 1:
                ax.set_xlabel(f"time per view change, ms ({results['vertices']} vertices, "
                              f"{results['threads']} threads)")
            if c == 0:
                ax.set_ylabel(f"relative RMSE vs reference (estimate, {results['control_pairs']} + "
                              f"{results['pairs']} pairs)")
    axes[0][min(1, len(ROUGHNESS) - 1)].legend(fontsize=7, loc="upper right")  # an empty corner there
    fig.suptitle("Speed against accuracy, specular-only Cook-Torrance (Beckmann, index 1.5): lines are each "
                 "method's Pareto front, labelled (rotation/slicing: global/local/normals map sides, v view grid, "
                 "c BRDF terms kept, lc lighting terms kept;\nsplit-sum: p prefilter side, s samples, t table "
                 "entries; SH: L order, v view elevations).  Slicing is rotation applied without matrices: "
                 "the same result as untruncated matrices, at sizes whose matrices would not fit.", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def near_groups(xs, ys, labels, apart=0.06):
    """Points of a log-log chart grouped while each is within `apart` decades of the group's first
    in both directions, so that settings which cost the same get one stacked label."""
    groups = []
    for x, y, label in sorted(zip(xs, ys, labels)):
        if groups:
            (x0, y0), members = groups[-1]
            if abs(math.log10(x / x0)) < apart and abs(math.log10(y / y0)) < apart:
                members.append(label)
                continue
        groups.append(((x, y), [label]))
    return groups


def memory_chart(results, path):
    """Time per view change (at the roughness memory was measured at) against the peak memory
    increment, one marker per setting; hollow markers are the shader's own count of its arrays."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [row for row in results["rows"] if "memory" in row]
    fig, ax = plt.subplots(figsize=(10, 5.6))
    for method in COLOURS:
        mine = [row for row in rows if row["method"] == method]
        if not mine:
            continue
        t = [row["shade_ms"][MEMORY_MATERIAL] for row in mine]
        mb = [max(row["memory"]["increment_mb"], 0.1) for row in mine]  # the log axis needs > 0
        ax.scatter(t, mb, c=COLOURS[method], marker=MARKERS[method], s=34, zorder=3, label=method)
        ax.scatter(t, [max(row["memory"]["model_mb"], 0.1) for row in mine], facecolors="none",
                   edgecolors=COLOURS[method], marker=MARKERS[method], s=34, lw=0.8, zorder=2)
        for (x, y), labels in near_groups(t, mb, [row["short"] for row in mine]):
            below = len(labels) > 1  # a stack of labels hangs down, clear of the points above
            ax.annotate("\n".join(labels), (x, y), fontsize=6, xytext=(5, -3 if below else 3),
                        textcoords="offset points", color=COLOURS[method], va="top" if below else "bottom")
    ax.scatter([], [], facecolors="none", edgecolors="grey", marker="o",
               label="hollow: the shader's\nown count (stats)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.25)
    ax.set_xlabel(f"time per view change, ms ({results['vertices']} vertices, {results['threads']} threads, "
                  f"m = {MEMORY_MATERIAL[1:]})")
    ax.set_ylabel("peak memory over the process's baseline, MB")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))  # outside: no point is hidden
    matrices = ", ".join(sorted({row["memory"]["cache"] for row in rows if row["method"] == "rotation"}))
    ax.set_title(f"Memory against speed: peak resident growth while the shader is built and shades one view "
                 f"(fresh process,\n{results.get('memory_hdri', results['hdris'][0])}, Cook-Torrance m = "
                 f"{MEMORY_MATERIAL[1:]}, rotation matrices {matrices or '-'}; floor 0.1 MB)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def write_outputs(results, out):
    os.makedirs(out, exist_ok=True)
    hdris = results["hdris"]
    with open(os.path.join(out, "speed_vs_accuracy.json"), "w") as fp:
        json.dump(results, fp, indent=1)
    with open(os.path.join(out, "speed_vs_accuracy.csv"), "w", newline="") as fp:
        w = csv.writer(fp)
        w.writerow(["method", "settings", "roughness", "shade_ms_median"] + [f"rel_rmse_{h}" for h in hdris]
                   + ["setup_s", "memory_increment_mb", "memory_peak_mb", "memory_held_mb", "memory_model_mb",
                      "over_gather_limit"])
        for row in results["rows"]:
            mem = row.get("memory")
            mem = [f"{mem[k]:.1f}" for k in ("increment_mb", "peak_mb", "held_mb", "model_mb")] if mem else [""] * 4
            for name in ROUGHNESS:
                w.writerow([row["method"], row["short"], name[1:], f"{row['shade_ms'][name]:.2f}"]
                           + [f"{row['rel_rmse'][f'{h}/{name}']:.5f}" for h in hdris]
                           + [f"{row['setup_s'][name]:.2f}"] + mem
                           + [f"{row['shade_ms'][name] / results['gather_limit_ms'][name]:.2f}"
                              if results.get("gather_limit_ms") else ""])
    charts(results, out)
    print("wrote", os.path.join(out, "speed_vs_accuracy.{json,csv,png}"))


def charts(results, out):
    chart(results, os.path.join(out, "speed_vs_accuracy.png"))
    if any("memory" in row for row in results["rows"]):
        memory_chart(results, os.path.join(out, "memory_vs_time.png"))
        print("wrote", os.path.join(out, "memory_vs_time.png"))
    else:
        print("no memory figures in the JSON: memory_vs_time.png not drawn")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--hdris", default="sunset,city")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--pairs", type=int, default=8000, help="stored reference pairs")
    ap.add_argument("--control-pairs", type=int, default=50000, help="weighted pairs the control is read on")
    ap.add_argument("--configs", default="", help="comma-separated methods, method:preset names or CONFIGS indices")
    ap.add_argument("--no-memory", action="store_true", help="skip the peak-memory measurements")
    ap.add_argument("--out", default=DOCS)
    ap.add_argument("--replot", action="store_true", help="redraw the charts from the JSON of an earlier run")
    ap.add_argument("--memory-only", action="store_true",
                    help="measure the memory of the settings in the JSON of an earlier run and add it there")
    args = ap.parse_args()
    if args.replot or args.memory_only:
        with open(os.path.join(args.out, "speed_vs_accuracy.json")) as fp:
            results = json.load(fp)
        if args.replot:
            charts(results, args.out)
            return
        pos, mesh_nrm = suzanne(4)
        assert len(pos) == results["vertices"], "the JSON was measured on another mesh"
        results["memory_hdri"] = results["hdris"][0]
        measure_memory(results["rows"], results["memory_hdri"], pos, mesh_nrm)
        write_outputs(results, args.out)
        return
    configs = select_configs(args.configs)
    hdris = args.hdris.split(",")
    wenv.set_num_threads(2)
    nrm, v, refs = load_references(hdris, args.pairs)
    envs = {h: wenv.load_environment(bundled_hdri(h)) for h in hdris}
    pos, mesh_nrm = suzanne(4)
    results = {"hdris": hdris, "pairs": len(nrm), "control_pairs": args.control_pairs, "vertices": len(pos),
               "threads": wenv.get_num_threads(),
               "repeats": args.repeats, "timing_hdri": hdris[0], "rows": [], "gather_limit_ms": {},
               "gather_terms": GATHER_TERMS}
    # the floor a view of these vertices could reach: each vertex's 128 kept terms read once
    gather = gather_limit_data(len(pos), GATHER_TERMS)
    print(f"{len(nrm)} pairs, Suzanne {len(pos)} vertices, {results['threads']} threads", flush=True)

    results["rows"] = [{"method": method, "preset": quality if isinstance(quality, str) else None,
                        "rel_rmse": {}, "rel_rmse_stored_pairs": {}, "shade_ms": {}, "shade_ms_all": {},
                        "setup_s": {}}
                       for method, quality in configs]
    for name in ROUGHNESS:
        # Fresh shaders per material, so every method's view changes start from the same state: the
        # first view (which fills rotation's tables) is not timed, the next ones are each a view not
        # seen before, timed in turn across all shaders so the machine's load falls on all alike.
        mat = material(MATERIALS[name])
        # the control (`high`) on the stored pairs and on pairs weighted toward the bright reflections
        many, control, control_many = {}, {}, {}
        for i, h in enumerate(hdris):
            many[h] = mirror_weighted_pairs(envs[h], MATERIALS[name]["lobes"][0]["alpha"], args.control_pairs,
                                            3000 + 100 * i + ROUGHNESS.index(name))
            high = wenv.Shader(envs[h], mat, quality="high", method="slicing")
            control[h], control_many[h] = high.shade(nrm, v), high.shade(*many[h][:2])
        del high
        shaders = []
        for (method, quality), row in zip(configs, results["rows"]):
            t0 = time.perf_counter()
            # rotation at 64/32/64 holds 2.1 GB of matrices, past the default budget of 1 GB
            sh = wenv.Shader(envs[hdris[0]], mat, quality=quality, method=method,
                             **({"memory_budget_mb": 4096} if method == "rotation" else {}))
            row["setup_s"][name] = time.perf_counter() - t0
            sh.shade_mesh(pos, mesh_nrm, orbit_eye(100))
            row["quality"], row["short"] = sh.quality, short_label(method, sh.quality)
            if method == "rotation":
                row["rotation_nnz"] = sh.stats.get("rotation_nnz")
            shaders.append(sh)
            print(f"{name}: built {method} {row['short']} in {row['setup_s'][name]:.1f} s", flush=True)
        times, limit = [[] for _ in shaders], []
        for i in range(args.repeats):
            for k, sh in enumerate(shaders):
                t0 = time.perf_counter()
                sh.shade_mesh(pos, mesh_nrm, orbit_eye(i))
                times[k].append((time.perf_counter() - t0) * 1e3)
            limit.append(gather_limit_ms(gather))  # in the same rounds, under the same load
        results["gather_limit_ms"][name] = statistics.median(limit)
        print(f"{name}: gather limit {results['gather_limit_ms'][name]:.1f} ms", flush=True)
        for sh, row, t in zip(shaders, results["rows"], times):
            row["shade_ms"][name] = statistics.median(t)
            row["shade_ms_all"][name] = t
            for h in hdris:
                sh.set_environment(envs[h])
                out, ref = sh.shade(nrm, v), refs[f"{h}/{name}"]
                row["rel_rmse"][f"{h}/{name}"] = estimated_error(out, ref, control[h], sh.shade(*many[h][:2]),
                                                                  control_many[h], many[h][2])
                row["rel_rmse_stored_pairs"][f"{h}/{name}"] = relative_rmse(out, ref)
            errs = "  ".join(f"{h} {100 * row['rel_rmse'][f'{h}/{name}']:6.2f}%" for h in hdris)
            print(f"{name:6s} {row['method']:9s} {row['short']:28s} {row['shade_ms'][name]:8.1f} ms  {errs}",
                  flush=True)
        del shaders, sh

    if not args.no_memory:  # after the timing, so rotation's matrices are in the cache
        results["memory_hdri"] = hdris[0]
        measure_memory(results["rows"], hdris[0], pos, mesh_nrm)
    write_outputs(results, args.out)


if __name__ == "__main__":
    main()
