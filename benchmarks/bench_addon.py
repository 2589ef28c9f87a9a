"""End-to-end speed of the Blender add-on in bpy: for Suzanne subdivided to ~31k and ~126k vertices
under Blender's "sunset" HDRI, wearing one Cook-Torrance lobe of Blender roughness 0.2 (or, with
--material principled, a new material's Principled BSDF as Blender makes it), the median time per
view change of

  - the add-on's shading path (read the evaluated mesh with foreach_get, shade, write the colour
    attribute with foreach_set), split into its three parts, and
  - the `wenv.shade` operator called through bpy.ops (adds operator dispatch and the depsgraph),
  - the same views from a viewport zoomed in on her (25 degree lens, 16:9), shading and writing only the
    vertices that face the eye and are on screen (Shade Only What Is Seen).

The view orbits the object by a small step each repeat (a new view every time, as when the user
drags the viewport).  Prints a table and writes out/bench_addon.json.

    python benchmarks/bench_addon.py [--quality default] [--material cook_torrance] [--repeats 21] [--threads 2]
"""
import argparse
import json
import math
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402
import mathutils  # noqa: E402
import wenv  # noqa: E402

import addon  # noqa: E402
from addon import engine, materials, meshes, shading, views  # noqa: E402
from measure import OUT  # noqa: E402
from tests.helpers.measure import bundled_hdri  # noqa: E402


def build_scene(levels, quality, material="cook_torrance"):
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    scene = bpy.context.scene
    scene.wenv.quality = quality.upper()
    tree = scene.world.node_tree
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(bundled_hdri("sunset"))
    tree.links.new(env.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.object
    mod = obj.modifiers.new("sub", "SUBSURF")
    mod.levels = levels
    with bpy.context.temp_override(object=obj):
        bpy.ops.object.modifier_apply(modifier="sub")
    obj.data.shade_smooth()
    mat = bpy.data.materials.new("paint")
    st = mat.wenv
    if material == "cook_torrance":
        st.model = "COOK_TORRANCE"  # else the new material's Principled BSDF node, as Blender made it
        st.diffuse = (0.3, 0.1, 0.05)
        lobe = st.lobes.add()
        lobe.roughness = 0.2
    st.initialized = True
    obj.data.materials.append(mat)
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    return scene, obj


def perspective(fov_degrees, aspect, near=0.1, far=100.0):
    """OpenGL's view -> clip matrix, as a viewport's window_matrix."""
    f = 1.0 / math.tan(math.radians(fov_degrees) / 2)
    return np.array([[f / aspect, 0, 0, 0], [0, f, 0, 0],
                     [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)], [0, 0, -1, 0]])


def orbit_view(i, distance=4.0):
    """World -> view matrix of a camera orbiting the origin, 1 degree per step."""
    a = math.radians(30 + i)
    eye = mathutils.Vector((distance * math.sin(a), -distance * math.cos(a), 1.0))
    rot = (-eye).to_track_quat("-Z", "Y").to_matrix().to_4x4()
    return (mathutils.Matrix.Translation(eye) @ rot).inverted()


def bench(levels, quality, repeats, material):
    scene, obj = build_scene(levels, quality, material)
    n = len(obj.data.vertices)
    dg = bpy.context.evaluated_depsgraph_get()
    t = time.perf_counter()
    view0 = views.View.from_view_matrix(np.array(orbit_view(0)), True)
    shading.shade_objects(scene, dg, [obj], view0, bpy.data)  # precompute/load matrices, lighting, material
    first = time.perf_counter() - t
    q = engine.quality_value(scene.wenv.quality)
    keys = materials.slot_material_keys(obj)

    parts = {"read": [], "shade": [], "write": [], "total": [], "shade_seen": [], "write_seen": [], "seen_fraction": []}
    for i in range(1, repeats + 1):
        view = views.View.from_view_matrix(np.array(orbit_view(i)), True)
        t0 = time.perf_counter()
        data = meshes.read_mesh(obj, dg)
        t1 = time.perf_counter()
        rgb, _ = engine.shade_arrays(engine.shaders.use_material(q, keys[0]), data, view)
        t2 = time.perf_counter()
        meshes.write_colors(obj.data, data.domain, rgb)
        t3 = time.perf_counter()
        parts["read"].append(t1 - t0)
        parts["shade"].append(t2 - t1)
        parts["write"].append(t3 - t2)
        parts["total"].append(t3 - t0)
        # the same view from a viewport zoomed in on her (25 degree lens, 16:9), shading only what it sees
        view.view_projection = perspective(25.0, 16 / 9) @ np.array(orbit_view(i))
        t0 = time.perf_counter()
        rgb, seen = engine.shade_arrays(engine.shaders.use_material(q, keys[0]), data, view, cull=True)
        t1 = time.perf_counter()
        meshes.write_colors(obj.data, data.domain, rgb, seen)
        t2 = time.perf_counter()
        parts["shade_seen"].append(t1 - t0)
        parts["write_seen"].append(t2 - t1)
        parts["seen_fraction"].append(float(seen.mean()) * 1e-3)  # reported x 1e3 below, like the times

    op = []
    for i in range(repeats + 1, 2 * repeats + 1):
        t0 = time.perf_counter()
        bpy.ops.wenv.shade(view="MATRIX", view_matrix=orbit_view(i), perspective=True)
        op.append(time.perf_counter() - t0)
    med = {k: statistics.median(v) * 1e3 for k, v in parts.items()}
    med["operator"] = statistics.median(op) * 1e3
    return {"vertices": n, "first_shade_s": first, "median_ms": med}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quality", default="default", choices=engine.QUALITIES)
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--material", default="cook_torrance", choices=["cook_torrance", "principled"],
                    help="one Cook-Torrance lobe of Blender roughness 0.2, or a new material's Principled BSDF "
                         "as Blender makes it (roughness 0.5)")
    ap.add_argument("--levels", type=int, nargs="+", default=[3, 4],
                    help="Subdivision levels of Suzanne (3: 31.5k vertices, 4: 126k)")
    ap.add_argument("--json", default=os.path.join(OUT, "bench_addon.json"))
    args = ap.parse_args()
    wenv.set_num_threads(args.threads)
    addon.register()
    rows = [bench(lv, args.quality, args.repeats, args.material) for lv in args.levels]
    print(f"quality {args.quality}, {args.material}, {args.threads} threads, median of {args.repeats} view changes (ms):")
    print(f"{'vertices':>9} {'read':>7} {'shade':>7} {'write':>7} {'total':>7} {'operator':>9}   "
          f"{'seen':>5} {'shade':>7} {'write':>7}  (only what a viewport sees)")
    for r in rows:
        m = r["median_ms"]
        print(f"{r['vertices']:>9} {m['read']:7.2f} {m['shade']:7.2f} {m['write']:7.2f} {m['total']:7.2f} "
              f"{m['operator']:9.2f}   {100 * m['seen_fraction']:4.0f}% {m['shade_seen']:7.2f} {m['write_seen']:7.2f}")
    path = args.json
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as fp:
        json.dump({"quality": args.quality, "material": args.material, "threads": args.threads,
                   "repeats": args.repeats, "results": rows},
                  fp, indent=2)
    print("wrote", path)
    addon.unregister()


if __name__ == "__main__":
    main()
