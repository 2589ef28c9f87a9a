"""A textured, normal-mapped, lamp-lit scene against Cycles and EEVEE, as a Blender user sets it up:
Suzanne subdivided 3 times (31,658 vertices) with a Principled paint whose Base Color is a UV-mapped
checker image, whose Roughness is a striped image (0.15 and 0.6) and whose Normal is a tangent-space
normal map of gentle bumps, lit by a sun, an area lamp and the World (sunset, then forest).

wenv reads the scene as the add-on does (addon/shading.py's plan: textures, the normal map and the
Light objects) and shades it at `default` with the mesh's shadows; its vertex colours are rendered
flat (Workbench).  Cycles renders the scene with direct light only (Max Bounces 0) and with its
default bounces, two seeds each (the mean is the truth, half the seeds' difference its noise);
EEVEE with its defaults.  Also shown: what wenv gave before lamps and textures were read (the
World's light on the unlinked values, no shadows).  With --bake N, the add-on also bakes every
texel of an N x N image through a UV map of its own (Smart UV Project; the textures keep theirs),
with shadows and Bounce Light off (against Cycles' direct light) and on (against full Cycles), the
bake shown as emitted light by Cycles.  Relative RMSE over the mean, over the pixels all cover;
writes out/scene_vs_cycles.json.  About 10 minutes, 15 with a bake.

    python benchmarks/scene_vs_cycles.py [--hdris sunset forest] [--size 256] [--samples 128]
                                         [--without checker stripes bumps lamps] [--bake 2048]
"""
import argparse
import json
import os
import platform
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))
import bpy  # noqa: E402
import wenv  # noqa: E402

import addon  # noqa: E402
from addon import engine, meshes, shading, views  # noqa: E402
from shadows_vs_cycles import (add_bake_map, baked_render, build, cycles_direct_and_full, eevee_engine,  # noqa: E402
                               render, set_world)
from tests.conftest import hdri_path  # noqa: E402


def image(name, pixels, non_color=False):
    img = bpy.data.images.new(name, pixels.shape[1], pixels.shape[0], float_buffer=True)
    if non_color:
        img.colorspace_settings.name = "Non-Color"
    rgba = np.ones(pixels.shape[:2] + (4,), np.float32)
    rgba[..., :3] = pixels
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    return img


def textured_paint():
    """The paint: a checker Base Color (8 x 8 squares), striped Roughness, a normal map of bumps."""
    size = 256
    u, v = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size)
    checker = ((np.floor(u * 8) + np.floor(v * 8)) % 2)[..., None]
    colour = np.where(checker > 0, np.float32([0.7, 0.12, 0.05]), np.float32([0.85, 0.8, 0.7]))
    stripes = np.where(np.floor(u * 6) % 2 > 0, 0.6, 0.15)[..., None] * np.ones(3, np.float32)
    # a height of gentle bumps, its slopes as a tangent-space normal
    h = 0.015 * np.sin(2 * np.pi * 5 * u) * np.sin(2 * np.pi * 5 * v)
    dx, dy = np.gradient(h, 1.0 / size)
    nrm = np.stack([-dx, -dy, np.ones_like(h)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    mat = bpy.data.materials.new("textured paint")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    tree = mat.node_tree
    node = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    for socket, img in (("Base Color", image("checker", colour)), ("Roughness", image("stripes", stripes, True))):
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image = img
        tree.links.new(tex.outputs["Color"], node.inputs[socket])
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = image("bumps", 0.5 * nrm + 0.5, True)
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], node.inputs["Normal"])
    return mat


def set_normals(mesh, data, normals):
    """Custom normals, per vertex or per corner as wenv read the mesh."""
    rows = [tuple(v) for v in normals.tolist()]
    if data.domain == "POINT":
        mesh.normals_split_custom_set_from_vertices(rows)
    else:
        mesh.normals_split_custom_set(rows)


