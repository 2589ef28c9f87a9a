"""wenv's shadows against Cycles and EEVEE, over the pixels of two scenes a Blender user shades:
Suzanne subdivided 3 times (31,658 vertices) and a sphere resting on a plane (a contact shadow),
under Blender's eight bundled HDRIs, for a Principled paint, metal and gloss.

For each case the scene is rendered
  - by Cycles with direct light only (Max Bounces 0: the World through every shadow ray) and with
    its default bounces, each at two seeds (their mean is the truth; half their difference's RMSE
    is the noise of that mean), every pixel at --samples (adaptive sampling off: it stops a pixel
    whose first samples missed a highlight smaller than the pixel, such as a one-pixel light of
    night's seen in the gloss, and both seeds then agree on a value far too dark);
  - by EEVEE (Blender's real-time engine, default settings);
  - flat (Workbench, the vertex colours) from wenv's vertex colours: `default`, shadows with no
    bounce (against direct Cycles), shadows with the mesh's own diffuse light as the bounce
    (against full Cycles), and without shadows;
  - with --bake N, from the add-on's bakes of every texel of an N x N image per object (`default`,
    through a UV map of their own, Smart UV Project), Shadows on and Bounce Light off (against
    direct Cycles) and on with Glossy Bounce (against full Cycles), the bakes shown as emitted
    light by Cycles; and what Glossy Bounce costs the add-on's shading of the scene's vertices.
Prints relative RMSEs (RMSE over the mean, over the pixels both cover) and writes
out/shadows_vs_cycles.json.  Long: a few minutes per scene and HDRI, a minute more with bakes.  --renders DIR keeps the Cycles and EEVEE
renders there and reads them back in a later run of the same scene, size and samples (they do not
depend on wenv): a run that changes only wenv then renders only wenv's images.

    python benchmarks/shadows_vs_cycles.py [--scenes suzanne plane] [--hdris sunset ...] [--size 256] [--samples 128]
                                           [--bake 2048] [--renders DIR]
    python benchmarks/shadows_vs_cycles.py --summary out/shadows_vs_cycles.json [more.json ...]
"""
import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
import bpy  # noqa: E402
import wenv  # noqa: E402

from addon import meshes  # noqa: E402
from tests.conftest import HDRI_NAMES, hdri_path  # noqa: E402

MATERIALS = {
    "paint": {"Base Color": (0.6, 0.15, 0.08, 1.0), "Roughness": 0.3},
    "metal": {"Base Color": (0.9, 0.6, 0.3, 1.0), "Metallic": 1.0, "Roughness": 0.3},
    "gloss": {"Base Color": (0.1, 0.3, 0.6, 1.0), "Roughness": 0.1},
}


def build(scene_name, size):
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    for name in ("Cube", "Light"):
        bpy.data.objects.remove(bpy.data.objects[name])
    scene = bpy.context.scene
    objs = []
    if scene_name == "suzanne":
        bpy.ops.mesh.primitive_monkey_add()
        obj = bpy.context.object
        obj.modifiers.new("subdivision", "SUBSURF").levels = 3
        with bpy.context.temp_override(object=obj):
            bpy.ops.object.modifier_apply(modifier="subdivision")
        obj.data.shade_smooth()
        objs.append(obj)
        scene.camera.location = (0.0, -4.2, 0.5)
        scene.camera.rotation_euler = (math.radians(84), 0.0, 0.0)
    else:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=1.0, location=(0.0, 0.0, 1.0))
        sphere = bpy.context.object
        sphere.data.shade_smooth()
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=160, y_subdivisions=160, size=10.0)
        plane = bpy.context.object
        plane.data.shade_smooth()
        objs += [sphere, plane]
        scene.camera.location = (0.0, -6.5, 3.5)
        scene.camera.rotation_euler = (math.radians(65), 0.0, 0.0)
    render_settings(scene, size)
    return scene, objs


def render_settings(scene, size):
    """size x size renders, transparent film, Standard view, 32-bit EXR, no denoising; Workbench
    flat with the vertex colours."""
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.display.shading.light = "FLAT"
    scene.display.shading.color_type = "VERTEX"


