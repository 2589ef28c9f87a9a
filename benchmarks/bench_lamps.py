"""The scene's lamps (wenv.Lamp): what they cost and how close they come to the reference.

Cost, on a sphere of 125,502 vertices resting on a square (its contact shadow), seen from 4.2 units
under forest at `default`, 2 threads, medians side by side:
  - a view change with the World alone against one with four lamps too (a sun, a soft point lamp, a
    spot and a 1 m area lamp), for a Principled paint and a metal of roughness 0.2 (whose narrow
    lobe reads the area lamp on a fine grid where its peak falls);
  - the same with shadows (an Occlusion of the sphere and the square; the lamps' rays);
  - a lamp's new power (nothing is made again) and a moved lamp (its shares and shadow cells made
    again), each against an unchanged call.
Accuracy: each lamp alone against wenv.reference (each lamp summed over a fine grid of its surface,
the exact BRDF at every point) at 800 random vertices facing the eye of a sphere resting on a
plane (tests/test_shadows.py's: its contact shadow), with and without shadows.
Prints tables and writes out/bench_lamps.json.  Timing is not part of the test suite.

    python benchmarks/bench_lamps.py [--repeat 7] [--reference 800] [--skip-accuracy] [--skip-cost]
"""
import argparse
import json
import os
import platform
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import wenv  # noqa: E402
from measure import OUT, side_by_side  # noqa: E402
from tests.conftest import hdri_path  # noqa: E402
from tests.helpers.meshes import merged, uv_sphere  # noqa: E402
from tests.test_lamps import placed, relative_rmse  # noqa: E402
from tests.test_shadows import sphere_on_plane  # noqa: E402

MATERIALS = {"paint": dict(base_color=(0.6, 0.15, 0.08), roughness=0.4),
             "metal": dict(base_color=(0.9, 0.62, 0.35), metallic=1.0, roughness=0.2)}
EYE = np.float32([0.0, -4.2, 1.6])


def lamps(area_at=(0.0, -2.0, 2.5), area_energy=300.0):
    return {"sun": wenv.Lamp("SUN", placed((0, 0, 0), shine=(0.4, 0.6, -1.0)), energy=2.0, angle=0.05),
            "point": wenv.Lamp("POINT", placed((1.8, -1.5, 2.2)), energy=400.0, radius=0.1),
            "spot": wenv.Lamp("SPOT", placed((-2.0, -2.0, 2.5), shine=(1.0, 1.0, -1.0)), energy=800.0, radius=0.1,
                              spot_size=0.8, spot_blend=0.2),
            "area": wenv.Lamp("AREA", placed(area_at, shine=(0.0, 0.8, -1.0)), energy=area_energy, size=1.0)}


def scene(rings, segments):
    """The sphere (radius 1, resting on z = 0) and a 6 x 6 square under it."""
    v, f = uv_sphere(rings, segments)
    v = v + np.float32([0.0, 0.0, 1.0])
    normals = (v - np.float32([0.0, 0.0, 1.0])).astype(np.float32)
    square = (np.float32([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]]), np.array([[0, 1, 2], [0, 2, 3]]))
    positions, triangles = merged((v, f), square)
    occluders = wenv.Occluders(positions, triangles)
    views = (EYE - v).astype(np.float32)
    return v.astype(np.float32), normals, views, occluders


