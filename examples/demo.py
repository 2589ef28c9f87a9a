"""The main job on the embedded default: a glossy sphere under one of Blender's bundled HDRIs,
shaded by wavelet rotation and by the brute-force reference; writes out/demo.png (wenv | reference
| error x10) and prints the error and the timings.

    .venv/bin/python examples/demo.py [--hdri sunset] [--quality default] [--size 64]
"""
import argparse
import glob
import importlib.util
import os
import time

import numpy as np

import wenv

OUT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "out")


def bundled_hdri(name):
    """One of the eight studio HDRIs that ship with Blender, here with the bpy wheel that
    scripts/setup.sh installs (city, courtyard, forest, interior, night, studio, sunrise, sunset)."""
    spec = importlib.util.find_spec("bpy")
    for root in spec.submodule_search_locations if spec else []:
        hits = sorted(glob.glob(os.path.join(root, "*", "datafiles", "studiolights", "world", name + ".exr")))
        if hits:
            return hits[-1]
    raise SystemExit(f"bundled HDRI {name!r} not found: run scripts/setup.sh first (it installs bpy)")


def sphere_image(size):
    """Normals of a unit sphere seen orthographically from -Y (looking along +Y), one per pixel
    inside the disk; returns (mask, normals, view) with the view pointing back at the camera."""
    t = (np.arange(size) + 0.5) / size * 2 - 1
    x, z = np.meshgrid(t, -t)
    r2 = x * x + z * z
    mask = r2 < 1
    n = np.stack([x[mask], -np.sqrt(1 - r2[mask]), z[mask]], axis=1).astype(np.float32)
    view = np.array([0.0, -1.0, 0.0], np.float32)
    return mask, n, view


def tone_map(rgb, l_max):
    """The thesis's global logarithmic operator: Ld = log10(1 + Lw) / log10(1 + Lmax)."""
    lw = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    ld = np.log10(1 + lw) / np.log10(1 + l_max)
    scale = np.where(lw > 0, ld / np.maximum(lw, 1e-12), 0)
    return np.clip(rgb * scale[..., None], 0, 1)


def relative_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


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
