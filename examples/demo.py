"""The main job, on an embedded default (no downloads): what a Blender user came for.  A bpy scene --
Suzanne with a Principled BSDF paint whose Base Color is a striped image texture (two paints, through
her UV map) under Blender's bundled "sunset" HDRI, a camera -- is shaded by
the wenv add-on (registered from this checkout) into its colour attribute, with her shadows and the
light she bounces into them; the colours are rendered to an image (Workbench, flat attribute
colours) beside Cycles' and EEVEE's renders of the same scene; the gloss of the material is read as
a glossmeter would.  Writes out/demo.png (wenv | Cycles | EEVEE | wenv's difference x 4) and prints
the timings, the differences and the readings.

    .venv/bin/python examples/demo.py [--hdri sunset] [--quality default] [--size 320] [--samples 64] [--out out/demo.png]

benchmarks/shadows_vs_cycles.py measures the same over the eight HDRIs, three materials and two
scenes, against Cycles with and without bounces and with Cycles' noise stated."""
import argparse
import math
import os
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "out")
sys.path.insert(0, ROOT)
import bpy  # noqa: E402

import addon  # noqa: E402
from addon import compat, meshes  # noqa: E402

PAINT = {"Base Color": (0.6, 0.15, 0.08, 1.0), "Roughness": 0.3}
# The texture's two paints, in stripes across her UV map (linear RGB): the red above and a cream
STRIPES = ((0.6, 0.15, 0.08), (0.8, 0.7, 0.45))


def striped_image(stripes=6, side=64):
    """A float image of vertical stripes of the two paints, made here (nothing to download)."""
    image = bpy.data.images.new("paint stripes", side, side, float_buffer=True)
    u = (np.arange(side) + 0.5) / side
    cream = (np.floor(u * stripes) % 2).astype(bool)
    px = np.ones((side, side, 4), np.float32)
    px[:, :, :3] = np.where(cream[None, :, None], np.float32(STRIPES[1]), np.float32(STRIPES[0]))
    image.pixels.foreach_set(px.ravel())
    image.pack()  # kept in the .blend, as an image a user painted would be
    return image


def bundled_hdri(name):
    """One of the eight studio HDRIs that ship with Blender (city, courtyard, forest, interior, night,
    studio, sunrise, sunset): the bpy module carries them."""
    return os.path.join(bpy.utils.system_resource("DATAFILES", path="studiolights/world"), name + ".exr")


