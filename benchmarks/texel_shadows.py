"""A bake's shadows against the ray-cast reference, at points of Suzanne's faces: each point's own
masks at a bake's side (4 x 4, point rays) alone, those plus what they miss against the vertices'
finer masks (the add-on's bake: the vertices' shading at their side less that at the points', point
rays both), and the vertices' ratio of shadowed to open shading interpolated to the point.
Suzanne subdivided 3 times (31,658 vertices, 16 x 16 masks at the vertices), `default`, direct
light (no bounce), 3,000 points facing the camera drawn uniformly over her triangles: under small
bright lights a few points carry most of the error, so the figures move with the draw.  Prints
relative RMSEs and mean biases (and, for comparison, each point's own masks at the vertices' side, and the
unshadowed shading against the unshadowed reference: the method's own error), writes out/texel_shadows.json.

    python benchmarks/texel_shadows.py [--cases city:paint night:gloss ...] [--points 3000] [--lobe-rings 0]
"""
import argparse
import json
import os
import platform
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))
import wenv  # noqa: E402
from bench_shadows import MATERIALS, suzanne  # noqa: E402
from tests.conftest import hdri_path  # noqa: E402

EYE = np.array([0.0, -4.2, 0.5])  # the camera of benchmarks/shadows_vs_cycles.py


def points_on_faces(p, n, t, count, seed=2):
    """(triangle, weights, positions, normals, view directions) of `count` points drawn uniformly
    over the triangles (by index), facing the camera."""
    rng = np.random.default_rng(seed)
    tri = rng.integers(0, len(t), 20 * count)
    w = rng.dirichlet((1, 1, 1), 20 * count)
    pts = np.einsum("mc,mcx->mx", w, p[t[tri]])
    nrm = np.einsum("mc,mcx->mx", w, n[t[tri]])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    view = EYE - pts
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    keep = np.flatnonzero(np.einsum("mx,mx->m", view, nrm) > 0.1)[:count]
    return (tri[keep], w[keep], pts[keep].astype(np.float32), nrm[keep].astype(np.float32),
            view[keep].astype(np.float32))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=["city:paint", "courtyard:paint", "night:gloss", "night:metal"])
    ap.add_argument("--points", type=int, default=3000)
    ap.add_argument("--lobe-rings", type=int, default=None,
                    help="the quality's lobe_rings (default: `default`'s): 0 reads a narrow lobe through nine rays")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "texel_shadows.json"))
    args = ap.parse_args()
    p, n, t = suzanne(3)
    occluders = wenv.Occluders(p, t)
    tri, w, pts, nrm, view = points_on_faces(p, n, t, args.points)
    vertex_view = EYE - p
    vertex_view = (vertex_view / np.linalg.norm(vertex_view, axis=1, keepdims=True)).astype(np.float32)
    fine_side, texel_side = wenv.Occluders.auto_resolution(len(p)), wenv.Occluders.auto_resolution(10 ** 6)
    vertices_own = occluders.occlusion(p, n, resolution=fine_side)  # the vertex shading's
    fine = occluders.occlusion(p, n, resolution=fine_side, point_rays=True)
    coarse = occluders.occlusion(p, n, resolution=texel_side, point_rays=True)
    at_points = occluders.occlusion(pts, nrm, resolution=texel_side, point_rays=True)
    fine_at_points = occluders.occlusion(pts, nrm, resolution=fine_side, point_rays=True)

    def interpolated(x):
        return np.einsum("mc,mcx->mx", w, x[t[tri]])

    rows = []
    print(f"{len(pts)} points; masks {fine_side} x {fine_side} at the vertices, "
          f"{texel_side} x {texel_side} at the points")
    for case in args.cases:
        hdri, material = case.split(":")
        env = wenv.load_environment(hdri_path(hdri))
        principled = wenv.Principled(**MATERIALS[material])
        quality = "default" if args.lobe_rings is None else {"lobe_rings": args.lobe_rings}
        shader = wenv.Shader(env, principled, quality=quality)
        truth = wenv.reference(env, principled, nrm, view, positions=pts, occluders=occluders)
        open_truth = wenv.reference(env, principled, nrm, view)

        def error(a, truth=truth):
            return dict(rmse=float(np.sqrt(np.mean((a - truth) ** 2)) / np.mean(truth)),
                        bias=float(np.mean(a - truth) / np.mean(truth)))

        vertex_own = shader.shade(n, vertex_view, occlusion=vertices_own, bounce=None)
        vertex_fine = shader.shade(n, vertex_view, occlusion=fine, bounce=None)
        vertex_coarse = shader.shade(n, vertex_view, occlusion=coarse, bounce=None)
        vertex_open = shader.shade(n, vertex_view)
        open_shading = shader.shade(nrm, view)
        floor = 1e-3 * vertex_open.mean()  # as the ratio was taken: dividing noise by noise kept at 1
        own = shader.shade(nrm, view, occlusion=at_points, bounce=None)
        row = dict(hdri=hdri, material=material,
                   own_masks=error(own),
                   own_masks_and_vertices=error(np.maximum(own + interpolated(vertex_fine - vertex_coarse), 0.0)),
                   vertices_ratio=error(open_shading * interpolated((vertex_own + floor) / (vertex_open + floor))),
                   unshadowed=error(open_shading),
                   fine_masks_at_points=error(shader.shade(nrm, view, occlusion=fine_at_points, bounce=None)),
                   method_unshadowed=error(open_shading, open_truth))
        rows.append(row)
        print(f"{hdri:10s} {material:6s} " + "  ".join(f"{k}: {100 * v['rmse']:.1f} % (bias {100 * v['bias']:+.1f} %)"
                                                       for k, v in row.items() if isinstance(v, dict)), flush=True)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/texel_shadows.py " + " ".join(sys.argv[1:]),
                       machine=platform.machine(), lobe_rings=args.lobe_rings, points=len(pts), vertices=len(p),
                       fine_side=fine_side, texel_side=texel_side, rows=rows), f, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
