"""Roughness and Metallic per vertex (Shader.shade(..., roughness=, metallic=)): accuracy and the cost
of a view change.

Accuracy, per bundled HDRI, on a sphere of 19,802 vertices seen from 4.2 units (grazing rims
included), a Principled paint and a metal whose Roughness varies smoothly from 0.1 to 0.7 (in steps
of 1/40, between the levels 1/16 apart) and, for the paint, whose Metallic goes from 0 to 1 across a
band (in steps of 1/4):
  - interpolation: against the same shader given each vertex's own material (the vertices of each
    value shaded with a plain material at it), so the method's own error cancels;
  - against wenv.reference(..., roughness=, metallic=) at 800 random visible vertices, beside the
    same shader's error with each vertex's own material (what the method itself costs there) and
    for a plain material at the mean roughness.
Cost: a view change on a sphere of 125,502 vertices under forest, side by side with a plain
material at the texture's mean roughness: a smooth roughness (0.15 to 0.6), stripes of 0.15 and 0.6,
a smooth roughness with a metallic band, and the same with a colour per vertex (a PBR asset's three
maps).  Medians, 2 threads.  Prints tables and writes
out/bench_vertex_material.json.  Timing is not part of the test suite.

    python benchmarks/bench_vertex_material.py [--repeat 9] [--hdris forest,city] [--reference 800]
                                               [--skip-accuracy] [--skip-cost]
"""
import argparse
import json
import os
import platform
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import wenv  # noqa: E402
from measure import side_by_side  # noqa: E402
from tests.conftest import hdri_path  # noqa: E402
from tests.helpers.measure import relative_rmse  # noqa: E402
from tests.helpers.meshes import uv_sphere  # noqa: E402

HDRIS = ("city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset")
PAINT = dict(base_color=(0.6, 0.15, 0.08))
METAL = dict(base_color=(0.9, 0.62, 0.35), metallic=1.0)
EYE = np.float32([0.0, -4.2, 0.0])


def sphere(rings, segments):
    v, _ = uv_sphere(rings, segments)
    views = ((EYE - v) / np.linalg.norm(EYE - v, axis=1)[:, None]).astype(np.float32)
    return v.astype(np.float32), views


def smooth_field(v, lo, hi, step=None):
    """A roughness varying smoothly over the sphere between lo and hi (rounded to `step`)."""
    t = 0.5 + 0.25 * np.sin(3.0 * v[:, 0] + 1.0) + 0.25 * np.cos(4.0 * v[:, 2])
    r = lo + (hi - lo) * t
    if step:
        r = np.round(r / step) * step
    return r.astype(np.float32)


def per_vertex_exact(shader, inputs, v, views, roughness, metallic):
    """The shader's result with each vertex's own material: every (roughness, metallic) pair shaded
    with a plain Principled at it."""
    out = np.zeros((len(v), 3), np.float32)
    keys = np.stack([roughness, metallic], axis=1)
    for r, m in np.unique(keys, axis=0):
        sel = (roughness == r) & (metallic == m)
        shader.set_material(wenv.Principled(**{**inputs, "roughness": float(r), "metallic": float(m)}))
        out[sel] = shader.shade(v[sel], views[sel])
    return out


def accuracy(args):
    v, views = sphere(100, 200)
    roughness = smooth_field(v, 0.1, 0.7, 1 / 40)  # 25 values, each shaded alone for the comparison
    band = np.clip((v[:, 2] + 0.3) / 0.6, 0.0, 1.0)
    metallic_band = np.round(band * 4).astype(np.float32) / 4
    rng = np.random.default_rng(1)
    visible = np.flatnonzero(np.sum(v * views, axis=1) > 0.0)
    sample = np.sort(rng.choice(visible, size=min(args.reference, len(visible)), replace=False))
    rows = []
    print(f"\naccuracy: {len(v)} vertices, roughness 0.1-0.7, `{args.quality}` (relative RMSE, %)")
    print(f"{'hdri':10s} {'material':14s} {'interp.':>8s} {'vs ref':>8s} {'own vs ref':>11s} {'plain vs ref':>13s}")
    for hdri in args.hdris:
        env = wenv.load_environment(hdri_path(hdri))
        for name, inputs, metallic in (("paint", PAINT, np.zeros(len(v), np.float32)),
                                       ("metal", METAL, np.ones(len(v), np.float32)),
                                       ("paint+metal", PAINT, metallic_band)):
            base = wenv.Principled(**{**inputs, "roughness": float(roughness.mean()), "metallic": 0.0})
            shader = wenv.Shader(env, base, quality=args.quality, method="slicing")
            kw = dict(roughness=roughness, metallic=metallic)
            got = shader.shade(v, views, **kw)
            exact = per_vertex_exact(shader, inputs, v, views, roughness, metallic)
            ref = wenv.reference(env, base, v[sample], views[sample], **{k: a[sample] for k, a in kw.items()})
            mean_mat = wenv.Principled(**{**inputs, "roughness": float(roughness.mean()),
                                          "metallic": float(metallic.mean())})
            shader.set_material(mean_mat)
            plain = shader.shade(v[sample], views[sample])
            plain_ref = wenv.reference(env, mean_mat, v[sample], views[sample])
            row = dict(hdri=hdri, material=name, interpolation=relative_rmse(got, exact),
                       vs_reference=relative_rmse(got[sample], ref), own_vs_reference=relative_rmse(exact[sample], ref),
                       plain_vs_reference=relative_rmse(plain, plain_ref))
            rows.append(row)
            print(f"{hdri:10s} {name:14s} {100 * row['interpolation']:8.2f} {100 * row['vs_reference']:8.2f} "
                  f"{100 * row['own_vs_reference']:11.2f} {100 * row['plain_vs_reference']:13.2f}", flush=True)
    return rows