def set_world(scene, hdri):
    tree = scene.world.node_tree
    env = tree.nodes.get("wenv_env") or tree.nodes.new("ShaderNodeTexEnvironment")
    env.name = "wenv_env"
    env.image = bpy.data.images.load(hdri_path(hdri), check_existing=True)
    tree.links.new(env.outputs["Color"], tree.nodes["Background"].inputs["Color"])


def set_material(objs, inputs):
    mat = bpy.data.materials.new("m")
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    for socket, value in inputs.items():
        node.inputs[socket].default_value = value
    for obj in objs:
        obj.data.materials.clear()
        obj.data.materials.append(mat)
    return mat


def render(scene, engine, folder, seed=0):
    scene.render.engine = engine
    scene.cycles.seed = seed
    scene.render.filepath = os.path.join(folder, f"{engine}-{seed}.exr")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(scene.render.filepath)
    px = np.array(img.pixels[:], np.float32).reshape(img.size[1], img.size[0], 4)[::-1]
    bpy.data.images.remove(img)
    return px


def smart_project(obj):
    """Unwraps obj's active UV map into islands that do not overlap (Smart UV Project)."""
    with bpy.context.temp_override(active_object=obj, object=obj, selected_objects=[obj]):
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        bpy.ops.uv.smart_project(island_margin=0.02)
        bpy.ops.object.mode_set(mode="OBJECT")


def emission_material(image, uv_map=None):
    """The bake shown as emitted light through the UV map `uv_map` (None: the active render one;
    linear texels)."""
    mat = bpy.data.materials.new("baked")
    tree = mat.node_tree
    tree.nodes.clear()
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = image, "Linear"
    if uv_map is not None:
        uv = tree.nodes.new("ShaderNodeUVMap")
        uv.uv_map = uv_map
        tree.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    emit = tree.nodes.new("ShaderNodeEmission")
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(tex.outputs["Color"], emit.inputs["Color"])
    tree.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return mat


BAKE_UV = "bake"


def add_bake_map(obj):
    """A UV map of islands that do not overlap (Smart UV Project), for the bake alone: the
    textures keep reading the active render map."""
    render_map = obj.data.uv_layers.active.name
    layer = obj.data.uv_layers.new(name=BAKE_UV)
    obj.data.uv_layers.active = layer
    smart_project(obj)
    obj.data.uv_layers.active = obj.data.uv_layers[render_map]
    obj.data.uv_layers[render_map].active_render = True


def baked_render(scene, objs, size, bounce, folder, seed=1, shadows=True):
    """The add-on's bake of each of objs at size x size from the camera (Shadows and Bounce Light as
    given; each bake sees the others' materials as they are), rendered by Cycles as emitted light
    through the bakes' UV map; and the bakes' time."""
    from addon import bake, views

    scene.wenv.shadows, scene.wenv.bounce_light = shadows, bounce
    images, seconds = [], 0.0
    for k, obj in enumerate(objs):
        name = f"wenv bake {k} {size}"
        image = bpy.data.images.get(name) or bpy.data.images.new(name, size, size, float_buffer=True)
        start = time.perf_counter()
        bake.bake(scene, bpy.context.evaluated_depsgraph_get(), obj, image, views.camera_view(scene), bpy.data,
                  uv_map=BAKE_UV, view_source="CAMERA")
        seconds += time.perf_counter() - start
        images.append(image)
    kept = [obj.data.materials[0] for obj in objs]
    emits = [emission_material(image, BAKE_UV) for image in images]
    for obj, emit in zip(objs, emits):
        obj.data.materials[0] = emit
    bounces = scene.cycles.max_bounces
    scene.cycles.max_bounces = 0
    try:
        return render(scene, "CYCLES", folder, seed), seconds
    finally:
        for obj, mat in zip(objs, kept):
            obj.data.materials[0] = mat
        scene.cycles.max_bounces = bounces
        for emit in emits:
            bpy.data.materials.remove(emit)


