"""Gloss at 20, 60 and 85 degrees against roughness for one Beckmann and one GGX lobe.

Writes a CSV table and a chart (matplotlib PNG) with the instruments' rule of thumb marked: read 60
degrees for 10-70 GU, 20 degrees above 70 GU, 85 degrees below 10 GU (ISO 2813 / ASTM D523).

    python benchmarks/gloss_sweep.py --out docs        # docs/gloss_sweep.csv, docs/gloss_sweep.png
"""
import argparse
import csv
import os
import time

import numpy as np

import wenv

GEOMETRIES = (20, 60, 85)
COLOURS = {20: "tab:blue", 60: "tab:green", 85: "tab:red"}


def sweep(distribution, roughness, ior, diffuse):
    rows = []
    for m in roughness:
        mat = wenv.CookTorrance(diffuse=diffuse, lobes=[dict(alpha=float(m), ior=ior)], distribution=distribution)
        readings = wenv.gloss(mat, GEOMETRIES, return_error=True)
        rows.append((distribution, float(m), *[g for g, _ in readings], *[e for _, e in readings]))
    return rows


def recommended(g60):
    """Geometry an instrument user would read, from the 60 degree reading."""
    return 20 if g60 > 70.0 else (85 if g60 < 10.0 else 60)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="docs", help="output folder (default: docs)")
    ap.add_argument("--points", type=int, default=41, help="roughness values per distribution (default 41)")
    ap.add_argument("--ior", type=float, default=1.5, help="index of refraction of the lobe (default 1.5)")
    ap.add_argument("--diffuse", type=float, default=0.0, help="Lambertian albedo under the lobe (default 0)")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)

    roughness = np.geomspace(1e-4, 1.0, args.points)
    t0 = time.perf_counter()
    rows = sweep("beckmann", roughness, args.ior, args.diffuse) + sweep("ggx", roughness, args.ior, args.diffuse)
    elapsed = time.perf_counter() - t0
    smooth = wenv.gloss(wenv.CookTorrance(diffuse=args.diffuse, lobes=[dict(alpha=1e-4, ior=args.ior)]),
                        GEOMETRIES, smooth=True)

    csv_path = os.path.join(args.out, "gloss_sweep.csv")
    with open(csv_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["distribution", "roughness", "gu20", "gu60", "gu85", "err20", "err60", "err85", "recommended"])
        for r in rows:
            w.writerow([r[0], f"{r[1]:.6g}", *[f"{x:.4f}" for x in r[2:5]], *[f"{x:.2g}" for x in r[5:8]],
                        recommended(r[3])])
    print(f"{len(rows)} materials x 3 geometries in {elapsed:.2f} s -> {csv_path}")
    print(f"smooth limit (ior {args.ior}): " + ", ".join(f"{g} deg {v:.2f} GU" for g, v in zip(GEOMETRIES, smooth)))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), sharey=True)
    for ax, dist in zip(axes, ("beckmann", "ggx")):
        data = np.array([r[1:5] for r in rows if r[0] == dist])
        m, g = data[:, 0], data[:, 1:]
        # Shade the roughness ranges by the geometry the rule of thumb picks (from the 60 deg reading).
        pick = np.array([recommended(x) for x in g[:, 1]])
        edges = np.sqrt(m[1:] * m[:-1])
        lo = np.concatenate([[m[0]], edges])
        hi = np.concatenate([edges, [m[-1]]])
        for geom in GEOMETRIES:
            sel = pick == geom
            for a, b in zip(lo[sel], hi[sel]):
                ax.axvspan(a, b, color=COLOURS[geom], alpha=0.08, lw=0)
        for k, geom in enumerate(GEOMETRIES):
            ax.plot(m, np.maximum(g[:, k], 1e-3), color=COLOURS[geom], lw=2, label=f"{geom}°")
            ax.plot(m[pick == geom], np.maximum(g[pick == geom, k], 1e-3), "o", ms=3.5, color=COLOURS[geom])
        ax.axhline(70, color="0.4", ls="--", lw=0.8)
        ax.axhline(10, color="0.4", ls=":", lw=0.8)
        ax.text(m[-1], 120, "60° reads > 70 GU: use 20°", fontsize=8, color="0.3", ha="right")
        ax.text(m[0], 8.0, "60° reads < 10 GU: use 85°", fontsize=8, color="0.3", va="top")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_ylim(5e-3, 200)
        ax.set_xlabel("roughness m (Beckmann RMS slope / GGX alpha)")
        ax.set_title(f"{dist.upper() if dist == 'ggx' else 'Beckmann'} lobe, n = {args.ior}"
                     + (f", diffuse {args.diffuse}" if args.diffuse else ""))
        ax.grid(True, which="both", alpha=0.2)
    axes[0].set_ylabel("specular gloss (GU)")
    axes[0].legend(title="geometry", loc="lower left")
    fig.suptitle("wenv virtual glossmeter (ISO 2813): dots and shading = geometry the rule of thumb picks "
                 "(60° for 10–70 GU at 60°, 20° above, 85° below)", fontsize=9)
    fig.tight_layout()
    png_path = os.path.join(args.out, "gloss_sweep.png")
    fig.savefig(png_path, dpi=110)
    print(f"chart -> {png_path}")


if __name__ == "__main__":
    main()