def cost(repeat):
    positions, normals, views, occluders = scene(250, 502)
    env = wenv.load_environment(hdri_path("forest"))
    occlusion = occluders.occlusion(positions, normals)
    all_lamps = list(lamps().values())
    rows = []
    for name, inputs in MATERIALS.items():
        shader = wenv.Shader(env, wenv.Principled(**inputs), quality="default")
        for shadowed in (False, True):
            kw = dict(occlusion=occlusion, bounce=None) if shadowed else {}
            shader.shade(normals, views, positions=positions, lamps=all_lamps, **kw)  # made once
            world, lit = side_by_side(lambda: shader.shade(normals, views, **kw),
                                      lambda: shader.shade(normals, views, positions=positions, lamps=all_lamps, **kw),
                                      repeat)
            rows.append(dict(material=name, shadows=shadowed, world_ms=1e3 * world, with_lamps_ms=1e3 * lit,
                             lamps_ms=1e3 * (lit - world), ratio=lit / world))
            print(f"{name:6s} shadows {str(shadowed):5s}: World alone {1e3 * world:6.1f} ms, with 4 lamps "
                  f"{1e3 * lit:6.1f} ms ({lit / world:.2f}x)")
    # a new power, and a moved lamp, against an unchanged call (paint, with shadows): one shader each,
    # so that what one call keeps is not what the other changes
    kw = dict(occlusion=occlusion, bounce=None, positions=positions)
    fixed = list(lamps().values())
    shaders = [wenv.Shader(env, wenv.Principled(**MATERIALS["paint"]), quality="default") for _ in range(3)]
    for shader in shaders:
        shader.shade(normals, views, lamps=fixed, **kw)
    state = {"k": 0}

    def powered():
        state["k"] += 1
        return shaders[1].shade(normals, views, lamps=list(lamps(area_energy=300.0 + state["k"]).values()), **kw)

    def moved():
        state["k"] += 1
        return shaders[2].shade(normals, views,
                                lamps=list(lamps(area_at=(0.0, -2.0, 2.5 + 0.01 * state["k"])).values()), **kw)
    same, power = side_by_side(lambda: shaders[0].shade(normals, views, lamps=fixed, **kw), powered, repeat)
    same2, move = side_by_side(lambda: shaders[0].shade(normals, views, lamps=fixed, **kw), moved, repeat)
    changes = dict(unchanged_ms=1e3 * same, new_power_ms=1e3 * power, unchanged_again_ms=1e3 * same2,
                   moved_ms=1e3 * move)
    print(f"a new power: {1e3 * power:.1f} ms against {1e3 * same:.1f} ms unchanged; a moved area lamp (its "
          f"shares and shadow rays cast again at {len(positions)} vertices): {1e3 * move:.1f} ms against "
          f"{1e3 * same2:.1f} ms")
    return dict(vertices=len(positions), rows=rows, changes=changes)


def accuracy(count):
    positions, triangles, normals = sphere_on_plane()
    occluders = wenv.Occluders(positions, triangles)
    views = (EYE - positions).astype(np.float32)
    rng = np.random.default_rng(7)
    facing = np.flatnonzero(np.einsum("ij,ij->i", normals, views) > 0)
    pick = np.sort(rng.choice(facing, size=min(count, len(facing)), replace=False))
    p, n, v = positions[pick], normals[pick], views[pick]
    black = wenv.Environment(np.zeros((8, 16, 3), np.float32))
    occlusion = occluders.occlusion(p, n)
    rows = []
    for name, inputs in MATERIALS.items():
        mat = wenv.Principled(**inputs)
        shader = wenv.Shader(black, mat, quality="default")
        for lamp_name, lamp in lamps().items():
            plain = shader.shade(n, v, positions=p, lamps=[lamp])
            ref = wenv.reference(black, mat, n, v, positions=p, lamps=[lamp])
            shadowed = shader.shade(n, v, positions=p, lamps=[lamp], occlusion=occlusion, bounce=None)
            ref_shadowed = wenv.reference(black, mat, n, v, positions=p, lamps=[lamp], occluders=occluders)
            row = dict(material=name, lamp=lamp_name, error=relative_rmse(plain, ref),
                       shadowed_error=relative_rmse(shadowed, ref_shadowed))
            rows.append(row)
            print(f"{name:6s} {lamp_name:6s}: {100 * row['error']:.2f} % unshadowed, "
                  f"{100 * row['shadowed_error']:.2f} % with shadows")
    return dict(vertices=len(pick), rows=rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--reference", type=int, default=800)
    ap.add_argument("--skip-accuracy", action="store_true")
    ap.add_argument("--skip-cost", action="store_true")
    args = ap.parse_args()
    wenv.set_num_threads(2)
    result = {"machine": platform.processor() or platform.machine(), "threads": 2}
    if not args.skip_accuracy:
        result["accuracy"] = accuracy(args.reference)
    if not args.skip_cost:
        result["cost"] = cost(args.repeat)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "bench_lamps.json"), "w") as fh:
        json.dump(result, fh, indent=1)


if __name__ == "__main__":
    main()
