"""Where each shading method holds and where it breaks down: relative error against wenv.reference
swept over roughness (0.01 to 1), view angle (0 to 89.9 degrees) and normal direction (a great
circle through both poles and the maps' seams), under two bundled HDRIs (sunset; city, whose sun
holds a fifth of the light), plus the largest colour jump between views 0.1 degrees apart.
Writes docs/stability.{png,json}.

    .venv/bin/python benchmarks/stability.py [--hdris sunset,city] [--pairs 48] [--downsample 2]

The environments are box-filtered by --downsample (flux kept) so the brute-force reference stays
cheap; the references are cached in out/stability_reference/.  Materials are specular-only
Cook-Torrance (Beckmann, index 1.5, white), as in benchmarks/accuracy.py."""
import argparse
import json
import math
import os
import time

import numpy as np

import wenv
from measure import OUT, ROOT
from tests.helpers.measure import bundled_hdri

DOCS = os.path.join(ROOT, "docs")
CONFIGS = [
    ("rotation", "draft"), ("slicing", "default"), ("slicing", "high"),
    ("split_sum", "default"), ("split_sum", "high"),
    ("sh", {"order": 2}), ("sh", "draft"), ("sh", "default"), ("sh", "high"),
]
ROUGHNESS_SWEEP = [0.01, 0.02, 0.035, 0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0]
ANGLE_SWEEP = [0, 15, 30, 45, 60, 70, 75, 80, 85, 88, 89, 89.9]
SWEEP_ROUGHNESS = 0.2      # view-angle and normal sweeps
NORMAL_STEP = 2.0          # degrees along the great circle
NORMAL_VIEWS = [(a, az) for a in (20.0, 50.0, 75.0) for az in (0.0, 120.0, 240.0)]


def label(method, quality):
    if isinstance(quality, str):
        return f"{method} {quality}"
    return f"{method} " + ",".join(f"{k}={v}" for k, v in quality.items())


def specular(m):
    return wenv.CookTorrance(diffuse=0.0, lobes=[dict(specular=(1, 1, 1), roughness=m, ior=1.5)])


def unit(a):
    a = np.asarray(a, np.float64)
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def tilted(nrm, angle_deg, azimuth_deg, helper):
    """Views at angle_deg from each normal, at an azimuth measured from a tangent fixed by `helper`."""
    t = unit(np.cross(nrm, helper))
    b = np.cross(nrm, t)
    a, z = np.radians(angle_deg)[..., None], np.radians(azimuth_deg)[..., None]
    return unit(np.cos(a) * nrm + np.sin(a) * (np.cos(z) * t + np.sin(z) * b))


def random_normals(n, seed):
    return unit(np.random.default_rng(seed).normal(size=(n, 3)))


def downsampled(name, factor):
    env = wenv.load_environment(bundled_hdri(name))
    px = env.pixels[..., :3]
    h, w = px.shape[0] // factor, px.shape[1] // factor
    return wenv.Environment(np.ascontiguousarray(px[:h * factor, :w * factor].reshape(h, factor, w, factor, 3)
                                                 .mean(axis=(1, 3)), dtype=np.float32))


class References:
    """wenv.reference values, cached on disk by a name that says what they are."""

    def __init__(self, folder):
        self.folder = folder
        os.makedirs(folder, exist_ok=True)

    def get(self, key, env, mat, nrm, v):
        path = os.path.join(self.folder, key + ".npz")
        if os.path.exists(path):
            data = np.load(path)
            if np.array_equal(data["normals"], nrm) and np.array_equal(data["views"], v):
                return data["values"]
        t0 = time.perf_counter()
        values = wenv.reference(env, mat, nrm, v)
        print(f"  reference {key}: {len(nrm)} pairs, {time.perf_counter() - t0:.1f} s", flush=True)
        np.savez_compressed(path, normals=nrm, views=v, values=values)
        return values


def rel_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2) / max(np.mean(b ** 2), 1e-30)))


def groups_error(out, ref, groups):
    """Relative RMSE within each consecutive group of rows."""
    return [rel_rmse(o, r) for o, r in zip(np.split(out, groups), np.split(ref, groups))]


