"""A headless shading sweep with the Blender add-on: one object shaded from the scene camera for
every (roughness, World rotation) pair; writes a CSV of summary values and, with --images, a
Workbench render of each result showing the colour attribute.

    python examples/addon_shade_sweep.py                                # Suzanne under "sunset"
    python examples/addon_shade_sweep.py --blend scene.blend --object Suzanne \
        --roughness 0.02 0.1 0.3 --rotation 0 90 180 270 --images

The jobs run on wenv_sweep, each in a Blender process of the sweep's: --workers of them on this
machine, or on a Dask cluster's workers (--scheduler tcp://host:8786).  Each result is kept in
OUT/sweep.jsonl as it comes, so running again resumes an interrupted sweep.  Without --blend a
scene is built: smooth Suzanne (subdivided twice, 7958 vertices), a Principled material and
Blender's bundled "sunset" HDRI.  The sweep sets the roughness as Blender takes it (alpha = roughness^2): the
Principled BSDF's Roughness for a material shaded from its node (the add-on's default), every lobe's for a
Cook-Torrance one.
"""
import argparse
import concurrent.futures
import csv
import math
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
import bpy  # noqa: E402

import addon  # noqa: E402
from addon import compat, engine, materials, meshes, shading  # noqa: E402
import wenv_sweep  # noqa: E402

OUT = os.path.join(ROOT, "out")


def bundled_hdri(name):
    """One of the studio HDRIs that ship with Blender (city, courtyard, forest, interior, night,
    studio, sunrise, sunset)."""
    return os.path.join(bpy.utils.system_resource("DATAFILES", path="studiolights/world"), name + ".exr")


def demo_scene(levels=2):
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    scene = bpy.context.scene
    tree = compat.world_node_tree(scene.world)
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(bundled_hdri("sunset"))
    tree.links.new(env.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.object
    obj.modifiers.new("sub", "SUBSURF").levels = levels
    with bpy.context.temp_override(object=obj):
        bpy.ops.object.modifier_apply(modifier="sub")
    obj.data.shade_smooth()
    mat = compat.new_node_material("paint")
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.5, 0.08, 0.03, 1)
    obj.data.materials.append(mat)
    scene.camera.location = (0.0, -4.5, 0.6)
    scene.camera.rotation_euler = (math.radians(84), 0.0, 0.0)
    return scene, obj


def mapping_node(world):
    """The World's Mapping node feeding the Environment Texture, added if there is none."""
    tree = compat.world_node_tree(world)
    env = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexEnvironment")
    if env.inputs["Vector"].is_linked:
        return env.inputs["Vector"].links[0].from_node
    mapping = tree.nodes.new("ShaderNodeMapping")
    coords = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    return mapping


def prepared(settings):
    """In a job's Blender: the scene the sweep shades (built or opened once per Blender process, and
    kept while the settings are the same), its object, material, Principled node and World Mapping."""
    key = repr(sorted(settings.items()))
    if not hasattr(bpy.types.Material, "wenv"):
        addon.register()
    scene = bpy.context.scene
    if scene.get("wenv_sweep") != key:
        if settings["blend"]:
            bpy.ops.wm.open_mainfile(filepath=settings["blend"])
            scene = bpy.context.scene
        else:
            scene, _ = demo_scene(settings.get("levels", 2))
        st = scene.wenv
        st.quality = settings["quality"].upper()
        st.tone_mapping = "LOG"
        st.max_luminance = settings["max_luminance"]
        if settings["images"]:
            scene.render.engine = "BLENDER_WORKBENCH"
            scene.display.shading.light = "FLAT"
            scene.display.shading.color_type = "VERTEX"
            scene.view_settings.view_transform = "Standard"
            scene.render.resolution_x = scene.render.resolution_y = settings["size"]
        scene["wenv_sweep"] = key
    obj = bpy.data.objects[settings["object"]]
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    mat = obj.active_material
    materials.ensure_material_settings(mat)
    node = materials.principled_node(mat) if mat.wenv.model == "PRINCIPLED" else None
    return scene, obj, mat, node, mapping_node(scene.world)


