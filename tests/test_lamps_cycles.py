"""Lamps against Cycles: a sphere resting on a square, lit by a sun, a soft-falloff point lamp, a spot
and an area lamp under a black World, rendered by Cycles with direct light only (Max Bounces 0), and
shaded by wenv from the Light objects as the add-on reads them (addon/lamps.py): the reference and the
shader, both with the sphere's and the square's shadows, within Cycles' noise."""
import math

import numpy as np
import pytest

import bpy  # noqa: E402  (installed by scripts/setup.sh; missing, the tests fail rather than skip)

import wenv  # noqa: E402
from addon import engine, lamps  # noqa: E402
from tests.helpers.cycles_sphere import LAMP_SETUPS, SphereScene  # noqa: E402


@pytest.fixture(scope="module")
def lit_scene():
    scene = SphereScene(size=40, samples=256, image=np.zeros((8, 16, 3), np.float32), ground=True)
    LAMP_SETUPS["four lamps"](scene)
    bpy.context.view_layer.update()
    scene.scene.cycles.max_bounces = 0
    return scene


@pytest.mark.parametrize("material", [dict(base_color=(0.7, 0.5, 0.3), roughness=0.5),
                                      dict(base_color=(0.9, 0.7, 0.4), metallic=1.0, roughness=0.35)])
def test_lamps_match_cycles_within_its_noise(lit_scene, material):
    scene = lit_scene
    scene.principled(**material)
    settings, notes = lamps.read_lamps(scene.scene)
    assert len(settings) == 4 and not notes
    lit = engine.make_lamps(settings)
    a, b = (scene.render(seed)[scene.mask].astype(np.float64) for seed in (1, 2))
    mat = wenv.Principled(**material)
    black = wenv.Environment(np.zeros((8, 16, 3), np.float32))
    occluders = scene.occluders()
    ref = wenv.reference(black, mat, scene.normals, scene.views, positions=scene.positions, occluders=occluders,
                         lamps=lit).astype(np.float64)
    occlusion = occluders.occlusion(scene.positions, scene.normals)
    fast = wenv.Shader(black, mat, quality="draft").shade(scene.normals, scene.views, occlusion=occlusion, bounce=None,
                                                         positions=scene.positions, lamps=lit).astype(np.float64)
    scale = math.sqrt(float(np.mean(ref ** 2)))
    noise_of_mean = math.sqrt(float(np.mean((a - b) ** 2)) / 2) / scale / math.sqrt(2)
    cycles = (a + b) / 2
    for shaded in (ref, fast):
        error = math.sqrt(float(np.mean((cycles - shaded) ** 2))) / scale
        # the mean's own noise, with room for the noise's own spread and the mesh's facets
        assert error < 1.5 * noise_of_mean + 0.01, (error, noise_of_mean)
    assert abs(cycles.mean() / ref.mean() - 1.0) < 0.02


def test_light_linking_matches_cycles(lit_scene):
    """The area lamp's receiver collection includes only the ground, the spot's excludes only the
    ground: Cycles lights the sphere with neither the area lamp nor less of the spot, and wenv, the
    lamps chosen for the sphere as the add-on chooses them (addon/lamps.py), within Cycles' noise."""
    scene = lit_scene
    material = dict(base_color=(0.7, 0.5, 0.3), roughness=0.5)
    scene.principled(**material)
    made = []
    try:
        for light, state in (("area", "INCLUDE"), ("spot", "EXCLUDE")):
            coll = bpy.data.collections.new(f"receivers of {light}")
            coll.objects.link(scene.ground)
            coll.collection_objects[0].light_linking.link_state = state
            bpy.data.objects[light].light_linking.receiver_collection = coll
            made.append(light)
        bpy.context.view_layer.update()
        settings, _ = lamps.read_lamps(scene.scene)
        everything = engine.make_lamps(settings)
        lit = [lamp for lamp, s in zip(everything, settings) if lamps.lights(s, scene.sphere.name)]
        assert len(lit) == 3 and not lamps.lights(next(s for s in settings if s["name"] == "area"), scene.sphere.name)
        a, b = (scene.render(seed)[scene.mask].astype(np.float64) for seed in (1, 2))
    finally:
        for light in made:
            bpy.data.objects[light].light_linking.receiver_collection = None
        bpy.context.view_layer.update()
    black = wenv.Environment(np.zeros((8, 16, 3), np.float32))
    mat = wenv.Principled(**material)
    occluders = scene.occluders()
    kw = dict(positions=scene.positions, occluders=occluders)
    ref = wenv.reference(black, mat, scene.normals, scene.views, lamps=lit, **kw).astype(np.float64)
    unlinked = wenv.reference(black, mat, scene.normals, scene.views, lamps=everything, **kw).astype(np.float64)
    scale = math.sqrt(float(np.mean(ref ** 2)))
    noise_of_mean = math.sqrt(float(np.mean((a - b) ** 2)) / 2) / scale / math.sqrt(2)
    cycles = (a + b) / 2
    error = math.sqrt(float(np.mean((cycles - ref) ** 2))) / scale
    assert error < 1.5 * noise_of_mean + 0.01, (error, noise_of_mean)
    # the area lamp's light would be well outside the noise
    assert math.sqrt(float(np.mean((cycles - unlinked) ** 2))) / scale > 5 * (noise_of_mean + 0.01)


