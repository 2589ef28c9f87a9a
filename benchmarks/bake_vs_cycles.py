"""A bake of every texel against Cycles: Suzanne subdivided 3 times (31,658 vertices, Smart UV
Project), a Principled metal (roughness 0.3) under forest, seen from the camera at 256 x 256.

Rendered
  - by Cycles, direct light only (Max Bounces 0), at two seeds (their mean is the truth; half their
    difference's RMSE is the noise of that mean), every pixel at --samples (adaptive sampling off):
    without self-shadowing (the object invisible to every secondary ray: what wenv models without
    shadows) and with it;
  - from wenv's bakes at `default` and `high` (1024 x 1024, 1600 x 1600 and 2048 x 2048, shadows off
    and on, Bounce Light off), the baked image shown as emitted light through the UV map, by Cycles;
  - flat (Workbench) from wenv's vertex colours at `default`, for comparison;
  - from a bake of --finest (4096 x 4096) at each quality, shadows off and on, shown the same way: each bake's
    distance from it is what the image's size alone costs at this view (the column `image`), whatever the
    shading's own error.
Prints relative RMSEs (RMSE over the mean, over the pixels every render covers) and the bakes' times
(median of --repeat bakes after one to warm the shader), writes out/bake_vs_cycles.json and, with
--picture, docs/bake_vs_cycles.png.

    python benchmarks/bake_vs_cycles.py [--hdri forest] [--sizes 1024 1600 2048] [--samples 2048] [--repeat 3] [--picture]
"""
import argparse
import json
import os
import platform
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
import bpy  # noqa: E402

import addon  # noqa: E402
from addon import bake, meshes, shading, views  # noqa: E402
from benchmarks import shadows_vs_cycles  # noqa: E402
from benchmarks.shadows_vs_cycles import (MATERIALS, emission_material, render, set_material, set_world,  # noqa: E402
                                          smart_project)

METAL = MATERIALS["metal"]
# what an object is to Cycles' rays after the camera's: all off, its light reaches every point of it
# unblocked (no self-shadowing, no self-reflection), as wenv shades without shadows
SECONDARY_RAYS = ("visible_shadow", "visible_diffuse", "visible_glossy", "visible_transmission",
                  "visible_volume_scatter")


def build(size, hdri):
    """shadows_vs_cycles' Suzanne, unwrapped by Smart UV Project, the World `hdri`, Cycles' direct light."""
    scene, (obj,) = shadows_vs_cycles.build("suzanne", size)
    smart_project(obj)
    scene.cycles.max_bounces = 0
    set_world(scene, hdri)
    scene.wenv.quality = "DEFAULT"
    scene.wenv.tone_mapping = "NONE"
    scene.wenv.bounce_light = False  # Cycles' direct light: what the mesh blocks is black
    bpy.context.view_layer.update()  # the camera's matrix_world follows its new place only once evaluated
    return scene, obj


def timed_bake(scene, obj, image, view, repeat):
    dg = bpy.context.evaluated_depsgraph_get()
    count, _ = bake.bake(scene, dg, obj, image, view, bpy.data, view_source="CAMERA")  # warms the shader and shadows
    if not repeat:
        return count, None
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        count, _ = bake.bake(scene, dg, obj, image, view, bpy.data, view_source="CAMERA")
        times.append(time.perf_counter() - start)
    return count, float(np.median(times))


def box_filtered(image, size):
    """A size x size image whose every texel is the mean of the texels of `image` (a multiple of
    `size` on a side) over its area: a bake whose texels are filtered as Cycles' bake filters them
    (its samples spread evenly over each texel), from a finer bake."""
    side = image.size[0]
    k = side // size
    px = np.empty(side * side * 4, np.float32)
    image.pixels.foreach_get(px)
    small = px.reshape(size, k, size, k, 4).mean(axis=(1, 3))
    out = bpy.data.images.new(f"box {size}", size, size, alpha=True, float_buffer=True)
    out.pixels.foreach_set(np.ascontiguousarray(small, np.float32).ravel())
    return out


