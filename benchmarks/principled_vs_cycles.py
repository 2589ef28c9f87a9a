"""wenv.reference of Principled BSDF materials against Cycles' render of them (through bpy): a grid of
dielectrics, metals, coated paints, sheens and a rough diffuse at several roughnesses and colours, each on an unoccluded
sphere under bundled HDRIs (tests/helpers/cycles_sphere.py), rendered twice with different seeds so
that Cycles' own noise is measured beside the difference.  docs/principled.md's Cycles table.

    .venv/bin/python benchmarks/principled_vs_cycles.py [--hdris sunset,forest,studio] [--size 48] [--samples 512]

Per case: the relative RMSE of one render against the other (/ sqrt 2: one render's noise), of their
mean against wenv.reference, what the mean's own noise accounts for (noise / sqrt 2), and the mean
radiance per channel, Cycles over wenv.  Writes out/principled_vs_cycles.json; about 20 minutes."""
import argparse
import json
import os
import time

import numpy as np

import wenv
from measure import OUT
from tests.helpers.cycles_sphere import SphereScene

GRID = {
    "paint r0.1": dict(base_color=(0.6, 0.15, 0.08), roughness=0.1),
    "paint r0.3": dict(base_color=(0.6, 0.15, 0.08), roughness=0.3),
    "paint r0.6": dict(base_color=(0.6, 0.15, 0.08), roughness=0.6),
    "white plastic r0.2, IOR 1.45": dict(base_color=(0.9, 0.9, 0.9), roughness=0.2, ior=1.45),
    "blue, Specular IOR Level 1, tint": dict(base_color=(0.1, 0.2, 0.7), roughness=0.3, specular_ior_level=1.0,
                                             specular_tint=(1.0, 0.8, 0.6)),
    "metal r0.3": dict(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.3),
    "metal r0.6, tint": dict(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.6, specular_tint=(0.5, 0.5, 0.5)),
    "half metal r0.4": dict(base_color=(0.5, 0.5, 0.55), metallic=0.5, roughness=0.4),
    "coated paint, coat r0.03": dict(base_color=(0.2, 0.3, 0.6), roughness=0.5, coat_weight=1.0),
    "coated paint, coat r0.15, tint": dict(base_color=(0.2, 0.3, 0.6), roughness=0.5, coat_weight=1.0,
                                           coat_roughness=0.15, coat_tint=(0.9, 0.7, 0.5)),
    "coated metal": dict(base_color=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.4, coat_weight=0.8,
                         coat_roughness=0.05),
    "GGX (not Multiscatter) metal r0.6": dict(base_color=(0.9, 0.9, 0.9), metallic=1.0, roughness=0.6,
                                              distribution="ggx"),
    "velvet: sheen r0.3 over paint": dict(base_color=(0.3, 0.05, 0.1), roughness=0.6, sheen_weight=1.0,
                                          sheen_roughness=0.3, sheen_tint=(1.0, 0.8, 0.9)),
    "sheen r0.8 under a coat": dict(base_color=(0.1, 0.3, 0.2), roughness=0.5, sheen_weight=0.7,
                                    sheen_roughness=0.8, coat_weight=1.0, coat_roughness=0.2),
    "rough diffuse (Diffuse Roughness 1)": dict(base_color=(0.6, 0.4, 0.3), roughness=0.5, diffuse_roughness=1.0),
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hdris", default="sunset,forest,studio")
    ap.add_argument("--size", type=int, default=48)
    ap.add_argument("--samples", type=int, default=512)
    ap.add_argument("--cases", default="", help="names of GRID separated by semicolons (default: all)")
    args = ap.parse_args()
    names = [c for c in args.cases.split(";") if c] or list(GRID)
    results = []
    for hdri in args.hdris.split(","):
        scene = SphereScene(hdri, size=args.size, samples=args.samples)
        for name in names:
            inputs = GRID[name]
            t0 = time.perf_counter()
            scene.principled(**inputs)
            r = scene.compare(wenv.Principled(**inputs))
            row = {"hdri": hdri, "material": name, "inputs": inputs, "noise": r["noise"],
                   "noise_of_mean": r["noise_of_mean"], "error": r["error"], "ratio": r["ratio"].tolist(),
                   "seconds": time.perf_counter() - t0}
            results.append(row)
            print(f"{hdri:<9} {name:<34} error {100 * r['error']:5.2f} %  noise of the mean "
                  f"{100 * r['noise_of_mean']:5.2f} %  ratio {np.round(r['ratio'], 4)}", flush=True)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "principled_vs_cycles.json"), "w") as fp:
        json.dump({"size": args.size, "samples": args.samples, "pixels": int(scene.mask.sum()), "results": results},
                  fp, indent=2)
    within = sum(r["error"] <= 1.5 * r["noise_of_mean"] + 0.003 for r in results)
    ratios = np.array([r["ratio"] for r in results])
    print(f"{within} of {len(results)} within 1.5x the mean's noise + 0.3 %; mean radiance ratio "
          f"{ratios.min():.4f} .. {ratios.max():.4f}")


if __name__ == "__main__":
    main()
