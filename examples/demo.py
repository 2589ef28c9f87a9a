"""The main job on the embedded default: a glossy sphere under one of Blender's bundled HDRIs,
shaded by wavelet rotation and by the brute-force reference; writes out/demo.png (wenv | reference
| error x10) and prints the error and the timings.

    .venv/bin/python examples/demo.py [--hdri sunset] [--quality default] [--size 64]
"""
import argparse
import os
import time

import numpy as np

import wenv
from _common import OUT, bundled_hdri, relative_rmse, sphere_image, tone_map


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hdri", default="sunset")
    ap.add_argument("--quality", default="default", choices=["draft", "default", "high"])
    ap.add_argument("--method", default="rotation", choices=["rotation", "slicing"])
    ap.add_argument("--size", type=int, default=64, help="image side in pixels (the reference costs about 10 ms a pixel)")
    ap.add_argument("--roughness", type=float, default=0.2)
    args = ap.parse_args()

    env = wenv.load_environment(bundled_hdri(args.hdri))
    material = wenv.CookTorrance(diffuse=(0.25, 0.05, 0.04),
                                 lobes=[{"specular": (1, 1, 1), "roughness": args.roughness, "ior": 1.5}])
    mask, normals, view = sphere_image(args.size)
    views = np.broadcast_to(view, normals.shape).copy()

    t0 = time.perf_counter()
    shader = wenv.Shader(env, material, quality=args.quality, method=args.method)
    t_setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    ours = shader.shade(normals, views)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    ours = shader.shade(normals, views)
    t_again = time.perf_counter() - t0
    t0 = time.perf_counter()
    ref = wenv.reference(env, material, normals, views)
    t_ref = time.perf_counter() - t0

    err = relative_rmse(ours, ref)
    print(f"{args.hdri}, Cook-Torrance m={args.roughness}, quality={args.quality}, method={args.method}, "
          f"{len(normals)} points, {wenv.get_num_threads()} threads")
    print(f"  set-up (matrices {shader.stats['cache']}, lighting, BRDF slices): {t_setup * 1e3:8.1f} ms")
    print(f"  shade, first view:   {t_first * 1e3:8.1f} ms")
    print(f"  shade, same view:    {t_again * 1e3:8.1f} ms")
    print(f"  reference:           {t_ref * 1e3:8.1f} ms")
    print(f"  relative RMSE against the reference: {100 * err:.2f} %")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    l_max = float(np.percentile(ref @ np.array([0.2126, 0.7152, 0.0722]), 99.5))
    panels = []
    for rgb in (ours, ref, np.abs(ours - ref) * 10):
        img = np.zeros((args.size, args.size, 3), np.float32)
        img[mask] = tone_map(rgb, l_max)
        panels.append(img)
    fig, axes = plt.subplots(1, 3, figsize=(9, 3.3))
    for ax, img, title in zip(axes, panels, ["wenv " + args.quality, "reference", "|difference| x 10"]):
        ax.imshow(img)
        ax.set_title(title)
        ax.axis("off")
    fig.suptitle(f"{args.hdri}: relative RMSE {100 * err:.2f} %")
    os.makedirs(OUT, exist_ok=True)
    path = os.path.join(OUT, "demo.png")
    fig.savefig(path, dpi=100, bbox_inches="tight")
    print(f"  wrote {path}")


if __name__ == "__main__":
    main()
