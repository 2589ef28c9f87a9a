"""What a bake costs with and without shadows: Suzanne subdivided 3 times (31,658 vertices, Smart UV
Project), a material of shadows_vs_cycles.py (the gloss unless told) under night, `default`, Bounce
Light on, from the camera; each size baked four times, the median of the last three.  Prints and
writes out/bake_cost.json.  Run it with two builds in turn to compare them side by side.

    python benchmarks/bake_cost.py [--sizes 1024 2048] [--material gloss|paint|metal]
"""
import argparse
import json
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
import bpy  # noqa: E402

import addon  # noqa: E402
from addon import bake, views  # noqa: E402
from benchmarks import shadows_vs_cycles as scenes  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[1024, 2048])
    ap.add_argument("--material", default="gloss", choices=list(scenes.MATERIALS))
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bake_cost.json"))
    args = ap.parse_args()
    addon.register()
    scene, objs = scenes.build("suzanne", 160)
    scenes.add_bake_map(objs[0])
    scene.wenv.quality, scene.wenv.tone_mapping = "DEFAULT", "NONE"
    scenes.set_world(scene, "night")
    scenes.set_material(objs, scenes.MATERIALS[args.material])
    rows = []
    for size in args.sizes:
        for shadows in (False, True):
            scene.wenv.shadows, scene.wenv.bounce_light, scene.wenv.glossy_bounce = shadows, True, False
            image = bpy.data.images.new(f"cost {size}", size, size, float_buffer=True)
            times = []
            for _ in range(4):
                start = time.perf_counter()
                texels, _ = bake.bake(scene, bpy.context.evaluated_depsgraph_get(), objs[0], image,
                                      views.camera_view(scene), bpy.data, uv_map=scenes.BAKE_UV)
                times.append(time.perf_counter() - start)
            rows.append(dict(size=size, shadows=shadows, texels=texels, seconds=float(np.median(times[1:]))))
            print(f"{size} x {size}, shadows {'on ' if shadows else 'off'}: {texels} texels in "
                  f"{rows[-1]['seconds']:.2f} s", flush=True)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/bake_cost.py " + " ".join(sys.argv[1:]), machine=platform.machine(),
                       material=args.material, rows=rows), f, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