def glossy_cost(scene, objs):
    """Seconds the add-on takes to shade `objs`' vertices from the camera (Shadows, Bounce Light, the
    last material and World set) with the bounce made anew (its rays kept), without and with Glossy
    Bounce: the median of three each."""
    from addon import engine, shading, views

    scene.wenv.shadows = scene.wenv.bounce_light = True
    dg = bpy.context.evaluated_depsgraph_get()
    shading.shade_objects(scene, dg, objs, views.camera_view(scene), bpy.data)  # the rays and shaders made
    seconds = {}
    for key, glossy in (("diffuse", False), ("glossy", True)):
        scene.wenv.glossy_bounce = glossy
        times = []
        for _ in range(3):
            engine.shadows.drop_light()
            start = time.perf_counter()
            shading.shade_objects(scene, dg, objs, views.camera_view(scene), bpy.data)
            times.append(time.perf_counter() - start)
        seconds[key] = float(np.median(times))
    scene.wenv.glossy_bounce = True
    return seconds


def kept_render(scene, engine, kept, seed=0):
    """render() through a folder of renders kept between runs: `kept` is (folder, name of the case),
    the folder None to render into a temporary one and keep nothing.  Cycles' renders are known by
    their samples too (EEVEE's do not depend on them)."""
    folder, case = kept
    if folder is None:
        with tempfile.TemporaryDirectory(prefix="wenv-shadows-") as tmp:
            return render(scene, engine, tmp, seed)
    if engine == "CYCLES":
        case += f"-{scene.cycles.samples}-fixed"
    path = os.path.join(folder, f"{case}-{engine}-{scene.cycles.max_bounces}-{seed}.npy")
    if os.path.exists(path):
        return np.load(path)
    px = render(scene, engine, folder, seed)
    np.save(path, px)
    return px


def cycles_direct_and_full(scene, kept):
    """Cycles at two seeds with direct light only (Max Bounces 0, the World through every shadow ray)
    and with its default bounces: (direct, full), two images each."""
    scene.cycles.max_bounces = 0
    direct = [kept_render(scene, "CYCLES", kept, seed) for seed in (1, 2)]
    scene.cycles.max_bounces = 12
    return direct, [kept_render(scene, "CYCLES", kept, seed) for seed in (1, 2)]


def eevee_engine():
    items = bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items.keys()
    return "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in items else "BLENDER_EEVEE"


def arrays(objs):
    dg = bpy.context.evaluated_depsgraph_get()
    data = [meshes.read_mesh(o, dg) for o in objs]
    p = np.vstack([d.positions for d in data])
    n = np.vstack([d.normals for d in data])
    offsets = np.cumsum([0] + [d.count for d in data])
    t = np.vstack([d.triangles + o for d, o in zip(data, offsets)])
    return data, p, n, t, offsets