def picture(path, panels):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 3.5))
    for ax, (title, img) in zip(axes, panels):
        rgb = np.clip(img[..., :3], 0.0, None)
        srgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(np.minimum(rgb, 1.0), 1 / 2.4) - 0.055)
        ax.imshow(np.clip(srgb, 0, 1) * img[..., 3:4] + (1 - img[..., 3:4]) * 0.18)
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print("wrote", path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hdri", default="forest")
    ap.add_argument("--sizes", type=int, nargs="*", default=[1024, 1600, 2048],
                    help="bake sizes (1600: about a million texels in Suzanne's islands)")
    ap.add_argument("--finest", type=int, default=4096,
                    help="the bake each size is measured against for what the image's size alone costs (0: none)")
    ap.add_argument("--size", type=int, default=256, help="the renders' side")
    ap.add_argument("--samples", type=int, default=2048, help="Cycles' samples in every pixel (its truth)")
    ap.add_argument("--qualities", nargs="*", default=["default", "high"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--picture", action="store_true", help="write docs/bake_vs_cycles.png")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bake_vs_cycles.json"))
    args = ap.parse_args()
    all_sizes = args.sizes + ([args.finest] if args.finest else [])
    addon.register()
    scene, obj = build(args.size, args.hdri)
    scene.cycles.samples = args.samples
    metal = set_material([obj], METAL)
    view = views.camera_view(scene)
    dg = bpy.context.evaluated_depsgraph_get()
    rows, imgs = [], {}
    with tempfile.TemporaryDirectory(prefix="wenv-bake-") as folder:
        cycles = {}
        for shadows in (False, True):
            for ray in SECONDARY_RAYS:
                setattr(obj, ray, shadows)
            cycles[shadows] = [render(scene, "CYCLES", folder, seed) for seed in (1, 2)]
        samples = scene.cycles.samples
        scene.cycles.samples = 64  # the bakes shown as emission: no noise but the pixels' antialiasing
        # wenv's vertex colours, rendered flat
        vertex = {}
        for shadows in (False, True):
            scene.wenv.shadows = shadows
            data = meshes.read_mesh(obj, dg)
            plan = shading.plan_shading(scene, dg, [obj], view, bpy.data.images)
            plan.cull = False
            plan.compute()
            meshes.write_colors(obj.data, data.domain, plan.results[0][2])
            vertex[shadows] = render(scene, "BLENDER_WORKBENCH", folder)
        def shown(image):
            obj.data.materials.clear()
            obj.data.materials.append(emission_material(image))
            img = render(scene, "CYCLES", folder, 0)
            obj.data.materials.clear()
            obj.data.materials.append(metal)
            return img

        bakes = {}
        for quality in args.qualities:
            scene.wenv.quality = quality.upper()
            for size in all_sizes:
                image = bpy.data.images.new(f"bake {size}", size, size, alpha=True, float_buffer=True)
                for shadows in (False, True):
                    scene.wenv.shadows = shadows
                    count, seconds = timed_bake(scene, obj, image, view, args.repeat if size in args.sizes else 0)
                    bakes[(quality, size, shadows)] = (shown(image), count, seconds)
                    if size == args.finest and size % args.sizes[0] == 0:
                        small = box_filtered(image, args.sizes[0])
                        texels = bakes[(quality, args.sizes[0], shadows)][1]
                        bakes[(quality, "box", shadows)] = (shown(small), texels, None)
                        bpy.data.images.remove(small)
                bpy.data.images.remove(image)
        scene.wenv.quality = "DEFAULT"
        scene.cycles.samples = samples
    mask = np.ones(cycles[False][0].shape[:2], bool)
    for img in cycles[False] + cycles[True] + list(vertex.values()) + [b[0] for b in bakes.values()]:
        mask &= img[..., 3] > 0.99

    def rel(a, b):
        a, b = a[..., :3][mask].astype(np.float64), b[..., :3][mask].astype(np.float64)
        return float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(b))

    def darker(a, b):
        return float(1.0 - np.mean(a[..., :3][mask]) / np.mean(b[..., :3][mask]))

    print(f"{'what':36s} {'shadows':>7s} {'texels':>9s} {'bake':>8s} {'vs Cycles':>9s} {'noise':>6s} {'darker':>7s}"
          f" {'image':>6s}")
    for shadows in (False, True):
        truth = (cycles[shadows][0] + cycles[shadows][1]) / 2
        noise = rel(cycles[shadows][0], cycles[shadows][1]) / 2
        entries = [("vertex colours, default", vertex[shadows], len(obj.data.vertices), None, None)]
        entries += [(f"bake {size} x {size}, {quality}",) + bakes[(quality, size, shadows)]
                    + (bakes[(quality, args.finest, shadows)][0] if args.finest else None,)
                    for quality in args.qualities for size in all_sizes]
        entries += [(f"bake {args.sizes[0]} x {args.sizes[0]} box-filtered from {args.finest}, {quality}",)
                    + bakes[(quality, "box", shadows)] + (bakes[(quality, args.finest, shadows)][0],)
                    for quality in args.qualities if (quality, "box", shadows) in bakes]
        for what, img, count, seconds, finest in entries:
            row = dict(what=what, shadows=shadows, points=int(count), seconds=seconds, relative_rmse=rel(img, truth),
                       cycles_noise=noise, darker=darker(img, truth),
                       image_resolution=None if finest is None or finest is img else rel(img, finest))
            rows.append(row)
            print(f"{what:36s} {str(shadows):>7s} {count:9d} " + (f"{seconds:7.2f}s" if seconds else f"{'':8s}")
                  + f" {100 * row['relative_rmse']:8.1f}% {100 * noise:5.1f}% {100 * row['darker']:6.1f}%"
                  + (f" {100 * row['image_resolution']:5.1f}%" if row["image_resolution"] is not None else ""),
                  flush=True)
        imgs[shadows] = truth
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/bake_vs_cycles.py " + " ".join(sys.argv[1:]),
                       machine=platform.machine(), hdri=args.hdri, samples=args.samples, size=args.size,
                       vertices=len(obj.data.vertices), pixels=int(mask.sum()), rows=rows), f, indent=1)
    print("wrote", args.out)
    if args.picture:
        size, quality = args.sizes[-1], args.qualities[0]
        picture(os.path.join(ROOT, "docs", "bake_vs_cycles.png"),
                [(f"Cycles, {args.samples} spp x 2", imgs[False]),
                 (f"wenv bake {size}² ({quality})", bakes[(quality, size, False)][0]),
                 ("wenv vertex colours", vertex[False])])


if __name__ == "__main__":
    main()
