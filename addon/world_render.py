"""A World as Cycles renders it, in a Blender process of its own (world.render_world starts it):

    blender -b --factory-startup --python world_render.py -- BLEND WORLD NPY WIDTH SAMPLES FRAME
    python world_render.py -- ...      (where bpy is a Python module)

It appends the World from BLEND (written by the add-on's process), renders it through an
equirectangular panoramic camera -- the projection of an Environment Texture's image -- into a
WIDTH x WIDTH / 2 image, each pixel the mean of SAMPLES samples over its area (a box filter), then
the pixels of a small bright feature (a sun's disc) again at SUN_SAMPLES, so that its few pixels
keep its energy, and saves the image's RGBA to NPY (float32, scene linear, row 0 the bottom).  A
process of its own leaves the user's file alone: its Render Result, render slots and scenes.
Standalone: it imports nothing of the add-on."""
import math
import sys

SUN_SAMPLES = 1024
SUN_CONTRAST = 100.0  # a pixel this many times the image's mean is the bright feature's


def bright_box(px):
    """(x0, y0, x1, y1), pixels from the bottom left, about the pixels SUN_CONTRAST times brighter
    than the image's mean (and two more on each side), or None: none, or spread over more than a
    hundredth of the image (a bright sky rather than a sun)."""
    import numpy as np

    lum = px[..., :3].mean(axis=2)
    ys, xs = np.nonzero(lum > SUN_CONTRAST * max(float(lum.mean()), 1e-30))
    if not len(xs):
        return None
    h, w = lum.shape
    x0, x1 = max(int(xs.min()) - 2, 0), min(int(xs.max()) + 3, w)
    y0, y1 = max(int(ys.min()) - 2, 0), min(int(ys.max()) + 3, h)
    if (x1 - x0) * (y1 - y0) > w * h // 100:
        return None
    return x0, y0, x1, y1


def render(blend, world_name, out, width, samples, frame):
    import bpy
    import numpy as np

    bpy.ops.wm.read_factory_settings(use_empty=True)
    with bpy.data.libraries.load(blend, link=False) as (source, target):
        target.worlds = [world_name]
    world = target.worlds[0]
    sc = bpy.context.scene
    sc.world = world
    sc.frame_set(frame)
    height = width // 2
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = samples
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = False
    sc.cycles.pixel_filter_type = "BOX"  # each pixel the mean over its own area
    sc.cycles.filter_width = 1.0
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = width, height, 100
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.filepath = out + ".exr"
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    sc.collection.objects.link(camera)
    sc.camera = camera
    camera.data.type, camera.data.panorama_type = "PANO", "EQUIRECTANGULAR"
    camera.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)  # the image's centre along -X, as the texture's

    def shot():
        bpy.ops.render.render(write_still=True)
        loaded = bpy.data.images.load(sc.render.filepath, check_existing=False)
        buf = np.empty(width * height * 4, np.float32)
        loaded.pixels.foreach_get(buf)
        bpy.data.images.remove(loaded)
        return buf.reshape(height, width, 4)  # (row 0 the bottom)
    px = shot()
    box = bright_box(px) if samples < SUN_SAMPLES else None
    if box is not None:
        x0, y0, x1, y1 = box
        sc.cycles.samples = SUN_SAMPLES
        sc.render.use_border, sc.render.use_crop_to_border = True, False
        sc.render.border_min_x, sc.render.border_max_x = x0 / width, x1 / width
        sc.render.border_min_y, sc.render.border_max_y = y0 / height, y1 / height
        fine = shot()
        px[y0:y1, x0:x1] = fine[y0:y1, x0:x1]
    np.save(out, px)


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:]
    render(args[0], args[1], args[2], int(args[3]), int(args[4]), int(args[5]))