def cost(args):
    v, views = sphere(252, 500)
    env = wenv.load_environment(hdri_path("forest"))
    smooth = smooth_field(v, 0.15, 0.6)
    stripes = np.where(np.sin(12.0 * v[:, 0]) > 0.0, 0.15, 0.6).astype(np.float32)
    band = np.clip((v[:, 2] + 0.3) / 0.6, 0.0, 1.0).astype(np.float32)
    colour = np.random.default_rng(2).uniform(0.05, 0.95, (len(v), 3)).astype(np.float32)
    cases = (("smooth roughness", dict(roughness=smooth)), ("roughness stripes", dict(roughness=stripes)),
             ("smooth roughness, metallic band", dict(roughness=smooth, metallic=band)),
             ("colour, roughness, metallic band", dict(base_color=colour, roughness=smooth, metallic=band)),
             ("smooth Specular IOR Level", dict(specular_ior_level=smooth_field(v, 0.0, 1.0))),
             ("coat mask", dict(coat_weight=np.where(band > 0.5, 1.0, 0.0).astype(np.float32))),
             ("smooth Coat Roughness, coat 1", dict(coat_weight=np.ones(len(v), np.float32),
                                                    coat_roughness=smooth_field(v, 0.03, 0.3))),
             ("smooth roughness and IOR Level", dict(roughness=smooth, specular_ior_level=smooth_field(v, 0.0, 1.0))))
    rows = []
    print(f"\ncost of a view change: {len(v)} vertices, forest, `{args.quality}`, {wenv.get_num_threads()} threads")
    print(f"{'textures':32s} {'plain ms':>9s} {'per vertex ms':>14s} {'ratio':>6s} {'members':>8s}")
    for name, kw in cases:
        mean = {k: float(a.mean()) if a.ndim == 1 else tuple(float(c) for c in a.mean(axis=0)) for k, a in kw.items()}
        shader = wenv.Shader(env, wenv.Principled(**{**PAINT, **mean}), quality=args.quality, method="slicing")
        plain_shader = wenv.Shader(env, wenv.Principled(**{**PAINT, **mean}), quality=args.quality, method="slicing")
        shader.shade(v, views, **kw)
        plain_shader.shade(v, views)
        plain, textured = side_by_side(lambda: plain_shader.shade(v, views),
                                       lambda: shader.shade(v, views, **kw), args.repeat)  # noqa: B023
        row = dict(textures=name, plain_ms=1e3 * plain, per_vertex_ms=1e3 * textured,
                   members=shader.stats.get("materials_kept"))
        row["ratio"] = row["per_vertex_ms"] / row["plain_ms"]
        rows.append(row)
        print(f"{name:32s} {row['plain_ms']:9.1f} {row['per_vertex_ms']:14.1f} {row['ratio']:6.2f} {row['members']:8d}",
              flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=9)
    ap.add_argument("--hdris", default=",".join(HDRIS))
    ap.add_argument("--reference", type=int, default=800, help="vertices compared with wenv.reference")
    ap.add_argument("--quality", default="default")
    ap.add_argument("--skip-accuracy", action="store_true")
    ap.add_argument("--skip-cost", action="store_true")
    ap.add_argument("--out", default=os.path.join("out", "bench_vertex_material.json"))
    args = ap.parse_args()
    args.hdris = args.hdris.split(",")
    acc = [] if args.skip_accuracy else accuracy(args)
    speed = [] if args.skip_cost else cost(args)
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/bench_vertex_material.py " + " ".join(sys.argv[1:]),
                       machine=platform.machine(), threads=wenv.get_num_threads(), quality=args.quality,
                       accuracy=acc, cost=speed), f, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
