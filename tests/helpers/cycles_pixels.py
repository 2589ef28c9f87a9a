"""A factory-fresh Blender scene that Cycles renders one sample a pixel, at the pixel's centre, into a
32-bit EXR of scene-linear values (no denoising, the Standard view transform), an orthographic
camera of `ortho_scale` looking down -Z from `at` + (0, 0, 5): what the node tests compare
wenv's reading of a node with, pixel by pixel (tests/test_procedural_textures.py,
tests/test_attributes.py)."""
import tempfile

import numpy as np


def pixel_scene(bpy, n, at=(0.0, 0.0), ortho_scale=4.0):
    """The scene set up for n x n pixels; returns shot(), which renders it and gives the pixels'
    RGB ((n * n, 3) float32, row 0 at the bottom)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 1
    sc.cycles.use_denoising = False
    sc.cycles.filter_width = 0.01  # the sample at the pixel's centre
    sc.render.resolution_x = sc.render.resolution_y = n
    sc.view_settings.view_transform = "Standard"
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.filepath = f"{tempfile.mkdtemp(prefix='wenv-pixels-')}/pixels.exr"
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.data.type, cam.data.ortho_scale = "ORTHO", ortho_scale
    cam.location = (at[0], at[1], 5.0)

    def shot():
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(sc.render.filepath)
        px = np.array(img.pixels[:], np.float32).reshape(n * n, 4)[:, :3]
        bpy.data.images.remove(img)
        return px
    return shot