def light_tree(name):
    """The Light `name`'s node tree, switched on: its Emission node and the tree."""
    light = bpy.data.objects[name].data
    light.use_nodes = True
    tree = light.node_tree
    return next(n for n in tree.nodes if n.bl_idname == "ShaderNodeEmission"), tree


def test_a_lamps_node_tree_of_constants_matches_cycles(lit_scene):
    """The spot's Emission Color from a Blackbody of 3,500 K and its Strength from Math on a Value, the
    area lamp's Color from an RGB node: read into the lamps' colour and power (no note), and the
    sphere as Cycles renders it, within its noise.  A Light Path node into a Strength (a light's
    emission is read along the rays that reach it, not a camera's) is named, not read."""
    scene = lit_scene
    material = dict(base_color=(0.7, 0.5, 0.3), roughness=0.5)
    scene.principled(**material)
    spot, spot_tree = light_tree("spot")
    area, area_tree = light_tree("area")
    try:
        body = spot_tree.nodes.new("ShaderNodeBlackbody")
        body.inputs["Temperature"].default_value = 3500.0
        spot_tree.links.new(body.outputs["Color"], spot.inputs["Color"])
        value, times = spot_tree.nodes.new("ShaderNodeValue"), spot_tree.nodes.new("ShaderNodeMath")
        value.outputs[0].default_value, times.operation, times.inputs[1].default_value = 0.5, "MULTIPLY", 3.0
        spot_tree.links.new(value.outputs[0], times.inputs[0])
        spot_tree.links.new(times.outputs[0], spot.inputs["Strength"])
        rgb = area_tree.nodes.new("ShaderNodeRGB")
        rgb.outputs[0].default_value = (0.2, 0.6, 1.0, 1.0)
        area_tree.links.new(rgb.outputs[0], area.inputs["Color"])
        bpy.context.view_layer.update()
        settings, notes = lamps.read_lamps(scene.scene)
        assert not notes, notes
        by_name = {s["name"]: s for s in settings}
        assert by_name["spot"]["energy"] == pytest.approx(400.0 * 1.5)
        assert by_name["area"]["color"] == pytest.approx((0.2, 0.6, 1.0))
        assert by_name["spot"]["color"][2] < 0.5 * by_name["spot"]["color"][0]  # a warm white
        lit = engine.make_lamps(settings)
        a, b = (scene.render(seed)[scene.mask].astype(np.float64) for seed in (1, 2))
        path = area_tree.nodes.new("ShaderNodeLightPath")
        area_tree.links.new(path.outputs["Is Camera Ray"], area.inputs["Strength"])
        assert any("Light 'area': its node tree is not read" in n for n in lamps.read_lamps(scene.scene)[1])
    finally:
        for light in ("spot", "area"):
            bpy.data.objects[light].data.use_nodes = False
        bpy.context.view_layer.update()
    black = wenv.Environment(np.zeros((8, 16, 3), np.float32))
    ref = wenv.reference(black, wenv.Principled(**material), scene.normals, scene.views, positions=scene.positions,
                         occluders=scene.occluders(), lamps=lit).astype(np.float64)
    scale = math.sqrt(float(np.mean(ref ** 2)))
    noise_of_mean = math.sqrt(float(np.mean((a - b) ** 2)) / 2) / scale / math.sqrt(2)
    error = math.sqrt(float(np.mean(((a + b) / 2 - ref) ** 2))) / scale
    assert error < 1.5 * noise_of_mean + 0.01, (error, noise_of_mean)
