"""Speed against accuracy of every shading method over its quality settings, in one run on the same
inputs: time per view change (shade_mesh on Suzanne subdivided to ~126k vertices, 2 threads, median
of interleaved runs) against relative RMSE versus wenv.reference on the fixed (normal, view) pairs of
examples/accuracy.py, for specular-only Cook-Torrance m = 0.05, 0.2 and 0.5 under two bundled HDRIs.
Writes docs/speed_vs_accuracy.{json,csv,png}: a log-log chart with each method's Pareto front.

    .venv/bin/python examples/speed_vs_accuracy.py [--hdris sunset,city] [--repeats 5] [--pairs 2000]
    .venv/bin/python examples/speed_vs_accuracy.py --replot     # the chart again from the JSON

Reference values come from tests/data/accuracy_reference.npz (--reference); keys missing there are
computed (wenv.reference, ~20-40 ms per pair) and cached in out/.  `slicing` is wavelet rotation with
the resampling applied directly instead of through truncated matrices (the same result when nothing
is truncated), which is how resolutions whose matrices would not fit in memory are shown."""
import argparse
import csv
import json
import os
import statistics
import time

import numpy as np

import wenv
from _common import OUT, ROOT, bundled_hdri, relative_rmse
from accuracy import DATA, MATERIALS, make_pairs, material
from bench_shade import orbit_eye, suzanne