def build_scene(hdri, size):
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    for name in ("Cube", "Light"):  # wenv shades the World's light only: no lamp, for a like comparison
        bpy.data.objects.remove(bpy.data.objects[name])
    scene = bpy.context.scene
    tree = compat.world_node_tree(scene.world)
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(bundled_hdri(hdri))
    tree.links.new(env.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.object
    obj.modifiers.new("subdivision", "SUBSURF").levels = 2
    with bpy.context.temp_override(object=obj):  # applied: the add-on shades a mesh vertex by vertex
        bpy.ops.object.modifier_apply(modifier="subdivision")
    obj.data.shade_smooth()
    mat = compat.new_node_material("paint")
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    for socket, value in PAINT.items():
        node.inputs[socket].default_value = value
    texture = mat.node_tree.nodes.new("ShaderNodeTexImage")
    texture.image = striped_image()
    mat.node_tree.links.new(texture.outputs["Color"], node.inputs["Base Color"])
    obj.data.materials.append(mat)
    scene.camera.location = (0.0, -4.2, 0.5)
    scene.camera.rotation_euler = (math.radians(84), 0.0, 0.0)
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    return scene, obj, mat


def render(scene, engine, folder):
    """The scene rendered by `engine`, float32 RGBA (size, size, 4), linear, row 0 the top."""
    scene.render.engine = engine
    scene.render.filepath = os.path.join(folder, engine + ".exr")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(scene.render.filepath)
    px = np.array(img.pixels[:], np.float32).reshape(img.size[1], img.size[0], 4)[::-1]
    bpy.data.images.remove(img)
    return px


def display(rgb):
    """Linear radiance to sRGB for the picture (Blender's "Standard" view), clipped at white."""
    c = np.clip(rgb, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hdri", default="sunset")
    ap.add_argument("--quality", default="default", choices=["draft", "default", "high", "auto"])
    ap.add_argument("--size", type=int, default=320, help="image side in pixels")
    ap.add_argument("--samples", type=int, default=64, help="Cycles samples per pixel")
    ap.add_argument("--out", default=os.path.join(OUT, "demo.png"), help="the picture written")
    args = ap.parse_args()

    addon.register()
    scene, obj, mat = build_scene(args.hdri, args.size)
    scene.wenv.quality = args.quality.upper()
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.context.view_layer.objects.active = obj
    vertices = len(obj.data.vertices)

    t0 = time.perf_counter()
    assert bpy.ops.wenv.shade(view="CAMERA") == {"FINISHED"}  # precomputes (or loads) the matrices first
    t_first = time.perf_counter() - t0
    scene.camera.location.x += 0.3  # a new view: what a viewport orbit costs
    t0 = time.perf_counter()
    assert bpy.ops.wenv.shade(view="CAMERA") == {"FINISHED"}
    t_view = time.perf_counter() - t0

    scene.display.shading.light = "FLAT"
    scene.display.shading.color_type = "VERTEX"
    mesh = obj.data
    mesh.color_attributes.active_color_name = meshes.ATTRIBUTE
    scene.cycles.samples = args.samples
    scene.cycles.use_denoising = False
    engines = bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items.keys()
    eevee = "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines else "BLENDER_EEVEE"
    with tempfile.TemporaryDirectory(prefix="wenv-demo-") as folder:
        wenv_img = render(scene, "BLENDER_WORKBENCH", folder)
        t0 = time.perf_counter()
        cycles_img = render(scene, "CYCLES", folder)
        t_cycles = time.perf_counter() - t0
        t0 = time.perf_counter()
        eevee_img = render(scene, eevee, folder)
        t_eevee = time.perf_counter() - t0

    # Workbench keeps alpha at half precision
    mask = (wenv_img[..., 3] > 0.99) & (cycles_img[..., 3] > 0.99) & (eevee_img[..., 3] > 0.99)
    a, b = wenv_img[..., :3][mask].astype(np.float64), cycles_img[..., :3][mask].astype(np.float64)
    e = eevee_img[..., :3][mask].astype(np.float64)
    rel = math.sqrt(float(np.mean((a - b) ** 2)) / float(np.mean(b ** 2)))
    rel_eevee = math.sqrt(float(np.mean((e - b) ** 2)) / float(np.mean(b ** 2)))
    st = mat.wenv
    print(f"Suzanne ({vertices} vertices), Principled paint (Base Color: stripes of {STRIPES[0]} and "
          f"{STRIPES[1]} through her UV map; roughness {PAINT['Roughness']}), {args.hdri} HDRI, quality {args.quality}")
    print(f"  wenv, first shade (matrices built or loaded, lighting, material): {t_first:8.2f} s")
    print(f"  wenv, a new view:                                                  {1e3 * t_view:8.1f} ms")
    print(f"  Cycles, {args.samples} samples per pixel:                                 {t_cycles:8.2f} s")
    print(f"  EEVEE (Blender's real-time engine, default settings, headless):   {t_eevee:8.2f} s")
    print(f"  against Cycles over Suzanne's pixels (relative RMSE, with Cycles' own noise): wenv {100 * rel:.1f} % "
          f"(mean radiance ratio {a.mean() / b.mean():.3f}), EEVEE {100 * rel_eevee:.1f} %")
    print(f"  gloss: {st.gloss_20:.2f} GU at 20 deg, {st.gloss_60:.2f} GU at 60 deg, {st.gloss_85:.2f} GU at 85 deg; "
          f"haze {st.haze:.2f} HU")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(14, 3.8))
    diff = np.zeros_like(wenv_img[..., :3])
    diff[mask] = np.abs(a - b) * 4
    for ax, img, title in zip(axes, (wenv_img[..., :3], cycles_img[..., :3], eevee_img[..., :3], diff),
                              (f"wenv add-on ({args.quality}, {1e3 * t_view:.0f} ms a view)",
                               f"Cycles ({args.samples} spp, {t_cycles:.0f} s)",
                               f"EEVEE ({100 * rel_eevee:.1f} % from Cycles)", "wenv |difference| x 4")):
        ax.imshow(display(img))
        ax.set_title(title, fontsize=10)
        ax.axis("off")
    fig.suptitle(f"Striped Principled paint under {args.hdri}: 60 deg gloss {st.gloss_60:.1f} GU, relative RMSE "
                 f"{100 * rel:.1f} %", fontsize=11)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    fig.savefig(args.out, dpi=90, bbox_inches="tight")
    print(f"  wrote {args.out}")


if __name__ == "__main__":
    main()