def at_vertices(obj, data):
    """The material's textured Base Color and Roughness replaced by attributes holding what wenv read
    at each vertex, and its normal map by the shading normals wenv read (custom normals); returns
    what puts the material and mesh back."""
    mesh, mat = obj.data, obj.data.materials[0]
    tree = mat.node_tree
    node = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    links = {s: node.inputs[s].links[0].from_socket for s in ("Base Color", "Roughness", "Normal")
             if node.inputs[s].is_linked}
    added = []
    if "base_color" in data.inputs:
        colour = mesh.attributes.new("wenv_base", "FLOAT_COLOR", data.domain)
        rgba = np.ones((data.count, 4), np.float32)
        rgba[:, :3] = data.inputs["base_color"]
        colour.data.foreach_set("color", rgba.ravel())
        read = tree.nodes.new("ShaderNodeAttribute")
        read.attribute_name = "wenv_base"
        tree.links.new(read.outputs["Color"], node.inputs["Base Color"])
        added.append(read)
    if "roughness" in data.inputs:
        value = mesh.attributes.new("wenv_rough", "FLOAT", data.domain)
        value.data.foreach_set("value", data.inputs["roughness"])
        read = tree.nodes.new("ShaderNodeAttribute")
        read.attribute_name = "wenv_rough"
        tree.links.new(read.outputs["Fac"], node.inputs["Roughness"])
        added.append(read)
    if data.shading_normals is not None:  # the object is unturned: world normals are its own
        tree.links.remove(node.inputs["Normal"].links[0])
        set_normals(mesh, data, data.shading_normals)

    def undo():
        for n in added:
            tree.nodes.remove(n)
        for socket, source in links.items():
            tree.links.new(source, node.inputs[socket])
        for name in ("wenv_base", "wenv_rough"):
            if mesh.attributes.get(name) is not None:
                mesh.attributes.remove(mesh.attributes[name])
        if data.shading_normals is not None:
            set_normals(mesh, data, data.normals)
    return undo