def summary(rows):
    """The rows as a markdown table, and per material how many cases meet the targets: within Cycles'
    noise + 2 % of direct Cycles, and at most half EEVEE's error from full Cycles."""
    bake = "bake_direct" in rows[0]
    head = ["scene", "HDRI", "material", "noise (direct)", "wenv, direct", "unshadowed", "noise (full)", "wenv, full",
            "EEVEE"] + (["bake, direct", "bake, full"] if bake else [])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["scene"], r["hdri"], r["material"]] + [f"{100 * r[k]:.1f} %" for k in (
            "noise_direct", "direct", "unshadowed_vs_direct", "noise_full", "full", "eevee_vs_full")]
        cells += [f"{100 * r[k]:.1f} %" for k in ("bake_direct", "bake_full")] if bake else []
        lines.append("| " + " | ".join(cells) + " |")
    for material in dict.fromkeys(r["material"] for r in rows):
        mine = [r for r in rows if r["material"] == material]
        for what, direct, full in [("vertex colours", "direct", "full")] + ([("bake", "bake_direct", "bake_full")]
                                                                             if bake else []):
            ok_direct = sum(r[direct] <= r["noise_direct"] + 0.02 for r in mine)
            ok_full = sum(r[full] <= 0.5 * r["eevee_vs_full"] for r in mine)
            excess = np.median([r[direct] - r["noise_direct"] for r in mine])
            lines.append(f"{material}, {what}: within noise + 2 % of direct Cycles in {ok_direct} of {len(mine)} "
                         f"(median excess over the noise {100 * excess:.1f} %); within half EEVEE's error of full "
                         f"Cycles in {ok_full} of {len(mine)}")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=["suzanne", "plane"])
    ap.add_argument("--hdris", nargs="*", default=HDRI_NAMES)
    ap.add_argument("--materials", nargs="*", default=list(MATERIALS))
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--samples", type=int, default=1024, help="Cycles' samples per pixel (every pixel)")
    ap.add_argument("--resolution", type=int, default=0, help="occlusion side (0: the add-on's choice)")
    ap.add_argument("--bake", type=int, default=0, metavar="N",
                    help="also bake every texel of an N x N image per object (0: no bake)")
    ap.add_argument("--renders", metavar="DIR", help="keep Cycles' and EEVEE's renders here, and reuse them")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "shadows_vs_cycles.json"))
    ap.add_argument("--summary", metavar="JSON", nargs="+",
                    help="print the table and the targets met of runs' JSON (a later run's case replaces an earlier "
                         "one's), and stop")
    args = ap.parse_args()
    if args.summary:
        cases = {}
        for path in args.summary:
            with open(path) as f:
                cases.update(((r["scene"], r["hdri"], r["material"]), r) for r in json.load(f)["rows"])
        order = (["suzanne", "plane"], HDRI_NAMES, list(MATERIALS))
        def place(row):
            return tuple(o.index(row[k]) for o, k in zip(order, ("scene", "hdri", "material")))

        print(summary(sorted(cases.values(), key=place)))
        return
    rows, costs = [], {}
    eevee = eevee_engine()
    if args.bake:
        import addon
        addon.register()
    if args.renders:
        os.makedirs(args.renders, exist_ok=True)
    print(f"{'scene':8s} {'HDRI':10s} {'material':8s} | {'noise':>6s} {'direct':>7s} {'unshad':>7s} | "
          f"{'noise':>6s} {'full':>7s} {'unshad':>7s} {'EEVEE':>7s}" + (" | bake: direct full" if args.bake else ""))
    for scene_name in args.scenes:
        scene, objs = build(scene_name, args.size)
        scene.cycles.samples = args.samples
        if args.bake:
            for obj in objs:
                add_bake_map(obj)
            scene.wenv.quality, scene.wenv.tone_mapping = "DEFAULT", "NONE"
            scene.wenv.glossy_bounce = True
            bpy.context.view_layer.update()
        data, p, n, t, offsets = arrays(objs)
        occluders = wenv.Occluders(p, t)
        res = args.resolution or (16 if len(p) < 40000 else 8)
        start = time.perf_counter()
        occlusion = occluders.occlusion(p, n, resolution=res)
        t_occ = time.perf_counter() - start
        eye = tuple(scene.camera.matrix_world.translation)
        for hdri in args.hdris:
            set_world(scene, hdri)
            env = wenv.load_environment(hdri_path(hdri))
            for mname in args.materials:
                mat = set_material(objs, MATERIALS[mname])
                pr = wenv.Principled(base_color=MATERIALS[mname]["Base Color"][:3],
                                     metallic=MATERIALS[mname].get("Metallic", 0.0),
                                     roughness=MATERIALS[mname]["Roughness"])
                shader = wenv.Shader(env, pr, quality="default")
                light = shader.diffuse_light(n, occlusion=occlusion)
                shaded = {
                    "direct": shader.shade_mesh(p, n, eye, occlusion=occlusion, bounce=None),
                    "full": shader.shade_mesh(p, n, eye, occlusion=occlusion, bounce=light),
                    "unshadowed": shader.shade_mesh(p, n, eye),
                }
                with tempfile.TemporaryDirectory(prefix="wenv-shadows-") as folder:
                    imgs = {}
                    for key, rgb in shaded.items():
                        for obj, d, o in zip(objs, data, offsets):
                            meshes.write_colors(obj.data, d.domain, rgb[o:o + d.count])
                        imgs[key] = render(scene, "BLENDER_WORKBENCH", folder)
                    kept = (args.renders, f"{scene_name}-{hdri}-{mname}-{args.size}")
                    imgs["eevee"] = kept_render(scene, eevee, kept)
                    direct, full = cycles_direct_and_full(scene, kept)
                    baked = {key: baked_render(scene, objs, args.bake, bounce, folder)
                             for key, bounce in (("bake_direct", False), ("bake_full", True))} if args.bake else {}
                    imgs.update((key, img) for key, (img, _) in baked.items())
                mask = np.ones(imgs["direct"].shape[:2], bool)
                for img in list(imgs.values()) + direct + full:
                    mask &= img[..., 3] > 0.99

                def rel(a, b):
                    a, b = a[..., :3][mask].astype(np.float64), b[..., :3][mask].astype(np.float64)
                    return float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(b))

                def half_error_pixels(a, b):
                    """How few pixels hold half of a's squared error against b (a few: highlights
                    smaller than a pixel)."""
                    e = np.sort(((a[..., :3] - b[..., :3]) ** 2).sum(-1)[mask].astype(np.float64))[::-1]
                    return int(np.searchsorted(np.cumsum(e), 0.5 * e.sum()) + 1)

                d_mean, f_mean = (direct[0] + direct[1]) / 2, (full[0] + full[1]) / 2
                row = dict(scene=scene_name, hdri=hdri, material=mname, vertices=len(p), pixels=int(mask.sum()),
                           noise_direct=rel(direct[0], direct[1]) / 2,
                           direct=rel(imgs["direct"], d_mean), unshadowed_vs_direct=rel(imgs["unshadowed"], d_mean),
                           noise_full=rel(full[0], full[1]) / 2, full=rel(imgs["full"], f_mean),
                           unshadowed_vs_full=rel(imgs["unshadowed"], f_mean), eevee_vs_full=rel(imgs["eevee"], f_mean),
                           direct_half_error_pixels=half_error_pixels(imgs["direct"], d_mean))
                if args.bake:
                    row.update(bake=args.bake, bake_direct=rel(imgs["bake_direct"], d_mean),
                               bake_full=rel(imgs["bake_full"], f_mean),
                               bake_half_error_pixels=half_error_pixels(imgs["bake_direct"], d_mean),
                               bake_seconds={key: seconds for key, (_, seconds) in baked.items()})
                rows.append(row)
                print(f"{scene_name:8s} {hdri:10s} {mname:8s} | {100 * row['noise_direct']:5.1f}% "
                      f"{100 * row['direct']:6.1f}% {100 * row['unshadowed_vs_direct']:6.1f}% | "
                      f"{100 * row['noise_full']:5.1f}% {100 * row['full']:6.1f}% "
                      f"{100 * row['unshadowed_vs_full']:6.1f}% {100 * row['eevee_vs_full']:6.1f}%"
                      + (f" | {100 * row['bake_direct']:6.1f}% {100 * row['bake_full']:6.1f}%" if args.bake else ""),
                      flush=True)
                bpy.data.materials.remove(mat)
        print(f"{scene_name}: {len(p)} vertices, occlusion {res}x{res} in {t_occ:.2f} s")
        if args.bake:
            cost = glossy_cost(scene, objs)
            costs[scene_name] = cost
            print(f"{scene_name}: the add-on's shading with Bounce Light in {cost['diffuse']:.2f} s, with Glossy "
                  f"Bounce in {cost['glossy']:.2f} s (the bounce made anew, the rays kept)")
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/shadows_vs_cycles.py " + " ".join(sys.argv[1:]),
                       machine=platform.machine(), samples=args.samples, size=args.size, bake=args.bake, rows=rows,
                       glossy_bounce_seconds=costs), f, indent=1)
    print("wrote", args.out)
    print(summary(rows))


if __name__ == "__main__":
    main()