DOCS = os.path.join(ROOT, "docs")
ROUGHNESS = ["m0.05", "m0.2", "m0.5"]
D = wenv.QUALITY_PRESETS["default"]
CONFIGS = [
    ("rotation", "draft"),
    ("rotation", {"global": 32, "local": 16, "normals": 16, "views": 8, "coefficients": 128, "light_coefficients": 0}),
    ("rotation", "default"),
    ("rotation", {"coefficients": 512, "light_coefficients": 0}),
    ("rotation", {"normals": 64, "views": 32, "coefficients": 512, "light_coefficients": 0}),
    ("slicing", {"coefficients": 512, "light_coefficients": 0}),
    ("slicing", "high"),
    ("slicing", {"global": 128, "local": 64, "normals": 64, "views": 32, "coefficients": 2048,
                 "light_coefficients": 0}),
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
        return s + (f" lc{q['light_coefficients']}" if q["light_coefficients"] else "")
    if method == "split_sum":
        return f"p{q['prefilter']} s{q['samples']} t{q['lut']}"
    return f"L{q['order']} v{q['views']}"


def rss_mb():
    """Resident memory of this process (Linux), MB: the growth when a shader is built is its size."""
    with open("/proc/self/status") as fp:
        for line in fp:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def load_references(path, hdris, pairs):
    nrm, v = make_pairs()
    stored = np.load(path) if os.path.exists(path) else None
    if stored is not None:
        assert np.array_equal(stored["normals"], nrm) and np.array_equal(stored["views"], v), "pairs differ"
    nrm, v = nrm[:pairs], v[:pairs]
    refs = {}
    for h in hdris:
        env = None
        for name in ROUGHNESS:
            key = f"{h}/{name}"
            if stored is not None and key in stored.files:
                refs[key] = stored[key][:pairs]
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
                ax.set_ylabel(f"relative RMSE vs reference ({results['pairs']} pairs)")
    axes[0][min(1, len(ROUGHNESS) - 1)].legend(fontsize=7, loc="upper right")  # an empty corner there
    fig.suptitle("Speed against accuracy, specular-only Cook-Torrance (Beckmann, index 1.5): lines are each "
                 "method's Pareto front, labelled (rotation/slicing: global/local/normals map sides, v view grid, "
                 "c BRDF terms kept, lc lighting terms kept;\nsplit-sum: p prefilter side, s samples, t table "
                 "entries; SH: L order, v view elevations).  Slicing is rotation applied without matrices: "
                 "the same result as untruncated matrices, at sizes whose matrices would not fit.", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--hdris", default="sunset,city")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--pairs", type=int, default=2000)
    ap.add_argument("--reference", default=DATA)
    ap.add_argument("--out", default=DOCS)
    ap.add_argument("--replot", action="store_true", help="redraw the chart from the JSON of an earlier run")
    args = ap.parse_args()
    if args.replot:
        with open(os.path.join(args.out, "speed_vs_accuracy.json")) as fp:
            chart(json.load(fp), os.path.join(args.out, "speed_vs_accuracy.png"))
        return
    hdris = args.hdris.split(",")
    wenv.set_num_threads(2)
    nrm, v, refs = load_references(args.reference, hdris, args.pairs)
    envs = {h: wenv.load_environment(bundled_hdri(h)) for h in hdris}
    pos, mesh_nrm = suzanne(4)
    results = {"hdris": hdris, "pairs": len(nrm), "vertices": len(pos), "threads": wenv.get_num_threads(),
               "repeats": args.repeats, "timing_hdri": hdris[0], "rows": []}
    print(f"{len(nrm)} pairs, Suzanne {len(pos)} vertices, {results['threads']} threads", flush=True)

    results["rows"] = [{"method": method, "preset": quality if isinstance(quality, str) else None,
                        "rel_rmse": {}, "shade_ms": {}, "shade_ms_all": {}, "setup_s": {}}
                       for method, quality in CONFIGS]
    for name in ROUGHNESS:
        # Fresh shaders per material, so every method's view changes start from the same state: the
        # first view (which fills rotation's tables) is not timed, the next ones are each a view not
        # seen before, timed in turn across all shaders so the machine's load falls on all alike.
        mat = material(MATERIALS[name])
        shaders = []
        for (method, quality), row in zip(CONFIGS, results["rows"]):
            before = rss_mb()
            t0 = time.perf_counter()
            sh = wenv.Shader(envs[hdris[0]], mat, quality=quality, method=method)
            row["setup_s"][name] = time.perf_counter() - t0
            sh.shade_mesh(pos, mesh_nrm, orbit_eye(100))
            if "memory_mb" not in row:  # the first round runs on fresh memory
                row["memory_mb"] = rss_mb() - before
            row["quality"], row["short"] = sh.quality, short_label(method, sh.quality)
            if method == "rotation":
                row["rotation_nnz"] = sh.stats.get("rotation_nnz")
            shaders.append(sh)
            print(f"{name}: built {method} {row['short']} in {row['setup_s'][name]:.1f} s, "
                  f"+{row['memory_mb']:.0f} MB", flush=True)
        times = [[] for _ in shaders]
        for i in range(args.repeats):
            for k, sh in enumerate(shaders):
                t0 = time.perf_counter()
                sh.shade_mesh(pos, mesh_nrm, orbit_eye(i))
                times[k].append((time.perf_counter() - t0) * 1e3)
        for sh, row, t in zip(shaders, results["rows"], times):
            row["shade_ms"][name] = statistics.median(t)
            row["shade_ms_all"][name] = t
            for h in hdris:
                sh.set_environment(envs[h])
                row["rel_rmse"][f"{h}/{name}"] = relative_rmse(sh.shade(nrm, v), refs[f"{h}/{name}"])
            errs = "  ".join(f"{h} {100 * row['rel_rmse'][f'{h}/{name}']:6.2f}%" for h in hdris)
            print(f"{name:6s} {row['method']:9s} {row['short']:28s} {row['shade_ms'][name]:8.1f} ms  {errs}",
                  flush=True)
        del shaders, sh

    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "speed_vs_accuracy.json"), "w") as fp:
        json.dump(results, fp, indent=1)
    with open(os.path.join(args.out, "speed_vs_accuracy.csv"), "w", newline="") as fp:
        w = csv.writer(fp)
        w.writerow(["method", "settings", "roughness", "shade_ms_median"] + [f"rel_rmse_{h}" for h in hdris]
                   + ["setup_s", "memory_mb"])
        for row in results["rows"]:
            for name in ROUGHNESS:
                w.writerow([row["method"], row["short"], name[1:], f"{row['shade_ms'][name]:.2f}"]
                           + [f"{row['rel_rmse'][f'{h}/{name}']:.5f}" for h in hdris]
                           + [f"{row['setup_s'][name]:.2f}", f"{row['memory_mb']:.0f}"])
    chart(results, os.path.join(args.out, "speed_vs_accuracy.png"))
    print("wrote", os.path.join(args.out, "speed_vs_accuracy.{json,csv,png}"))


if __name__ == "__main__":
    main()