def add_lamps(scene):
    for kind, name, location, rotation, settings in (
            ("SUN", "sun", (0, 0, 5), (0.7, 0.2, 0.6), dict(energy=3.0, angle=0.05)),
            ("AREA", "area", (-1.5, -2.0, 1.5), (1.0, 0.0, -0.6), dict(energy=150.0, size=1.0))):
        data = bpy.data.lights.new(name, kind)
        for key, value in settings.items():
            setattr(data, key, value)
        obj = bpy.data.objects.new(name, data)
        scene.collection.objects.link(obj)
        obj.location, obj.rotation_euler = location, rotation


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hdris", nargs="*", default=["sunset", "forest"])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--samples", type=int, default=128)
    ap.add_argument("--without", nargs="*", default=[], choices=["checker", "stripes", "bumps", "lamps"],
                    help="leave parts out, to see what each costs")
    ap.add_argument("--bake", type=int, default=0, metavar="N",
                    help="also bake every texel of an N x N image (0: no bake)")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "scene_vs_cycles.json"))
    args = ap.parse_args()
    wenv.set_num_threads(2)
    addon.register()
    scene, objs = build("suzanne", args.size)
    scene.cycles.samples = args.samples
    obj = objs[0]
    mat = textured_paint()
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    for part, socket in (("checker", "Base Color"), ("stripes", "Roughness"), ("bumps", "Normal")):
        if part in args.without:
            mat.node_tree.links.remove(node.inputs[socket].links[0])
    obj.data.materials.append(mat)
    if "lamps" not in args.without:
        add_lamps(scene)
    if args.bake:
        add_bake_map(obj)
        scene.wenv.quality, scene.wenv.tone_mapping = "DEFAULT", "NONE"
    bpy.context.view_layer.update()
    eevee = eevee_engine()
    rows = []
    for hdri in args.hdris:
        set_world(scene, hdri)
        env = wenv.load_environment(hdri_path(hdri))
        plan = shading.plan_shading(scene, bpy.context.evaluated_depsgraph_get(), [obj], views.camera_view(scene),
                                    bpy.data.images)
        _, data, keys = plan.items[0]
        shader = wenv.Shader(env, engine.material_from_key(keys[0]), quality="default")
        p, n = data.positions, data.normals if data.shading_normals is None else data.shading_normals
        occlusion = wenv.Occluders(p, data.triangles).occlusion(p, data.normals)
        eye = tuple(scene.camera.matrix_world.translation)
        kw = dict(data.inputs, lamps=plan.lamps)
        # Cycles given the bent normals as the mesh's own (below) sees no bump: wenv's shading of them
        # as unbent is what that comparison reads
        shaded = {"unbent": shader.shade_mesh(p, n, eye, occlusion=occlusion, bounce=None, **kw)}
        if data.shading_normals is not None:  # bent by the normal map, as the add-on shades them
            kw.update(smooth_normals=data.normals, bump_map_correction=data.bump_map_correction)
        light = shader.diffuse_light(n, occlusion=occlusion, positions=p, **kw)
        shaded.update(direct=shader.shade_mesh(p, n, eye, occlusion=occlusion, bounce=None, **kw),
                      full=shader.shade_mesh(p, n, eye, occlusion=occlusion, bounce=light, **kw),
                      before=shader.shade_mesh(p, data.normals, eye))
        with tempfile.TemporaryDirectory(prefix="wenv-scene-") as folder:
            imgs = {}
            for key, rgb in shaded.items():
                meshes.write_colors(obj.data, data.domain, rgb)
                imgs[key] = render(scene, "BLENDER_WORKBENCH", folder)
            imgs["eevee"] = render(scene, eevee, folder)
            direct, full = cycles_direct_and_full(scene, (None, "scene"))  # (nothing kept between runs)
            # Cycles given the inputs wenv read at the vertices (interpolated across the faces, as
            # Cycles interpolates attributes): what is left is wenv's own, not the mesh's resolution
            undo = at_vertices(obj, data)
            scene.cycles.max_bounces = 0
            matched = [render(scene, "CYCLES", folder, seed) for seed in (1, 2)]
            undo()
            baked = {}
            if args.bake:
                for key, bounce in (("bake_direct", False), ("bake_full", True)):
                    baked[key] = baked_render(scene, [obj], args.bake, bounce, folder)
                imgs.update((key, img) for key, (img, _) in baked.items())
        mask = np.ones(imgs["direct"].shape[:2], bool)
        for img in list(imgs.values()) + direct + full + matched:
            mask &= img[..., 3] > 0.99

        def rel(a, b):
            a, b = a[..., :3][mask].astype(np.float64), b[..., :3][mask].astype(np.float64)
            return float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(b))

        d_mean, f_mean = (direct[0] + direct[1]) / 2, (full[0] + full[1]) / 2
        m_mean = (matched[0] + matched[1]) / 2
        row = dict(hdri=hdri, vertices=len(p), pixels=int(mask.sum()), notes=plan.notes,
                   noise_direct=rel(direct[0], direct[1]) / 2, direct=rel(imgs["direct"], d_mean),
                   before_vs_direct=rel(imgs["before"], d_mean), noise_full=rel(full[0], full[1]) / 2,
                   full=rel(imgs["full"], f_mean), eevee_vs_full=rel(imgs["eevee"], f_mean),
                   mean_ratio_direct=float(imgs["direct"][..., :3][mask].mean() / d_mean[..., :3][mask].mean()),
                   noise_matched=rel(matched[0], matched[1]) / 2, matched=rel(imgs["unbent"], m_mean))
        if args.bake:
            row.update(bake=args.bake, bake_direct=rel(imgs["bake_direct"], d_mean),
                       bake_full=rel(imgs["bake_full"], f_mean),
                       bake_seconds={key: seconds for key, (_, seconds) in baked.items()})
        rows.append(row)
        print(f"{hdri:8s}: direct {100 * row['direct']:.1f} % (Cycles' noise {100 * row['noise_direct']:.1f} %, "
              f"before {100 * row['before_vs_direct']:.1f} %, wenv / Cycles {row['mean_ratio_direct']:.3f}); full "
              f"{100 * row['full']:.1f} % (noise {100 * row['noise_full']:.1f} %, EEVEE "
              f"{100 * row['eevee_vs_full']:.1f} %); direct against Cycles given the inputs at the vertices "
              f"{100 * row['matched']:.1f} % (noise {100 * row['noise_matched']:.1f} %)", flush=True)
        if args.bake:
            print(f"  bake {args.bake}^2: direct {100 * row['bake_direct']:.1f} %, full {100 * row['bake_full']:.1f} % "
                  f"(baked in {row['bake_seconds']['bake_direct']:.2f} / {row['bake_seconds']['bake_full']:.2f} s)",
                  flush=True)
        if plan.notes:
            print("  notes:", "; ".join(plan.notes))
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(dict(command="python benchmarks/scene_vs_cycles.py " + " ".join(sys.argv[1:]), without=args.without,
                       bake=args.bake,
                       machine=platform.machine(), samples=args.samples, size=args.size, rows=rows), f, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
