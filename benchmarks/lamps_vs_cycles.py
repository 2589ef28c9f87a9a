"""wenv's lamps against Cycles: a sphere resting on a square (its contact shadow), lit by the scene's
Light objects as the add-on reads them (addon/lamps.py), rendered by Cycles with direct light only
(Max Bounces 0) at two seeds, beside wenv.reference and wenv's `default` shading (both with the
sphere's and the square's shadows) on the sphere's pixels.

Lightings:
  - four lamps (a sun, a soft point lamp, a spot and an area lamp) under a black World;
  - the same four under the bundled forest and sunset HDRIs;
  - a point lamp close to the surface (radius 0.25 at 0.4 from the sphere) and a large area lamp
    (3 x 3 at 1.2 above), where the lamp's solid angle matters.
Materials: a Principled paint (roughness 0.5) and a metal (roughness 0.35).  Prints relative RMSEs
(over the reference's RMS) beside the noise of Cycles' mean and writes out/lamps_vs_cycles.json.
A few minutes.

    python benchmarks/lamps_vs_cycles.py [--size 64] [--samples 512]
"""
import argparse
import json
import math
import os
import platform
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
import bpy  # noqa: E402
import wenv  # noqa: E402

from addon import engine, lamps  # noqa: E402
from tests.conftest import hdri_path  # noqa: E402
from tests.helpers.cycles_sphere import LAMP_SETUPS, SphereScene  # noqa: E402

MATERIALS = {"paint": dict(base_color=(0.7, 0.5, 0.3), roughness=0.5),
             "metal": dict(base_color=(0.9, 0.7, 0.4), metallic=1.0, roughness=0.35)}


CASES = [("four lamps", None), ("four lamps", "forest"), ("four lamps", "sunset"), ("close point lamp", None),
         ("large area lamp", None)]


def run_case(lighting, hdri, size, samples):
    image = None if hdri else np.zeros((8, 16, 3), np.float32)
    scene = SphereScene(hdri or "forest", size=size, samples=samples, image=image, ground=True)
    LAMP_SETUPS[lighting](scene)
    bpy.context.view_layer.update()
    scene.scene.cycles.max_bounces = 0
    settings, notes = lamps.read_lamps(scene.scene)
    lit = engine.make_lamps(settings)
    env = wenv.load_environment(hdri_path(hdri)) if hdri else wenv.Environment(image)
    occluders = scene.occluders()
    occlusion = occluders.occlusion(scene.positions, scene.normals)
    rows = []
    for name, inputs in MATERIALS.items():
        scene.principled(**inputs)
        a, b = (scene.render(seed)[scene.mask].astype(np.float64) for seed in (1, 2))
        mat = wenv.Principled(**inputs)
        ref = wenv.reference(env, mat, scene.normals, scene.views, positions=scene.positions, occluders=occluders,
                             lamps=lit).astype(np.float64)
        shaded = wenv.Shader(env, mat, quality="default").shade(
            scene.normals, scene.views, occlusion=occlusion, bounce=None, positions=scene.positions,
            lamps=lit).astype(np.float64)
        scale = math.sqrt(float(np.mean(ref ** 2)))
        cycles = (a + b) / 2
        row = dict(lighting=lighting, hdri=hdri or "black", material=name, pixels=len(ref),
                   noise_of_mean=math.sqrt(float(np.mean((a - b) ** 2)) / 2) / scale / math.sqrt(2),
                   reference=math.sqrt(float(np.mean((cycles - ref) ** 2))) / scale,
                   default=math.sqrt(float(np.mean((cycles - shaded) ** 2))) / scale,
                   mean_ratio=float(cycles.mean() / ref.mean()), notes=notes)
        rows.append(row)
        print(f"{lighting:17s} {row['hdri']:7s} {name:6s}: reference {100 * row['reference']:5.2f} %, default "
              f"{100 * row['default']:5.2f} %, Cycles' noise of its mean {100 * row['noise_of_mean']:5.2f} %, "
              f"Cycles / reference {row['mean_ratio']:.3f}", flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--samples", type=int, default=512)
    args = ap.parse_args()
    wenv.set_num_threads(2)
    rows = []
    for lighting, hdri in CASES:
        rows += run_case(lighting, hdri, args.size, args.samples)
    os.makedirs(os.path.join(ROOT, "out"), exist_ok=True)
    with open(os.path.join(ROOT, "out", "lamps_vs_cycles.json"), "w") as fh:
        json.dump({"machine": platform.processor() or platform.machine(), "size": args.size,
                   "samples": args.samples, "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
