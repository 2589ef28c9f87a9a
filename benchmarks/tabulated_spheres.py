"""Spheres shaded with tabulated BRDFs (90 x 90 x 180, MERL's layout) next to the reference: docs/measured_brdfs.md's
picture of measured and tabulated materials.  Each row is one table -- a paint (a Cook-Torrance lobe
over a coloured diffuse floor), a retro-reflective lobe and a lobe whose colour shifts with the
difference angle, neither of them a Cook-Torrance lobe -- shaded at `default` and
`high` (both through slicing) and by wenv.reference, with the difference of `high` from the reference x 10.

    .venv/bin/python benchmarks/tabulated_spheres.py [--hdri sunset] [--size 96]   # ~5 min

Writes docs/tabulated_spheres.png and out/tabulated_spheres.json (errors and times)."""
import argparse
import json
import os
import sys
import time

import numpy as np

import wenv
from measure import OUT, ROOT, sphere_image, tone_map
from tests.helpers import merl_files
from tests.helpers.measure import bundled_hdri, relative_rmse

ROWS = {
    "paint: m = 0.2 lobe\nover a diffuse floor": {"brdf": "cook_torrance", "roughness": 0.2,
                                                            "diffuse": [0.5, 0.15, 0.08]},
    "retro-reflective": {"brdf": "retro", "width": 0.5},
    "colour shifting\nwith theta_d": {"brdf": "tinted", "roughness": 0.2},
}
COLUMNS = (("slicing", "default"), ("slicing", "high"))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hdri", default="sunset")
    ap.add_argument("--size", type=int, default=96)
    args = ap.parse_args()
    env = wenv.load_environment(bundled_hdri(args.hdri))
    mask, normals, view = sphere_image(args.size)
    views = np.broadcast_to(view, normals.shape).copy()
    results, images = {}, []
    for name, spec in ROWS.items():
        mat = wenv.Tabulated(merl_files.table_of(spec))
        t0 = time.perf_counter()
        ref = wenv.reference(env, mat, normals, views)
        row = {"reference_s": time.perf_counter() - t0}
        shaded = []
        for method, preset in COLUMNS:
            shader = wenv.Shader(env, mat, quality=preset, method=method)
            shader.shade(normals, views)
            t0 = time.perf_counter()
            rgb = shader.shade(normals, views)
            row[preset] = {"relative_rmse": relative_rmse(rgb, ref), "shade_ms": 1e3 * (time.perf_counter() - t0)}
            shaded.append(rgb)
        print(f"{name.replace(chr(10), ' ')}: " + ", ".join(f"{p} {100 * row[p]['relative_rmse']:.2f} %" for _, p in COLUMNS), flush=True)
        results[name] = row
        images.append((name, shaded + [ref, np.abs(shaded[-1] - ref) * 10], row))

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(images), 4, figsize=(10, 2.7 * len(images)))
    for r, (name, panels, row) in enumerate(images):
        l_max = float(np.percentile(panels[2] @ np.array([0.2126, 0.7152, 0.0722]), 99.5))
        titles = [f"default: {100 * row['default']['relative_rmse']:.2f} %",
                  f"high: {100 * row['high']['relative_rmse']:.2f} %", "reference", "|high - reference| x 10"]
        for c, (rgb, title) in enumerate(zip(panels, titles)):
            img = np.zeros((args.size, args.size, 3), np.float32)
            img[mask] = tone_map(rgb, l_max)
            axes[r, c].imshow(img)
            axes[r, c].set_title(title, fontsize=9)
            axes[r, c].axis("off")
        axes[r, 0].text(-0.08, 0.5, name, transform=axes[r, 0].transAxes, rotation=90, va="center", ha="right",
                        fontsize=9)
    fig.suptitle(f"Tabulated BRDFs (90 x 90 x 180) under {args.hdri}", fontsize=11)
    os.makedirs(os.path.join(ROOT, "docs"), exist_ok=True)
    path = os.path.join(ROOT, "docs", "tabulated_spheres.png")
    fig.savefig(path, dpi=90, bbox_inches="tight")
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "tabulated_spheres.json"), "w") as fp:
        json.dump({"hdri": args.hdri, "size": args.size, "rows": results}, fp, indent=2)
    print("wrote", path)


if __name__ == "__main__":
    main()