def flicker(shader, nrm, elevation_deg, step_deg=0.1):
    """Largest colour change between views step_deg apart on a ring around nrm, over the ring's
    largest colour (both Euclidean RGB)."""
    az = np.arange(0, 360, step_deg)
    helper = np.array([0.31, 0.52, 0.79])
    nn = np.tile(unit(nrm), (len(az), 1))
    v = tilted(nn, np.full(len(az), elevation_deg), az, helper)
    out = shader.shade(nn.astype(np.float32), v.astype(np.float32)).astype(np.float64)
    jump = np.linalg.norm(np.diff(np.vstack([out, out[:1]]), axis=0), axis=1)
    return float(jump.max() / np.linalg.norm(out, axis=1).max())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--hdris", default="sunset,city")
    ap.add_argument("--pairs", type=int, default=48, help="pairs per point of the roughness and angle sweeps")
    ap.add_argument("--downsample", type=int, default=2)
    ap.add_argument("--out", default=DOCS)
    args = ap.parse_args()
    wenv.set_num_threads(2)
    refs = References(os.path.join(OUT, "stability_reference"))
    hdris = args.hdris.split(",")
    labels = [label(m, q) for m, q in CONFIGS]
    results = {"hdris": hdris, "downsample": args.downsample, "pairs": args.pairs, "configs": labels,
               "roughness": ROUGHNESS_SWEEP, "angles": ANGLE_SWEEP, "sweep_roughness": SWEEP_ROUGHNESS,
               "normal_step_deg": NORMAL_STEP, "normal_views": NORMAL_VIEWS, "sweeps": {}}
    n_pairs = args.pairs
    # the roughness sweep: random normals, random views on their hemispheres
    nrm_r = random_normals(n_pairs, 1)
    view_r = unit(np.random.default_rng(2).normal(size=(n_pairs, 3)))
    view_r[np.sum(nrm_r * view_r, axis=1) < 0] *= -1
    # the angle sweep: random normals, each angle at a random azimuth
    nrm_a = np.tile(random_normals(n_pairs, 3), (len(ANGLE_SWEEP), 1))
    az_a = np.random.default_rng(4).uniform(0, 360, len(nrm_a))
    ang_a = np.repeat(ANGLE_SWEEP, n_pairs)
    view_a = tilted(nrm_a, ang_a, az_a, np.array([0.31, 0.52, 0.79]))
    # the normal sweep: n = (sin t, 0, cos t) passes +Z, the +X fold of the octahedral map, -Z (the
    # frame's singular point, on the map's y = 0 seam) and -X (the equirect seam)
    t = np.radians(np.arange(0, 360, NORMAL_STEP))
    nrm_n = np.repeat(np.stack([np.sin(t), 0 * t, np.cos(t)], axis=1), len(NORMAL_VIEWS), axis=0)
    va = np.tile([a for a, _ in NORMAL_VIEWS], len(t))
    vz = np.tile([z for _, z in NORMAL_VIEWS], len(t))
    view_n = tilted(nrm_n, va, vz, np.array([0.0, 1.0, 0.0]))
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    nrm_r, view_r, nrm_a, view_a, nrm_n, view_n = map(f32, (nrm_r, view_r, nrm_a, view_a, nrm_n, view_n))

    for h in hdris:
        env = downsampled(h, args.downsample)
        tag = f"{h}_d{args.downsample}"
        print(f"{h} ({env.pixels.shape[1]} x {env.pixels.shape[0]})", flush=True)
        ref_r = {m: refs.get(f"{tag}_rough{m}_{n_pairs}", env, specular(m), nrm_r, view_r) for m in ROUGHNESS_SWEEP}
        mat = specular(SWEEP_ROUGHNESS)
        ref_a = refs.get(f"{tag}_angle_m{SWEEP_ROUGHNESS}_{n_pairs}", env, mat, nrm_a, view_a)
        ref_n = refs.get(f"{tag}_normal_m{SWEEP_ROUGHNESS}_{NORMAL_STEP}", env, mat, nrm_n, view_n)
        sweeps = results["sweeps"][h] = {}
        for (method, quality), name in zip(CONFIGS, labels):
            t0 = time.perf_counter()
            sh = wenv.Shader(env, specular(ROUGHNESS_SWEEP[0]), quality=quality, method=method)
            rough = []
            for m in ROUGHNESS_SWEEP:
                sh.set_material(specular(m))
                out = sh.shade(nrm_r, view_r)
                assert np.all(np.isfinite(out)), (name, m)
                rough.append(rel_rmse(out, ref_r[m]))
            sh.set_material(mat)
            out_a = sh.shade(nrm_a, view_a)
            out_n = sh.shade(nrm_n, view_n)
            assert np.all(np.isfinite(out_a)) and np.all(np.isfinite(out_n)), name
            jumps = {f"{e:g}": flicker(sh, np.array(n), e) for n in ([0.3, -0.4, 0.87], [0.0, 0.0, -1.0])
                     for e in (30.0, 80.0)}
            sweeps[name] = {
                "roughness": rough,
                "angle": groups_error(out_a, ref_a, len(ANGLE_SWEEP)),
                "normal": groups_error(out_n, ref_n, len(t)),
                "flicker": max(jumps.values()),
                "flicker_by_elevation": jumps,
            }
            s = sweeps[name]
            print(f"  {name:28s} m=0.01 {100 * rough[0]:6.1f}%  m=1 {100 * rough[-1]:6.2f}%  "
                  f"0deg {100 * s['angle'][0]:6.2f}%  89.9deg {100 * s['angle'][-1]:6.1f}%  "
                  f"normals worst {100 * max(s['normal']):6.2f}% median {100 * np.median(s['normal']):6.2f}%  "
                  f"flicker {100 * s['flicker']:.2f}%  ({time.perf_counter() - t0:.1f} s)", flush=True)

    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "stability.json"), "w") as fp:
        json.dump(results, fp, indent=1)
    chart(results, os.path.join(args.out, "stability.png"))
    print("wrote", os.path.join(args.out, "stability.{json,png}"))