def shade_one(roughness, rotation, settings):
    """One job, in a Blender of the sweep's: the object shaded at this roughness and World rotation;
    its summary row (and, with images, a Workbench render of it)."""
    scene, obj, mat, node, mapping = prepared(settings)
    if node is not None:
        node.inputs["Roughness"].default_value = roughness
    for lobe in mat.wenv.lobes:
        lobe.roughness = roughness
    mapping.inputs["Rotation"].default_value[2] = math.radians(rotation)
    t = time.perf_counter()
    bpy.ops.wenv.shade(view="CAMERA")
    ms = (time.perf_counter() - t) * 1e3
    attr = obj.data.color_attributes[meshes.ATTRIBUTE]
    rgb = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color", rgb)
    rgb = rgb.reshape(-1, 4)[:, :3]
    lum = rgb @ shading.LUMINANCE
    if settings["images"]:
        scene.render.filepath = os.path.join(settings["out"], f"r{roughness:g}_rot{rotation:g}.png")
        bpy.ops.render.render(write_still=True)
    return {"roughness": roughness, "rotation_deg": rotation, "mean_r": float(rgb[:, 0].mean()),
            "mean_g": float(rgb[:, 1].mean()), "mean_b": float(rgb[:, 2].mean()),
            "max_display_luminance": float(lum.max()), "shade_ms": ms}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--blend", help=".blend to open (default: a built-in demo scene)")
    ap.add_argument("--object", default="Suzanne")
    ap.add_argument("--roughness", type=float, nargs="+", default=[0.01, 0.05, 0.2, 0.5])
    ap.add_argument("--rotation", type=float, nargs="+", default=[0, 90, 180, 270], help="degrees")
    ap.add_argument("--quality", default="draft", choices=engine.QUALITIES)
    ap.add_argument("--max-luminance", type=float, default=4.0, help="logarithmic tone mapping")
    ap.add_argument("--images", action="store_true", help="render each result with Workbench")
    ap.add_argument("--size", type=int, default=320, help="image size in pixels")
    ap.add_argument("--workers", type=int, default=2, help="Blender processes on this machine")
    ap.add_argument("--scheduler", help="a Dask scheduler's address: run the jobs on its cluster")
    ap.add_argument("--out", default=os.path.join(OUT, "addon_sweep"))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    settings = {"blend": args.blend and os.path.abspath(args.blend), "object": args.object,
                "quality": args.quality, "max_luminance": args.max_luminance, "images": args.images,
                "size": args.size, "out": os.path.abspath(args.out)}
    jobs = [{"roughness": r, "rotation": deg, "settings": settings} for r in args.roughness for deg in args.rotation]
    if args.scheduler:
        from dask.distributed import Client
        executor = Client(args.scheduler).get_executor()
    else:  # each thread drives a Blender process of its own (in_blender)
        executor = concurrent.futures.ThreadPoolExecutor(args.workers)
    # each result is kept as it comes: run again to resume an interrupted sweep
    with executor:
        report = wenv_sweep.run(jobs, wenv_sweep.in_blender(shade_one), executor=executor,
                                results=os.path.join(args.out, "sweep.jsonl"))
    rows = [report.results[wenv_sweep.key(job)] for job in jobs if wenv_sweep.key(job) in report.results]
    for job, error in report.failed:
        print(f"failed: roughness {job['roughness']:g}, rotation {job['rotation']:g}: {error}")
    for row in rows:
        print(f"roughness {row['roughness']:g}, rotation {row['rotation_deg']:g} deg: mean "
              f"{(row['mean_r'] + row['mean_g'] + row['mean_b']) / 3:.3f}, {row['shade_ms']:.1f} ms")
    path = os.path.join(args.out, "sweep.csv")
    with open(path, "w", newline="") as fp:
        w = csv.DictWriter(fp, fieldnames=list(rows[0]))
        w.writeheader()
        for row in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
    print("wrote", path)
    return 1 if report.failed else 0


if __name__ == "__main__":
    sys.exit(main())
