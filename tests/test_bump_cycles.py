"""A plane whose Normal Map bends every normal by a fixed angle, under a white World: the add-on's
colours against Cycles' render of it (direct light), with the material's Bump Map Correction on and
off.  A Lambertian part under a uniform sky reflects the share of it Cycles' bump terminator lets
through, so the plane's one colour is compared with the render's mean, within its noise."""
import math
import os
import tempfile

import numpy as np
import pytest

import bpy  # noqa: E402  (installed by scripts/setup.sh; missing, the tests fail rather than skip)

from test_addon import attribute, flat_pngs, registered, scene, select_only, shade_op  # noqa: E402,F401

BENDS = (30.0, 60.0)


def bent_plane(scene, folder, bend_deg):
    """A 2 m plane seen from straight above by an orthographic camera that it fills, a white Principled
    diffuse (no specular) whose Normal Map reads a flat image bending the normal by bend_deg along the
    UV map's u."""
    for name in ("Cube", "Light"):
        bpy.data.objects.remove(bpy.data.objects[name])
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    plane = bpy.context.object
    plane.data.shade_smooth()
    cam = scene.camera
    cam.location, cam.rotation_euler = (0.0, 0.0, 3.0), (0.0, 0.0, 0.0)
    cam.data.type, cam.data.ortho_scale = "ORTHO", 1.0
    d = math.radians(bend_deg)
    path = os.path.join(folder, f"bend{int(bend_deg)}.png")
    flat_pngs({path: (0.5 + 0.5 * math.sin(d), 0.5, 0.5 + 0.5 * math.cos(d))})
    image = bpy.data.images.load(path)
    image.colorspace_settings.name = "Non-Color"
    mat = bpy.data.materials.new("bent")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    tree = mat.node_tree
    node = tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    node.inputs["Specular IOR Level"].default_value = 0.0
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = image, "Closest"
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], node.inputs["Normal"])
    plane.data.materials.append(mat)
    background = scene.world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    background.inputs["Strength"].default_value = 1.0
    select_only(plane)
    return plane, mat


def cycles_mean(scene, folder):
    """Cycles' direct light on the plane, 16 x 16 pixels at 512 samples: the mean and its noise."""
    scene.render.engine = "CYCLES"
    scene.render.resolution_x = scene.render.resolution_y = 16
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.view_settings.view_transform = "Standard"
    scene.cycles.samples, scene.cycles.max_bounces, scene.cycles.use_denoising = 512, 0, False
    scene.render.filepath = os.path.join(folder, "bent.exr")
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(scene.render.filepath)
    px = np.array(img.pixels[:], np.float64).reshape(-1, 4)[:, :3]
    bpy.data.images.remove(img)
    return px.mean(), px.std() / math.sqrt(px.size)


@pytest.mark.parametrize("correction", [True, False])
@pytest.mark.parametrize("bend", BENDS)
def test_a_bent_plane_shades_as_cycles_renders_it(scene, bend, correction):
    """The add-on reads the material's Bump Map Correction and the plane's one colour is Cycles'
    mean within 4 times its noise (and 0.5 %), where the unbent white would be 1."""
    with tempfile.TemporaryDirectory() as folder:
        plane, mat = bent_plane(scene, folder, bend)
        mat.cycles.use_bump_map_correction = correction
        truth, noise = cycles_mean(scene, folder)
        scene.wenv.quality = "DEFAULT"
        assert shade_op(view="CAMERA") == {"FINISHED"}
        _, rgb = attribute(plane)
    got = float(rgb.mean())
    assert abs(got - truth) <= max(4 * noise, 0.005 * truth), (got, truth, noise)
    assert truth < 0.95  # the terminator, not the white, is what is compared