def chart(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hdris = results["hdris"]
    colours = {"rotation": "tab:blue", "slicing": "tab:cyan", "split_sum": "tab:red", "sh": "tab:green"}
    styles = ["-", "--", ":", "-."]
    fig, axes = plt.subplots(3, len(hdris), figsize=(6.5 * len(hdris), 12), squeeze=False)
    t = np.arange(0, 360, results["normal_step_deg"])
    for c, h in enumerate(hdris):
        seen = {}
        for name, s in results["sweeps"][h].items():
            method = name.split()[0]
            k = seen.setdefault(method, [0])
            style = dict(color=colours[method], ls=styles[k[0] % 4], lw=1.3, label=name)
            k[0] += 1
            axes[0][c].plot(results["roughness"], s["roughness"], marker=".", **style)
            axes[1][c].plot(results["angles"], s["angle"], marker=".", **style)
            axes[2][c].plot(t, s["normal"], **style)
        ax = axes[0][c]
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("Cook-Torrance roughness m (Beckmann)")
        ax.set_title(f"{h}: error against roughness ({results['pairs']} random pairs per point)", fontsize=10)
        ax = axes[1][c]
        ax.set_yscale("log")
        ax.set_xlabel("view angle from the normal, degrees")
        ax.set_title(f"{h}: error against view angle (m = {results['sweep_roughness']}, "
                     f"{results['pairs']} normals per point)", fontsize=10)
        ax = axes[2][c]
        ax.set_yscale("log")
        ax.set_xlabel("normal (sin t, 0, cos t): t in degrees")
        for x, what in ((0, "+Z"), (90, "+X fold"), (180, "-Z: frame pole, seam"), (270, "-X: equirect seam")):
            ax.axvline(x, color="0.6", lw=0.8)
            ax.text(x + 2, 0.98, what, transform=ax.get_xaxis_transform(), fontsize=7, va="top", color="0.4")
        ax.set_title(f"{h}: error against normal direction (m = {results['sweep_roughness']}, "
                     f"{len(results['normal_views'])} views per normal)", fontsize=10)
        for r in range(3):
            axes[r][c].grid(True, which="both", alpha=0.25)
            axes[r][c].set_ylabel("relative RMSE vs reference")
    axes[0][0].legend(fontsize=7, ncol=2)
    fig.suptitle(f"Stability: environments box-filtered by {results['downsample']}, specular-only Cook-Torrance, "
                 "index 1.5; slicing = rotation without matrix truncation", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
