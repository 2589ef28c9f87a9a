"""docs/principled.md's gallery of Principled BSDF materials: spheres shaded by wenv (`default` and `high`,
both through slicing) beside wenv.reference and Cycles' render of the same sphere (through bpy), each
with its relative RMSE against the reference (Cycles': the render's noise included; its noise alone
is measured from a second seed).

    .venv/bin/python benchmarks/principled_gallery.py [--hdri sunset] [--size 96] [--samples 1024]   # ~5 min

Writes docs/principled_gallery.png and out/principled_gallery.json."""
import argparse
import json
import math
import os

import numpy as np

import wenv
from measure import OUT, ROOT
from tests.helpers.cycles_sphere import SphereScene
from tests.helpers.measure import bundled_hdri, relative_rmse

MATERIALS = {
    "paint\n(roughness 0.3)": dict(base_color=(0.6, 0.15, 0.08), roughness=0.3),
    "copper-like metal\n(roughness 0.35)": dict(base_color=(0.95, 0.64, 0.54), metallic=1.0, roughness=0.35),
    "coated paint\n(coat roughness 0.03)": dict(base_color=(0.05, 0.15, 0.45), roughness=0.5, coat_weight=1.0),
    "satin plastic\n(roughness 0.55)": dict(base_color=(0.8, 0.8, 0.75), roughness=0.55, ior=1.45),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hdri", default="sunset")
    ap.add_argument("--size", type=int, default=96)
    ap.add_argument("--samples", type=int, default=1024)
    args = ap.parse_args()
    scene = SphereScene(args.hdri, size=args.size, samples=args.samples)
    env = wenv.load_environment(bundled_hdri(args.hdri))
    rows, panels = {}, []
    for name, inputs in MATERIALS.items():
        mat = wenv.Principled(**inputs)
        scene.principled(**inputs)
        r = scene.compare(mat)
        ref = r["reference"]
        shaded = {}
        for method, preset in (("slicing", "default"), ("slicing", "high")):
            shaded[preset] = wenv.Shader(env, mat, quality=preset, method=method).shade(scene.normals, scene.views)
        row = {p: relative_rmse(v, ref) for p, v in shaded.items()}
        row.update(cycles=r["error"], cycles_noise=r["noise"], cycles_ratio=r["ratio"].tolist())
        rows[name.replace("\n", " ")] = row
        panels.append((name, [shaded["default"], shaded["high"], ref, r["cycles"]], row))
        print(f"{name.replace(chr(10), ' ')}: default {100 * row['default']:.2f} %, high {100 * row['high']:.2f} %, "
              f"Cycles {100 * row['cycles']:.2f} % (its noise {100 * row['cycles_noise'] / math.sqrt(2):.2f} %)",
              flush=True)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def display(rgb):
        c = np.clip(rgb, 0.0, 1.0)
        return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)

    fig, axes = plt.subplots(len(panels), 4, figsize=(9.5, 2.5 * len(panels)))
    for i, (name, images, row) in enumerate(panels):
        titles = [f"wenv default: {100 * row['default']:.2f} %", f"wenv high: {100 * row['high']:.2f} %",
                  "wenv.reference", f"Cycles {args.samples} spp: {100 * row['cycles']:.2f} %"]
        for j, (rgb, title) in enumerate(zip(images, titles)):
            img = np.zeros((args.size, args.size, 3), np.float32)
            img[scene.mask] = rgb
            axes[i, j].imshow(display(img))
            axes[i, j].set_title(title, fontsize=8.5)
            axes[i, j].axis("off")
        axes[i, 0].text(-0.08, 0.5, name, transform=axes[i, 0].transAxes, rotation=90, va="center", ha="right",
                        fontsize=8.5)
    fig.suptitle(f"Principled BSDF under {args.hdri}: relative RMSE against wenv.reference "
                 f"(Cycles': its sampling noise included)", fontsize=10)
    path = os.path.join(ROOT, "docs", "principled_gallery.png")
    fig.savefig(path, dpi=90, bbox_inches="tight")
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "principled_gallery.json"), "w") as fp:
        json.dump({"hdri": args.hdri, "size": args.size, "samples": args.samples, "rows": rows}, fp, indent=2)
    print("wrote", path)


if __name__ == "__main__":
    main()
