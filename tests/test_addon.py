"""The Blender add-on in the headless bpy module: registration, World set-ups, materials, meshes,
views, the shading operator against the core, live mode, frame changes, undo, save and reload.

Expected values are computed here independently (mathutils transforms, the core loading the HDRI
from its file, fresh wenv.Shader objects) and compared with what the operator wrote."""
import math
import os
import time

import numpy as np
import pytest

import wenv

import bpy  # noqa: E402  (installed by scripts/setup.sh; missing, the tests fail rather than skip)
import mathutils  # noqa: E402  (ships with bpy)

import addon  # noqa: E402
from addon import bake, compat, engine, gloss, live, materials, meshes, nodes, shading, views, world  # noqa: E402

from conftest import hdri_path, readme_block  # noqa: E402
from tests.helpers.blender_versions import has_diffuse_roughness, has_light_temperature, node_material

ATTR = meshes.ATTRIBUTE
BUMP = compat.BUMP_MAP_CORRECTION  # (the bump terminator of the Blender running)


@pytest.fixture(scope="module", autouse=True)
def registered(tmp_path_factory):
    old = os.environ.get("WENV_CACHE_DIR")
    os.environ["WENV_CACHE_DIR"] = str(tmp_path_factory.mktemp("wenv-cache"))
    addon.register()
    yield
    addon.unregister()
    if old is None:
        os.environ.pop("WENV_CACHE_DIR", None)
    else:
        os.environ["WENV_CACHE_DIR"] = old


@pytest.fixture
def scene():
    """Blender's factory start-up scene (cube, camera, light, grey World), draft quality, live mode
    not refining at rest (the tests of refinement turn it on), shadows off (their tests turn them
    on: the start-up cube would otherwise stand in every object's sky), and its Light hidden from
    renders (the lamps' tests show it again: the others compare with the World's light alone)."""
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    sc = bpy.context.scene
    bpy.data.objects["Light"].hide_render = True
    sc.wenv.quality = "DRAFT"
    assert sc.wenv.refine_at_rest and sc.wenv.shadows  # on for users
    sc.wenv.refine_at_rest = False
    sc.wenv.shadows = False
    return sc


def select_only(*objs):
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0] if objs else None


def add_monkey(subdivisions=0, smooth=True, name="Suzanne"):
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.object
    obj.name = name
    if subdivisions:
        mod = obj.modifiers.new("sub", "SUBSURF")
        mod.levels = subdivisions
        with bpy.context.temp_override(object=obj):
            bpy.ops.object.modifier_apply(modifier="sub")
    if smooth:
        obj.data.shade_smooth()
    else:
        obj.data.shade_flat()
    select_only(obj)
    return obj


def env_world(scene, name="sunset", rotation=0.0, strength=1.0, projection="EQUIRECTANGULAR", image=None):
    tree = scene.world.node_tree
    bg = tree.nodes["Background"]
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = image if image is not None else bpy.data.images.load(hdri_path(name))
    env.projection = projection
    tree.links.new(env.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = strength
    if rotation:
        mapping = tree.nodes.new("ShaderNodeMapping")
        coords = tree.nodes.new("ShaderNodeTexCoord")
        tree.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        tree.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
        mapping.inputs["Rotation"].default_value[2] = rotation
    return env


def set_material(obj, model="COOK_TORRANCE", diffuse=(0.3, 0.2, 0.1), lobes=((0.2, 1.5, "GGX"),), name=None):
    mat = node_material(bpy, name or f"M{len(bpy.data.materials)}")
    st = mat.wenv
    st.model = model
    st.diffuse = diffuse
    for alpha, ior, dist in lobes:
        lobe = st.lobes.add()
        lobe.alpha, lobe.ior, lobe.distribution = alpha, ior, dist
    st.initialized = True
    obj.data.materials.append(mat)
    return mat


def wenv_material(mat):
    st = mat.wenv
    if st.model == "LAMBERT":
        return wenv.Lambert(tuple(st.diffuse))
    return wenv.CookTorrance(diffuse=tuple(st.diffuse), lobes=[
        {"specular": tuple(l.specular), "alpha": l.alpha, "ior": l.ior,
         "distribution": l.distribution.lower()} for l in st.lobes], shadowing=st.shadowing.lower())


def world_arrays(obj, corner):
    """World-space positions and normals, computed with mathutils (independent of meshes.read_mesh)."""
    dg = bpy.context.evaluated_depsgraph_get()
    ob = obj.evaluated_get(dg)
    me = ob.data
    m = ob.matrix_world
    nm = m.to_3x3().inverted().transposed()
    if corner:
        pts = [me.vertices[l.vertex_index].co for l in me.loops]
        nrm = [c.vector for c in me.corner_normals]
    else:
        pts = [v.co for v in me.vertices]
        nrm = [v.vector for v in me.vertex_normals]
    p = np.array([tuple(m @ c) for c in pts], np.float32)
    n = np.array([tuple((nm @ v).normalized()) for v in nrm], np.float32)
    return p, n


def attribute(obj):
    attr = obj.data.color_attributes[ATTR]
    buf = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    return attr.domain, buf.reshape(-1, 4)[:, :3]


def core_shader(env, mat):
    return wenv.Shader(env, mat, quality="draft")


def animate_camera(cam):
    """Keys the camera at (7, -7, 5) on frame 1 and (-7, -7, 2) on frame 10."""
    cam.location = (7.0, -7.0, 5.0)
    cam.keyframe_insert("location", frame=1)
    cam.location = (-7.0, -7.0, 2.0)
    cam.keyframe_insert("location", frame=10)


def shade_op(**kw):
    return bpy.ops.wenv.shade(**kw)


# ---------------------------------------------------------------------------------------------


def test_register_unregister_leaves_nothing():
    assert bpy.ops.wenv.shade.poll() and hasattr(bpy.types, "WENV_PT_gloss")
    names = [n for n in dir(bpy.types) if n.startswith("WENV_")]
    assert {"WENV_PT_shading", "WENV_PT_material", "WENV_PT_gloss", "WENV_OT_shade",
            "WENV_OT_live", "WENV_OT_fit_roughness"} <= set(names)
    assert bpy.types.Scene.bl_rna.properties["wenv"].fixed_type.identifier == "WENV_SceneSettings"
    assert bpy.types.Material.bl_rna.properties["wenv"].fixed_type.identifier == "WENV_MaterialSettings"
    addon.unregister()
    try:
        assert not [n for n in dir(bpy.types) if n.startswith("WENV_")]
        assert "wenv" not in bpy.types.Scene.bl_rna.properties
        assert "wenv" not in bpy.types.Material.bl_rna.properties
        assert not [h for h in bpy.app.handlers.frame_change_post if h.__module__.startswith("addon")]
        for handlers in (bpy.app.handlers.load_post, bpy.app.handlers.undo_post, bpy.app.handlers.redo_post,
                         bpy.app.handlers.render_init, bpy.app.handlers.render_complete,
                         bpy.app.handlers.render_cancel):
            assert not [h for h in handlers if h.__module__.startswith("addon")]
        assert "wenv" not in bpy.types.WindowManager.bl_rna.properties
        assert "wenv" not in bpy.types.View3DShading.bl_rna.properties
        assert not engine.shaders.has("draft")
    finally:
        addon.register()
    assert bpy.types.Scene.bl_rna.properties["wenv"]


def test_only_engine_touches_the_core():
    """engine.py is the one add-on module importing wenv, and what the core accepts (quality
    presets, roughness and IOR ranges) is read from it rather than repeated."""
    import glob
    import re
    folder = os.path.dirname(addon.__file__)
    importers = [os.path.basename(p) for p in sorted(glob.glob(os.path.join(folder, "*.py")))
                 if re.search(r"^\s*(import wenv\b|from wenv\b)", open(p).read(), re.M)]
    assert importers == ["engine.py"]
    quality = bpy.types.Scene.bl_rna.properties["wenv"].fixed_type.properties["quality"]
    assert [i.identifier for i in quality.enum_items] == [q.upper() for q in wenv.QUALITY_PRESETS] + ["AUTO"]
    lobe = bpy.types.Material.bl_rna.properties["wenv"].fixed_type.properties["lobes"].fixed_type.properties
    assert (lobe["alpha"].hard_min, lobe["alpha"].hard_max) == pytest.approx(wenv.ALPHA_RANGE)
    assert wenv.IOR_RANGE[0] < lobe["ior"].hard_min < 1.001 and lobe["ior"].hard_max == pytest.approx(wenv.IOR_RANGE[1])
    # Principled values past the core's limits come out clamped into them, mirrors floored at 1e-4 alpha.
    assert engine.alpha_from_roughness(0.3) == pytest.approx(0.09) and engine.alpha_from_roughness(0.0) == 1e-4
    _, lobes = materials.principled_lobes((0.5, 0.5, 0.5), 0.5, 0.0, 50.0, coat=1.0, coat_roughness=0.0, coat_ior=1.0)
    assert [l["alpha"] for l in lobes] == [1e-4] * 3
    assert all(wenv.IOR_RANGE[0] < l["ior"] <= wenv.IOR_RANGE[1] for l in lobes)
    assert lobes[0]["ior"] == wenv.IOR_RANGE[1] and lobes[2]["ior"] > wenv.IOR_RANGE[0]
    wenv.CookTorrance(diffuse=(0.5, 0.5, 0.5), lobes=[dict(l, distribution="ggx") for l in lobes])  # accepted


def test_operator_equals_core_shade(scene):
    """Sunset HDRI (file), rotated Mapping node, strength 2; rotated, non-uniformly scaled smooth
    Suzanne; perspective scene camera."""
    env_world(scene, "sunset", rotation=0.7, strength=2.0)
    obj = add_monkey()
    obj.rotation_euler = (0.3, -0.2, 1.1)
    obj.scale = (1.0, 1.5, 0.8)
    obj.location = (0.2, 0.1, -0.3)
    mat = set_material(obj, lobes=((0.15, 1.5, "GGX"), (0.4, 1.8, "BECKMANN")))
    assert shade_op(view="CAMERA") == {"FINISHED"}
    domain, rgb = attribute(obj)
    assert domain == "POINT"
    assert obj.data.color_attributes.active_color_name == ATTR

    p, n = world_arrays(obj, corner=False)
    env = wenv.load_environment(hdri_path("sunset"), rotation=0.7, strength=2.0)
    eye = tuple(scene.camera.matrix_world.translation)
    want = core_shader(env, wenv_material(mat)).shade_mesh(p, n, eye)
    assert rgb.max() > 0.05
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)


def test_lamps_are_shaded_as_the_core_shades_them(scene):
    """The start-up Light (a 1000 W point lamp), an area lamp of a temperature and a spot shine on
    Suzanne: the operator's colours are the core's with the lamps as addon/lamps.py reads them, in
    Cycles' units; a light a script gave a negative power is named; moving a lamp re-shades the live
    mode."""
    from addon import engine as addon_engine, lamps as addon_lamps
    env_world(scene, "forest", strength=0.3)
    obj = add_monkey()
    mat = set_material(obj, lobes=((0.2, 1.5, "GGX"),))
    point = bpy.data.objects["Light"]
    point.hide_render = False
    area = bpy.data.objects.new("area", bpy.data.lights.new("area", "AREA"))
    scene.collection.objects.link(area)
    area.location, area.rotation_euler = (0.0, -3.0, 1.0), (1.2, 0.0, 0.0)
    area.data.energy, area.data.size = 300.0, 1.5
    if has_light_temperature(bpy):
        area.data.use_temperature, area.data.temperature = True, 3200.0
    else:
        area.data.color = (1.0, 0.7, 0.4)  # what 3200 K is near, set as a colour before 4.5
    spot = bpy.data.objects.new("spot", bpy.data.lights.new("spot", "SPOT"))
    scene.collection.objects.link(spot)
    spot.location, spot.rotation_euler = (2.0, -2.0, 2.0), (0.8, 0.0, 0.8)
    spot.data.energy, spot.data.spot_size = 500.0, 0.8
    spot.data.use_square = True  # Cycles and EEVEE shade it round: nothing to note
    bpy.context.view_layer.update()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(obj)
    settings, notes = addon_lamps.read_lamps(scene)
    assert sorted(s["name"] for s in settings) == ["Light", "area", "spot"] and notes == []
    warm = next(s for s in settings if s["name"] == "area")["color"]
    assert warm[0] > warm[1] > warm[2]  # 3200 K: Blender's own colour of it (a warm colour before 4.5)
    p, n = world_arrays(obj, corner=False)
    env = wenv.load_environment(hdri_path("forest"), strength=0.3)
    eye = tuple(scene.camera.matrix_world.translation)
    shader = core_shader(env, wenv_material(mat))
    want = shader.shade_mesh(p, n, eye, lamps=addon_engine.make_lamps(settings))
    world_only = shader.shade_mesh(p, n, eye)
    assert np.mean(want) > 2 * np.mean(world_only)  # the lamps carry most of the light here
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)

    for bad in (-5.0, math.inf):  # a script may set what the UI would not
        spot.data.energy = bad
        with pytest.raises(addon_engine.SetupError, match="Light 'spot'.*energy"):
            addon_engine.make_lamps(addon_lamps.read_lamps(scene)[0])
        with pytest.raises(RuntimeError, match="Light 'spot'.*energy"):
            shade_op(view="CAMERA")
        np.testing.assert_array_equal(attribute(obj)[1], rgb)  # the colours shaded before are kept
    spot.data.energy = 500.0

    scene.wenv.view_source = "CAMERA"
    session = live.LiveSession([obj.name])
    session.tick(bpy.context)
    session.wait(60)
    session.tick(bpy.context)
    before = attribute(obj)[1].copy()
    area.location = (0.0, -3.0, 0.2)
    bpy.context.view_layer.update()
    session.tick(bpy.context)
    session.wait(60)
    assert session.tick(bpy.context)  # the moved lamp is a change
    assert not np.allclose(attribute(obj)[1], before)
    session.stop()


@pytest.mark.parametrize("perspective", [True, False])
def test_view_matrix_viewport_and_orthographic_camera(scene, perspective):
    env_world(scene, "forest")
    obj = add_monkey()
    mat = set_material(obj)
    # A viewport view: pivot, rotation, distance; its world -> view matrix as Blender builds it
    # (view3d_viewmatrix_set: viewmat = Tz(-dist) R(viewquat) T(-pivot); view_rotation = viewquat^-1).
    rv3d = next(a for a in bpy.context.screen.areas if a.type == "VIEW_3D").spaces.active.region_3d
    rv3d.view_location = (0.2, -0.1, 0.3)
    rv3d.view_rotation = mathutils.Euler((1.1, 0.0, 0.5)).to_quaternion()
    rv3d.view_distance = 6.0
    rv3d.view_perspective = "PERSP" if perspective else "ORTHO"
    rot = rv3d.view_rotation.to_matrix().to_4x4()
    eye = mathutils.Vector(rv3d.view_location) + rv3d.view_rotation @ mathutils.Vector((0, 0, 6.0))
    view = (mathutils.Matrix.Translation(eye) @ rot).inverted()

    assert shade_op(view="MATRIX", view_matrix=view, perspective=perspective) == {"FINISHED"}
    _, rgb = attribute(obj)
    p, n = world_arrays(obj, corner=False)
    sh = core_shader(wenv.load_environment(hdri_path("forest")), wenv_material(mat))
    inv = view.inverted()
    if perspective:
        want = sh.shade_mesh(p, n, tuple(inv.translation))
    else:
        want = sh.shade(n, np.array(inv.col[2][:3], np.float32))
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)

    # The 3D viewport itself gives the same colours (every vertex: test_viewport_shades_only_what_it_sees).
    obj.data.color_attributes.remove(obj.data.color_attributes[ATTR])
    scene.wenv.shade_only_seen = False
    assert shade_op(view="VIEWPORT") == {"FINISHED"}
    np.testing.assert_allclose(attribute(obj)[1], rgb, rtol=1e-5, atol=1e-6)
    # What the viewport draws, the evaluated mesh, follows each new shading.
    assert shade_op(view="MATRIX", view_matrix=view, perspective=not perspective) == {"FINISHED"}
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    shown = evaluated.data.color_attributes[ATTR]
    buf = np.empty(len(shown.data) * 4, np.float32)
    shown.data.foreach_get("color", buf)
    np.testing.assert_array_equal(buf.reshape(-1, 4)[:, :3], attribute(obj)[1])
    assert not np.allclose(attribute(obj)[1], rgb)

    # An orthographic scene camera: one view direction, the camera's +Z.
    if not perspective:
        scene.camera.data.type = "ORTHO"
        assert shade_op(view="CAMERA") == {"FINISHED"}
        d = np.array(scene.camera.matrix_world.col[2][:3], np.float32)
        np.testing.assert_allclose(attribute(obj)[1], sh.shade(n, d), rtol=1e-4, atol=1e-5)


def test_viewport_shades_only_what_it_sees(scene):
    """From a perspective viewport, Shade Only What Is Seen (the default) shades the vertices facing
    the eye and inside the viewport's frustum (its window_matrix after the view: Blender's
    perspective_matrix convention) exactly as shading all does, and leaves the others' colours as
    they were; off, or from the camera, every vertex is shaded."""
    env_world(scene, "forest")
    obj = add_monkey(subdivisions=1)
    mat = set_material(obj)
    rv3d = next(a for a in bpy.context.screen.areas if a.type == "VIEW_3D").spaces.active.region_3d
    rv3d.view_location = (0.6, 0.0, 0.4)  # off centre: part of the head is off screen
    rv3d.view_rotation = mathutils.Euler((1.2, 0.0, 0.3)).to_quaternion()
    rv3d.view_distance = 2.2
    rv3d.view_perspective = "PERSP"
    rot = np.array(rv3d.view_rotation.to_matrix(), np.float64)
    cam = np.eye(4)
    cam[:3, :3] = rot
    cam[:3, 3] = np.array(rv3d.view_location) + rot[:, 2] * rv3d.view_distance
    vp = np.array(rv3d.window_matrix, np.float64) @ np.linalg.inv(cam)
    eye = tuple(cam[:3, 3])
    p, n = world_arrays(obj, corner=False)
    seen = wenv.visible_vertices(p, n, eye, vp)
    facing = wenv.visible_vertices(p, n, eye)
    assert 0.05 < seen.mean() < facing.mean() < 0.9  # some face away, some facing ones are off screen

    meshes.write_colors(obj.data, "POINT", np.full((len(p), 3), 0.25, np.float32))
    assert scene.wenv.shade_only_seen and shade_op(view="VIEWPORT") == {"FINISHED"}
    _, rgb = attribute(obj)
    want = core_shader(wenv.load_environment(hdri_path("forest")), wenv_material(mat)).shade_mesh(p, n, eye)
    np.testing.assert_allclose(rgb[seen], want[seen], rtol=1e-4, atol=1e-5)
    assert np.all(rgb[~seen] == 0.25)

    scene.wenv.shade_only_seen = False
    assert shade_op(view="VIEWPORT") == {"FINISHED"}
    np.testing.assert_allclose(attribute(obj)[1], want, rtol=1e-4, atol=1e-5)


def first_viewport():
    area = next(a for a in bpy.context.screen.areas if a.type == "VIEW_3D")
    return area, area.spaces.active.shading


def test_viewport_shows_the_colours_only_when_asked_and_is_restored(scene, tmp_path):
    """Shading (the operator, frame changes, live mode) leaves the viewports alone; one click (Show
    in Viewports) shows the colours in every 3D viewport, and the next sets each back as the user
    had it.  Each viewport keeps what it is to be set back to itself, saved with the file and, like
    the viewports, out of undo: undoing data never parts them, and no undo step is made."""
    env_world(scene, "sunset")
    obj = add_monkey()
    wm = bpy.context.window_manager
    area, shading = first_viewport()
    user = ("SOLID", "STUDIO", "OBJECT")
    shading.type, shading.light, shading.color_type = user

    def state():
        return (shading.type, shading.light, shading.color_type)

    assert shade_op(view="CAMERA") == {"FINISHED"} and ATTR in obj.data.color_attributes
    scene.wenv.shade_on_frame_change = True
    scene.frame_set(2)
    session = live.LiveSession([obj.name])
    assert not session.tick(bpy.context) and session.wait(60) and session.tick(bpy.context)
    assert state() == user and not wm.wenv.show_in_viewports

    bpy.ops.ed.undo_push(message="before showing")
    wm.wenv.show_in_viewports = True
    assert state() == ("SOLID", "FLAT", "VERTEX") and wm.wenv.show_in_viewports
    wm.wenv.show_in_viewports = True  # clicked on again: the first backup stays
    bpy.ops.ed.undo_push(message="while showing")
    bpy.ops.ed.undo()  # the data goes back to before the click; the viewports stay as they are
    area, shading = first_viewport()
    assert state() == ("SOLID", "FLAT", "VERTEX") and wm.wenv.show_in_viewports

    path = str(tmp_path / "showing.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    assert not bpy.context.window_manager.wenv.show_in_viewports
    bpy.ops.wm.open_mainfile(filepath=path)
    wm = bpy.context.window_manager
    area, shading = first_viewport()
    assert state() == ("SOLID", "FLAT", "VERTEX") and wm.wenv.show_in_viewports
    # A viewport whose area shows another editor is set back too, for when it returns.
    area.type = "IMAGE_EDITOR"
    assert not wm.wenv.show_in_viewports
    wm.wenv.show_in_viewports = False
    area.type = "VIEW_3D"
    shading = area.spaces.active.shading
    assert state() == user and not wm.wenv.show_in_viewports


def test_plain_colour_world_is_constant(scene):
    bg = scene.world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.2, 0.3, 0.4, 1.0)
    bg.inputs["Strength"].default_value = 1.5
    obj = add_monkey()
    set_material(obj, model="LAMBERT", diffuse=(0.8, 0.5, 0.25))
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(obj)
    p, n = world_arrays(obj, corner=False)
    v = np.array(scene.camera.matrix_world.translation, np.float32) - p
    front = np.sum(n * v, axis=1) > 0.05 * np.linalg.norm(v, axis=1)
    want = 1.5 * np.array([0.2 * 0.8, 0.3 * 0.5, 0.4 * 0.25], np.float32)
    assert front.sum() > 100
    np.testing.assert_allclose(rgb[front], np.broadcast_to(want, rgb[front].shape), rtol=1e-4)


def pattern_image(name="pattern", w=64, h=32):
    """A float image with a distinct colour per pixel (row 0 of the array is the top)."""
    rows, cols = np.mgrid[0:h, 0:w]
    top_first = np.empty((h, w, 4), np.float32)
    top_first[..., 0] = 0.5 + 0.5 * np.cos(2 * np.pi * cols / w)
    top_first[..., 1] = 1.0 - rows / h
    top_first[..., 2] = 0.1 + 0.05 * (cols % 7)
    top_first[..., 3] = 1.0
    top_first[3, 10, :3] = (30.0, 20.0, 10.0)
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    img.pixels.foreach_set(top_first[::-1].ravel())  # Blender: bottom row first
    return img, top_first


@pytest.mark.parametrize("projection", ["EQUIRECTANGULAR", "MIRROR_BALL"])
def test_packed_image_and_mirror_ball(scene, tmp_path, projection):
    img, top_first = pattern_image()
    path = str(tmp_path / "pattern.exr")
    img.filepath_raw = path
    img.file_format = "OPEN_EXR"
    img.save()
    img.pack()
    os.remove(path)  # only the packed copy is left
    assert img.packed_file is not None
    env_world(scene, image=img, projection=projection, rotation=0.4, strength=0.5)
    obj = add_monkey()
    mat = set_material(obj)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(obj)
    proj = "mirror_ball" if projection == "MIRROR_BALL" else "equirect"
    # the pixels Blender holds for the packed file (its EXR codec need not be lossless)
    held = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(held)
    held = held.reshape(top_first.shape)[::-1]
    assert np.allclose(held, top_first, rtol=1e-2, atol=1e-3)
    env = wenv.Environment(np.ascontiguousarray(held), projection=proj, rotation=0.4, strength=0.5)
    p, n = world_arrays(obj, corner=False)
    want = core_shader(env, wenv_material(mat)).shade_mesh(p, n, tuple(scene.camera.matrix_world.translation))
    np.testing.assert_allclose(rgb, want, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("space,decoded", [("sRGB", True), ("Non-Color", False), ("Display P3", False)])
def test_8_bit_world_images_by_colour_space(scene, space, decoded):
    """An 8-bit World image: sRGB is decoded, a linear space or data read as stored, and any other
    space read as stored with a note saying so (Blender hands out 8-bit images' stored values)."""
    img = bpy.data.images.new("ldr", 16, 8, alpha=True, float_buffer=False)
    img.colorspace_settings.name = space  # first: a generated image is made again when it changes
    img.pixels.foreach_set(np.full(16 * 8 * 4, 0.5, np.float32))
    env_world(scene, image=img)
    obj = add_monkey()
    spec = world.world_spec(scene.world)
    held = world.image_pixels(img)[..., :3]
    byte = np.float32(128 / 255)  # 0.5 as stored in 8 bits
    np.testing.assert_allclose(held, world.srgb_to_linear(byte) if decoded else byte, rtol=1e-6)
    _, notes = shading.shade_objects(scene, bpy.context.evaluated_depsgraph_get(), [obj],
                                     views.camera_view(scene), bpy.data)
    noted = [n for n in notes if "8-bit in colour space" in n]
    if space == "Display P3":
        assert noted == [world.world_note(spec, bpy.data.images)] and "'Display P3'" in noted[0]
    else:
        assert noted == [] and world.world_note(spec, bpy.data.images) is None


def _break(scene, how):
    tree = scene.world.node_tree
    bg = tree.nodes["Background"]
    if how == "no world":
        scene.world = None
        return "no World"
    if how == "no nodes":
        tree.nodes.clear()
        return "no World Output"
    if how == "nothing connected":
        tree.links.remove(tree.nodes["World Output"].inputs["Surface"].links[0])
        return "nothing is connected"
    if how == "no image":
        env = env_world(scene, "sunset")
        env.image = None
        return "has no image"
    if how == "missing file":
        env = env_world(scene, "sunset")
        env.image.filepath = "/nonexistent/sky.exr"
        env.image.reload()
        return "could not be loaded"
    if how == "absurd strength":
        env_world(scene, "sunset", strength=1e30)
        return "more than 1e\\+18"
    raise AssertionError(how)


@pytest.mark.parametrize("how", ["no world", "no nodes", "nothing connected", "no image", "missing file",
                                 "absurd strength"])
def test_broken_world_is_reported_and_cancelled(scene, how):
    expect = _break(scene, how)
    obj = add_monkey()
    with pytest.raises(RuntimeError, match=expect):
        shade_op(view="CAMERA")
    assert ATTR not in obj.data.color_attributes


def test_a_world_of_other_nodes_is_rendered_by_cycles(scene):
    """A World the image path does not read -- a linked Strength, a Sky Texture -- is rendered by
    Cycles through an equirectangular camera, in a process of its own: an Environment Texture's
    image renders as the image itself (Closest: to float rounding); it is rendered once per state of
    its nodes (a new view renders nothing), and nothing of the render is left in the file.  Under the Sky Texture a white Lambertian plane facing up shades as Cycles
    renders it (its sun and sky), within 1 % (0.3 % here at Draft, 0.01 % at Default; 1.9 % before
    the sun's pixels took more samples)."""
    from addon import world
    tree = scene.world.node_tree
    bg = tree.nodes["Background"]
    w, h = 64, 32
    image = bpy.data.images.new("bands", w, h, float_buffer=True)
    px = np.zeros((h, w, 4), np.float32)
    px[..., 0] = (np.arange(w) + 0.5)[None, :] / w
    px[..., 1] = (np.arange(h) + 0.5)[:, None] / h
    px[..., 3] = 1.0
    image.pixels.foreach_set(px.ravel())
    image.pack()  # (the World is rendered from a file: an unsaved image's pixels must be in it)
    env = env_world(scene, image=image, rotation=0.0)
    env.interpolation = "Closest"
    assert world.world_spec(scene.world).kind == "image"
    rendered = world.render_world(scene.world, width=w, samples=1)
    np.testing.assert_allclose(rendered[::-1], px, atol=1e-6)  # (row 0 the top: the image's last row)
    value = tree.nodes.new("ShaderNodeValue")
    value.outputs[0].default_value = 2.0
    tree.links.new(value.outputs[0], bg.inputs["Strength"])
    spec = world.world_spec(scene.world)
    assert spec.kind == "rendered" and "strength is driven by a node link" in spec.reason
    sky = tree.nodes.new("ShaderNodeTexSky")
    tree.links.new(sky.outputs["Color"], bg.inputs["Color"])
    tree.links.remove(bg.inputs["Strength"].links[0])
    sky.sun_elevation, sky.sun_rotation = math.radians(35.0), math.radians(60.0)
    for name in ("Cube", "Light"):
        bpy.data.objects[name].hide_render = True
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    plane = bpy.context.object
    mat = node_material(bpy, "white")
    tree_m = mat.node_tree
    tree_m.nodes.clear()
    diffuse, out = tree_m.nodes.new("ShaderNodeBsdfDiffuse"), tree_m.nodes.new("ShaderNodeOutputMaterial")
    diffuse.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    tree_m.links.new(diffuse.outputs[0], out.inputs["Surface"])
    plane.data.materials.append(mat)
    select_only(plane)
    made = []
    real = world.render_world
    world.render_world = lambda *a, **k: made.append(1) or real(*a, **k)
    try:
        assert shade_op(view="CAMERA") == {"FINISHED"}
        scene.camera.location.x += 0.5
        assert shade_op(view="CAMERA") == {"FINISHED"}
    finally:
        world.render_world = real
    assert made == [1]
    assert [s.name for s in bpy.data.scenes] == [scene.name] and not any(o.name.startswith(".wenv") for o in
                                                                          bpy.data.objects)
    _, rgb = attribute(plane)
    # Cycles: the plane from straight above, its own sky (importance-sampled, its sun among it)
    cam = scene.camera
    cam.location, cam.rotation_euler = (0.0, 0.0, 3.0), (0.0, 0.0, 0.0)
    cam.data.type, cam.data.ortho_scale = "ORTHO", 1.0
    scene.render.engine = "CYCLES"
    scene.cycles.samples, scene.cycles.use_denoising, scene.cycles.device = 128, False, "CPU"
    scene.render.resolution_x = scene.render.resolution_y = 4
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format, scene.render.image_settings.color_depth = "OPEN_EXR", "32"
    import tempfile
    scene.render.filepath = os.path.join(tempfile.mkdtemp(prefix="wenv-sky-"), "plane.exr")
    bpy.ops.render.render(write_still=True)
    shot = bpy.data.images.load(scene.render.filepath)
    cycles = np.array(shot.pixels[:], np.float32).reshape(-1, 4)[:, :3].mean(axis=0)
    ours = rgb.mean(axis=0)
    assert cycles.min() > 1.0  # a sunlit plane
    np.testing.assert_allclose(ours, cycles, rtol=0.01)


@pytest.mark.parametrize("kind", ["flat", "split"])
def test_flat_and_split_normals_use_corners(scene, kind):
    env_world(scene, "courtyard")
    obj = add_monkey(smooth=(kind == "split"))
    if kind == "split":
        obj.data.set_sharp_from_angle(angle=math.radians(40))
    assert obj.data.normals_domain == ("FACE" if kind == "flat" else "CORNER")
    mat = set_material(obj)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    domain, rgb = attribute(obj)
    assert domain == "CORNER" and len(rgb) == len(obj.data.loops)
    p, n = world_arrays(obj, corner=True)
    want = core_shader(wenv.load_environment(hdri_path("courtyard")), wenv_material(mat)).shade_mesh(
        p, n, tuple(scene.camera.matrix_world.translation))
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)
    # Smoothing every edge later replaces the corner attribute with a point one.
    obj.data.shade_smooth()
    obj.data.set_sharp_from_angle(angle=math.pi)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert attribute(obj)[0] == "POINT"


def test_deform_modifier_uses_evaluated_mesh(scene):
    env_world(scene, "city")
    obj = add_monkey()
    mod = obj.modifiers.new("twist", "SIMPLE_DEFORM")
    mod.deform_method = "TWIST"
    mod.angle = 1.0
    mat = set_material(obj)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(obj)
    p, n = world_arrays(obj, corner=False)  # evaluated (twisted) mesh
    base = np.array([tuple(obj.matrix_world @ v.co) for v in obj.data.vertices], np.float32)
    assert np.abs(p - base).max() > 0.1  # the modifier does move the vertices
    want = core_shader(wenv.load_environment(hdri_path("city")), wenv_material(mat)).shade_mesh(
        p, n, tuple(scene.camera.matrix_world.translation))
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)


def test_topology_changing_modifier_shades_base_mesh(scene):
    obj = add_monkey()
    obj.modifiers.new("sub", "SUBSURF").levels = 1
    assert shade_op(view="CAMERA") == {"FINISHED"}
    domain, rgb = attribute(obj)
    assert domain == "POINT" and len(rgb) == len(obj.data.vertices)
    assert np.isfinite(rgb).all() and rgb.max() > 0
    assert "topology" in " ".join(meshes.read_mesh(obj, bpy.context.evaluated_depsgraph_get()).notes)


def test_vertices_at_no_finite_position_are_left_black(scene):
    """A vertex at NaN or infinity (a broken import) is lit from nowhere: it is black, the rest of
    the mesh is shaded as without it, and the pass says so."""
    env_world(scene, "sunset")
    obj = add_monkey()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    before = attribute(obj)[1]
    pos = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", pos)
    pos = pos.reshape(-1, 3)
    # the smooth normals of the faces around a moved vertex change, so the check is on the others
    bad = [3, 100]
    pos[3, 0], pos[100, 2] = np.nan, np.inf
    obj.data.vertices.foreach_set("co", pos.ravel())
    obj.data.update()
    touched = {v for f in obj.data.polygons for v in f.vertices if set(f.vertices) & set(bad)}
    data = meshes.read_mesh(obj, bpy.context.evaluated_depsgraph_get())
    assert data.unplaced.nonzero()[0].tolist() == bad
    assert any("2 vertices at no finite position" in n for n in data.notes)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    after = attribute(obj)[1]
    assert np.isfinite(after).all() and (after[bad] == 0).all()
    keep = np.array([i not in touched and i not in bad for i in range(len(pos))])
    np.testing.assert_allclose(after[keep], before[keep], rtol=1e-5, atol=1e-7)


def test_broken_geometry_with_shadows_is_shaded_and_named(scene):
    """With Shadows: Suzanne (open and in pieces: non-manifold) with a vertex at NaN and one moved
    onto its neighbour (faces of no area) is shaded: the NaN vertex black, every colour finite, and
    the report names both; the faces of no area cast no shadow."""
    env_world(scene, "sunset")
    obj = add_monkey()
    scene.wenv.shadows = True
    pos = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", pos)
    pos = pos.reshape(-1, 3)
    a, b = obj.data.edges[0].vertices
    pos[a] = pos[b]  # the faces about that edge collapse
    pos[40, 1] = np.nan
    obj.data.vertices.foreach_set("co", pos.ravel())
    obj.data.update()
    notes = plan_of(scene, obj).notes
    assert any("degenerate face(s) (no area) cast no shadow" in n for n in notes), notes
    assert any("1 vertices at no finite position" in n for n in notes), notes
    assert shade_op(view="CAMERA") == {"FINISHED"}
    rgb = attribute(obj)[1]
    assert np.isfinite(rgb).all() and (rgb[40] == 0).all() and (rgb.sum(axis=1) > 0).mean() > 0.5


@pytest.mark.parametrize("cull", [False, True])
def test_a_vertex_at_the_eye_is_black(scene, cull):
    """A vertex exactly at the eye has no view (the core refuses it): it is black, the rest shaded."""
    env_world(scene, "sunset")
    eye = tuple(scene.camera.matrix_world.translation)
    mesh = bpy.data.meshes.new("at eye")
    mesh.from_pydata([eye, (0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2), (1, 2, 3)])
    obj = bpy.data.objects.new("at eye", mesh)
    scene.collection.objects.link(obj)
    select_only(obj)
    view = views.camera_view(scene)
    if cull:  # as a viewport's view, which tells what is on screen
        view.view_projection = np.array(scene.camera.calc_matrix_camera(bpy.context.evaluated_depsgraph_get())) @ \
            np.array(scene.camera.matrix_world.inverted())
    data = meshes.read_mesh(obj, bpy.context.evaluated_depsgraph_get())
    shader = core_shader(world.environment(world.world_spec(scene.world), bpy.data.images), wenv.Lambert(0.8))
    rgb, seen = engine.shade_arrays(shader, data, view, cull=cull)
    assert np.isfinite(rgb).all() and (rgb[0] == 0).all() and (rgb[1:].max(axis=1) > 0).any()
    if cull:
        assert seen[0]
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert (attribute(obj)[1][0] == 0).all()


@pytest.mark.parametrize("setting,label", [("max_luminance", "Max Luminance"), ("target_error", "Target Error")])
def test_a_scene_setting_a_script_set_to_nan_is_reported(scene, setting, label):
    """Blender's limits on a float property let NaN through; the pass says which setting it is
    rather than writing NaN colours (Max Luminance's tone mapping) or failing in the core."""
    env_world(scene, "sunset")
    obj = add_monkey()
    scene.wenv.tone_mapping = "LOG"
    setattr(scene.wenv, setting, math.nan)
    with pytest.raises(RuntimeError, match=f"wenv {label} is nan"):
        shade_op(view="CAMERA")
    assert ATTR not in obj.data.color_attributes


@pytest.mark.parametrize("matrix", [np.zeros((4, 4)), np.full((4, 4), np.nan)])
def test_a_view_matrix_with_no_view_is_reported(scene, matrix):
    add_monkey()
    with pytest.raises(RuntimeError, match="view matrix (is singular|holds values that are not finite)"):
        shade_op(view="MATRIX", view_matrix=[tuple(r) for r in matrix.tolist()])


def test_non_mesh_and_empty_objects(scene):
    light = bpy.data.objects["Light"]
    cam = scene.camera
    select_only(light, cam)
    with pytest.raises(RuntimeError, match="No mesh objects"):
        shade_op(view="CAMERA")
    empty = bpy.data.objects.new("Empty mesh", bpy.data.meshes.new("empty"))
    scene.collection.objects.link(empty)
    cube = bpy.data.objects["Cube"]
    select_only(empty, light, cube)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert ATTR in cube.data.color_attributes
    assert ATTR not in empty.data.color_attributes


def test_several_materials_per_object(scene):
    env_world(scene, "studio")
    obj = add_monkey()
    glossy = set_material(obj, lobes=((0.05, 1.5, "GGX"),), name="glossy")
    # (Two Cook-Torrance materials: see README on the core's Lambert irradiance after a switch.)
    matte = set_material(obj, diffuse=(0.2, 0.6, 0.2), lobes=((0.5, 1.4, "BECKMANN"),), name="matte")
    idx = np.zeros(len(obj.data.polygons), np.int32)
    idx[::2] = 1
    obj.data.polygons.foreach_set("material_index", idx)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    domain, rgb = attribute(obj)
    assert domain == "CORNER"
    p, n = world_arrays(obj, corner=True)
    slot = np.repeat(idx, [poly.loop_total for poly in obj.data.polygons])
    env = wenv.load_environment(hdri_path("studio"))
    eye = tuple(scene.camera.matrix_world.translation)
    # The same calls the add-on makes, in its order: the core's diffuse term after set_material
    # depends on the material that was current when a normal sample's lighting was first needed.
    sh = core_shader(env, wenv_material(glossy))
    for s, mat in enumerate((glossy, matte)):
        sel = slot == s
        sh.set_material(wenv_material(mat))
        want = sh.shade_mesh(p[sel], n[sel], eye)
        np.testing.assert_allclose(rgb[sel], want, rtol=1e-4, atol=1e-5)


def test_logarithmic_tone_mapping(scene):
    env_world(scene, "sunset")
    obj = add_monkey()
    set_material(obj)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    linear = attribute(obj)[1]
    scene.wenv.tone_mapping = "LOG"
    scene.wenv.max_luminance = 5.0
    assert shade_op(view="CAMERA") == {"FINISHED"}
    mapped = attribute(obj)[1]
    lw = linear @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    ld = np.log10(1 + lw) / np.log10(1 + 5.0)
    want = np.clip(linear * np.where(lw > 0, ld / np.maximum(lw, 1e-12), 0)[:, None], 0, 1)
    np.testing.assert_allclose(mapped, want, rtol=1e-5, atol=1e-6)
    assert mapped.max() <= 1.0 and mapped.max() > 0.2


# ---------------------------------------------------------------------------------------------
# Materials and the glossmeter


def principled_material(name, base=(0.8, 0.2, 0.1), metallic=0.0, roughness=0.4, ior=1.45, coat=0.0):
    mat = node_material(bpy, name)
    node = mat.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (*base, 1.0)
    node.inputs["Metallic"].default_value = metallic
    node.inputs["Roughness"].default_value = roughness
    node.inputs["IOR"].default_value = ior
    node.inputs["Coat Weight"].default_value = coat
    return mat


def test_from_principled_dielectric_metal_and_coat(scene):
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    plastic = principled_material("plastic", roughness=0.4, ior=1.45)
    cube.active_material = plastic
    assert bpy.ops.wenv.from_principled() == {"FINISHED"}
    st = plastic.wenv
    assert st.model == "COOK_TORRANCE" and st.initialized
    assert tuple(round(c, 5) for c in st.diffuse) == (0.8, 0.2, 0.1)
    assert len(st.lobes) == 1
    lobe = st.lobes[0]
    assert lobe.alpha == pytest.approx(0.16) and lobe.ior == pytest.approx(1.45)
    assert lobe.distribution == "GGX" and tuple(lobe.specular) == pytest.approx((1, 1, 1))

    gold = principled_material("gold", base=(1.0, 0.78, 0.34), metallic=1.0, roughness=0.2)
    cube.active_material = gold
    bpy.ops.wenv.from_principled()
    st = gold.wenv
    assert tuple(st.diffuse) == pytest.approx((0, 0, 0))
    assert len(st.lobes) == 1
    m = wenv_material(gold)
    # Head-on, the metal lobe reflects its base colour: specular x Fresnel(ior, normal) = base.
    n = st.lobes[0].ior
    f0 = ((n - 1) / (n + 1)) ** 2
    assert np.array(st.lobes[0].specular) * f0 == pytest.approx((1.0, 0.78, 0.34), rel=1e-5)
    assert st.lobes[0].alpha == pytest.approx(0.04)
    assert isinstance(m, wenv.CookTorrance)

    coated = principled_material("coated", roughness=0.5, coat=1.0)
    coated.node_tree.nodes["Principled BSDF"].inputs["Coat Roughness"].default_value = 0.1
    cube.active_material = coated
    bpy.ops.wenv.from_principled()
    assert [round(l.alpha, 6) for l in coated.wenv.lobes] == [0.25, 0.01]


def test_from_principled_warns_about_links_and_missing_node(scene):
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    mat = principled_material("textured")
    tex = mat.node_tree.nodes.new("ShaderNodeTexSky")
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    cube.active_material = mat
    warnings = materials.fill_from_principled(mat)
    assert any("Base Color" in w for w in warnings)
    plain = node_material(bpy, "plain")
    plain.node_tree.nodes.clear()
    plain.diffuse_color = (0.1, 0.2, 0.3, 1)
    assert any("no Principled BSDF" in w for w in materials.fill_from_principled(plain))
    assert plain.wenv.model == "LAMBERT" and tuple(plain.wenv.diffuse) == pytest.approx((0.1, 0.2, 0.3))


def test_from_principled_clamps_as_cycles_and_refuses_nan(scene):
    """Sockets a script set past their range are read as Cycles clamps them; NaN is reported."""
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    mat = principled_material("odd", roughness=0.0)
    cube.active_material = mat
    node = mat.node_tree.nodes["Principled BSDF"]
    node.inputs["Roughness"].default_value = -1.0
    assert bpy.ops.wenv.from_principled() == {"FINISHED"}
    floor = mat.wenv.lobes[0].alpha
    node.inputs["Roughness"].default_value = 0.0
    assert bpy.ops.wenv.from_principled() == {"FINISHED"} and mat.wenv.lobes[0].alpha == floor
    node.inputs["Roughness"].default_value = math.nan
    with pytest.raises(RuntimeError, match="Roughness is not finite"):
        bpy.ops.wenv.from_principled()


def test_a_principled_value_the_core_refuses_is_a_note_and_an_error(scene):
    """A socket a script set past what the core shades (3.4e38, the most a socket holds): the
    panel's notes say so (they never fail), and shading reports it naming the material."""
    obj = add_monkey()
    mat = principled_material("huge")
    obj.data.materials.append(mat)
    mat.node_tree.nodes["Principled BSDF"].inputs["Sheen Weight"].default_value = 3.4e38
    assert any(n.startswith("cannot be shaded: sheen_weight must be at most") for n in
               materials.principled_notes(mat))
    with pytest.raises(RuntimeError, match="'huge'.*sheen_weight must be at most 1e\\+06"):
        shade_op(view="CAMERA")


def test_principled_node_is_the_source_of_truth(scene):
    """A material's Principled BSDF is shaded as it is at every pass, as wenv.Principled of its inputs
    (the default model): changing Roughness re-shades with the new value, with no stale copy."""
    env_world(scene, "sunset")
    obj = add_monkey()
    mat = principled_material("fresh", roughness=0.3)
    obj.data.materials.append(mat)
    assert mat.wenv.model == "PRINCIPLED" and not mat.wenv.initialized
    p, n = world_arrays(obj, corner=False)
    env = wenv.load_environment(hdri_path("sunset"))
    eye = tuple(scene.camera.matrix_world.translation)
    node = mat.node_tree.nodes["Principled BSDF"]
    for roughness in (0.3, 0.6):
        node.inputs["Roughness"].default_value = roughness
        assert shade_op(view="CAMERA") == {"FINISHED"}
        # the node's values as Blender stores them (float32)
        want = core_shader(env, wenv.Principled(base_color=tuple(node.inputs["Base Color"].default_value),
                                                roughness=node.inputs["Roughness"].default_value,
                                                ior=node.inputs["IOR"].default_value))
        np.testing.assert_allclose(attribute(obj)[1], want.shade_mesh(p, n, eye), rtol=1e-4, atol=1e-5)
    assert len(mat.wenv.lobes) == 0  # nothing was copied into the add-on's settings
    # live mode watches the node: a new Roughness re-shades
    session = live.LiveSession([obj.name])
    scene.wenv.view_source = "CAMERA"
    for value in (0.6, 0.2):
        node.inputs["Roughness"].default_value = value
        assert session.tick(bpy.context) is False and session.wait(60)
        assert session.tick(bpy.context) is True
    assert session.shades == 2
    # the glossmeter reads the node, and fitting sets the node's Roughness (Blender's)
    select_only(obj)
    obj.active_material = mat
    assert mat.wenv.gloss_60 == pytest.approx(wenv.gloss(engine.principled(
        materials.principled_inputs(node)[0]), 60), abs=1e-3)
    assert bpy.ops.wenv.fit_roughness(target=30.0, geometry="60") == {"FINISHED"}
    assert 0.0 < node.inputs["Roughness"].default_value < 1.0 and mat.wenv.gloss_60 == pytest.approx(30.0, abs=0.05)


def textured_plane(image, interpolation="Linear", cuts=8):
    """A smooth grid of (cuts + 2)^2 vertices, UVs over [0, 1]^2, with a Principled paint whose Base
    Color is `image` through an Image Texture node; selected alone."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts + 1, y_subdivisions=cuts + 1, size=4.0)
    plane = bpy.context.object
    plane.data.shade_smooth()
    mat = principled_material("textured paint", roughness=0.4)
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = interpolation
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    plane.data.materials.append(mat)
    select_only(plane)
    return plane, mat


def plan_of(scene, obj):
    from addon import shading, views
    return shading.plan_shading(scene, bpy.context.evaluated_depsgraph_get(), [obj], views.camera_view(scene),
                                bpy.data.images)


def test_a_textured_base_color_is_read_at_each_vertex(scene):
    """An image of one colour reads as a material of that colour; an image of two halves (Closest)
    gives each vertex its half's colour, and the add-on's colours are the core's shading with them."""
    env_world(scene, "sunset")
    flat = bpy.data.images.new("flat", 8, 8, float_buffer=True)
    flat.pixels.foreach_set(np.tile(np.float32([0.2, 0.5, 0.7, 1.0]), 64))  # linear, as a float image holds them
    plane, _ = textured_plane(flat)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    p, n = world_arrays(plane, corner=False)
    eye = tuple(scene.camera.matrix_world.translation)
    env = wenv.load_environment(hdri_path("sunset"))
    ior = plane.active_material.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value
    want = core_shader(env, wenv.Principled(base_color=(0.2, 0.5, 0.7), roughness=0.4, ior=ior)).shade_mesh(p, n, eye)
    np.testing.assert_allclose(attribute(plane)[1], want, rtol=1e-4, atol=1e-5)
    assert not any("Base Color" in note for note in materials.principled_notes(plane.active_material))

    halves = bpy.data.images.new("halves", 64, 64, float_buffer=True)
    px = np.zeros((64, 64, 4), np.float32)
    px[:, :32] = (0.9, 0.1, 0.1, 1.0)
    px[:, 32:] = (0.1, 0.7, 0.2, 1.0)
    halves.pixels.foreach_set(px.ravel())
    plane.active_material.node_tree.nodes["Image Texture"].image = halves
    plane.active_material.node_tree.nodes["Image Texture"].interpolation = "Closest"
    assert shade_op(view="CAMERA") == {"FINISHED"}
    uv = np.empty(len(plane.data.loops) * 2, np.float32)
    plane.data.uv_layers.active.uv.foreach_get("vector", uv)
    u = np.zeros(len(plane.data.vertices), np.float32)
    u[[l.vertex_index for l in plane.data.loops]] = uv[0::2]
    left = np.floor(u * 64).astype(int) % 64 < 32  # u = 1 repeats to the first texel, as in Cycles
    colours = np.where(left[:, None], np.float32([0.9, 0.1, 0.1]), np.float32([0.1, 0.7, 0.2]))
    want = core_shader(env, wenv.Principled(base_color=(0.8, 0.2, 0.1), roughness=0.4, ior=ior)).shade_mesh(
        p, n, eye, base_color=colours.astype(np.float32))
    np.testing.assert_allclose(attribute(plane)[1], want, rtol=1e-4, atol=1e-5)


def flat_pngs(paths_colours, size=4):
    """Writes a flat size x size PNG of each RGB at its path, {path: RGB}."""
    for path, rgb in paths_colours.items():
        flat = bpy.data.images.new("flat png", size, size)
        flat.pixels.foreach_set(np.tile(np.append(np.float32(rgb), np.float32(1.0)), size * size))
        flat.filepath_raw = str(path)
        flat.file_format = "PNG"
        flat.save()
        bpy.data.images.remove(flat)


def udim_image(folder, colours):
    """A UDIM image of flat 4 x 4 PNG tiles, {tile number: RGB}, in `folder`, Non-Color."""
    flat_pngs({folder / f"paint.{number}.png": rgb for number, rgb in colours.items()})
    image = bpy.data.images.load(str(folder / f"paint.{min(colours)}.png"))
    image.source = "TILED"
    image.filepath = str(folder / "paint.<UDIM>.png")
    image.colorspace_settings.name = "Non-Color"
    image.reload()
    return image


def test_udim_tiles_are_read_as_cycles_reads_them(scene, tmp_path):
    """A Base Color from a UDIM image of two tiles, on a grid whose UVs run over three tiles (u from 0
    to 3): each vertex reads the tile under it at its offset into it, as Cycles does; the third tile,
    which the image lacks, reads Cycles' missing-image magenta.  Packed, the tiles read the same."""
    env_world(scene, "sunset")
    image = udim_image(tmp_path, {1001: (0.8, 0.2, 0.2), 1002: (0.2, 0.2, 0.8)})
    plane, mat = textured_plane(image)
    mat.node_tree.nodes["Image Texture"].interpolation = "Closest"
    uv = np.empty(len(plane.data.loops) * 2, np.float32)
    plane.data.uv_layers.active.uv.foreach_get("vector", uv)
    uv[0::2] = uv[0::2] * 2.999
    uv[1::2] = uv[1::2] * 0.999  # v = 1 exactly is tile 1011's edge, as in Cycles
    plane.data.uv_layers.active.uv.foreach_set("vector", uv)
    u = np.zeros(len(plane.data.vertices), np.float32)
    u[[l.vertex_index for l in plane.data.loops]] = uv[0::2]
    want = np.where((u < 1.0)[:, None], np.float32([0.8, 0.2, 0.2]),
                    np.where((u < 2.0)[:, None], np.float32([0.2, 0.2, 0.8]), np.float32([1.0, 0.0, 1.0])))
    got = plan_of(scene, plane).items[0][1].inputs["base_color"]
    np.testing.assert_allclose(got, want, atol=2 / 255)
    assert not any("Base Color" in n for n in materials.principled_notes(mat))
    image.pack()
    for f in tmp_path.iterdir():
        f.unlink()
    from addon import textures
    textures.images.clear()
    np.testing.assert_allclose(plan_of(scene, plane).items[0][1].inputs["base_color"], want, atol=2 / 255)
    assert shade_op(view="CAMERA") == {"FINISHED"}


def test_a_missing_udim_tile_file_is_named(scene, tmp_path):
    image = udim_image(tmp_path, {1001: (0.8, 0.2, 0.2), 1002: (0.2, 0.2, 0.8)})
    plane, mat = textured_plane(image)
    (tmp_path / "paint.1002.png").unlink()
    from addon import textures
    textures.images.clear()
    before = attribute(plane)[1] if plane.data.color_attributes else None
    with pytest.raises(RuntimeError, match="tile 1002 could not be loaded"):
        shade_op(view="CAMERA")
    if before is not None:
        np.testing.assert_array_equal(attribute(plane)[1], before)


def image_sequence(folder, colours):
    """An image sequence of flat 4 x 4 PNG frames, {frame number: RGB}, in `folder`, Non-Color."""
    flat_pngs({folder / f"wood_{number:03d}.png": rgb for number, rgb in colours.items()})
    image = bpy.data.images.load(str(folder / f"wood_{min(colours):03d}.png"))
    image.source = "SEQUENCE"
    image.colorspace_settings.name = "Non-Color"
    return image


def test_an_image_sequence_shows_the_frame_blender_gives(scene, tmp_path):
    """A Base Color from an image sequence of six flat frames (Frames 4, Start Frame 3, Offset 1),
    cyclic and not, over scene frames before, in and past its range: every vertex reads the frame
    Blender's own image user shows -- its evaluated copy's, with Auto Refresh on -- from the file
    Image.filepath_from_user names; a frame whose file is missing is an error naming it."""
    from addon import textures
    env_world(scene, "sunset")
    colours = {k: (0.1 * k, 0.5, 1.0 - 0.1 * k) for k in range(1, 7)}
    image = image_sequence(tmp_path, colours)
    plane, mat = textured_plane(image)
    tex = mat.node_tree.nodes["Image Texture"]
    user = tex.image_user
    user.frame_duration, user.frame_start, user.frame_offset, user.use_auto_refresh = 4, 3, 1, True
    seen = set()
    for cyclic in (False, True):
        user.use_cyclic = cyclic
        for frame in range(-2, 11):
            scene.frame_set(frame)
            evaluated = mat.evaluated_get(bpy.context.evaluated_depsgraph_get()).node_tree.nodes["Image Texture"]
            shown = evaluated.image_user.frame_current
            assert textures.user_frame(user, frame) == shown, (cyclic, frame)
            path = image.filepath_from_user(image_user=evaluated.image_user)
            assert textures.frame_shown(tex) == (bpy.path.abspath(path), shown)
            got = plan_of(scene, plane).items[0][1].inputs["base_color"]
            np.testing.assert_allclose(got, np.tile(np.float32(colours[shown]), (len(got), 1)), atol=1 / 255)
            seen.add(shown)
    assert seen == {1, 2, 3, 4, 5}  # held at 1 and 5 without Cyclic (Offset 1); 2-5 cycled with it
    assert not any("Base Color" in n for n in materials.principled_notes(mat))
    assert textures.sequence_path("/a/b.7/tex5.png", 12) == "/a/b.7/tex12.png"
    assert textures.sequence_path("/a/scan_0042_v2.exr", -3) == "/a/scan_0042_v-3.exr"
    assert textures.sequence_path("/a/plain.png", 0) == "/a/plain.png"
    scene.frame_set(4)  # the second frame of the range: file 3 with the offset
    (tmp_path / "wood_003.png").unlink()
    textures.images.clear()
    with pytest.raises(RuntimeError, match="frame could not be loaded: .*wood_003.png"):
        shade_op(view="CAMERA")


def flat_movie(folder, colours):
    """A QuickTime movie (PNG frames, lossless) of flat 16 x 16 frames, {frame number 1..n: RGB},
    rendered by Blender's sequencer in a scene of its own, loaded as a Non-Color image."""
    flat_pngs({folder / f"still_{number:03d}.png": rgb for number, rgb in colours.items()}, size=16)
    maker = bpy.data.scenes.new("movie maker")
    try:
        maker.render.resolution_x = maker.render.resolution_y = 16
        maker.render.resolution_percentage = 100
        maker.frame_start, maker.frame_end = 1, len(colours)
        maker.view_settings.view_transform = "Standard"
        editor = maker.sequence_editor_create()
        strips = editor.strips if hasattr(editor, "strips") else editor.sequences  # renamed in Blender 5.0
        strip = strips.new_image("stills", str(folder / "still_001.png"), 1, 1)
        for number in sorted(colours)[1:]:
            strip.elements.append(f"still_{number:03d}.png")
        strip.frame_final_duration = len(colours)
        settings = maker.render.image_settings
        if hasattr(settings, "media_type"):  # Blender 5.0 chooses video before the format
            settings.media_type = "VIDEO"
        settings.file_format = "FFMPEG"
        maker.render.ffmpeg.format, maker.render.ffmpeg.codec = "QUICKTIME", "PNG"
        maker.render.filepath = str(folder / "flat.mov")
        bpy.ops.render.render(animation=True, scene=maker.name)
    finally:
        bpy.data.scenes.remove(maker)
    image = bpy.data.images.load(str(folder / "flat.mov"))
    image.colorspace_settings.name = "Non-Color"
    return image


def test_a_movie_shows_the_frame_blender_gives(scene, tmp_path):
    """A Base Color from a movie of five flat frames (Frames 5, Start Frame 3), cyclic and held with
    Offset 1, over scene frames before, in and past its range: every vertex reads the frame Blender's
    own image user shows (its evaluated copy's, with Auto Refresh on), the first or last one where
    that frame lies past the movie's ends, as Blender decodes it; the material has no note.  A movie
    whose file is gone is an error naming it."""
    from addon import textures
    env_world(scene, "sunset")
    colours = {k: (0.15 * k, 0.5, 1.0 - 0.15 * k) for k in range(1, 6)}
    image = flat_movie(tmp_path, colours)
    assert image.source == "MOVIE" and image.frame_duration == 5
    plane, mat = textured_plane(image)
    tex = mat.node_tree.nodes["Image Texture"]
    user = tex.image_user
    user.frame_duration, user.frame_start, user.use_auto_refresh = 5, 3, True
    seen, shown_frames = set(), set()
    for cyclic, offset in ((True, 0), (False, 1)):
        user.use_cyclic, user.frame_offset = cyclic, offset
        for frame in range(-1, 12):
            scene.frame_set(frame)
            evaluated = mat.evaluated_get(bpy.context.evaluated_depsgraph_get()).node_tree.nodes["Image Texture"]
            shown = evaluated.image_user.frame_current
            assert textures.user_frame(user, frame) == shown, (cyclic, frame)
            assert textures.frame_shown(tex) == (bpy.path.abspath(image.filepath_raw), shown)
            shown_frames.add(textures.frames_shown(plane)[0][2])
            got = plan_of(scene, plane).items[0][1].inputs["base_color"]
            decoded = colours[min(max(shown, 1), 5)]
            np.testing.assert_allclose(got, np.tile(np.float32(decoded), (len(got), 1)), atol=1.5 / 255,
                                       err_msg=f"cyclic {cyclic}, scene frame {frame}, movie frame {shown}")
            seen.add(shown)
    assert seen == {1, 2, 3, 4, 5, 6}  # cycled over 1-5; held at 1 and 5, then moved by the offset
    assert len(shown_frames) == 6
    assert not any("Base Color" in n for n in materials.principled_notes(mat))
    image.filepath = str(tmp_path / "gone.mov")
    textures.images.clear()
    with pytest.raises(RuntimeError, match="Texture movie 'flat.mov' could not be loaded: .*gone.mov"):
        shade_op(view="CAMERA")


def test_a_texture_finer_than_the_mesh_averages(scene):
    """A checker of single texels (256 x 256) on a grid of 10 x 10 vertices: each vertex reads the
    mip level of its share of the image, grey, where a point sample would read black or white."""
    env_world(scene, "sunset")
    checker = bpy.data.images.new("checker", 256, 256, float_buffer=True)
    ii, jj = np.meshgrid(np.arange(256), np.arange(256))
    px = np.ones((256, 256, 4), np.float32)
    px[..., :3] = ((ii + jj) % 2)[..., None]
    checker.pixels.foreach_set(px.ravel())
    plane, _ = textured_plane(checker)
    plan = plan_of(scene, plane)
    colours = plan.items[0][1].inputs["base_color"]
    assert np.all(np.abs(colours - 0.5) < 0.1), colours.min()
    plane.active_material.node_tree.nodes["Image Texture"].interpolation = "Closest"
    colours = plan_of(scene, plane).items[0][1].inputs["base_color"]
    assert set(np.unique(colours)) <= {0.0, 1.0}  # the texel under each vertex, as Cycles' Closest


def test_a_noise_texture_is_read_at_each_vertex(scene):
    """A Principled Base Color from a Noise Texture (its unlinked Vector: Generated coordinates) and a
    Roughness from another's Fac through a Texture Coordinate's Object and a Mapping node, on a moved,
    turned and stretched Suzanne: each vertex reads wenv.noise_texture at its own coordinates (as
    tests/test_procedural_textures.py holds it to Cycles); a Bump node of the noise tilts the normals; a
    Scale from a Value node is read, one that varies from point to point named and the socket's
    unlinked value used."""
    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    obj.location, obj.rotation_euler, obj.scale = (0.3, -0.2, 0.5), (0.2, 0.1, 0.4), (1.2, 0.8, 1.0)
    mat = principled_material("noisy")
    obj.data.materials.append(mat)
    select_only(obj)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    colour_noise, rough_noise = tree.nodes.new("ShaderNodeTexNoise"), tree.nodes.new("ShaderNodeTexNoise")
    rough_noise.noise_type, rough_noise.inputs["Detail"].default_value = "RIDGED_MULTIFRACTAL", 3.0
    coords, mapping = tree.nodes.new("ShaderNodeTexCoord"), tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Location"].default_value = (0.1, 0.2, 0.3)
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, 0.5)
    tree.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], rough_noise.inputs["Vector"])
    tree.links.new(colour_noise.outputs["Color"], bsdf.inputs["Base Color"])
    tree.links.new(rough_noise.outputs[0], bsdf.inputs["Roughness"])
    bpy.context.view_layer.update()
    data = plan_of(scene, obj).items[0][1]
    inverse = np.array(obj.matrix_world.inverted(), np.float64)
    local = data.positions.astype(np.float64) @ inverse[:3, :3].T + inverse[:3, 3]
    loc, size = np.array(obj.data.texspace_location), np.array(obj.data.texspace_size)
    want_colour = wenv.noise_texture(((local - loc) / (2.0 * size) + 0.5).astype(np.float32))[1]
    c, s_ = np.cos(0.5), np.sin(0.5)
    mapped = local @ np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]]).T + (0.1, 0.2, 0.3)
    want_rough = wenv.noise_texture(mapped.astype(np.float32), type="RIDGED_MULTIFRACTAL", detail=3.0)[0]
    np.testing.assert_allclose(data.inputs["base_color"], want_colour, atol=1e-4)
    assert np.ptp(data.inputs["base_color"][:, 0]) > 0.2  # it varies over the mesh
    np.testing.assert_allclose(data.inputs["roughness"], np.clip(want_rough, 0.0, 1.0), atol=1e-4)
    assert not any("Noise" in n for n in materials.principled_notes(mat))
    from addon import textures
    mean, images = textures.socket_at_means(bsdf, "Base Color")  # the glossmeter's: over the unit cube
    assert images == [] and np.all(np.abs(np.asarray(mean) - 0.5) < 0.05), mean

    bump = tree.nodes.new("ShaderNodeBump")
    bump.inputs["Distance"].default_value = 0.3
    tree.links.new(colour_noise.outputs[0], bump.inputs["Height"])
    tree.links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])
    data = plan_of(scene, obj).items[0][1]
    unit = [n / np.linalg.norm(n, axis=1, keepdims=True) for n in (data.shading_normals, data.normals)]
    tilt = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", *unit), -1.0, 1.0)))
    assert np.median(tilt) > 1.0, np.median(tilt)

    obj.modifiers.new("bend", "SIMPLE_DEFORM")  # moves the vertices, not their Generated coordinates
    plan = plan_of(scene, obj)
    assert any("reads Generated coordinates on the deformed mesh" in n for n in plan.notes), plan.notes
    obj.modifiers.clear()
    # a Scale from a Value node (the same at every point) is read; one that varies is named
    value = tree.nodes.new("ShaderNodeValue")
    value.outputs[0].default_value = 2.5
    tree.links.new(value.outputs[0], colour_noise.inputs["Scale"])
    data = plan_of(scene, obj).items[0][1]
    generated = ((local - loc) / (2.0 * size) + 0.5).astype(np.float32)
    np.testing.assert_allclose(data.inputs["base_color"], wenv.noise_texture(generated, scale=2.5)[1], atol=1e-4)
    assert not any("Scale" in n for n in materials.principled_notes(mat))
    split = tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(coords.outputs["Object"], split.inputs[0])
    tree.links.new(split.outputs["X"], colour_noise.inputs["Scale"])
    plan = plan_of(scene, obj)
    assert any("Base Color' ('noisy') reads 'Noise Texture''s Scale, linked to values that vary" in n
               for n in plan.notes), plan.notes
    assert "base_color" not in plan.items[0][1].inputs


def test_mesh_attributes_are_read_at_each_vertex(scene):
    """A Principled Base Color from a Color Attribute node (unnamed: the mesh's default colour, bytes
    per face corner) and a Roughness from an Attribute node's Fac (a float per vertex) on Suzanne:
    each vertex reads its corners' mean colour, decoded from sRGB, and its own value (as
    tests/test_attributes.py holds the reading to Cycles), and the add-on's colours are the core's
    shading with them.  An attribute the mesh lacks reads black, as in Cycles; the glossmeter, which
    has no mesh to average over, says so."""
    from addon import gloss
    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    mesh = obj.data
    rng = np.random.default_rng(3)
    codes = rng.integers(0, 256, (len(mesh.loops), 4))
    mesh.color_attributes.new("paint", "BYTE_COLOR", "CORNER").data.foreach_set(
        "color_srgb", (codes / 255.0).astype(np.float32).ravel())
    rough = np.where(rng.random(len(mesh.vertices)) < 0.5, 0.25, 0.6).astype(np.float32)
    mesh.attributes.new("rough", "FLOAT", "POINT").data.foreach_set("value", rough)
    mat = principled_material("painted", roughness=0.4)
    obj.data.materials.append(mat)
    select_only(obj)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    paint, reading = tree.nodes.new("ShaderNodeVertexColor"), tree.nodes.new("ShaderNodeAttribute")
    reading.attribute_name = "rough"
    tree.links.new(paint.outputs["Color"], bsdf.inputs["Base Color"])
    tree.links.new(reading.outputs["Fac"], bsdf.inputs["Roughness"])
    assert shade_op(view="CAMERA") == {"FINISHED"}
    c = codes[:, :3] / 255.0  # sRGB's decoding, written out
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    corner_vert = np.array([loop.vertex_index for loop in mesh.loops])
    count = np.bincount(corner_vert, minlength=len(mesh.vertices))
    colours = np.stack([np.bincount(corner_vert, linear[:, k], len(mesh.vertices)) for k in range(3)], 1)
    colours = (colours / count[:, None]).astype(np.float32)
    data = plan_of(scene, obj).items[0][1]
    np.testing.assert_allclose(data.inputs["base_color"], colours, atol=2e-6)
    np.testing.assert_array_equal(data.inputs["roughness"], rough)
    assert not any("Color Attribute" in n or "Attribute" in n for n in materials.principled_notes(mat))
    p, n = world_arrays(obj, corner=False)
    eye = tuple(scene.camera.matrix_world.translation)
    want = core_shader(wenv.load_environment(hdri_path("sunset")),
                       wenv.Principled(base_color=(0.8, 0.2, 0.1), roughness=0.4, ior=bsdf.inputs["IOR"].default_value)
                       ).shade_mesh(p, n, eye, base_color=colours, roughness=rough)
    np.testing.assert_allclose(attribute(obj)[1], want, rtol=1e-4, atol=1e-5)
    obj.active_material = mat
    _key, note = gloss.reading_key(mat)
    assert "Base Color's texture cannot be read" in note and "a mesh attribute" in note, note

    paint.layer_name = "not there"
    np.testing.assert_array_equal(plan_of(scene, obj).items[0][1].inputs["base_color"], 0.0)


def test_object_info_and_geometry_are_read_at_each_vertex(scene):
    """Roughness from Object Info's Random and Base Color from the Geometry node's Normal, on a
    turned Suzanne: every vertex reads the object's Random (hashed from its name as Cycles hashes it:
    tests/test_attributes.py) and its own unit world normal, below 0 read as 0 as Cycles' Principled
    BSDF clamps it (and she shades); a second object reads its own Random."""
    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    obj.rotation_euler = (0.3, 0.0, 0.7)
    mat = principled_material("per object")
    obj.data.materials.append(mat)
    select_only(obj)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    info, geometry = tree.nodes.new("ShaderNodeObjectInfo"), tree.nodes.new("ShaderNodeNewGeometry")
    tree.links.new(info.outputs["Random"], bsdf.inputs["Roughness"])
    tree.links.new(geometry.outputs["Normal"], bsdf.inputs["Base Color"])
    bpy.context.view_layer.update()
    data = plan_of(scene, obj).items[0][1]
    np.testing.assert_array_equal(data.inputs["roughness"], np.float32(nodes.object_random(obj.name)))
    unit = data.normals / np.linalg.norm(data.normals, axis=1, keepdims=True)
    assert (unit < -0.5).any()
    np.testing.assert_allclose(data.inputs["base_color"], np.maximum(unit, 0.0), atol=1e-6)
    assert not any("below 0" in n for n in plan_of(scene, obj).notes)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    other = obj.copy()
    other.name = "Another monkey"
    scene.collection.objects.link(other)
    bpy.context.view_layer.update()
    assert nodes.object_random(other.name) != nodes.object_random(obj.name)
    np.testing.assert_array_equal(plan_of(scene, other).items[0][1].inputs["roughness"],
                                  np.float32(nodes.object_random(other.name)))
    assert not any("Object Info" in n or "Geometry" in n for n in materials.principled_notes(mat))


@pytest.mark.parametrize("kind", ["ShaderNodeBsdfDiffuse", "ShaderNodeEmission"])
def test_a_colour_below_zero_in_a_mix_is_named_and_read_as_zero(scene, kind):
    """A Diffuse BSDF's or an Emission's Color from the Geometry's Normal, in a Mix Shader: where it
    is below 0 Cycles takes light away, which wenv does not shade.  It is read as 0, and named."""
    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    mat = node_material(bpy, "below zero")
    tree = mat.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    node, other, mix = tree.nodes.new(kind), tree.nodes.new("ShaderNodeBsdfDiffuse"), tree.nodes.new("ShaderNodeMixShader")
    tree.links.new(tree.nodes.new("ShaderNodeNewGeometry").outputs["Normal"], node.inputs["Color"])
    tree.links.new(node.outputs[0], mix.inputs[1])
    tree.links.new(other.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    obj.data.materials.append(mat)
    select_only(obj)
    bpy.context.view_layer.update()
    plan = plan_of(scene, obj)
    read = plan.items[0][1].term_inputs[0][0]["base_color" if kind.endswith("Diffuse") else "emission_color"]
    assert read.min() == 0.0 and read.max() > 0.5
    assert any(f"'Color' of '{node.name}' is below 0 in places" in n for n in plan.notes)
    assert shade_op(view="CAMERA") == {"FINISHED"}


def test_the_parametric_output_reads_zero_at_the_vertices_and_says_so(scene):
    """The Geometry's Parametric is where a point lies in its triangle: a vertex lies in several, so
    it reads 0 there (a bake reads it at each texel: tests/test_attributes.py), and the panel says so."""
    env_world(scene, "sunset")
    obj = add_monkey()
    mat = principled_material("parametric")
    obj.data.materials.append(mat)
    tree = mat.node_tree
    tree.links.new(tree.nodes.new("ShaderNodeNewGeometry").outputs["Parametric"],
                   tree.nodes["Principled BSDF"].inputs["Base Color"])
    bpy.context.view_layer.update()
    data = plan_of(scene, obj).items[0][1]
    np.testing.assert_array_equal(data.inputs["base_color"], 0.0)
    assert any("Parametric is read at a bake's texels; at a vertex" in n for n in materials.principled_notes(mat))


def test_what_only_the_rows_show_in_a_mix_factor_is_named(scene):
    """A Mix Shader's Fac from a Noise Texture whose Scale varies from point to point, or from an
    image through a UV map the mesh lacks: a check of the material cannot tell, so reading the rows
    names it (once), the factor's unlinked value used, and the operator finishes."""
    env_world(scene, "sunset")
    obj = add_monkey()
    mat = node_material(bpy, "mixed")
    tree = mat.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.25
    tree.links.new(tree.nodes.new("ShaderNodeBsdfDiffuse").outputs[0], mix.inputs[1])
    tree.links.new(tree.nodes.new("ShaderNodeBsdfGlossy").outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    noise, split = tree.nodes.new("ShaderNodeTexNoise"), tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(tree.nodes.new("ShaderNodeNewGeometry").outputs["Position"], split.inputs[0])
    tree.links.new(split.outputs["X"], noise.inputs["Scale"])
    tree.links.new(noise.outputs[0], mix.inputs[0])
    obj.data.materials.append(mat)
    select_only(obj)
    bpy.context.view_layer.update()
    plan = plan_of(scene, obj)
    said = [n for n in plan.notes if "a Mix Shader's Fac ('mixed') reads 'Noise Texture''s Scale, linked to values "
            "that vary" in n]
    assert len(said) == 1, plan.notes
    weights = plan.items[0][1].term_weights[0]
    np.testing.assert_allclose(weights[0], 0.75, rtol=1e-6)  # (the Diffuse's share at the unlinked 0.25)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    image = tree.nodes.new("ShaderNodeTexImage")
    image.image = bpy.data.images.new("stripes", 4, 4)
    uv = tree.nodes.new("ShaderNodeUVMap")
    uv.uv_map = "no such map"
    tree.links.new(uv.outputs[0], image.inputs["Vector"])
    tree.links.new(image.outputs["Color"], mix.inputs[0])
    plan = plan_of(scene, obj)
    assert any("no UV map 'no such map' for a Mix Shader's Fac ('mixed')" in n for n in plan.notes), plan.notes


def test_a_procedural_texture_through_the_uv_map_averages_a_seams_corners(scene):
    """A Noise Texture read through the UV map (Texture Coordinate's UV, as (u, v, 0)) on Suzanne,
    whose UV map has seams: each vertex reads the noise at each of its corners' UVs and takes their
    mean, as it does an image's samples, rather than the noise at a mean UV between two islands."""
    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    mat = principled_material("uv noise")
    obj.data.materials.append(mat)
    select_only(obj)
    tree = mat.node_tree
    noise, coords = tree.nodes.new("ShaderNodeTexNoise"), tree.nodes.new("ShaderNodeTexCoord")
    noise.inputs["Scale"].default_value = 9.0
    tree.links.new(coords.outputs["UV"], noise.inputs["Vector"])
    tree.links.new(noise.outputs[0], tree.nodes["Principled BSDF"].inputs["Roughness"])
    mesh = obj.data
    uv = np.empty(len(mesh.loops) * 2, np.float32)
    mesh.uv_layers.active.uv.foreach_get("vector", uv)
    uv = uv.reshape(-1, 2)
    corner_vert = np.array([loop.vertex_index for loop in mesh.loops])
    at_corners = wenv.noise_texture(np.column_stack([uv, np.zeros(len(uv), np.float32)]), scale=9.0)[0]
    want = np.bincount(corner_vert, at_corners, len(mesh.vertices)) / np.bincount(corner_vert)
    data = plan_of(scene, obj).items[0][1]
    np.testing.assert_allclose(data.inputs["roughness"], np.clip(want, 0.0, 1.0), atol=2e-6)
    high, low = np.zeros(len(mesh.vertices)), np.full(len(mesh.vertices), np.inf)
    np.maximum.at(high, corner_vert, uv[:, 0])
    np.minimum.at(low, corner_vert, uv[:, 0])
    assert ((high - low) > 0.05).sum() > 20  # seams: vertices whose corners lie far apart in UV
    assert not any("Noise" in n for n in materials.principled_notes(mat))


def test_an_ambient_occlusion_node_is_read_at_each_vertex(scene):
    """A Principled Base Color from an Ambient Occlusion node's Color on Suzanne, the start-up cube
    beside her: each vertex reads the share of its cosine-weighted hemisphere within the node's
    Distance that no mesh blocks (ambient.py's 64 stratified rays at least), within 0.06 of 4096 random rays
    cast here, the cube's shadow included; the shares are kept, so a new view casts nothing; with
    Only Local the cube blocks nothing."""
    from addon import ambient
    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    obj.location = (0.0, -1.6, 0.0)  # (the cube's face 0.6 from her ear)
    mat = principled_material("dirt")
    obj.data.materials.append(mat)
    tree = mat.node_tree
    ao = tree.nodes.new("ShaderNodeAmbientOcclusion")
    ao.inputs["Color"].default_value = (0.8, 0.4, 0.2, 1.0)
    ao.inputs["Distance"].default_value = 1.5
    tree.links.new(ao.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    select_only(obj)
    bpy.context.view_layer.update()
    plan = plan_of(scene, obj)
    assert not any("Ambient Occlusion" in n for n in plan.notes), plan.notes
    data = plan.items[0][1]
    share = data.inputs["base_color"][:, 0] / 0.8
    assert share.min() < 0.5 and share.max() > 0.95  # her eyes and the top of her head
    # brute force at 40 vertices: 4096 random cosine-weighted rays each, against her and the cube
    cube = bpy.data.objects["Cube"]
    meshes_in = [(o.positions, engine.shadow_triangles(o.positions, o.triangles)[0])
                 for o in (meshes.read_mesh(x, bpy.context.evaluated_depsgraph_get()) for x in (obj, cube))]
    occ = engine.merged_occluders(meshes_in)[0]
    rng = np.random.default_rng(3)
    picked = rng.choice(data.count, 40, replace=False)
    for i in picked:
        n = data.normals[i] / np.linalg.norm(data.normals[i])
        u1, u2 = rng.random(4096), rng.random(4096)
        r, phi = np.sqrt(u1), 2.0 * np.pi * u2
        t = np.cross(n, (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 1.0, 0.0))
        t /= np.linalg.norm(t)
        b = np.cross(n, t)
        d = (r * np.cos(phi))[:, None] * t + (r * np.sin(phi))[:, None] * b + np.sqrt(1.0 - u1)[:, None] * n
        o = data.positions[i] + occ.offset * d
        free = 1.0 - occ.occluded(o.astype(np.float32), d.astype(np.float32), 1.5 - occ.offset).mean()
        assert abs(share[i] - free) < 0.06, (i, share[i], free)
    near_cube = data.positions[:, 0] > 0.55  # (her right ear, towards the cube)
    held = dict(ambient._shares)
    scene.camera.location = (-7.0, -7.0, 2.0)
    again = plan_of(scene, obj).items[0][1]
    np.testing.assert_array_equal(again.inputs["base_color"], data.inputs["base_color"])
    assert all(ambient._shares[k] is held[k] for k in held)  # nothing cast again
    ao.only_local = True
    local = plan_of(scene, obj).items[0][1].inputs["base_color"][:, 0] / 0.8
    # (a vertex where her eye meets her head may lose a ray the smaller scene's offset no longer skips)
    assert (local[near_cube] - share[near_cube]).mean() > 0.02 and np.mean(local < share - 0.05) < 0.01


def test_a_light_path_ray_length_is_the_distance_from_the_eye(scene):
    """A Light Path's Ray Length into Roughness (through a Math node dividing it by 20): each vertex
    reads its distance from the camera's eye, as the camera ray that meets it has run."""
    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    mat = principled_material("depth")
    obj.data.materials.append(mat)
    tree = mat.node_tree
    path, divide = tree.nodes.new("ShaderNodeLightPath"), tree.nodes.new("ShaderNodeMath")
    divide.operation, divide.inputs[1].default_value = "DIVIDE", 20.0
    tree.links.new(path.outputs["Ray Length"], divide.inputs[0])
    tree.links.new(divide.outputs[0], tree.nodes["Principled BSDF"].inputs["Roughness"])
    select_only(obj)
    bpy.context.view_layer.update()
    data = plan_of(scene, obj).items[0][1]
    eye = np.array(scene.camera.matrix_world.translation)
    want = np.linalg.norm(data.positions - eye, axis=1) / 20.0
    np.testing.assert_allclose(data.inputs["roughness"], want, rtol=1e-5)
    assert np.ptp(want) > 0.05


def test_a_texture_wenv_cannot_read_is_named_with_the_value_used(scene):
    """A Base Color through a Sky Texture's Color (in an object's material), or a UV map the mesh
    lacks: the report says so and the unlinked value is used."""
    env_world(scene, "sunset")
    image = bpy.data.images.new("flat", 8, 8, float_buffer=True)
    plane, mat = textured_plane(image)
    tree = mat.node_tree
    uv_node = tree.nodes.new("ShaderNodeUVMap")
    uv_node.uv_map = "no such map"
    tree.links.new(uv_node.outputs["UV"], tree.nodes["Image Texture"].inputs["Vector"])
    plan = plan_of(scene, plane)
    assert "base_color" not in plan.items[0][1].inputs
    assert any("no UV map 'no such map'" in note and "unlinked value is used" in note for note in plan.notes)
    sky = tree.nodes.new("ShaderNodeTexSky")
    tree.links.new(sky.outputs["Color"], tree.nodes["Image Texture"].inputs["Vector"])
    notes = materials.principled_notes(mat)
    assert any("'Base Color' is linked" in n and "'Sky Texture'" in n and "(0.8, 0.2, 0.1) is used"
               in n for n in notes), notes


def test_a_broken_texture_or_uv_map_is_a_named_error(scene):
    """A NaN texel, NaN or infinite UV coordinates or an image that cannot be loaded (Blender's size
    of it: 0 x 0) stop the pass with an error naming them, and the colours shaded before are kept;
    a mesh without a UV map is shaded at the texture's socket's unlinked value, named."""
    env_world(scene, "sunset")
    image = bpy.data.images.new("flat", 8, 8, float_buffer=True)
    plane, mat = textured_plane(image)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    before = attribute(plane)[1].copy()
    px = np.ones(8 * 8 * 4, np.float32)
    px[4 * 10] = np.nan
    image.pixels.foreach_set(px)
    with pytest.raises(RuntimeError, match="Texture image 'flat' has a texel that is not finite"):
        shade_op(view="CAMERA")
    image.pixels.foreach_set(np.ones(8 * 8 * 4, np.float32))
    uv = np.zeros(len(plane.data.loops) * 2, np.float32)
    for bad in (np.inf, np.nan):
        uv[7] = bad
        plane.data.uv_layers.active.uv.foreach_set("vector", uv)
        with pytest.raises(RuntimeError, match="UV map 'UVMap' of mesh '.*' has a coordinate that is not finite"):
            shade_op(view="CAMERA")
    uv[7] = 0.0
    plane.data.uv_layers.active.uv.foreach_set("vector", uv)
    missing = bpy.data.images.load(hdri_path("sunset"))
    missing.filepath = "//no such file.png"
    missing.reload()
    mat.node_tree.nodes["Image Texture"].image = missing
    assert tuple(missing.size) == (0, 0)
    with pytest.raises(RuntimeError, match="Texture image .* could not be loaded"):
        shade_op(view="CAMERA")
    np.testing.assert_array_equal(attribute(plane)[1], before)
    mat.node_tree.nodes["Image Texture"].image = image
    plane.data.uv_layers.remove(plane.data.uv_layers[0])
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert any(f"'{plane.name}' has no UV map to render with for 'Base Color'" in n
               for n in plan_of(scene, plane).notes), plan_of(scene, plane).notes


def test_a_normal_map_bends_the_shading_normals(scene):
    """A tangent-space Normal Map of one tilt (0.3 along the UV map's u, which runs along +X here) on
    a grid: the add-on shades each vertex as the core does at that bent normal, bent from the mesh's
    (smooth_normals: Cycles' bump terminator takes its share); at Strength 0, at the mesh's own.
    The report says a normal map is read at the vertices."""
    env_world(scene, "sunset")
    tilt = bpy.data.images.new("tilt", 4, 4, float_buffer=True)
    bent = np.float32([0.3, 0.0, np.sqrt(1.0 - 0.09)])
    tilt.pixels.foreach_set(np.tile(np.append(0.5 * bent + 0.5, 1.0).astype(np.float32), 16))
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=9, y_subdivisions=9, size=4.0)
    plane = bpy.context.object
    plane.data.shade_smooth()
    mat = principled_material("bumpy", roughness=0.4)
    tree = mat.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = tilt
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], tree.nodes["Principled BSDF"].inputs["Normal"])
    plane.data.materials.append(mat)
    select_only(plane)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    p, n = world_arrays(plane, corner=False)
    eye = tuple(scene.camera.matrix_world.translation)
    ior = tree.nodes["Principled BSDF"].inputs["IOR"].default_value
    shader = core_shader(wenv.load_environment(hdri_path("sunset")),
                         wenv.Principled(base_color=(0.8, 0.2, 0.1), roughness=0.4, ior=ior))
    np.testing.assert_allclose(attribute(plane)[1],
                               shader.shade_mesh(p, np.tile(bent, (len(p), 1)), eye, smooth_normals=n,
                                                 bump_map_correction=BUMP), rtol=1e-4,
                               atol=1e-5)
    assert shader.shade_mesh(p, np.tile(bent, (len(p), 1)), eye).mean() > attribute(plane)[1].mean() * 1.005
    assert any("'Normal' from a normal map is read at the vertices" in note for note in
               materials.principled_notes(mat))
    normal_map.inputs["Strength"].default_value = 0.0
    assert shade_op(view="CAMERA") == {"FINISHED"}
    np.testing.assert_allclose(attribute(plane)[1], shader.shade_mesh(p, n, eye), rtol=1e-4, atol=1e-5)
    # a Strength from nodes that give it one value everywhere (a Value node, through Math) is read;
    # one that varies from point to point is named, and the map not read
    normal_map.inputs["Strength"].default_value = 0.7
    value, half = tree.nodes.new("ShaderNodeValue"), tree.nodes.new("ShaderNodeMath")
    value.outputs[0].default_value, half.operation, half.inputs[1].default_value = 0.0, "MULTIPLY", 0.5
    tree.links.new(value.outputs[0], half.inputs[0])
    tree.links.new(half.outputs[0], normal_map.inputs["Strength"])
    assert shade_op(view="CAMERA") == {"FINISHED"}
    np.testing.assert_allclose(attribute(plane)[1], shader.shade_mesh(p, n, eye), rtol=1e-4, atol=1e-5)
    value.outputs[0].default_value = 2.0  # (a Strength of 1)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    np.testing.assert_allclose(attribute(plane)[1],
                               shader.shade_mesh(p, np.tile(bent, (len(p), 1)), eye, smooth_normals=n,
                                                 bump_map_correction=BUMP), rtol=1e-4,
                               atol=1e-5)
    split = tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(tree.nodes.new("ShaderNodeNewGeometry").outputs["Position"], split.inputs[0])
    tree.links.new(split.outputs["X"], half.inputs[0])
    assert any("Strength is linked to values that vary from point to point" in note
               for note in materials.principled_notes(mat))


def test_a_normal_map_on_a_face_of_many_corners(scene):
    """A tangent-space Normal Map on a disc that is one face of 12 corners (for which Blender's own
    calc_tangents computes nothing), turned 40 degrees about X: each vertex is shaded at the map's
    tilt of 0.3 along the UV map's u, which runs 30 degrees from the disc's +X here, carried into the
    world with the disc."""
    env_world(scene, "sunset")
    tilt = bpy.data.images.new("tilt", 4, 4, float_buffer=True)
    bent = np.float32([0.3, 0.0, np.sqrt(1.0 - 0.09)])
    tilt.pixels.foreach_set(np.tile(np.append(0.5 * bent + 0.5, 1.0).astype(np.float32), 16))
    bpy.ops.mesh.primitive_circle_add(vertices=12, radius=1.5, fill_type="NGON", rotation=(math.radians(40.0), 0, 0))
    disc = bpy.context.object
    mesh = disc.data
    assert [len(p.vertices) for p in mesh.polygons] == [12]
    turn = math.radians(30.0)
    co = np.array([mesh.vertices[l.vertex_index].co[:2] for l in mesh.loops], np.float64)
    uv = np.column_stack([co @ (math.cos(turn), math.sin(turn)), co @ (-math.sin(turn), math.cos(turn))]) / 4 + 0.5
    layer = mesh.uv_layers.new(name="turned")
    layer.uv.foreach_set("vector", uv.astype(np.float32).ravel())
    mat = principled_material("bumpy", roughness=0.4)
    tree = mat.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = tilt
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    normal_map.uv_map = "turned"
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], tree.nodes["Principled BSDF"].inputs["Normal"])
    mesh.materials.append(mat)
    select_only(disc)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    p, n = world_arrays(disc, corner=False)
    frame = np.array([[math.cos(turn), -math.sin(turn), 0.0], [math.sin(turn), math.cos(turn), 0.0], [0.0, 0.0, 1.0]])
    want = np.array(disc.matrix_world.to_3x3()) @ frame @ bent
    eye = tuple(scene.camera.matrix_world.translation)
    ior = tree.nodes["Principled BSDF"].inputs["IOR"].default_value
    shader = core_shader(wenv.load_environment(hdri_path("sunset")),
                         wenv.Principled(base_color=(0.8, 0.2, 0.1), roughness=0.4, ior=ior))
    np.testing.assert_allclose(attribute(disc)[1], shader.shade_mesh(p, np.tile(want.astype(np.float32), (len(p), 1)),
                                                                     eye, smooth_normals=n, bump_map_correction=BUMP),
                               rtol=1e-4, atol=1e-5)
    assert not np.allclose(attribute(disc)[1], shader.shade_mesh(p, n, eye), rtol=0.01)


@pytest.mark.parametrize("space", ["OBJECT", "WORLD", "BLENDER_OBJECT", "BLENDER_WORLD"])
def test_object_and_world_space_normal_maps(scene, space):
    """A Normal Map in object or world space (Blender's own with Y and Z flipped, as Cycles reads
    them) on a turned grid: object space turns with the object, world space does not; Strength 0.5
    blends towards the mesh's normal as Cycles does."""
    env_world(scene, "sunset")
    want = np.float32([0.4, -0.2, 0.0])
    want[2] = np.sqrt(1.0 - want[0] ** 2 - want[1] ** 2)
    stored = want * (np.float32([1, -1, -1]) if space.startswith("BLENDER_") else 1.0)
    image = bpy.data.images.new("map", 4, 4, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(np.tile(np.append(0.5 * stored + 0.5, 1.0).astype(np.float32), 16))
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=5, y_subdivisions=5, size=4.0)
    plane = bpy.context.object
    plane.rotation_euler = (0.3, 0.0, 0.5)
    plane.data.shade_smooth()
    mat = principled_material("mapped", roughness=0.4)
    tree = mat.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    normal_map.space = space
    normal_map.inputs["Strength"].default_value = 0.5
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], tree.nodes["Principled BSDF"].inputs["Normal"])
    plane.data.materials.append(mat)
    select_only(plane)
    bpy.context.view_layer.update()
    plan = plan_of(scene, plane)
    data = plan.items[0][1]
    rot = np.array(plane.matrix_world.to_3x3(), np.float64)
    mapped = rot @ want if space.endswith("OBJECT") else np.float64(want)
    mapped /= np.linalg.norm(mapped)
    mesh_n = rot @ np.float64([0.0, 0.0, 1.0])
    blended = mesh_n + (mapped - mesh_n) * 0.5
    blended /= np.linalg.norm(blended)
    np.testing.assert_allclose(data.shading_normals, np.tile(blended, (data.count, 1)), atol=2e-4)
    assert not any("not used" in n for n in materials.principled_notes(mat))


@pytest.mark.parametrize("invert", [False, True])
def test_a_bump_node_tilts_the_normals_against_its_heights_gradient(scene, invert):
    """A Bump node whose Height is an image ramping along u (through a Math node) on a turned grid:
    each interior vertex's normal is Cycles' bump of that gradient, normalize(N - Distance x grad h)
    (towards the ramp's descent; inverted, the other way), blended towards N by Strength."""
    env_world(scene, "sunset")
    width = 64
    ramp = bpy.data.images.new("ramp", width, 1, float_buffer=True)
    ramp.colorspace_settings.name = "Non-Color"
    u = (np.arange(width, dtype=np.float32) + 0.5) / width
    ramp.pixels.foreach_set(np.stack([u, u, u, np.ones_like(u)], axis=1).ravel())
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=9, y_subdivisions=9, size=4.0)
    plane = bpy.context.object
    plane.rotation_euler = (0.3, 0.0, 0.5)
    mat = principled_material("bumped", roughness=0.4)
    tree = mat.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = ramp
    tex.extension = "EXTEND"
    times = tree.nodes.new("ShaderNodeMath")
    times.operation = "MULTIPLY"
    times.inputs[1].default_value = 3.0
    bump = tree.nodes.new("ShaderNodeBump")
    bump.invert = invert
    bump.inputs["Distance"].default_value = 0.5
    bump.inputs["Strength"].default_value = 0.7
    tree.links.new(tex.outputs["Color"], times.inputs[0])
    tree.links.new(times.outputs["Value"], bump.inputs["Height"])
    tree.links.new(bump.outputs["Normal"], tree.nodes["Principled BSDF"].inputs["Normal"])
    plane.data.materials.append(mat)
    select_only(plane)
    bpy.context.view_layer.update()
    data = plan_of(scene, plane).items[0][1]
    rot = np.array(plane.matrix_world.to_3x3(), np.float64)
    n = rot @ np.float64([0.0, 0.0, 1.0])
    # h = 3u and u runs over the grid's 4 units of x: a gradient of 3/4 along the object's x
    grad = rot @ np.float64([0.75, 0.0, 0.0])
    tilted = n - (-0.5 if invert else 0.5) * grad
    tilted /= np.linalg.norm(tilted)
    want = 0.7 * tilted + 0.3 * n
    want /= np.linalg.norm(want)
    local = np.asarray(data.positions, np.float64) - np.array(plane.matrix_world.translation)
    inside = np.all(np.abs(local @ rot)[:, :2] < 1.5, axis=1)  # away from the ramp's clamped ends
    assert inside.sum() > 20
    np.testing.assert_allclose(data.shading_normals[inside], np.tile(want, (int(inside.sum()), 1)), atol=1e-3)
    assert "'Normal' from a Bump node is read at the vertices: detail finer than the mesh is lost" in \
        materials.principled_notes(mat)
    bump.inputs["Strength"].default_value = 0.0
    flat = plan_of(scene, plane).items[0][1]
    np.testing.assert_allclose(flat.shading_normals, np.tile(n, (flat.count, 1)), atol=1e-5)
    # Distance and Strength from Value nodes: as their values unlinked
    for name, v in (("Distance", 0.5), ("Strength", 0.7)):
        value = tree.nodes.new("ShaderNodeValue")
        value.outputs[0].default_value = v
        bump.inputs[name].default_value = 0.1
        tree.links.new(value.outputs[0], bump.inputs[name])
    linked = plan_of(scene, plane).items[0][1]
    np.testing.assert_array_equal(linked.shading_normals, data.shading_normals)


def test_a_bump_node_over_a_normal_map_and_what_it_does_not_read(scene):
    """A Bump node whose Normal is a Normal Map bends the mapped normal; one whose Height comes from a
    node wenv does not evaluate is named, and the mesh's normals are used."""
    env_world(scene, "sunset")
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=5, y_subdivisions=5, size=4.0)
    plane = bpy.context.object
    image = bpy.data.images.new("map", 4, 4, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    want = np.float32([0.3, 0.0, np.sqrt(1.0 - 0.09)])
    image.pixels.foreach_set(np.tile(np.append(0.5 * want + 0.5, 1.0).astype(np.float32), 16))
    mat = principled_material("mapped and bumped", roughness=0.4)
    tree = mat.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    normal_map.space = "OBJECT"
    bump = tree.nodes.new("ShaderNodeBump")
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], bump.inputs["Normal"])
    tree.links.new(bump.outputs["Normal"], tree.nodes["Principled BSDF"].inputs["Normal"])
    plane.data.materials.append(mat)
    select_only(plane)
    bpy.context.view_layer.update()
    # a Height left unlinked: a flat height, the mapped normal as it is
    data = plan_of(scene, plane).items[0][1]
    np.testing.assert_allclose(data.shading_normals, np.tile(want, (data.count, 1)), atol=2e-4)
    assert "'Normal' from a Bump node over a normal map is read at the vertices: detail finer than the mesh " \
        "is lost" in materials.principled_notes(mat)
    sky = tree.nodes.new("ShaderNodeTexSky")
    tree.links.new(sky.outputs["Color"], bump.inputs["Height"])
    notes = materials.principled_notes(mat)
    assert any("'Normal' is linked" in n and "Height comes from" in n and "Sky Texture" in n
               for n in notes), notes
    data = plan_of(scene, plane).items[0][1]
    assert data.shading_normals is None
    # a Height from what reads the scene about each point (which a height's points do not): named, the
    # mapped normal as it is, and the operator does not fail
    for kind, output in (("ShaderNodeAmbientOcclusion", "AO"), ("ShaderNodeBevel", "Normal")):
        source = tree.nodes.new(kind)
        tree.links.new(source.outputs[output], bump.inputs["Height"])
        plan = plan_of(scene, plane)
        np.testing.assert_allclose(plan.items[0][1].shading_normals, np.tile(want, (plan.items[0][1].count, 1)),
                                   atol=2e-4)
        assert any("the Bump node of 'mapped and bumped' takes its Height from" in n and source.name in n
                   for n in plan.notes), plan.notes
        assert shade_op(view="CAMERA") == {"FINISHED"}


def test_a_bevel_over_a_normal_map_keeps_the_mapped_normal(scene):
    """A Bevel node whose Normal is a Normal Map's (or a Bump node's), into the Principled's Normal,
    on Suzanne: each vertex's normal is the mapped one turned as the bevel turns the mesh's,
    normalize(mapped + (bevelled - mesh)), as Cycles' svm_node_bevel composes them; the report
    names the chain as read at the vertices."""
    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    tilt = bpy.data.images.new("tilt", 4, 4, float_buffer=True)
    tilt.pixels.foreach_set(np.tile(np.float32([0.65, 0.5, 0.95, 1.0]), 16))
    mat = principled_material("bevelled", roughness=0.4)
    obj.data.materials.append(mat)
    select_only(obj)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = tilt
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    bevel_node = tree.nodes.new("ShaderNodeBevel")
    bevel_node.inputs["Radius"].default_value = 0.15

    def normals_with(source):
        tree.links.new(source, bsdf.inputs["Normal"])
        data = plan_of(scene, obj).items[0][1]
        return data.shading_normals, data.normals / np.linalg.norm(data.normals, axis=1, keepdims=True)
    mapped, mesh_n = normals_with(normal_map.outputs["Normal"])
    rounded, _ = normals_with(bevel_node.outputs["Normal"])
    tree.links.new(normal_map.outputs["Normal"], bevel_node.inputs["Normal"])
    both, _ = normals_with(bevel_node.outputs["Normal"])
    want = mapped + (rounded - mesh_n)
    want /= np.linalg.norm(want, axis=1, keepdims=True)
    np.testing.assert_allclose(both, want, atol=1e-5)
    for got, other in ((both, mapped), (both, rounded), (mapped, mesh_n), (rounded, mesh_n)):
        assert np.abs(got - other).max() > 0.05  # each bends the normals its own way
    notes = materials.principled_notes(mat)
    assert "'Normal' from a Bevel node over a normal map is read at the vertices: detail finer than the mesh " \
        "is lost" in notes, notes
    bump = tree.nodes.new("ShaderNodeBump")
    tree.links.new(tex.outputs["Color"], bump.inputs["Height"])
    tree.links.new(bump.outputs["Normal"], bevel_node.inputs["Normal"])
    assert "'Normal' from a Bevel node over a Bump node is read at the vertices: detail finer than the mesh " \
        "is lost" in materials.principled_notes(mat)
    combine = tree.nodes.new("ShaderNodeCombineXYZ")
    tree.links.new(combine.outputs[0], bevel_node.inputs["Normal"])
    assert any("whose Normal is not a Normal Map or Bump node" in n for n in materials.principled_notes(mat))
    assert shade_op(view="CAMERA") == {"FINISHED"}


def test_the_glossmeter_reads_a_textured_base_color_at_its_mean(scene):
    """Base Color from a texture of two halves: the glossmeter panel reads the material at the
    texture's mean colour and says so; the reading is the core's at that colour."""
    from addon import gloss, ui
    halves = bpy.data.images.new("halves", 4, 4, float_buffer=True)
    px = np.zeros((4, 4, 4), np.float32)
    px[:, :2] = (0.9, 0.1, 0.1, 1.0)
    px[:, 2:] = (0.1, 0.7, 0.3, 1.0)
    halves.pixels.foreach_set(px.ravel())
    plane, mat = textured_plane(halves)
    plane.active_material = mat
    key, note = gloss.reading_key(mat)
    assert note == "Base Color: the mean of 'halves'"
    assert dict(key[1])["base_color"] == pytest.approx((0.5, 0.4, 0.2))
    ior = mat.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value
    want = wenv.gloss(wenv.Principled(base_color=(0.5, 0.4, 0.2), roughness=0.4, ior=ior), [60])[0]
    assert mat.wenv.gloss_60 == pytest.approx(want, rel=1e-6)
    panel = [l[1] for l in draw_panel(ui.WENV_PT_gloss) if l[0] == "label"]
    assert note in panel


def value_image(name, pixels):
    """A float image of Non-Color data holding `pixels` (h, w, 4), set after the colour space (setting
    it regenerates a generated image's buffer)."""
    image = bpy.data.images.new(name, pixels.shape[1], pixels.shape[0], float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(np.ascontiguousarray(pixels, np.float32).ravel())
    return image


def value_texture(mat, socket, image):
    """An Image Texture of `image` feeding the material's Principled `socket`."""
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tex.interpolation = "Closest"
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs[socket])
    return tex


def test_a_textured_emission_color_is_read_at_each_vertex(scene):
    """Emission Color from an image of two halves (Closest), Strength 2: each vertex emits its half's
    colour, as the core shades it given them (emission_color=)."""
    env_world(scene, "sunset")
    plane, mat = textured_plane(bpy.data.images.new("unused", 4, 4, float_buffer=True))
    tree = mat.node_tree
    node = tree.nodes["Principled BSDF"]
    tree.links.remove(node.inputs["Base Color"].links[0])
    node.inputs["Emission Strength"].default_value = 2.0
    px = np.ones((64, 64, 4), np.float32)
    px[:, :32, :3], px[:, 32:, :3] = (1.0, 0.5, 0.1), (0.1, 0.4, 1.0)
    halves = bpy.data.images.new("glow halves", 64, 64, float_buffer=True)
    halves.pixels.foreach_set(px.ravel())
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = halves, "Closest"
    tree.links.new(tex.outputs["Color"], node.inputs["Emission Color"])
    assert not any("Emission" in n for n in materials.principled_notes(mat))
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(plane)
    u = corner_uv_rows(plane)[:, 0]
    glow = np.where((np.floor(u * 64).astype(int) % 64 < 32)[:, None], np.float32([1.0, 0.5, 0.1]),
                    np.float32([0.1, 0.4, 1.0])).astype(np.float32)
    p, n = world_arrays(plane, corner=False)
    eye = tuple(scene.camera.matrix_world.translation)
    inputs, _ = materials.principled_inputs(node)
    want = core_shader(wenv.load_environment(hdri_path("sunset")), engine.principled(inputs)).shade_mesh(
        p, n, eye, emission_color=glow)
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)
    assert rgb.max() > 1.5  # the emission shows


def test_the_glossmeter_says_when_it_reads_a_stand_in(scene):
    """A material of a lone Glass BSDF (a node wenv does not shade): the panel's note names it, and the
    glossmeter's reading says it is of the Lambertian stand-in."""
    from addon import gloss
    mat = principled_material("glass only", roughness=0.1)
    tree = mat.node_tree
    glass = tree.nodes.new("ShaderNodeBsdfGlass")
    tree.links.new(glass.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    assert any("'Glass BSDF'" in n and "not shaded" in n for n in materials.principled_notes(mat))
    key, note = gloss.reading_key(mat)
    assert key[0] == "LAMBERT" and "the reading is of a stand-in" in note, (key, note)
    _key, plain = gloss.reading_key(principled_material("plain", roughness=0.1))
    assert plain is None


def test_a_mix_of_shader_nodes_with_a_textured_factor(scene):
    """A Mix Shader of a Diffuse BSDF and a coloured Glossy BSDF whose Fac is an image of two halves
    (0.2 and 0.9), inside a node group, added to a Glass BSDF: each vertex is the core's shading of
    each term (Principled materials: addon/closures.py) weighted by its texel's factor; the Glass
    BSDF is named as not shaded; the glossmeter reads the terms summed at the factor's mean and says
    so, and not the Lambertian stand-in."""
    from addon import closures, gloss
    env_world(scene, "sunset")
    plane, mat = textured_plane(bpy.data.images.new("unused", 4, 4, float_buffer=True))
    tree = mat.node_tree
    for n in [n for n in tree.nodes if n.bl_idname != "ShaderNodeOutputMaterial"]:
        tree.nodes.remove(n)
    group = bpy.data.node_groups.new("mixed", "ShaderNodeTree")
    group.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    group.interface.new_socket("Fac", in_out="INPUT", socket_type="NodeSocketFloat")
    g_in, g_out = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
    diffuse, glossy = group.nodes.new("ShaderNodeBsdfDiffuse"), group.nodes.new("ShaderNodeBsdfGlossy")
    diffuse.inputs["Color"].default_value = (0.6, 0.3, 0.1, 1.0)
    glossy.inputs["Color"].default_value = (0.9, 0.8, 0.6, 1.0)
    glossy.inputs["Roughness"].default_value = 0.3
    glossy.distribution = "GGX"
    mix_node = group.nodes.new("ShaderNodeMixShader")
    group.links.new(g_in.outputs[0], mix_node.inputs[0])
    group.links.new(diffuse.outputs[0], mix_node.inputs[1])
    group.links.new(glossy.outputs[0], mix_node.inputs[2])
    group.links.new(mix_node.outputs[0], g_out.inputs[0])
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    px = np.ones((64, 64, 4), np.float32)
    px[:, :32, :3], px[:, 32:, :3] = 0.2, 0.9
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = value_image("fac halves", px), "Closest"
    tree.links.new(tex.outputs["Color"], node.inputs[0])
    add = tree.nodes.new("ShaderNodeAddShader")
    glass = tree.nodes.new("ShaderNodeBsdfGlass")
    tree.links.new(node.outputs[0], add.inputs[0])
    tree.links.new(glass.outputs[0], add.inputs[1])
    tree.links.new(add.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    mat.wenv.model = "PRINCIPLED"

    found, notes = closures.terms(mat)
    assert [t.label for t in found] == ["Diffuse BSDF", "Glossy BSDF"]
    assert any("'Glass BSDF'" in n and "not shaded" in n for n in materials.principled_notes(mat))
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(plane)
    u = corner_uv_rows(plane)[:, 0]
    fac = np.where(np.floor(u * 64).astype(int) % 64 < 32, 0.2, 0.9).astype(np.float32)
    p, n = world_arrays(plane, corner=False)
    env = wenv.load_environment(hdri_path("sunset"))
    eye = tuple(scene.camera.matrix_world.translation)
    want = np.zeros_like(rgb)
    for term, w in zip(found, ((1 - fac)[:, None], fac[:, None])):
        shaded = core_shader(env, engine.principled(term.inputs)).shade_mesh(p, n, eye)
        want += w * np.float32(term.colour) * shaded
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)

    key, said = gloss.reading_key(mat)
    assert key[0] == "MIXTURE" and "mix of 2 shader nodes" in said
    readings = gloss.gloss_readings(key)
    lum = np.array([0.2126, 0.7152, 0.0722])
    glossy_term = gloss.gloss_readings(found[1].key())
    diffuse_term = gloss.gloss_readings(found[0].key())
    mean_fac = 0.55
    expected = (1 - mean_fac) * diffuse_term[60] + mean_fac * float(np.float32(found[1].colour) @ lum) * glossy_term[60]
    assert readings[60] == pytest.approx(expected, rel=1e-3)
    assert readings[60] > 10 * gloss.gloss_readings(("LAMBERT", (0.8, 0.8, 0.8), "SMITH", ()))[60]


def test_a_mix_by_layer_weight_follows_the_view(scene):
    """A Mix Shader of a Diffuse and a Glossy BSDF whose Fac is Layer Weight's Facing (Blend 0.3), on
    Suzanne: each vertex's factor is 1 - |cos|^0.6 of the angle between its normal and the direction
    to the camera (as Cycles' svm_node_layer_weight, held to Cycles' pixels in test_attributes.py),
    the colours are the core's shading of each term weighted by it, and another view gives other
    factors; inside a node group, a factor made from the group's input by nodes there follows the
    input out."""
    from addon import closures
    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    mat = principled_material("facing")
    obj.data.materials.append(mat)
    select_only(obj)
    tree = mat.node_tree
    for n in [n for n in tree.nodes if n.bl_idname != "ShaderNodeOutputMaterial"]:
        tree.nodes.remove(n)
    diffuse, glossy = tree.nodes.new("ShaderNodeBsdfDiffuse"), tree.nodes.new("ShaderNodeBsdfGlossy")
    diffuse.inputs["Color"].default_value = (0.5, 0.2, 0.1, 1.0)
    glossy.inputs["Roughness"].default_value = 0.25
    glossy.distribution = "GGX"
    mix_node, weight = tree.nodes.new("ShaderNodeMixShader"), tree.nodes.new("ShaderNodeLayerWeight")
    weight.inputs["Blend"].default_value = 0.3
    tree.links.new(weight.outputs["Facing"], mix_node.inputs[0])
    tree.links.new(diffuse.outputs[0], mix_node.inputs[1])
    tree.links.new(glossy.outputs[0], mix_node.inputs[2])
    tree.links.new(mix_node.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    mat.wenv.model = "PRINCIPLED"
    found, _ = closures.terms(mat)
    assert not closures.factor_notes(mat)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(obj)
    p, n = world_arrays(obj, corner=False)
    eye = np.array(scene.camera.matrix_world.translation)

    def facing(eye):
        towards = (eye - p) / np.linalg.norm(eye - p, axis=1, keepdims=True)
        unit = n / np.linalg.norm(n, axis=1, keepdims=True)
        return 1.0 - np.abs(np.einsum("ij,ij->i", towards, unit)) ** 0.6
    fac = facing(eye)
    env = wenv.load_environment(hdri_path("sunset"))
    want = np.zeros_like(rgb)
    for term, w in zip(found, ((1 - fac)[:, None], fac[:, None])):
        want += w * np.float32(term.colour) * core_shader(env, engine.principled(term.inputs)).shade_mesh(
            p, n, tuple(eye))
    np.testing.assert_allclose(rgb, want, rtol=2e-4, atol=2e-5)
    assert np.ptp(fac) > 0.5
    scene.camera.location = (-4.0, 3.0, 2.0)
    bpy.context.view_layer.update()
    data = plan_of(scene, obj).items[0][1]
    moved = facing(np.array(scene.camera.matrix_world.translation))
    np.testing.assert_allclose(data.term_weights[0][1][:, 0], moved * np.float32(found[1].colour[0]), atol=2e-5)

    # the Mix Shader inside a node group, its Fac half the group's input through a Math node there
    group = bpy.data.node_groups.new("halved mix", "ShaderNodeTree")
    group.interface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    group.interface.new_socket("Fac", in_out="INPUT", socket_type="NodeSocketFloat")
    g_in, g_out = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
    half, inner_mix = group.nodes.new("ShaderNodeMath"), group.nodes.new("ShaderNodeMixShader")
    half.operation, half.inputs[1].default_value = "MULTIPLY", 0.5
    group.links.new(g_in.outputs[0], half.inputs[0])
    group.links.new(half.outputs[0], inner_mix.inputs[0])
    for k, kind in ((1, "ShaderNodeBsdfDiffuse"), (2, "ShaderNodeBsdfGlossy")):
        bsdf = group.nodes.new(kind)
        bsdf.inputs["Color"].default_value = tuple(found[k - 1].colour) + (1.0,)
        group.links.new(bsdf.outputs[0], inner_mix.inputs[k])
    group.links.new(inner_mix.outputs[0], g_out.inputs[0])
    holder = tree.nodes.new("ShaderNodeGroup")
    holder.node_tree = group
    tree.links.new(weight.outputs["Facing"], holder.inputs[0])
    tree.links.new(holder.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    assert not closures.factor_notes(mat)
    data = plan_of(scene, obj).items[0][1]
    np.testing.assert_allclose(data.term_weights[0][1][:, 0], 0.5 * moved * np.float32(found[1].colour[0]),
                               atol=2e-5)


def test_textured_inputs_of_mixed_bsdfs_are_read_at_each_vertex(scene):
    """A Mix Shader (Fac 0.3) of a Principled BSDF whose Roughness is an image of two halves and a
    Glossy BSDF whose Color and Roughness are images of halves: each vertex is the core's shading of
    each term with the term's own inputs at that vertex (the Glossy's colour its weight); an input
    whose nodes wenv does not evaluate is named with its unlinked value used."""
    from addon import closures
    env_world(scene, "sunset")
    plane, mat = textured_plane(bpy.data.images.new("unused", 4, 4, float_buffer=True))
    tree = mat.node_tree
    tree.nodes.remove(tree.nodes["Image Texture"])
    principled = tree.nodes["Principled BSDF"]
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    glossy.distribution = "GGX"
    mix_node = tree.nodes.new("ShaderNodeMixShader")
    mix_node.inputs[0].default_value = 0.3
    tree.links.new(principled.outputs[0], mix_node.inputs[1])
    tree.links.new(glossy.outputs[0], mix_node.inputs[2])
    tree.links.new(mix_node.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    px = np.ones((64, 64, 4), np.float32)
    px[:, :32, :3], px[:, 32:, :3] = 0.15, 0.6
    value_texture(mat, "Roughness", value_image("rough halves", px))
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = value_image("glossy rough", px[:, ::-1].copy()), "Closest"
    tree.links.new(tex.outputs["Color"], glossy.inputs["Roughness"])
    tint = np.ones((64, 64, 4), np.float32)
    tint[:, :32, :3], tint[:, 32:, :3] = (0.9, 0.5, 0.2), (0.2, 0.6, 0.9)
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = value_image("glossy tint", tint), "Closest"
    tree.links.new(tex.outputs["Color"], glossy.inputs["Color"])
    found, _ = closures.terms(mat)
    assert [t.label for t in found] == ["Principled BSDF", "Glossy BSDF"]
    assert not any("is linked" in n for n in materials.principled_notes(mat)), materials.principled_notes(mat)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(plane)
    left = np.floor(corner_uv_rows(plane)[:, 0] * 64).astype(int) % 64 < 32
    p, n = world_arrays(plane, corner=False)
    env = wenv.load_environment(hdri_path("sunset"))
    eye = tuple(scene.camera.matrix_world.translation)
    principled_rough = np.where(left, 0.15, 0.6).astype(np.float32)
    glossy_rough = np.where(left, 0.6, 0.15).astype(np.float32)
    colour = np.where(left[:, None], np.float32([0.9, 0.5, 0.2]), np.float32([0.2, 0.6, 0.9]))
    want = 0.7 * core_shader(env, engine.principled(found[0].inputs)).shade_mesh(p, n, eye, roughness=principled_rough)
    want += 0.3 * colour * core_shader(env, engine.principled(found[1].inputs)).shade_mesh(p, n, eye,
                                                                                       roughness=glossy_rough)
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)
    sky = tree.nodes.new("ShaderNodeTexSky")
    tree.links.new(sky.outputs["Color"], glossy.inputs["Roughness"])
    assert any("'Glossy BSDF': 'Roughness' is linked (" in n and "unlinked value is used" in n
               for n in materials.principled_notes(mat))


def test_textured_roughness_and_metallic_are_read_at_each_vertex(scene):
    """Roughness from an image of two halves (0.15 and 0.6) and Metallic from one of halves the other
    way (0 and 1), over a Base Color texture: the add-on gives each vertex its texel's values (a
    colour's luminance, as Cycles converts it) and its colours are the core's shading with them; the
    report names none of them, and the glossmeter reads the textures' means and says so."""
    from addon import gloss
    env_world(scene, "sunset")
    flat = bpy.data.images.new("flat paint", 4, 4, float_buffer=True)
    flat.pixels.foreach_set(np.tile(np.float32([0.6, 0.15, 0.08, 1.0]), 16))
    plane, mat = textured_plane(flat)
    px = np.ones((64, 64, 4), np.float32)
    px[:, :32, :3] = 0.15
    px[:, 32:, :3] = (0.5, 0.6, 0.8)  # a colour: its luminance is read
    value_texture(mat, "Roughness", value_image("rough halves", px))
    px = np.ones((64, 64, 4), np.float32)
    px[:32, :, :3] = 0.0
    value_texture(mat, "Metallic", value_image("metal halves", px))
    mat.node_tree.nodes["Image Texture"].interpolation = "Closest"
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert not any(s in note for note in materials.principled_notes(mat) for s in ("Roughness", "Metallic"))
    uv = np.empty(len(plane.data.loops) * 2, np.float32)
    plane.data.uv_layers.active.uv.foreach_get("vector", uv)
    u = np.zeros(len(plane.data.vertices), np.float32)
    w = np.zeros(len(plane.data.vertices), np.float32)
    u[[l.vertex_index for l in plane.data.loops]] = uv[0::2]
    w[[l.vertex_index for l in plane.data.loops]] = uv[1::2]
    luminance = np.float32((0.2126729 * 0.5 + 0.7151522 * 0.6 + 0.0721750 * 0.8) / 1.0000001)
    roughness = np.where(np.floor(u * 64).astype(int) % 64 < 32, np.float32(0.15), luminance).astype(np.float32)
    metallic = np.where(np.floor(w * 64).astype(int) % 64 < 32, 0.0, 1.0).astype(np.float32)
    plan = plan_of(scene, plane)
    np.testing.assert_allclose(plan.items[0][1].inputs["roughness"], roughness, rtol=1e-6)
    np.testing.assert_array_equal(plan.items[0][1].inputs["metallic"], metallic)
    p, n = world_arrays(plane, corner=False)
    eye = tuple(scene.camera.matrix_world.translation)
    ior = mat.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value
    want = core_shader(wenv.load_environment(hdri_path("sunset")),
                       wenv.Principled(base_color=(0.6, 0.15, 0.08), roughness=0.4, ior=ior)).shade_mesh(
        p, n, eye, base_color=np.tile(np.float32([0.6, 0.15, 0.08]), (len(p), 1)), roughness=roughness,
        metallic=metallic)
    np.testing.assert_allclose(attribute(plane)[1], want, rtol=1e-4, atol=1e-5)
    plane.active_material = mat
    key, note = gloss.reading_key(mat)
    assert note == ("Base Color: the mean of 'flat paint'; Metallic: the mean of 'metal halves'; "
                    "Roughness: the mean of 'rough halves'")
    assert dict(key[1])["roughness"] == pytest.approx((0.15 + luminance) / 2, rel=1e-5)
    assert dict(key[1])["metallic"] == pytest.approx(0.5)


def corner_uv_rows(plane):
    """Each vertex's UV (the grid's vertices have one each)."""
    uv = np.empty(len(plane.data.loops) * 2, np.float32)
    plane.data.uv_layers.active.uv.foreach_get("vector", uv)
    per_vertex = np.zeros((len(plane.data.vertices), 2), np.float32)
    per_vertex[[l.vertex_index for l in plane.data.loops]] = uv.reshape(-1, 2)
    return per_vertex


def test_nodes_between_textures_and_sockets_are_evaluated(scene):
    """Base Color = Mix (Multiply, factor 0.5) of a two-halves texture, read through a Mapping node that
    scales its UVs by 2, and an RGB node; Roughness = a ColorRamp (linear, 0.1 to 0.7) of a gradient
    texture's luminance; Metallic = a Math node (x 0.5) of a flat texture: each vertex gets the values
    Cycles' nodes give, the core shades them, the report names none, and the glossmeter reads the
    textures' means through the nodes."""
    from addon import gloss
    env_world(scene, "sunset")
    px = np.ones((64, 64, 4), np.float32)
    px[:, :32, :3] = (0.9, 0.2, 0.1)
    px[:, 32:, :3] = (0.2, 0.6, 0.9)
    halves = bpy.data.images.new("halves", 64, 64, float_buffer=True)
    halves.pixels.foreach_set(px.ravel())
    plane, mat = textured_plane(halves, interpolation="Closest")
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (2.0, 2.0, 1.0)
    coords = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(coords.outputs["UV"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], tree.nodes["Image Texture"].inputs["Vector"])
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.blend_type = "MULTIPLY"
    mix.inputs["Factor"].default_value = 0.5
    rgb = tree.nodes.new("ShaderNodeRGB")
    rgb.outputs[0].default_value = (0.5, 1.0, 1.0, 1.0)
    tree.links.new(tree.nodes["Image Texture"].outputs["Color"], next(s for s in mix.inputs if s.identifier == "A_Color"))
    tree.links.new(rgb.outputs[0], next(s for s in mix.inputs if s.identifier == "B_Color"))
    tree.links.new(next(s for s in mix.outputs if s.identifier == "Result_Color"), bsdf.inputs["Base Color"])
    ramp_px = np.ones((4, 64, 4), np.float32)
    ramp_px[..., :3] = (np.arange(64)[None, :, None] + 0.5) / 64
    gradient = value_image("gradient", ramp_px)
    ramp_tex = value_texture(mat, "Roughness", gradient)
    ramp = tree.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.1, 0.1, 0.1, 1.0)
    ramp.color_ramp.elements[1].color = (0.7, 0.7, 0.7, 1.0)
    tree.links.new(ramp_tex.outputs["Color"], ramp.inputs["Fac"])
    tree.links.new(ramp.outputs["Color"], bsdf.inputs["Roughness"])
    metal_tex = value_texture(mat, "Metallic", value_image("flat metal", np.full((4, 4, 4), 0.6, np.float32)))
    math_node = tree.nodes.new("ShaderNodeMath")
    math_node.operation = "MULTIPLY"
    math_node.inputs[1].default_value = 0.5
    tree.links.new(metal_tex.outputs["Color"], math_node.inputs[0])
    tree.links.new(math_node.outputs[0], bsdf.inputs["Metallic"])
    assert not any(s in note for note in materials.principled_notes(mat)
                   for s in ("Base Color", "Roughness", "Metallic")), materials.principled_notes(mat)
    uv = corner_uv_rows(plane)
    texel = np.floor(uv * 2.0 * 64).astype(int) % 64  # Closest, repeated past 1
    colour = np.where((texel[:, 0] < 32)[:, None], [0.9, 0.2, 0.1], [0.2, 0.6, 0.9]) * [0.75, 1.0, 1.0]
    plan = plan_of(scene, plane)
    got = plan.items[0][1].inputs
    np.testing.assert_allclose(got["base_color"], colour, rtol=1e-5)
    assert got["metallic"] == pytest.approx(np.full(len(uv), 0.3), rel=1e-5)
    # the gradient is read linearly at each vertex (mip-filtered over its share): the ramp maps it
    # onto 0.1 .. 0.7
    gradient_at = got["roughness"]
    assert np.all((gradient_at >= 0.1 - 1e-6) & (gradient_at <= 0.7 + 1e-6)) and np.ptp(gradient_at) > 0.4
    assert shade_op(view="CAMERA") == {"FINISHED"}
    p, n = world_arrays(plane, corner=False)
    eye = tuple(scene.camera.matrix_world.translation)
    ior = bsdf.inputs["IOR"].default_value
    want = core_shader(wenv.load_environment(hdri_path("sunset")),
                       wenv.Principled(base_color=(0.8, 0.2, 0.1), roughness=0.4, ior=ior)).shade_mesh(
        p, n, eye, base_color=got["base_color"], roughness=got["roughness"], metallic=got["metallic"])
    np.testing.assert_allclose(attribute(plane)[1], want, rtol=1e-4, atol=1e-5)
    key, note = gloss.reading_key(mat)
    assert note == ("Base Color: the mean of 'halves'; Metallic: the mean of 'flat metal'; "
                    "Roughness: the mean of 'gradient'")
    inputs = dict(key[1])
    assert inputs["metallic"] == pytest.approx(0.3, rel=1e-5)
    assert inputs["roughness"] == pytest.approx(0.4, abs=0.01)  # the ramp at the gradient's mean, 0.5
    assert inputs["base_color"] == pytest.approx((0.55 * 0.75, 0.4, 0.5), rel=1e-4)


def test_hue_saturation_converts_as_colorsys_does():
    """The Hue/Saturation/Value node's conversions against Python's colorsys (the same HSV model as
    Cycles' rgb_to_hsv and hsv_to_rgb), over random colours and the greys."""
    import colorsys
    rgb = np.vstack([np.random.default_rng(4).uniform(0.0, 1.0, (200, 3)), [[0.3, 0.3, 0.3], [0.0, 0.0, 0.0]]])
    h, s, v = nodes._rgb_to_hsv(rgb)
    want = np.array([colorsys.rgb_to_hsv(*c) for c in rgb])
    np.testing.assert_allclose(np.stack([h, s, v], 1), want, atol=1e-12)
    np.testing.assert_allclose(nodes._hsv_to_rgb(h, s, v), rgb, atol=1e-12)


def test_a_node_wenv_does_not_evaluate_is_named_and_the_value_used(scene):
    """A Sky Texture into Roughness, or a loop of links: the report names it, the socket's
    unlinked value is used, and the pass goes on."""
    env_world(scene, "sunset")
    plane, mat = textured_plane(bpy.data.images.new("flat", 4, 4, float_buffer=True))
    tree = mat.node_tree
    sky = tree.nodes.new("ShaderNodeTexSky")
    tree.links.new(sky.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Roughness"])
    notes = materials.principled_notes(mat)
    assert any("'Roughness' is linked ('Sky Texture', a node wenv does not evaluate yet): its unlinked value "
               "0.4 is used" in n for n in notes), notes
    assert "roughness" not in plan_of(scene, plane).items[0][1].inputs
    a, b = tree.nodes.new("ShaderNodeMath"), tree.nodes.new("ShaderNodeMath")
    tree.links.new(a.outputs[0], b.inputs[0])
    tree.links.new(b.outputs[0], a.inputs[0])
    tree.links.new(a.outputs[0], tree.nodes["Principled BSDF"].inputs["Metallic"])
    notes = materials.principled_notes(mat)
    # (Blender marks the links of a loop invalid; a loop it would not is wenv's "nodes in a cycle")
    assert any(n.startswith("'Metallic' is linked (a muted or invalid link)") for n in notes), notes
    assert shade_op(view="CAMERA") == {"FINISHED"}


def test_every_input_the_core_takes_per_vertex_is_read_from_textures(scene):
    """Specular IOR Level, Specular Tint, Coat Weight and Roughness, Sheen Weight, Roughness and Tint
    and Alpha, each from an image of two halves: the add-on gives each vertex its texel's value and
    its colours are the core's shading with them; Alpha's see-through part is named; the glossmeter
    reads each texture's mean."""
    from addon import gloss
    env_world(scene, "sunset")
    flat = bpy.data.images.new("flat paint", 4, 4, float_buffer=True)
    flat.pixels.foreach_set(np.tile(np.float32([0.6, 0.15, 0.08, 1.0]), 16))
    plane, mat = textured_plane(flat)
    mat.node_tree.nodes["Image Texture"].interpolation = "Closest"
    halves = {"Specular IOR Level": (0.2, 0.9), "Specular Tint": ((1.0, 0.5, 0.3), (0.4, 1.0, 1.0)),
              "Coat Weight": (0.0, 1.0), "Coat Roughness": (0.05, 0.4), "Sheen Weight": (0.0, 0.8),
              "Sheen Roughness": (0.2, 0.7), "Sheen Tint": ((1.0, 0.6, 0.2), (0.3, 0.3, 1.0)), "Alpha": (0.3, 1.0)}
    for k, (socket, (a, b)) in enumerate(halves.items()):
        px = np.ones((64, 64, 4), np.float32)
        px[:, :32, :3] = a
        px[:, 32:, :3] = b
        value_texture(mat, socket, value_image(f"halves {k}", px))
    assert shade_op(view="CAMERA") == {"FINISHED"}
    notes = materials.principled_notes(mat)
    assert not any("is linked" in note for note in notes), notes
    assert any("see-through part is not shaded" in note for note in notes), notes
    uv = np.empty(len(plane.data.loops) * 2, np.float32)
    plane.data.uv_layers.active.uv.foreach_get("vector", uv)
    u = np.zeros(len(plane.data.vertices), np.float32)
    u[[l.vertex_index for l in plane.data.loops]] = uv[0::2]
    left = np.floor(u * 64).astype(int) % 64 < 32
    plan = plan_of(scene, plane)
    inputs = plan.items[0][1].inputs
    want_inputs = {}
    for socket, (a, b) in halves.items():
        keyword = socket.lower().replace(" ", "_")
        a, b = np.float32(a), np.float32(b)
        want_inputs[keyword] = np.where(left[:, None] if a.ndim else left, a, b).astype(np.float32)
        np.testing.assert_allclose(inputs[keyword], want_inputs[keyword], rtol=1e-6, err_msg=socket)
    p, n = world_arrays(plane, corner=False)
    eye = tuple(scene.camera.matrix_world.translation)
    ior = mat.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value
    want = core_shader(wenv.load_environment(hdri_path("sunset")),
                       wenv.Principled(base_color=(0.6, 0.15, 0.08), roughness=0.4, ior=ior)).shade_mesh(
        p, n, eye, base_color=np.tile(np.float32([0.6, 0.15, 0.08]), (len(p), 1)), **want_inputs)
    np.testing.assert_allclose(attribute(plane)[1], want, rtol=1e-4, atol=1e-5)
    key, said = gloss.reading_key(mat)
    read = dict(key[1])
    assert read["coat_weight"] == pytest.approx(0.5) and read["specular_tint"] == pytest.approx((0.7, 0.75, 0.65))
    assert "Sheen Roughness: the mean of 'halves 5'" in said


def test_more_smooth_inputs_than_a_vertex_mixes_are_read_at_their_mean(scene):
    """Roughness, Specular IOR Level, Coat Weight and Sheen Tint (three channels) all ramping across the
    image: more channels vary smoothly than the core mixes at once, so the last of them are read at
    their mean over the slot, each named, and the pass shades."""
    env_world(scene, "sunset")
    flat = bpy.data.images.new("flat paint", 4, 4, float_buffer=True)
    flat.pixels.foreach_set(np.tile(np.float32([0.6, 0.15, 0.08, 1.0]), 16))
    plane, mat = textured_plane(flat)
    ramp = np.linspace(0.1, 0.9, 64, dtype=np.float32)
    for k, socket in enumerate(("Roughness", "Specular IOR Level", "Coat Weight", "Sheen Tint")):
        px = np.ones((64, 64, 4), np.float32)
        px[..., :3] = (ramp[None, :, None] if k % 2 == 0 else ramp[:, None, None]) * np.float32([1.0, 0.8, 0.6])
        value_texture(mat, socket, value_image(f"ramp {k}", px)).interpolation = "Linear"
    mat.node_tree.nodes["Principled BSDF"].inputs["Sheen Weight"].default_value = 0.5
    plan = plan_of(scene, plane)
    inputs = plan.items[0][1].inputs
    assert np.ptp(inputs["sheen_tint"], axis=0).max() == 0.0  # read at its mean
    assert np.ptp(inputs["roughness"]) > 0.3 and np.ptp(inputs["specular_ior_level"]) > 0.3
    assert any("'Sheen Tint' ('textured paint') is read at its mean" in note for note in plan.notes), plan.notes
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert np.isfinite(attribute(plane)[1]).all()


def test_a_peer_method_names_the_roughness_texture_it_does_not_read(scene):
    """Auto may shade with a peer method, which takes no roughness per vertex: the report says the
    texture is shaded at its unlinked value, and the pass does not fail."""
    from addon import shading
    env_world(scene, "sunset")
    flat = bpy.data.images.new("flat paint", 4, 4, float_buffer=True)
    plane, mat = textured_plane(flat)
    value_texture(mat, "Roughness", value_image("rough", np.full((4, 4, 4), 0.5, np.float32)))
    plan = plan_of(scene, plane)

    class Peer:
        method = "split_sum"

    part = plan.items[0][1]
    taken = plan._takes(Peer(), plane.name, part)
    assert "roughness" not in taken.inputs and "base_color" in taken.inputs
    assert any("textured Roughness shaded at the unlinked value by split_sum" in n for n in plan.notes)
    assert shading.ShadingPlan._takes(plan, type("Wavelet", (), {"method": "slicing"})(), plane.name, part) is part


def test_a_texture_change_reshades_without_remaking_the_material(scene, monkeypatch):
    """New pixels in a Base Color's image: the next pass shades the new colours (the core's shading
    with them) and sets no material anew: the shader keeps the one it holds."""
    env_world(scene, "sunset")
    image = bpy.data.images.new("paint", 4, 4, float_buffer=True)
    image.pixels.foreach_set(np.tile(np.float32([0.2, 0.5, 0.7, 1.0]), 16))
    plane, mat = textured_plane(image)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    calls = []

    class Counting:  # the shader, its set_material counted
        def __init__(self, shader):
            self.shader = shader

        def set_material(self, material):
            calls.append(material)
            return self.shader.set_material(material)

        def __getattr__(self, name):
            return getattr(self.shader, name)

    monkeypatch.setitem(engine.shaders._shaders, "draft", Counting(engine.shaders.get("draft")))
    image.pixels.foreach_set(np.tile(np.float32([0.7, 0.3, 0.1, 1.0]), 16))
    assert shade_op(view="CAMERA") == {"FINISHED"} and calls == []
    p, n = world_arrays(plane, corner=False)
    ior = mat.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value
    want = core_shader(wenv.load_environment(hdri_path("sunset")),
                       wenv.Principled(base_color=(0.7, 0.3, 0.1), roughness=0.4, ior=ior)).shade_mesh(
        p, n, tuple(scene.camera.matrix_world.translation))
    np.testing.assert_allclose(attribute(plane)[1], want, rtol=1e-4, atol=1e-5)


def test_texture_sampling_wraps_as_the_node_extends():
    """Repeat, extend, clip and mirror past the image's edge, as Cycles' Image Texture does."""
    from addon import textures
    image = np.float32([[[0.0] * 3, [1.0] * 3]])  # 1 row, 2 texels: black, white
    levels = textures._pyramid(image)
    uv = np.float32([[1.3, 0.5], [-0.2, 0.5]])  # 1.3: the second copy's first texel; -0.2: left of 0
    got = {ext: textures.sample(levels, uv, np.ones(2, np.float32), "Closest", ext)[:, 0]
           for ext in textures.EXTENSIONS}
    assert got["REPEAT"].tolist() == [0.0, 1.0] and got["EXTEND"].tolist() == [1.0, 0.0]
    assert got["CLIP"].tolist() == [0.0, 0.0] and got["MIRROR"].tolist() == [1.0, 0.0]
    # linear: half way between the texel centres is their mean
    mid = textures.sample(levels, np.float32([[0.5, 0.5]]), np.ones(1, np.float32), "Linear", "EXTEND")
    assert mid[0, 0] == pytest.approx(0.5)


def test_what_wenv_does_not_shade_is_reported(scene):
    """Linked inputs (a texture: its unlinked value is used; a normal map: not used), inputs wenv does
    not shade, a node tree with more than the Principled BSDF and an emitting mesh's light linking are named in
    the shading report and in the Material panel, never dropped silently."""
    from addon import ui
    env_world(scene, "sunset")
    obj = add_monkey()
    select_only(obj)
    mat = principled_material("textured", roughness=0.3)
    obj.data.materials.append(mat)
    obj.active_material = mat
    tree = mat.node_tree
    node = tree.nodes["Principled BSDF"]
    tex = tree.nodes.new("ShaderNodeTexSky")
    tree.links.new(tex.outputs["Color"], node.inputs["Base Color"])
    bump = tree.nodes.new("ShaderNodeBump")
    tree.links.new(tex.outputs["Color"], bump.inputs["Height"])
    tree.links.new(bump.outputs["Normal"], node.inputs["Normal"])
    node.inputs["Transmission Weight"].default_value = 0.5
    node.inputs["Emission Strength"].default_value = 2.0
    notes = materials.principled_notes(mat)
    assert any("'Base Color' is linked" in n and "(0.8, 0.2, 0.1)" in n for n in notes), notes
    assert any("'Normal' is linked" in n for n in notes) and any("Transmission" in n for n in notes)
    assert not any("Emission" in n for n in notes)  # emission is shaded
    from addon import shading, views
    receivers = bpy.data.collections.new("lit-only")
    obj.light_linking.receiver_collection = receivers  # an emitting mesh's
    view = views.camera_view(bpy.context.scene)
    _, report = shading.shade_objects(bpy.context.scene, bpy.context.evaluated_depsgraph_get(), [obj], view,
                                      bpy.data)
    assert any(f"'{obj.name}': an emitting mesh's light linking is not honoured" in n for n in report), report
    assert all(f"'textured': {n}" in report for n in notes), report
    panel = [l[1] for l in draw_panel(ui.WENV_PT_material) if l[0] == "label"]
    assert all(n in panel for n in notes)
    assert ("prop", "default_value") in draw_panel(ui.WENV_PT_material)  # the node's own inputs, editable there


def test_gloss_readings_follow_settings(scene):
    cube = bpy.data.objects["Cube"]
    mat = set_material(cube, diffuse=(0.3, 0.3, 0.3), lobes=((0.05, 1.5, "BECKMANN"),))
    want = wenv.gloss(wenv_material(mat), (20, 60, 85))
    assert (mat.wenv.gloss_20, mat.wenv.gloss_60, mat.wenv.gloss_85) == pytest.approx(want, abs=1e-3)
    before = mat.wenv.gloss_60
    mat.wenv.lobes[0].alpha = 0.2
    assert mat.wenv.gloss_60 < before - 5
    assert mat.wenv.gloss_60 == pytest.approx(wenv.gloss(wenv_material(mat), 60), abs=1e-3)
    assert gloss.instrument_geometry(mat.wenv.gloss_60) == (60 if 10 <= mat.wenv.gloss_60 <= 70 else
                                                          20 if mat.wenv.gloss_60 > 70 else 85)
    assert [gloss.instrument_geometry(g) for g in (95, 70, 40, 10, 3)] == [20, 60, 60, 60, 85]


def test_fit_roughness_operator(scene):
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    mat = set_material(cube, diffuse=(0.2, 0.2, 0.2), lobes=((0.3, 1.5, "GGX"),))
    cube.active_material = mat
    mat.wenv.target_gloss = 50.0
    mat.wenv.target_geometry = "60"
    assert bpy.ops.wenv.fit_roughness() == {"FINISHED"}
    assert mat.wenv.gloss_60 == pytest.approx(50.0, abs=0.05)
    assert bpy.ops.wenv.fit_roughness(target=80.0, geometry="20") == {"FINISHED"}
    assert mat.wenv.gloss_20 == pytest.approx(80.0, abs=0.05)
    with pytest.raises(RuntimeError, match="out of reach"):
        bpy.ops.wenv.fit_roughness(target=500.0, geometry="60")
    bpy.ops.wenv.lobe_add()
    with pytest.raises(RuntimeError, match="exactly one lobe"):
        bpy.ops.wenv.fit_roughness()
    assert bpy.ops.wenv.lobe_remove() == {"FINISHED"} and len(mat.wenv.lobes) == 1


def test_readme_scripting_block_runs_as_written(scene):
    """The scripting blocks as written -- README.md's quick start, then docs/addon.md's, which sets
    the add-on's own models -- on Suzanne with a Principled material named "paint" under the sunset
    HDRI: every line works and does what its comment says."""
    env_world(scene, "sunset")
    suzanne = add_monkey()
    suzanne.data.materials.append(principled_material("paint", base=(0.6, 0.15, 0.08), roughness=0.3))
    ns = {}
    try:
        exec(compile(readme_block("import bpy\nscene = bpy.context.scene"), "README.md", "exec"), ns)
        assert bpy.context.window_manager.wenv.show_in_viewports
        # the bake: a new 512 x 512 image holding Suzanne's texels, shown in her material
        assert tuple(ns["baked"].size) == (512, 512) and ns["baked"].wenv.texels > 10000
        assert suzanne.active_material.node_tree.nodes["wenv bake"].image == ns["baked"]
    finally:
        bpy.context.window_manager.wenv.show_in_viewports = False
    exec(compile(readme_block('import bpy\nmat = bpy.data.materials["paint"]'), "docs/addon.md", "exec"), {})
    mat = bpy.data.materials["paint"]
    # fit_roughness set the node's Roughness so that the node reads 60 GU at 60 degrees
    node = mat.node_tree.nodes["Principled BSDF"]
    fitted = wenv.Principled(base_color=(0.6, 0.15, 0.08), roughness=node.inputs["Roughness"].default_value,
                             ior=node.inputs["IOR"].default_value)
    assert wenv.gloss(fitted, 60) == pytest.approx(60.0, abs=0.05)
    # the shade wrote the colour attribute the block reads (per vertex on a smooth mesh), lit
    colors = ns["colors"]
    rgba = np.empty(len(colors.data) * 4, np.float32)
    colors.data.foreach_get("color", rgba)
    assert (colors.domain, len(colors.data)) == ("POINT", len(suzanne.data.vertices))
    assert np.isfinite(rgba).all() and rgba.max() > 0.0
    # from_principled made the add-on's lobes, then the block set a lobe and the measured model
    assert mat.wenv.lobes[0].roughness == pytest.approx(0.2)
    assert (mat.wenv.model, mat.wenv.brdf_path) == ("MEASURED", "//brdfs/gold-metallic-paint.binary")


# ---------------------------------------------------------------------------------------------
# Measured BRDFs (MERL files)


def measured_material(obj, path):
    """A material of model Measured reading `path` (as the user would type it, // relative to the
    .blend), appended to obj's slots."""
    mat = node_material(bpy, f"Measured{len(bpy.data.materials)}")
    mat.wenv.model = "MEASURED"
    mat.wenv.brdf_path = path
    obj.data.materials.append(mat)
    return mat


def write_paint_brdf(path):
    """A small MERL file: a Cook-Torrance lobe (m = 0.2) over a coloured diffuse floor."""
    from tests.helpers import merl_files as M
    return M.write_merl(path, M.table_of({"brdf": "cook_torrance", "roughness": 0.2, "diffuse": [0.4, 0.2, 0.1]},
                                         (16, 16, 32)))


def test_measured_brdf_file_relative_to_the_blend(scene, tmp_path):
    """A material reading a MERL file by a path relative to the saved .blend shades as the core does
    with wenv.load_brdf of that file, reads its gloss and haze, and is set up by choosing it (the
    first shading does not replace it with the Principled BSDF's values)."""
    (tmp_path / "brdfs").mkdir()
    path = write_paint_brdf(tmp_path / "brdfs" / "paint.binary")
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    env_world(bpy.context.scene, "sunset")
    obj = add_monkey()
    mat = measured_material(obj, "//brdfs/paint.binary")
    assert mat.wenv.initialized
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert mat.wenv.model == "MEASURED"
    _, rgb = attribute(obj)
    table = wenv.load_brdf(str(path))
    p, n = world_arrays(obj, corner=False)
    env = wenv.load_environment(hdri_path("sunset"))
    want = core_shader(env, table).shade_mesh(p, n, tuple(bpy.context.scene.camera.matrix_world.translation))
    assert rgb.max() > 0.05
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)
    g = wenv.gloss(table, (20, 60, 85))
    assert (mat.wenv.gloss_20, mat.wenv.gloss_60, mat.wenv.gloss_85) == pytest.approx(g, abs=1e-3)
    assert mat.wenv.haze == pytest.approx(wenv.haze(table), abs=1e-3) and mat.wenv.haze > 0
    # the table is read once per version of the file and shared
    key = materials.material_key(mat.wenv)
    assert engine.material_from_key(key) is engine.material_from_key(key)


def test_measured_brdf_panels(scene, tmp_path):
    from addon import ui
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    path = write_paint_brdf(tmp_path / "paint.binary")
    mat = measured_material(cube, str(path))
    cube.active_material = mat
    log = draw_panel(ui.WENV_PT_material)
    assert ("prop", "brdf_path") in log and ("prop", "diffuse") not in log
    assert any(l[0] == "label" and l[1].startswith("Table 16 x 16 x 32") for l in log)
    gloss_panel = draw_panel(ui.WENV_PT_gloss)
    labels = [l[1] for l in gloss_panel if l[0] == "label"]
    assert f"{mat.wenv.haze:.2f} HU" in labels and f"{mat.wenv.gloss_60:.2f} GU" in labels
    assert ("operator", "wenv.fit_roughness") not in gloss_panel  # a measurement has no roughness to set


def test_missing_measured_brdf_file_is_named(scene, tmp_path):
    """A missing or broken file cancels shading with a message naming it, and the panels say so; the
    file appearing later is read (the key follows the file)."""
    from addon import ui
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    mat = measured_material(cube, "//gone.binary")
    cube.active_material = mat
    with pytest.raises(RuntimeError, match=r"Material '.*': Measured BRDF file '//gone.binary' not found"):
        shade_op(view="CAMERA")
    assert ATTR not in cube.data.color_attributes
    assert math.isnan(mat.wenv.gloss_60)
    errors = [l for l in draw_panel(ui.WENV_PT_material) if l[0] == "label" and l[2] == "ERROR"]
    assert errors and "gone.binary" in errors[0][1] and str(tmp_path) in errors[0][1]
    (tmp_path / "gone.binary").write_bytes(b"not a MERL table")
    with pytest.raises(RuntimeError, match="'//gone.binary' could not be read"):
        shade_op(view="CAMERA")
    write_paint_brdf(tmp_path / "gone.binary")
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert mat.wenv.gloss_60 > 0


# ---------------------------------------------------------------------------------------------
# Live mode, frame changes, precomputation


def settled(session):
    """What the modal timer does over a few ticks: start the worker, then write its result.
    (whether the first tick started nothing, whether the last wrote colours)"""
    started = session.tick(bpy.context)
    session.wait(60)
    return (started, session.tick(bpy.context))


def test_live_session_reshades_on_changes_only(scene):
    env_world(scene, "sunset")
    obj = add_monkey()
    mat = set_material(obj)
    scene.wenv.view_source = "CAMERA"
    session = live.LiveSession([obj.name])

    def settle():
        return settled(session)

    assert settle() == (False, True) and ATTR in obj.data.color_attributes
    assert settle() == (False, False)  # nothing changed: no work
    first = attribute(obj)[1].copy()

    def changed(step):
        nonlocal first
        step()
        shaded = settle() == (False, True)
        now = attribute(obj)[1].copy()
        moved = not np.allclose(now, first)
        first = now
        return (shaded, moved) == (True, True)

    assert changed(lambda: setattr(obj, "location", (0.3, 0.0, 0.0)))
    assert changed(lambda: setattr(mat.wenv.lobes[0], "alpha", 0.5))
    mapping_env = scene.world.node_tree.nodes["Background"].inputs["Strength"]
    assert changed(lambda: setattr(mapping_env, "default_value", 3.0))
    assert changed(lambda: setattr(scene.camera, "location", (5.0, -5.0, 3.0)))
    assert settle() == (False, False)
    assert session.shades == 5
    # A broken World is recorded, not raised; the session keeps going once it is fixed.
    env_node = scene.world.node_tree.nodes["Environment Texture"]
    image, env_node.image = env_node.image, None
    assert settle() == (False, False) and "has no image" in session.last_error
    env_node.image = image
    assert settle() == (False, True), session.last_error
    assert session.last_error is None


def test_camera_and_window_coordinates_follow_the_camera(scene):
    """Base Color from a Texture Coordinate's Window (or its Camera, moved into the positive by a
    Vector Math) on Suzanne seen by the start-up scene's perspective camera: each vertex reads its
    place in the camera's frame as Blender's own world_to_camera_view gives it (Cycles' orthographic
    pixels: tests/test_attributes.py), or its place in the camera's space, depth along +Z.  A turn of
    the camera that leaves its eye where it was reshades such a material in live mode and makes its
    bake stale; a material that does not read the camera is neither."""
    from bpy_extras.object_utils import world_to_camera_view

    env_world(scene, "sunset")
    obj = add_monkey(subdivisions=1)
    mat = principled_material("framed")
    obj.data.materials.append(mat)
    select_only(obj)
    tree = mat.node_tree
    coords, add = tree.nodes.new("ShaderNodeTexCoord"), tree.nodes.new("ShaderNodeVectorMath")
    add.inputs[1].default_value = (10.0, 10.0, 0.0)
    tree.links.new(coords.outputs["Window"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    bpy.context.view_layer.update()
    cam = scene.camera
    data = plan_of(scene, obj).items[0][1]
    assert data.reads_camera
    want = np.array([world_to_camera_view(scene, cam, mathutils.Vector(p)) for p in data.positions.astype(float)])
    want[:, 2] = 0.0
    assert 0.0 < want[:, :2].min() and want[:, :2].max() < 1.0 and np.ptp(want[:, 0]) > 0.1
    np.testing.assert_allclose(data.inputs["base_color"], want, atol=2e-5)
    tree.links.new(coords.outputs["Camera"], add.inputs[0])
    tree.links.new(add.outputs[0], tree.nodes["Principled BSDF"].inputs["Base Color"])
    data = plan_of(scene, obj).items[0][1]
    local = np.array([cam.matrix_world.normalized().inverted() @ mathutils.Vector(p)
                      for p in data.positions.astype(float)])
    np.testing.assert_allclose(data.inputs["base_color"], local * (1.0, 1.0, -1.0) + (10.0, 10.0, 0.0), atol=1e-4)

    scene.wenv.view_source = "CAMERA"
    session = live.LiveSession([obj.name])

    def settle():
        return settled(session)

    def turn():
        cam.rotation_euler.z += 0.05
        return settle() == (False, True)
    assert settle() == (False, True)
    settle()  # (the first pass learnt that the material reads the camera)
    assert turn()
    image = bpy.data.images.new("framed bake", 8, 8)
    scene.wenv.bake_image = image
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.wenv.bake(view="CAMERA") == {"FINISHED"} and bake.staleness(image, scene) is None
    cam.rotation_euler.z += 0.05
    bpy.context.view_layer.update()
    assert bake.staleness(image, scene) == "the camera moved"
    tree.links.new(tree.nodes.new("ShaderNodeRGB").outputs[0], tree.nodes["Principled BSDF"].inputs["Base Color"])
    assert settle() == (False, True)
    settle()
    assert not turn()
    assert bpy.ops.wenv.bake(view="CAMERA") == {"FINISHED"}
    cam.rotation_euler.z += 0.05
    bpy.context.view_layer.update()
    assert bake.staleness(image, scene) is None


def test_live_session_reshades_when_what_shadows_it_changes(scene):
    """With Shadows, live mode shades the plane again when the cube above it moves, its mesh is
    edited, an instance of it is placed or its material changes (the light it sends back), and not
    for its own colours; with Shadows off, another object's move changes nothing it shades."""
    env_world(scene, "sunset")
    plane = add_plane_under_cube()
    scene.wenv.shadows, scene.wenv.view_source = True, "CAMERA"
    session = live.LiveSession([plane.name])
    live.LiveState.session = session  # (the depsgraph handler tells the registered session)

    def settle():
        return settled(session)
    try:
        assert settle() == (False, True)
        assert settle() == (False, False)  # (its own colours, written, are no change)
        cube = bpy.data.objects["Cube"]
        before = attribute(plane)[1].copy()
        for change in (lambda: setattr(cube, "location", (0.5, 0.5, 0.0)),
                       lambda: (cube.data.vertices[0].co.__setitem__(2, 2.0), cube.data.update()),
                       lambda: scene.collection.objects.link(bpy.data.objects.new("copy", cube.data)),
                       lambda: setattr(cube.active_material.node_tree.nodes["Principled BSDF"].inputs["Base Color"],
                                       "default_value", (0.9, 0.1, 0.1, 1.0))):
            change()
            bpy.context.view_layer.update()
            assert settle() == (False, True)
            assert not np.array_equal(attribute(plane)[1], before)
            before = attribute(plane)[1].copy()
        scene.wenv.shadows = False
        assert settle() == (False, True)
        cube.location = (-0.5, 0.0, 0.0)
        bpy.context.view_layer.update()
        assert settle() == (False, False)
    finally:
        live.LiveState.session = None


def test_live_session_refines_at_rest_and_drops_it_on_a_change(scene):
    """At Draft, live mode writes Draft's colours at once, then, while nothing changes, High's
    (the core's result at high for the same arrays); a change shows Draft again at once and drops
    the refinement under way; the panel says which it shows."""
    from addon import engine, ui
    env_world(scene, "forest")
    obj = add_monkey(subdivisions=1)
    mat = set_material(obj, lobes=((0.1, 1.5, "BECKMANN"),))
    scene.wenv.view_source = "CAMERA"
    scene.wenv.refine_at_rest = True
    session = live.LiveSession([obj.name])
    live.LiveState.session = session  # what the panel reads
    ctx = bpy.context
    p, n = world_arrays(obj, corner=False)
    core_env, core_mat = wenv.load_environment(hdri_path("forest")), wenv_material(mat)

    def core(quality):
        eye = tuple(scene.camera.matrix_world.translation)
        return wenv.Shader(core_env, core_mat, quality=quality).shade_mesh(p, n, eye)

    assert session.tick(ctx) is False  # the Draft pass starts on a worker
    session._worker.join(60)
    assert session.tick(ctx) is True  # Draft written; the refinement starts
    assert session.refine_status[0] == "REFINING" and not session.refined
    np.testing.assert_allclose(attribute(obj)[1], core("draft"), rtol=1e-4, atol=1e-5)
    labels = [l[1] for l in draw_panel(ui.WENV_PT_shading) if l[0] == "label"]
    assert any(t.startswith("Draft shown, refining to High") for t in labels), labels
    session.wait(300)
    assert session.tick(ctx) is True and session.refined and session.refine_status == ("REFINED",)
    high = core("high")
    np.testing.assert_allclose(attribute(obj)[1], high, rtol=1e-4, atol=1e-5)
    assert not np.allclose(high, core("draft"), rtol=1e-2)
    assert session.tick(ctx) is False  # nothing changed, nothing more to refine
    labels = [l[1] for l in draw_panel(ui.WENV_PT_shading) if l[0] == "label"]
    assert any(t.startswith("Refined to High") for t in labels), labels

    # a change: Draft at once, the refinement dropped and started again from the new pass
    scene.camera.location = (6.0, -6.0, 2.0)
    assert session.tick(ctx) is False and session.refine_status is None and not session.refined
    session._worker.join(60)
    assert session.tick(ctx) is True and session.refine_status[0] == "REFINING"
    np.testing.assert_allclose(attribute(obj)[1], core("draft"), rtol=1e-4, atol=1e-5)
    # a change while refining cancels it: its result is never written
    job = session._refine
    scene.camera.location = (6.0, -5.0, 2.5)
    assert session.tick(ctx) is False and job._cancel.is_set()
    session.wait(300)
    job.wait(300)  # dropped by the session at the change, it ends at its next progress report
    assert job.done and session.tick(ctx) is True  # the new Draft pass
    np.testing.assert_allclose(attribute(obj)[1], core("draft"), rtol=1e-4, atol=1e-5)
    # off: no refinement
    session.stop()
    scene.wenv.refine_at_rest = False
    assert session.tick(ctx) is False and session.refine_status is None  # the setting is part of the signature
    session.wait(60)
    assert session.tick(ctx) is True and session.refine_status is None
    assert engine.REFINE_QUALITY == "high"
    live.LiveState.reset()


def test_live_session_shows_draft_while_the_setting_remakes_its_slices(scene):
    """At Default, a change that makes Default remake its slices -- the first pass, a new World
    image, a material edit -- shows Draft at once, then Default's own colours once made; a view
    change or a World rotation shows Default at once.  A change while Default's BRDF slices are
    being made cancels them, and the shader is whole afterwards.  Off, Default is shown at once."""
    from addon import engine, ui
    forest = env_world(scene, "forest").image
    obj = add_monkey(subdivisions=1)
    mat = set_material(obj, lobes=((0.3, 1.5, "GGX"),))
    scene.wenv.quality = "DEFAULT"
    scene.wenv.view_source = "CAMERA"
    session = live.LiveSession([obj.name])
    live.LiveState.session = session  # what the panel reads
    engine.shaders.get(engine.PREVIEW_QUALITY)  # the live operator builds it on a worker
    ctx = bpy.context
    p, n = world_arrays(obj, corner=False)

    def core(quality, hdri="forest", rotation=0.0):
        env = wenv.load_environment(hdri_path(hdri)).with_transform(rotation=rotation)
        eye = tuple(scene.camera.matrix_world.translation)
        return wenv.Shader(env, wenv_material(mat), quality=quality).shade_mesh(p, n, eye)

    def shows(quality, **world):
        np.testing.assert_allclose(attribute(obj)[1], core(quality, **world), rtol=1e-4, atol=1e-5)
        return True

    def pass_written():
        assert session.tick(ctx) is False
        session._worker.join(60)
        return session.tick(ctx) is True

    def previewed(**world):
        """Draft written at once, Default being made; then Default written, nothing after it."""
        assert pass_written() and session.shown == "draft" and shows("draft", **world)
        status = session.refine_status
        assert status[0] == "REFINING" and status[2:] == ("draft", "default"), status
        labels = [l[1] for l in draw_panel(ui.WENV_PT_shading) if l[0] == "label"]
        assert any(t.startswith("Draft shown, refining to Default: ") for t in labels), labels
        session.wait(300)
        assert session.tick(ctx) is True and session.shown == "default" and shows("default", **world)
        assert session.refine_status is None and not session.refined  # Refine at Rest is off
        return session.tick(ctx) is False  # nothing more to make

    def at_once(**world):
        assert pass_written() and session.shown == "default" and session.refine_status is None
        return shows("default", **world)

    assert previewed()  # Default's lighting and BRDF slices are made for the first pass
    scene.camera.location = (6.0, -6.0, 2.0)
    assert at_once()
    mat.wenv.lobes[0].alpha = 0.25  # new BRDF slices
    assert previewed()
    env_world(scene, image=forest, rotation=0.6)  # the same image (its pixels read once), turned
    assert at_once(rotation=0.6)
    env_world(scene, "city", rotation=0.6)  # a new image
    assert previewed(hdri="city", rotation=0.6)
    # a change while Default makes BRDF slices: they stop, and the next change makes them whole
    mat.wenv.lobes[0].alpha = 0.35
    assert pass_written() and session.shown == "draft"
    job = session._refine
    while not job.done and engine.shaders._relays["default"].target is None:
        time.sleep(0.002)  # Default's set_material has begun once its relay listens for the cancel
    scene.camera.location = (6.0, -5.0, 2.5)
    assert session.tick(ctx) is False and job._cancel.is_set()
    session.wait(300)
    assert job.done and job.results is None and job.error is None
    assert session.tick(ctx) is True and session.shown == "draft"
    p, n = world_arrays(obj, corner=False)
    session.wait(300)
    assert session.tick(ctx) is True and shows("default", hdri="city", rotation=0.6)
    # off: Default at once after a material edit
    scene.wenv.preview_changes = False
    mat.wenv.lobes[0].alpha = 0.3
    assert at_once(hdri="city", rotation=0.6)
    # Auto: Draft while its shader is chosen and made, then Auto's colours
    scene.wenv.preview_changes = True
    scene.wenv.quality = "AUTO"
    assert pass_written() and session.shown == "draft" and session.refine_status[2:] == ("draft", "auto")
    session.wait(300)
    assert session.tick(ctx) is True and session.shown == "auto" and session.refine_status is None
    env = wenv.load_environment(hdri_path("city")).with_transform(rotation=0.6)
    want = wenv.Shader(env, wenv_material(mat), quality="auto", target_error=scene.wenv.target_error / 100, normals=n)
    np.testing.assert_allclose(attribute(obj)[1], want.shade_mesh(p, n, tuple(scene.camera.matrix_world.translation)),
                               rtol=1e-4, atol=1e-5)
    live.LiveState.reset()
    # the live operator builds the preview's shader beside the session and installs it on a tick
    scene.wenv.preview_changes = True
    engine.shaders.clear()
    engine.shaders.get("default")
    op = LiveOperator()
    try:
        session = live.LiveState.session = live.LiveSession([obj.name])
        # as invoke starts them: Default's shader is there, so the session waits for nothing
        assert live.LiveState.start_jobs("default", True) is False and live.LiveState.job is None
        job = live.LiveState.preview_job
        assert job is not None and job.quality == engine.PREVIEW_QUALITY
        assert job.wait(120) and job.error is None
        assert op.event("TIMER") == {"PASS_THROUGH"} and live.LiveState.preview_job is None
        assert engine.shaders.has(engine.PREVIEW_QUALITY)
        session.wait(60)
        assert op.event("TIMER") == {"PASS_THROUGH"} and session.shown == "draft"
    finally:
        live.LiveState.reset()
    # at Draft itself there is no preview to build: one job, which the session waits for
    engine.shaders.clear()
    try:
        assert live.LiveState.start_jobs("draft", True) is True and live.LiveState.preview_job is None
        assert live.LiveState.job.quality == "draft" and live.LiveState.job.wait(120)
    finally:
        live.LiveState.reset()


def test_a_pass_sets_each_material_once_and_the_held_one_first(scene, monkeypatch):
    """One shader per quality holds one material at a time and keeps the last few; a pass over
    meshes of two materials sets each once (not once per mesh), starting with the material the
    shader holds, and later passes make neither again (the live mode shows them at once); the
    colours are each mesh's own."""
    env_world(scene, "sunset")
    a, b, c = add_monkey(name="A"), add_monkey(name="B"), add_monkey(name="C")
    b.location = (3.0, 0.0, 0.0)
    c.location = (-3.0, 0.0, 0.0)
    paint = set_material(a, lobes=((0.3, 1.5, "GGX"),))
    b.data.materials.append(set_material(b, model="LAMBERT", diffuse=(0.5, 0.5, 0.5)))
    c.data.materials.append(paint)
    scene.wenv.view_source = "CAMERA"
    class CountingShader:
        def __init__(self, shader):
            self.shader, self.sets = shader, 0

        def set_material(self, mat):
            self.sets += 1
            return self.shader.set_material(mat)

        def __getattr__(self, name):
            return getattr(self.shader, name)

    engine.shaders.clear()
    counted = CountingShader(engine.shaders.get("draft"))
    monkeypatch.setitem(engine.shaders._shaders, "draft", counted)
    dg = bpy.context.evaluated_depsgraph_get()
    objs = [a, b, c]
    keys = {materials.material_key(o.data.materials[0].wenv) for o in objs}
    spec = world.world_spec(scene.world)
    for eye, sets, made in (((7.0, -7.0, 5.0), 2, 2), ((6.0, -7.5, 4.0), 1, 0), ((6.5, -7.0, 4.5), 1, 0)):
        scene.camera.location = eye
        dg.update()
        counted.sets, reused = 0, counted.stats["materials_reused"]
        assert len(shading.shade_objects(scene, dg, objs, views.camera_view(scene), bpy.data)[0]) == 3
        assert counted.sets == sets and counted.sets - (counted.stats["materials_reused"] - reused) == made
        assert engine.shaders.ready("draft", spec, keys, 0.01, 1024)
        env = wenv.load_environment(hdri_path("sunset"))
        for obj in objs:
            p, n = world_arrays(obj, corner=False)
            want = core_shader(env, wenv_material(obj.data.materials[0])).shade_mesh(p, n, eye)
            np.testing.assert_allclose(attribute(obj)[1], want, rtol=1e-4, atol=1e-5)


def test_frame_change_shades_from_animated_camera(scene):
    env_world(scene, "sunrise")
    obj = add_monkey()
    mat = set_material(obj, lobes=((0.1, 1.5, "GGX"),))
    cam = scene.camera
    animate_camera(cam)
    scene.wenv.shade_on_frame_change = True
    scene.frame_set(1)
    assert ATTR not in obj.data.color_attributes  # only objects shaded before follow the camera
    assert shade_op(view="CAMERA") == {"FINISHED"}
    scene.frame_set(10)
    _, rgb = attribute(obj)
    p, n = world_arrays(obj, corner=False)
    want = core_shader(wenv.load_environment(hdri_path("sunrise")), wenv_material(mat)).shade_mesh(
        p, n, tuple(cam.matrix_world.translation))
    assert tuple(cam.matrix_world.translation) == pytest.approx((-7.0, -7.0, 2.0))
    np.testing.assert_allclose(rgb, want, rtol=1e-4, atol=1e-5)


def test_frame_changes_during_a_render_write_only_with_the_interface_locked(scene, monkeypatch):
    """While a render runs beside the interface, the frame handler (and the undo handler, which
    shades as it does) leaves the meshes alone unless Render > Lock Interface is on (Blender's rule
    for altering data from handlers), and says so; after the render, and with the lock, it
    re-shades as before."""
    from addon import handlers
    env_world(scene, "sunrise")
    obj = add_monkey()
    set_material(obj)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    scene.wenv.shade_on_frame_change = True
    monkeypatch.setattr(handlers, "interface_runs_beside_renders", lambda: True)
    n = len(obj.data.vertices)
    mark = np.full((n, 3), 0.25, np.float32)
    try:
        handlers.render_init(scene)
        scene.render.use_lock_interface = False
        meshes.write_colors(obj.data, "POINT", mark)
        handlers.frame_change_post(scene)
        assert np.all(attribute(obj)[1] == 0.25) and "Lock Interface" in handlers.last_error()
        scene.wenv.shaded_frame = scene.frame_current - 1  # colours of another frame, after an undo
        handlers.undo_post(scene)
        assert np.all(attribute(obj)[1] == 0.25)
        scene.render.use_lock_interface = True
        handlers.frame_change_post(scene)
        assert not np.any(attribute(obj)[1] == 0.25)
    finally:
        handlers.render_done(scene)
    scene.render.use_lock_interface = False
    meshes.write_colors(obj.data, "POINT", mark)
    handlers.frame_change_post(scene)
    assert not np.any(attribute(obj)[1] == 0.25)


def test_precompute_job_progress_and_cancel(tmp_path, monkeypatch, one_thread):
    monkeypatch.setenv("WENV_CACHE_DIR", str(tmp_path))
    job = live.PrecomputeJob("draft")  # the one preset with rotation matrices to build
    seen = []
    orig = job._progress

    def progress(fraction):
        seen.append(fraction)
        if len(seen) == 3:
            job.cancel()
        return orig(fraction)
    job._progress = progress
    job.start()
    assert job.wait(60)
    assert job.cancelled and job.result is None and not job.install()
    assert len(seen) >= 3 and 0 < seen[0] <= seen[-1] < 1
    done = live.PrecomputeJob("draft").start()
    assert done.wait(60) and done.error is None and done.result is not None
    assert done.fraction == pytest.approx(1.0, abs=0.05) and done.result[0].stats["cache"] == "built"
    # The operator's synchronous path (scripts; the UI runs the job above in a modal timer).
    engine.shaders.clear()
    bpy.context.scene.wenv.quality = "DRAFT"
    assert bpy.ops.wenv.precompute() == {"FINISHED"} and engine.shaders.has("draft")


# ---------------------------------------------------------------------------------------------
# Undo, save and reload


def as_the_interface_runs(op, **kw):
    """An operator called as the interface calls it.  Blender pushes an undo step for an operator with
    the UNDO option when it finishes, except when it is called from Python, unless asked to
    (undo=True, the second argument); in background mode the undo stack exists once a first step
    was pushed."""
    return op("EXEC_DEFAULT", True, **kw)


def test_each_operator_that_changes_data_is_one_undo_step(scene):
    """Shade, the material operators and Clear each make one step: one undo gives the data from
    before the operator, one redo what it made.  Precompute changes no data and makes no step."""
    env_world(scene, "sunset")
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    obj_name, mat_name = cube.name, cube.active_material.name

    def snapshot():
        # by name: undo frees the data Python held (a kept reference raises ReferenceError)
        obj, mat = bpy.data.objects[obj_name], bpy.data.materials[mat_name]
        colours = attribute(obj)[1].tobytes() if ATTR in obj.data.color_attributes else None
        st = mat.wenv
        lobes = [(tuple(l.specular), l.alpha, l.ior, l.distribution) for l in st.lobes]
        node_roughness = materials.principled_node(mat).inputs["Roughness"].default_value
        return colours, st.model, tuple(st.diffuse), lobes, st.active_lobe, node_roughness

    bpy.ops.ed.undo_push(message="start")
    steps = [("shade", bpy.ops.wenv.shade, {"view": "CAMERA"}),
             ("fit the Principled BSDF's roughness", bpy.ops.wenv.fit_roughness, {"target": 60.0, "geometry": "60"}),
             ("Cook-Torrance from Principled", bpy.ops.wenv.from_principled, {}),
             ("add a lobe", bpy.ops.wenv.lobe_add, {}),
             ("remove a lobe", bpy.ops.wenv.lobe_remove, {}),
             ("fit a lobe's roughness", bpy.ops.wenv.fit_roughness, {"target": 30.0, "geometry": "60"}),
             ("shade again", bpy.ops.wenv.shade, {"view": "CAMERA"}),
             ("clear", bpy.ops.wenv.clear, {})]
    for what, op, kw in steps:
        before = snapshot()
        assert as_the_interface_runs(op, **kw) == {"FINISHED"}, what
        after = snapshot()
        assert after != before, what
        bpy.ops.ed.undo()
        assert snapshot() == before, what
        bpy.ops.ed.redo()
        assert snapshot() == after, what
    cleared = snapshot()
    assert as_the_interface_runs(bpy.ops.wenv.precompute) == {"FINISHED"} and snapshot() == cleared
    bpy.ops.ed.undo()  # undoes Clear: precompute pushed no step of its own
    assert snapshot()[0] is not None
    # The add-on kept nothing of the data undo freed: shading again works.
    select_only(bpy.data.objects[obj_name])
    assert shade_op(view="CAMERA") == {"FINISHED"}


class LiveOperator:
    """The running wenv.live operator as Blender holds it (headless Blender runs no modal
    operator): a timer, and its own modal() and _stop() called with events."""

    def __init__(self):
        from addon import operators
        self.cls = operators.WENV_OT_live
        self._timer = bpy.context.window_manager.event_timer_add(10.0, window=bpy.context.window)
        self.reports = []

    def report(self, kind, text):
        self.reports.append(text)

    def _stop(self, context):
        return self.cls._stop(self, context)

    def event(self, kind):
        from types import SimpleNamespace
        return self.cls.modal(self, bpy.context, SimpleNamespace(type=kind))

    def click(self):
        return self.cls.invoke(self, bpy.context, None)


def bpy_ids_held_by_the_addon():
    """Every bpy.types.ID reachable from the add-on's modules: their globals, classes, instances
    of their classes, containers and closures."""
    import inspect
    import sys
    import types
    found, seen = [], set()

    def ours(x):
        return (getattr(x, "__module__", None) or "").startswith("addon")

    def walk(x, depth):
        if depth < 0 or id(x) in seen:
            return
        seen.add(id(x))
        if isinstance(x, bpy.types.ID):
            found.append(x)
            return
        if isinstance(x, dict):
            items = [*x.keys(), *x.values()]
        elif isinstance(x, (list, tuple, set, frozenset)):
            items = list(x)
        elif isinstance(x, types.FunctionType):
            items = [c.cell_contents for c in x.__closure__ or () if c.cell_contents is not None] if ours(x) else []
        elif isinstance(x, types.MethodType):
            items = [x.__self__, x.__func__]
        elif inspect.isclass(x):
            items = list(vars(x).values()) if ours(x) else []
        elif ours(type(x)):
            items = list(getattr(x, "__dict__", {}).values())
            items += [getattr(x, n, None) for c in type(x).__mro__ for n in getattr(c, "__slots__", ())]
        else:
            return
        for item in items:
            walk(item, depth - 1)

    for name, module in list(sys.modules.items()):
        if name == "addon" or name.startswith("addon."):
            for value in vars(module).values():
                if not isinstance(value, types.ModuleType):
                    walk(value, 8)
    return found


def test_live_mode_is_one_undo_step_when_it_stops(scene):
    """Live mode's passes make no undo step each (one every 50 ms would flood the history); when it
    stops it pushes one for the whole session: one undo gives what was there before it, one redo
    its last colours.  A session that wrote nothing pushes none.  Meanwhile the add-on holds no
    Blender data (an undo would free it): objects are held by name."""
    env_world(scene, "sunset")
    obj = add_monkey()
    set_material(obj)
    name, cam = obj.name, scene.camera.name
    scene.wenv.view_source = "CAMERA"
    assert shade_op(view="CAMERA") == {"FINISHED"}
    bpy.ops.ed.undo_push(message="shaded")
    shaded = attribute(obj)[1].copy()
    op = LiveOperator()
    try:
        live.LiveState.session = live.LiveSession([name])  # as invoke starts it
        passes = []
        for x in (5.0, -3.0, 0.0):
            bpy.data.objects[cam].location.x = x  # a change between passes (by a script: no step)
            assert op.event("TIMER") == {"PASS_THROUGH"}  # reads the meshes, starts the worker
            assert not bpy_ids_held_by_the_addon()
            assert live.LiveState.session.wait(60)
            op.event("TIMER")  # writes the colours
            passes.append(attribute(bpy.data.objects[name])[1].copy())
        assert live.LiveState.session.shades == 3
        assert all(not np.allclose(a, b) for a, b in zip([shaded] + passes, passes))
        assert op.click() == {"FINISHED"} and live.LiveState.running()  # clicked again: stops on the next event
        assert op.event("TIMER") == {"FINISHED"} and not live.LiveState.running()
    finally:
        live.LiveState.reset()
    assert not bpy_ids_held_by_the_addon()
    bpy.ops.ed.undo()
    np.testing.assert_array_equal(attribute(bpy.data.objects[name])[1], shaded)
    bpy.ops.ed.redo()
    np.testing.assert_array_equal(attribute(bpy.data.objects[name])[1], passes[-1])
    assert tuple(bpy.data.objects[cam].location) == (0.0, pytest.approx(-6.5, abs=1.0), pytest.approx(5.3, abs=1.0))

    op = LiveOperator()
    live.LiveState.session = live.LiveSession([name])
    assert op.event("ESC") == {"FINISHED"} and not live.LiveState.running()
    bpy.ops.ed.undo()  # no step for the empty session: this undoes the first one
    np.testing.assert_array_equal(attribute(bpy.data.objects[name])[1], shaded)


def test_live_mode_shades_what_an_undo_restores(scene):
    """An undo or redo while live mode runs restores a step, colours included.  Live mode then shades
    the restored data even when its settings are those it shaded last (the step's colours may be
    older than its settings), and drops a result it was computing from the data before."""
    env_world(scene, "sunset")
    obj = add_monkey()
    set_material(obj)
    name, cam = obj.name, scene.camera.name
    scene.wenv.view_source = "CAMERA"
    session = live.LiveSession([name])
    live.LiveState.session = session  # where the undo handler finds it

    def settle():
        return settled(session)

    try:
        assert settle() == (False, True)
        shaded = attribute(obj)[1].copy()
        meshes.write_colors(obj.data, "POINT", np.full((len(shaded), 3), 0.25, np.float32))
        bpy.ops.ed.undo_push(message="colours older than the settings")
        assert as_the_interface_runs(bpy.ops.wenv.clear) == {"FINISHED"}
        assert settle() == (False, False)  # nothing live mode watches changed
        bpy.ops.ed.undo()
        assert np.all(attribute(bpy.data.objects[name])[1] == 0.25)
        assert settle() == (False, True)
        np.testing.assert_array_equal(attribute(bpy.data.objects[name])[1], shaded)

        bpy.data.objects[cam].location.x = -3.0
        assert session.tick(bpy.context) is False  # a worker shades the new view
        bpy.ops.ed.redo()  # meanwhile: the Clear step, without colours
        assert session.wait(60)
        assert session.tick(bpy.context) is False and ATTR not in bpy.data.objects[name].data.color_attributes
        assert settle() == (False, True) and ATTR in bpy.data.objects[name].data.color_attributes
    finally:
        live.LiveState.reset()


def test_undo_and_redo_show_the_colours_of_the_frame_restored(scene):
    """Frame changes make no undo step of their own, and Blender pushes a frame change's step before
    it runs the frame handlers, so that step holds the colours of the frame before.  After an undo or
    redo such colours are shaded for the frame restored; colours of their own frame stay as the
    step holds them."""
    env_world(scene, "sunrise")
    obj = add_monkey()
    set_material(obj, lobes=((0.1, 1.5, "GGX"),))
    name = obj.name
    cam = scene.camera
    animate_camera(cam)
    scene.wenv.shade_on_frame_change = True
    scene.frame_set(1)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    n = len(obj.data.vertices)
    meshes.write_colors(obj.data, "POINT", np.full((n, 3), 0.25, np.float32))  # at frame 1
    bpy.ops.ed.undo_push(message="frame 1, its own colours")
    scene.frame_current = 10  # a frame change operator: the frame set, its step pushed,
    bpy.ops.ed.undo_push(message="Frame Change")
    scene.frame_set(10)  # then the frame handlers
    at_10 = attribute(obj)[1].copy()
    assert not np.any(at_10 == 0.25)
    bpy.ops.ed.undo()
    assert bpy.context.scene.frame_current == 1
    assert np.all(attribute(bpy.data.objects[name])[1] == 0.25)
    bpy.ops.ed.redo()
    assert bpy.context.scene.frame_current == 10
    np.testing.assert_array_equal(attribute(bpy.data.objects[name])[1], at_10)


def test_a_file_saved_before_the_rename_opens_with_its_alphas(scene, tmp_path):
    """A lobe's alpha was stored as "roughness" until `roughness` took Blender's meaning: a file saved
    so opens with each lobe's alpha where it was, the old key gone, and Roughness reads sqrt(alpha)."""
    obj = add_monkey()
    mat = set_material(obj, lobes=((0.09, 1.5, "GGX"), (0.3, 1.4, "BECKMANN")))
    for lobe in mat.wenv.lobes:  # as the earlier add-on stored it: the alpha under "roughness"
        lobe["roughness"] = lobe.alpha
        del lobe["alpha"]
    assert "roughness" in mat.wenv.lobes[0].keys() and "alpha" not in mat.wenv.lobes[0].keys()
    name, path = mat.name, str(tmp_path / "old.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    bpy.ops.wm.open_mainfile(filepath=path)
    lobes = bpy.data.materials[name].wenv.lobes
    assert [l.alpha for l in lobes] == [pytest.approx(0.09), pytest.approx(0.3)]
    assert [l.roughness for l in lobes] == [pytest.approx(0.3), pytest.approx(0.3 ** 0.5)]
    assert all("roughness" not in l.keys() for l in lobes)
    lobes[0].roughness = 0.5  # Blender's roughness, through the core's one conversion
    assert lobes[0].alpha == pytest.approx(wenv.alpha_from_roughness(0.5))
    lobes[0].roughness = 0.0  # a mirror keeps the conversion's floor
    assert lobes[0].alpha == pytest.approx(wenv.alpha_from_roughness(0.0))
    lobes[0].roughness = math.nan  # a script's NaN: a setter cannot refuse it, so nothing changes
    assert lobes[0].alpha == pytest.approx(wenv.alpha_from_roughness(0.0))


def test_the_panels_follow_the_core(scene):
    """What the panels say comes from the core: only rotation precomputes matrices (`draft`; the
    panel says so until they are built), `default` slices and precomputes nothing (the panel says
    nothing of matrices); the Principled inputs shown are the core's list of those wenv shades."""
    from addon import ui
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    engine.shaders.clear()
    said = {}
    for quality in ("DRAFT", "DEFAULT"):
        scene.wenv.quality = quality
        said[quality] = [l[1] for l in draw_panel(ui.WENV_PT_shading) if l[0] == "label" and "matrices" in l[1]]
    assert engine.needs_matrices("draft") and not engine.needs_matrices("default")
    assert said == {"DRAFT": ["Rotation matrices: precomputed on first use"], "DEFAULT": []}
    assert engine.preparing("draft") == "precomputing the draft matrices"
    assert engine.preparing("default") == "preparing default shading"
    mat = node_material(bpy, "principled panel")
    mat.wenv.model = "PRINCIPLED"
    cube.active_material = mat
    shown = [l for l in draw_panel(ui.WENV_PT_material) if l == ("prop", "default_value")]
    assert ui.PRINCIPLED_SHOWN == tuple(r["socket"] for r in wenv.Principled.INPUTS if r["shaded"] != "no")
    node = mat.node_tree.nodes["Principled BSDF"]
    assert len(shown) == len([s for s in ui.PRINCIPLED_SHOWN if node.inputs.get(s) is not None])  # this Blender's
    assert "Coat Tint" in ui.PRINCIPLED_SHOWN
    assert ("Diffuse Roughness" in node.inputs) == has_diffuse_roughness(bpy)
    assert "Transmission Weight" not in ui.PRINCIPLED_SHOWN


def test_save_reload_reshade(scene, tmp_path):
    env_world(scene, "night", rotation=1.2, strength=4.0)
    obj = add_monkey()
    mat = set_material(obj, lobes=((0.07, 1.6, "BECKMANN"), (0.3, 1.4, "GGX")))
    mat.wenv.target_gloss = 42.0
    mat_name = mat.name
    scene.wenv.tone_mapping = "LOG"
    scene.wenv.max_luminance = 3.0
    scene.wenv.view_source = "CAMERA"
    assert shade_op() == {"FINISHED"}
    before = attribute(obj)[1].copy()
    path = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    assert "Suzanne" not in bpy.data.objects
    bpy.ops.wm.open_mainfile(filepath=path)
    sc = bpy.context.scene
    assert (sc.wenv.quality, sc.wenv.tone_mapping, sc.wenv.max_luminance, sc.wenv.view_source) == \
        ("DRAFT", "LOG", pytest.approx(3.0), "CAMERA")
    st = bpy.data.materials[mat_name].wenv
    assert [(l.alpha, l.distribution) for l in st.lobes] == [(pytest.approx(0.07), "BECKMANN"),
                                                                (pytest.approx(0.3), "GGX")]
    assert st.target_gloss == pytest.approx(42.0)
    obj = bpy.data.objects["Suzanne"]
    np.testing.assert_array_equal(attribute(obj)[1], before)
    select_only(obj)
    obj.data.color_attributes.remove(obj.data.color_attributes[ATTR])
    assert shade_op() == {"FINISHED"}
    np.testing.assert_allclose(attribute(obj)[1], before, rtol=1e-5, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# Panels: drawn into a recording layout (headless Blender draws no UI)


class RecordingLayout:
    """Stands in for bpy.types.UILayout: records labels, props and operators, checks that every
    property and operator drawn exists."""

    def __init__(self, log):
        self.log = log

    def _child(self, *args, **kwargs):
        return RecordingLayout(self.log)

    row = column = box = split = _child

    def label(self, text="", icon="NONE"):
        self.log.append(("label", text, icon))

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, name
        self.log.append(("prop", name))

    def operator(self, idname, **kwargs):
        group, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, group), name), idname
        self.log.append(("operator", idname))

    def template_list(self, list_type, list_id, data, propname, active_data, active_propname, **kwargs):
        assert hasattr(bpy.types, list_type) and propname in data.bl_rna.properties
        self.log.append(("list", propname))

    def separator(self, **kwargs):
        pass


def draw_panel(panel_cls):
    log = []

    class Host:  # stands in for the panel instance: draw() only uses self.layout
        layout = RecordingLayout(log)
    assert panel_cls.poll(bpy.context) if hasattr(panel_cls, "poll") else True
    panel_cls.draw(Host(), bpy.context)
    return log


def test_panels_draw(scene):
    from addon import ui
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    mat = set_material(cube, lobes=((0.002, 1.5, "BECKMANN"),))
    cube.active_material = mat
    shading = draw_panel(ui.WENV_PT_shading)
    assert ("operator", "wenv.shade") in shading and ("operator", "wenv.live") in shading
    world = [l for l in shading if l[0] == "label" and l[1].startswith("World: ")]
    assert world and "constant" in world[0][1]

    assert ("list", "lobes") in draw_panel(ui.WENV_PT_material)

    gloss_panel = draw_panel(ui.WENV_PT_gloss)
    readings = [l[1] for l in gloss_panel if l[0] == "label" and l[1].endswith(" GU")]
    assert readings == [f"{mat.wenv.gloss_20:.2f} GU", f"{mat.wenv.gloss_60:.2f} GU", f"{mat.wenv.gloss_85:.2f} GU"]
    marks = [l for l in gloss_panel if l[0] == "label" and l[2] == "CHECKMARK"]
    assert mat.wenv.gloss_60 > 70 and len(marks) == 1  # a high-gloss material: the 20 degree reading
    assert gloss_panel.index(marks[0]) == gloss_panel.index(("label", readings[0], "NONE")) + 1
    assert ("operator", "wenv.fit_roughness") in gloss_panel

    scene.world = None
    errors = [l for l in draw_panel(ui.WENV_PT_shading) if l[0] == "label" and l[2] == "ERROR"]
    assert errors and "no World" in errors[0][1]


def test_edit_mode_is_refused(scene):
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    bpy.ops.object.mode_set(mode="EDIT")
    try:
        with pytest.raises(RuntimeError, match="Leave Edit Mode"):
            shade_op(view="CAMERA")
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")
    assert ATTR not in cube.data.color_attributes
    assert shade_op(view="CAMERA") == {"FINISHED"}


def test_live_session_result_for_a_deleted_object_is_dropped(scene):
    obj = add_monkey()
    other = bpy.data.objects["Cube"]
    scene.wenv.view_source = "CAMERA"
    session = live.LiveSession([obj.name, other.name])
    assert not session.tick(bpy.context)  # reads the meshes, starts the worker
    bpy.data.objects.remove(obj)  # meanwhile the user deletes one of them
    assert session.wait(60)
    assert session.tick(bpy.context)
    assert ATTR in other.data.color_attributes
    assert "Suzanne" not in bpy.data.objects and session.last_error is None


def test_byte_image_is_linearised(scene, tmp_path):
    _, top_first = pattern_image(w=32, h=16)
    img = bpy.data.images.new("bytes", 32, 16, alpha=True, float_buffer=False)
    img.pixels.foreach_set(np.clip(top_first[::-1], 0, 1).ravel())
    path = str(tmp_path / "sky.png")
    img.filepath_raw = path
    img.file_format = "PNG"
    img.save()
    png = bpy.data.images.load(path)
    assert not png.is_float and png.colorspace_settings.name == "sRGB"
    env_world(scene, image=png)
    obj = add_monkey()
    mat = set_material(obj)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    stored = np.empty(32 * 16 * 4, np.float32)
    png.pixels.foreach_get(stored)
    enc = stored.reshape(16, 32, 4)[::-1, :, :3]
    lin = np.where(enc <= 0.04045, enc / 12.92, ((enc + 0.055) / 1.055) ** 2.4).astype(np.float32)
    p, n = world_arrays(obj, corner=False)
    want = core_shader(wenv.Environment(np.ascontiguousarray(lin)), wenv_material(mat)).shade_mesh(
        p, n, tuple(scene.camera.matrix_world.translation))
    np.testing.assert_allclose(attribute(obj)[1], want, rtol=1e-4, atol=1e-5)


def test_viewport_looking_through_the_camera_uses_the_camera(scene):
    obj = add_monkey()
    set_material(obj)
    rv3d = next(a for a in bpy.context.screen.areas if a.type == "VIEW_3D").spaces.active.region_3d
    rv3d.view_perspective = "CAMERA"
    assert shade_op(view="VIEWPORT") == {"FINISHED"}
    through_viewport = attribute(obj)[1].copy()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    np.testing.assert_array_equal(attribute(obj)[1], through_viewport)
    rv3d.view_perspective = "PERSP"
    assert shade_op(view="VIEWPORT") == {"FINISHED"}
    assert not np.allclose(attribute(obj)[1], through_viewport)


def test_auto_quality_matches_core_and_builds_no_matrices(scene):
    """Quality Auto: each material gets the shader wenv's auto picks for this World, material and
    mesh; the colours equal the core's, no rotation matrices are built or cached, and the choice is
    reported."""
    env_world(scene, "sunset", rotation=0.4)
    obj = add_monkey(subdivisions=1)
    mat = set_material(obj, lobes=((0.3, 1.5, "BECKMANN"),))
    scene.wenv.quality = "AUTO"
    scene.wenv.target_error = 3.0
    cache = os.environ["WENV_CACHE_DIR"]
    before = set(os.listdir(cache))
    engine.shaders.clear()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert set(os.listdir(cache)) == before
    _, rgb = attribute(obj)
    p, n = world_arrays(obj, corner=False)
    env = wenv.load_environment(hdri_path("sunset"), rotation=0.4)
    want = wenv.Shader(env, wenv_material(mat), quality="auto", target_error=0.03, normals=n)
    assert want.stats["auto"]["met"] and want.stats["rotation_nnz"] == 0
    eye = tuple(scene.camera.matrix_world.translation)
    np.testing.assert_allclose(rgb, want.shade_mesh(p, n, eye), rtol=1e-4, atol=1e-5)
    # a tighter target picks a finer setting
    scene.wenv.target_error = 0.5
    assert shade_op(view="CAMERA") == {"FINISHED"}
    choices = [s.stats["auto"] for s in engine.shaders._auto.values()]
    levels = sorted(c["level"] for c in choices)
    assert levels[-1] > levels[0]
    # the World is analysed once: the second pass's choice reads the first's analysis
    assert sorted(c["analysis_seconds"] > 0 for c in choices) == [False, True]
    # a material without lobes gets SH irradiance, reported by its order
    obj.data.materials.clear()
    lam = set_material(obj, lobes=())
    engine.shaders.clear()
    view = views.camera_view(scene)
    notes = shading.shade_objects(scene, bpy.context.evaluated_depsgraph_get(), [obj], view, bpy.data)[1]
    assert any("spherical harmonics of order" in note for note in notes), notes
    want = wenv.Shader(env, wenv_material(lam), quality="auto", target_error=0.005, normals=n)
    assert want.method == "sh"
    np.testing.assert_allclose(attribute(obj)[1], want.shade_mesh(p, n, eye), rtol=1e-4, atol=1e-5)


def test_cached_shaders_do_not_keep_an_operator_s_progress_callback():
    """A shader built with an operator's progress callback (which holds the window manager) reports
    to it while building only: its later set_material calls, after the operator is gone, must not
    reach it (a callback on removed Blender data raised ReferenceError and failed the shade)."""
    calls = []
    shader, _relay = engine.ShaderCache().build("draft", progress=lambda f: calls.append(f))
    built = len(calls)  # none when the matrices come from the cache
    many = wenv.CookTorrance(diffuse=0.0, lobes=[dict(specular=0.04, alpha=0.05 + 0.02 * i) for i in range(8)])
    shader.set_material(many)
    assert len(calls) == built
    # what the relay prevents: the same callback given straight to a Shader hears set_material
    direct = wenv.Shader(shader.environment, wenv.Lambert(0.5), quality="draft", method="slicing",
                         progress=lambda f: calls.append(f))
    direct.set_material(many)
    assert len(calls) > built


# ---------------------------------------------------------------------------------------------
# Shadows and bounce light


def mesh_triangles(obj):
    me = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    t = np.empty(len(me.loop_triangles) * 3, np.int32)
    me.loop_triangles.foreach_get("vertices", t)
    return t.reshape(-1, 3)


def test_shadows_equal_the_core_with_occlusion(scene):
    """Suzanne alone with Shadows and Bounce Light: the colours are the core's shading with her
    occlusion (at the add-on's resolution for her size) and her own diffuse light as the bounce,
    and differ from the unshadowed ones where she blocks her own sky; with Bounce Light off, the
    core's with no bounce, darker."""
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    env_world(scene, "forest")
    obj = add_monkey(subdivisions=1)
    mat = set_material(obj, lobes=((0.2, 1.5, "GGX"),))
    scene.wenv.shadows = True
    scene.wenv.glossy_bounce = False  # the diffuse light alone, as the core gives it
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(obj)
    p, n = world_arrays(obj, corner=False)
    occlusion = wenv.Occluders(p, mesh_triangles(obj)).occlusion(p, n, resolution="auto")
    assert occlusion.resolution == 16 and occlusion.blocked_vertices > len(p) // 3
    shader = core_shader(wenv.load_environment(hdri_path("forest")), wenv_material(mat))
    eye = tuple(scene.camera.matrix_world.translation)
    want = shader.shade_mesh(p, n, eye, occlusion=occlusion, bounce=shader.diffuse_light(n, occlusion=occlusion))
    close = np.all(np.abs(rgb - want) <= 1e-3 * np.abs(want) + 1e-5, axis=1)
    assert close.mean() > 0.99  # (the add-on's normals are not unit: a ray at a texel's edge may flip)
    plain = shader.shade_mesh(p, n, eye)
    assert np.mean(np.abs(rgb - plain)) > 0.02 * np.mean(plain)
    # Bounce Light off: the blocked directions are black (Cycles' Max Bounces 0), darker where blocked
    scene.wenv.bounce_light = False
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, direct = attribute(obj)
    want = shader.shade_mesh(p, n, eye, occlusion=occlusion, bounce=None)
    close = np.all(np.abs(direct - want) <= 1e-3 * np.abs(want) + 1e-5, axis=1)
    assert close.mean() > 0.99
    assert np.mean(rgb - direct) > 0.005 * np.mean(rgb) and np.all(direct <= rgb + 1e-4 * rgb + 1e-6)


def test_a_convex_mesh_alone_shades_as_without_shadows(scene):
    """The start-up cube alone blocks nothing: the same colours to the bit with shadows on and off."""
    env_world(scene, "city")
    cube = bpy.data.objects["Cube"]
    set_material(cube)
    select_only(cube)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, without = attribute(cube)
    scene.wenv.shadows = True
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, with_shadows = attribute(cube)
    assert np.array_equal(with_shadows, without)


def add_plane_under_cube():
    """A Lambertian plane of 17 x 17 vertices under the start-up cube, selected alone."""
    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0.0, 0.0, -1.5))
    plane = bpy.context.object
    bpy.ops.object.modifier_add(type="SUBSURF")
    plane.modifiers[-1].subdivision_type = "SIMPLE"
    plane.modifiers[-1].levels = 4
    bpy.ops.object.modifier_apply(modifier=plane.modifiers[-1].name)
    plane.data.shade_smooth()
    set_material(plane, model="LAMBERT", diffuse=(0.6, 0.6, 0.6), lobes=())
    select_only(plane)
    return plane


def test_another_mesh_casts_shadows_unless_told_not_to(scene):
    """A plane under the start-up cube (not shaded): darker beneath it with shadows on; the same as
    without once the cube's Casts Shadows is off."""
    env_world(scene, "sunset")
    plane = add_plane_under_cube()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, plain = attribute(plane)
    scene.wenv.shadows = True
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, shadowed = attribute(plane)
    p, _ = world_arrays(plane, corner=False)
    under = np.hypot(p[:, 0], p[:, 1]) < 0.5
    assert under.any() and np.all(shadowed[under].sum(1) < 0.8 * plain[under].sum(1))
    bpy.data.objects["Cube"].wenv.casts_shadows = False
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, again = attribute(plane)
    assert np.array_equal(again, plain)


def test_instances_and_curves_cast_shadows_as_meshes_do(scene):
    """The start-up cube moved into a collection shown only through a collection instance, then a
    text object (which Cycles renders as a mesh), above the plane: the plane is shaded as under an
    ordinary mesh object of the same shape in the same place, with Bounce Light off and on (the
    instance sends its light back as the mesh object does); with the instanced object's Casts
    Shadows off, as under nothing.  (The text's mesh object and the text are cast from other rows:
    a ray along an edge may pass one and meet the other, so a few vertices differ, by under 1 %.)"""
    def same_as(got, want):
        off = np.abs(got - want) > 1e-5 + 1e-5 * np.abs(want)
        assert off.any(axis=1).mean() < 0.03 and np.abs(got - want).max() < 0.01 * np.abs(want).max()
    env_world(scene, "sunset")
    plane = add_plane_under_cube()
    scene.wenv.shadows, scene.wenv.bounce_light = True, False
    cube = bpy.data.objects["Cube"]
    cube.location = (0.3, -0.2, 0.0)
    bpy.context.view_layer.update()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, under_mesh = attribute(plane)
    scene.wenv.bounce_light = True
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, lit_by_mesh = attribute(plane)
    assert np.abs(lit_by_mesh - under_mesh).max() > 0.01 * np.abs(under_mesh).max()
    scene.wenv.bounce_light = False
    blocks = bpy.data.collections.new("blocks")
    for holder in list(cube.users_collection):
        holder.objects.unlink(cube)
    blocks.objects.link(cube)
    bpy.context.view_layer.update()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, under_nothing = attribute(plane)
    assert np.abs(under_nothing - under_mesh).max() > 0.01
    instance = bpy.data.objects.new("instancer", None)
    instance.instance_type, instance.instance_collection = "COLLECTION", blocks
    scene.collection.objects.link(instance)
    bpy.context.view_layer.update()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    same_as(attribute(plane)[1], under_mesh)
    # past the memory budget's room an instance is counted, not read
    got, left = meshes.other_geometry(bpy.context.evaluated_depsgraph_get(), room=100.0)
    assert got == [] and left == 1
    assert len(meshes.other_geometry(bpy.context.evaluated_depsgraph_get())[0]) == 1
    scene.wenv.bounce_light = True
    assert shade_op(view="CAMERA") == {"FINISHED"}
    same_as(attribute(plane)[1], lit_by_mesh)
    assert not [n for n in plan_of(scene, plane).notes if "instance" in n]
    # past the rows instances may send light from, they block it but send none, said
    from addon import shading
    rows, shading.SENDER_ROWS = shading.SENDER_ROWS, 10
    try:
        plan = plan_of(scene, plane)
        assert not plan.senders and len(plan.blockers) == 1
        assert any("1 instanced object(s), curve(s) or text(s) block light but send none back: past 10 vertices"
                   in n for n in plan.notes), plan.notes
        assert shade_op(view="CAMERA") == {"FINISHED"}
        same_as(attribute(plane)[1], under_mesh)  # (black where it blocks, as without Bounce Light)
    finally:
        shading.SENDER_ROWS = rows
    scene.wenv.bounce_light = False
    cube.wenv.casts_shadows = False
    assert shade_op(view="CAMERA") == {"FINISHED"}
    np.testing.assert_allclose(attribute(plane)[1], under_nothing, rtol=1e-5, atol=1e-6)
    # a text object, as the mesh Blender makes of it
    bpy.data.objects.remove(instance)
    bpy.ops.object.text_add(location=(-1.0, -0.5, 0.0))
    text = bpy.context.object
    text.data.extrude, text.scale = 0.2, (2.0, 2.0, 2.0)
    bpy.context.view_layer.update()
    select_only(plane)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, under_text = attribute(plane)
    as_mesh = bpy.data.objects.new("text as mesh", bpy.data.meshes.new_from_object(text.evaluated_get(
        bpy.context.evaluated_depsgraph_get())))
    as_mesh.matrix_world = text.matrix_world
    scene.collection.objects.link(as_mesh)
    text.hide_set(True)
    bpy.context.view_layer.update()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    same_as(attribute(plane)[1], under_text)
    assert np.abs(under_text - under_nothing).max() > 0.01


def test_an_instance_sends_the_light_of_its_textures(scene):
    """With Bounce Light, a collection instance of a cube whose Base Color is a checker (through its
    Generated coordinates, the same wherever the mesh lies) lights the plane below as the cube itself
    does in the same place, its texture read at each row; one read through world positions (which
    differ from instance to instance) sends its unlinked value, and the report says so."""
    env_world(scene, "sunset")
    plane = add_plane_under_cube()
    scene.wenv.shadows = scene.wenv.bounce_light = True
    cube = bpy.data.objects["Cube"]
    cube.location = (0.3, -0.2, 0.0)
    tree = cube.active_material.node_tree
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Color1"].default_value, checker.inputs["Color2"].default_value = (1, 0, 0, 1), (0, 0, 1, 1)
    checker.inputs["Scale"].default_value = 2.0
    textured = tree.links.new(checker.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    bpy.context.view_layer.update()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, lit_by_mesh = attribute(plane)
    blocks = bpy.data.collections.new("blocks")
    for holder in list(cube.users_collection):
        holder.objects.unlink(cube)
    blocks.objects.link(cube)
    instance = bpy.data.objects.new("instancer", None)
    instance.instance_type, instance.instance_collection = "COLLECTION", blocks
    scene.collection.objects.link(instance)
    bpy.context.view_layer.update()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, lit_by_instance = attribute(plane)
    np.testing.assert_allclose(lit_by_instance, lit_by_mesh, rtol=1e-5, atol=1e-6)
    assert not [n for n in plan_of(scene, plane).notes if "instance" in n]
    tree.links.remove(textured)
    bpy.context.view_layer.update()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, grey = attribute(plane)
    assert np.abs(grey - lit_by_instance).max() > 0.01 * np.abs(grey).max()  # (the texture's light mattered)
    where = tree.nodes.new("ShaderNodeNewGeometry")
    tree.links.new(where.outputs["Position"], checker.inputs["Vector"])
    tree.links.new(checker.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    notes = plan_of(scene, plane).notes
    assert any("'Cube' (instanced, or a curve or text) sends back the light of its materials' unlinked values: "
               "'Material' read where each instance lies" in n for n in notes), notes


def test_an_instance_of_the_shaded_object_shadows_it(scene):
    """The start-up cube shaded while a collection instance puts a copy of it right above it (as a
    Geometry Nodes scatter's instances lie on their own mesh): its top is darker than alone."""
    env_world(scene, "sunset")
    scene.wenv.shadows, scene.wenv.bounce_light = True, False
    cube = bpy.data.objects["Cube"]
    select_only(cube)
    assert shade_op(view="CAMERA") == {"FINISHED"}
    p, _ = world_arrays(cube, corner=False)
    top = p[:, 2] > 0.99
    alone = attribute(cube)[1].copy()
    copies = bpy.data.collections.new("copies")
    copies.objects.link(cube)  # (also in the scene's own collection)
    instance = bpy.data.objects.new("above", None)
    instance.instance_type, instance.instance_collection = "COLLECTION", copies
    instance.location = (0.0, 0.0, 2.5)
    scene.collection.objects.link(instance)
    bpy.context.view_layer.update()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    domain, shaded = attribute(cube)
    rows = top if domain == "POINT" else top[meshes.corner_vertices(cube.data)]
    assert rows.any() and shaded[rows].mean() < 0.9 * alone[rows].mean()


def test_a_blocker_not_shaded_sends_its_light_back(scene):
    """The plane shaded alone under the start-up cube (smooth, an orange Lambert): with Bounce Light,
    what the cube blocks shows the cube's own diffuse light (its shadows included), as the core
    gives it; brighter beneath the cube than with Bounce Light off."""
    env_world(scene, "sunset")
    plane = add_plane_under_cube()
    cube = bpy.data.objects["Cube"]
    cube.data.shade_smooth()
    cube.data.materials.clear()
    cube_mat = set_material(cube, model="LAMBERT", diffuse=(0.8, 0.5, 0.2), lobes=())
    scene.wenv.shadows = True
    scene.wenv.glossy_bounce = False  # the diffuse light alone, which the core gives
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, rgb = attribute(plane)
    pp, pn = world_arrays(plane, corner=False)
    cp, cn = world_arrays(cube, corner=False)
    occluders = wenv.Occluders(np.vstack([pp, cp]), np.vstack([mesh_triangles(plane), mesh_triangles(cube) + len(pp)]))
    plane_occlusion = occluders.occlusion(pp, pn, resolution="auto")
    cube_occlusion = occluders.occlusion(cp, cn, resolution="auto")
    env = wenv.load_environment(hdri_path("sunset"))
    shader = core_shader(env, wenv_material(plane.data.materials[0]))
    bounce = np.vstack([shader.diffuse_light(pn, occlusion=plane_occlusion),
                        core_shader(env, wenv_material(cube_mat)).diffuse_light(cn, occlusion=cube_occlusion)])
    eye = tuple(scene.camera.matrix_world.translation)
    want = shader.shade_mesh(pp, pn, eye, occlusion=plane_occlusion, bounce=bounce)
    close = np.all(np.abs(rgb - want) <= 1e-3 * np.abs(want) + 1e-5, axis=1)
    assert close.mean() > 0.99
    scene.wenv.bounce_light = False
    assert shade_op(view="CAMERA") == {"FINISHED"}
    _, black = attribute(plane)
    under = np.hypot(pp[:, 0], pp[:, 1]) < 1.5
    assert np.all(rgb[under].sum(1) > black[under].sum(1) * 1.01)


def test_light_linking_is_honoured(scene):
    """The start-up Light over a plane under the cube (shadows on): a receiver collection that
    includes only the cube leaves the plane unlit by it, one that only excludes the cube lights the
    plane as before; a blocker collection that excludes the cube (or includes only the plane) takes
    the cube's shadow of that Light away, exactly as a Light casting no shadow, while the World's
    shadows stay; one including the cube keeps it."""
    from addon import lamps as addon_lamps
    env_world(scene, "sunset", strength=0.3)
    plane = add_plane_under_cube()
    light = bpy.data.objects["Light"]
    light.hide_render = False
    light.data.energy = 3000.0
    scene.wenv.shadows, scene.wenv.bounce_light = True, False

    def shaded():
        bpy.context.view_layer.update()
        assert shade_op(view="CAMERA") == {"FINISHED"}
        return attribute(plane)[1].copy()

    def linking(kind, **states):
        coll = bpy.data.collections.new(f"{kind}-{len(bpy.data.collections)}")
        setattr(light.light_linking, f"{kind}_collection", coll)
        for name, state in states.items():
            coll.objects.link(bpy.data.objects[name])
            coll.collection_objects[len(coll.objects) - 1].light_linking.link_state = state
    lit = shaded()
    light.hide_render = True
    world_only = shaded()
    light.hide_render = False
    assert lit.sum() > 1.5 * world_only.sum()
    linking("receiver", Cube="INCLUDE")
    np.testing.assert_allclose(shaded(), world_only, rtol=1e-5, atol=1e-6)
    linking("receiver", Cube="EXCLUDE")
    np.testing.assert_allclose(shaded(), lit, rtol=1e-5, atol=1e-6)
    light.light_linking.receiver_collection = None

    light.data.use_shadow = False
    unblocked = shaded()
    light.data.use_shadow = True
    in_shadow = np.abs(unblocked - lit).sum(1) > 0.05 * np.abs(unblocked).sum(1)
    assert in_shadow.sum() >= 5  # the cube's shadow of the Light on the plane
    for states in ({"Cube": "EXCLUDE"}, {plane.name: "INCLUDE"}):
        linking("blocker", **states)
        np.testing.assert_allclose(shaded(), unblocked, rtol=1e-5, atol=1e-6)
    linking("blocker", Cube="INCLUDE")
    np.testing.assert_allclose(shaded(), lit, rtol=1e-5, atol=1e-6)
    # a new state is a change of the lamps (the live mode shades again)
    before = addon_lamps.signature(scene)
    light.light_linking.blocker_collection.collection_objects[0].light_linking.link_state = "EXCLUDE"
    assert addon_lamps.signature(scene) != before


def test_glossy_bounce_shows_a_metal_blocker_in_a_metal_floor(scene):
    """A metal floor under a metal cube (lobes alone): with Glossy Bounce, the floor shows what the
    cube reflects towards it where it mirrors the cube, several times brighter than the cube's
    albedo sent as if diffuse (the bounce without it); far from the cube, about the same."""
    env_world(scene, "sunset")
    plane = add_plane_under_cube()
    plane.data.materials.clear()
    set_material(plane, diffuse=(0.0, 0.0, 0.0), lobes=((0.15, 10.0, "GGX"),))
    cube = bpy.data.objects["Cube"]
    cube.data.materials.clear()
    set_material(cube, diffuse=(0.0, 0.0, 0.0), lobes=((0.15, 10.0, "GGX"),))
    scene.wenv.shadows = True
    shaded = {}
    for glossy in (False, True):
        scene.wenv.glossy_bounce = glossy
        assert shade_op(view="CAMERA") == {"FINISHED"}
        shaded[glossy] = attribute(plane)[1].sum(1)
    p, _ = world_arrays(plane, corner=False)
    near = np.hypot(p[:, 0], p[:, 1]) < 1.3
    assert np.mean(shaded[True][near]) > 1.2 * np.mean(shaded[False][near])
    assert np.count_nonzero(shaded[True][near] > 3 * shaded[False][near]) >= 4  # where it mirrors the cube
    far = np.hypot(p[:, 0], p[:, 1]) > 3.0
    assert np.mean(np.abs(shaded[True][far] - shaded[False][far])) < 0.05 * np.mean(shaded[False][far])


def test_the_sending_maps_widen_narrow_lobes():
    """The sending maps are shaded with lobes no narrower than engine.SENDING_ROUGHNESS (a sun's
    highlight caught on a texel centre would otherwise spread over its neighbours): a Principled's
    Roughness and Coat Roughness, a Cook-Torrance lobe's alpha and textured roughness are raised to
    it, wider ones kept, a measured BRDF kept as it is."""
    least = engine.SENDING_ROUGHNESS
    key = ("PRINCIPLED", tuple(sorted({"roughness": 0.1, "coat_roughness": 0.9, "metallic": 1.0}.items())))
    widened = dict(engine.sending_key(key)[1])
    assert widened == {"roughness": least, "coat_roughness": 0.9, "metallic": 1.0}
    lobes = (((1.0, 1.0, 1.0), 0.01, 1.5, "GGX"), ((1.0, 1.0, 1.0), 0.9, 1.5, "GGX"))
    _, _, _, wide = engine.sending_key(("COOK_TORRANCE", (0.1, 0.1, 0.1), "SMITH", lobes))
    assert [a for _, a, _, _ in wide] == [pytest.approx(engine.alpha_from_roughness(least)), 0.9]
    measured = ("MEASURED", "x.binary", (1, 2))
    assert engine.sending_key(measured) == measured
    inputs = engine.sending_inputs({"roughness": np.float32([0.05, 0.9]), "base_color": np.ones((2, 3), np.float32)})
    np.testing.assert_allclose(inputs["roughness"], [least, 0.9])
    assert np.array_equal(inputs["base_color"], np.ones((2, 3), np.float32))


def test_what_a_blocker_sends_is_read_towards_each_hit(monkeypatch):
    """The sending maps (engine.sent_light: each vertex's radiance at 8 x 8 directions of its
    hemisphere) read at a hit (Occlusion.read_sent) give what the hit triangle's corners, shaded
    with the ray's reverse as their view, send back: within the maps' spacing for a glossy lobe of
    alpha 0.25 (closer with finer maps), and exactly for a Lambert (the same light every way)."""
    from tests.helpers.measure import relative_rmse
    from tests.test_shadows import sky, sphere_on_plane

    p, t, n = sphere_on_plane()
    occlusion = wenv.Occluders(p, t).occlusion(p, n, resolution=8)
    data = meshes.MeshData("POINT", p, n, np.zeros(len(p), np.int32))
    hits = occlusion.hits
    pick = np.random.default_rng(3).choice(len(hits["vertex"]), 24, replace=False)
    glossy = wenv.CookTorrance(0.05, [dict(alpha=0.25, specular=(0.9, 0.6, 0.3), ior=1.5)])
    for material, bounds in ((glossy, {8: 0.2, 16: 0.05}), (wenv.Lambert(0.6), {8: 1e-4})):
        shader = wenv.Shader(sky((30.0, 35.0)), material, quality="draft")
        exact = np.array([np.einsum("c,cx->x", hits["weights"][k], shader.shade(
            n, -hits["direction"][k], occlusion=occlusion, bounce=None)[t[hits["triangle"][k]]]) for k in pick])
        for side, bound in bounds.items():
            monkeypatch.setattr(engine, "SENDING_SIDE", side)
            at_hits = occlusion.read_sent(n, engine.sent_light(shader, data, occlusion))
            assert relative_rmse(at_hits[pick], exact) < bound


def test_a_moved_object_recasts_only_what_sees_it(scene):
    """The cube moved over the plane, beside a wall: the plane's occlusion is made from the one
    before, casting only the vertices whose rays met the cube or meet it now (not those behind the
    wall), and the colours are those of casting everything anew."""
    env_world(scene, "sunset")
    bpy.ops.mesh.primitive_cube_add(location=(-1.2, 0.0, 0.75), scale=(0.1, 4.0, 2.25))
    plane = add_plane_under_cube()
    scene.wenv.shadows = True
    engine.shadows.clear()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    bpy.data.objects["Cube"].location.x += 1.5
    assert shade_op(view="CAMERA") == {"FINISHED"}

    def plane_occlusion():  # the cubes' own occlusions are kept too: their light is the plane's bounce
        (occlusion,) = [o for o in engine.shadows._occlusions.values() if o.vertices == len(plane.data.vertices)]
        return occlusion
    occlusion = plane_occlusion()
    assert 0 < occlusion.cast_vertices < occlusion.vertices
    _, moved = attribute(plane)
    engine.shadows.clear()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    again = plane_occlusion()
    assert again.cast_vertices == again.vertices
    np.testing.assert_array_equal(attribute(plane)[1], moved)


def test_the_shade_operator_reports_its_shadow_rays(scene, capfd):
    """Casting the occlusion is progress the operator shows (printed in a background run), and a
    pass that casts no new ray shows none."""
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    env_world(scene, "forest")
    set_material(add_monkey(subdivisions=1))
    scene.wenv.shadows = True
    engine.shadows.clear()
    assert shade_op(view="CAMERA") == {"FINISHED"}
    printed = capfd.readouterr().out
    assert "wenv: casting shadow rays: 0 %" in printed and "wenv: casting shadow rays: 100 %" in printed
    assert shade_op(view="CAMERA") == {"FINISHED"}
    assert "casting shadow rays" not in capfd.readouterr().out


def test_a_cancelled_refinement_stops_its_rays(scene):
    """A refinement cancelled while the occlusion is cast stops there: refine() returns None and the
    occlusion is not kept half made; the next pass casts it whole."""
    import threading
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    env_world(scene, "forest")
    obj = add_monkey(subdivisions=1)
    set_material(obj)
    scene.wenv.shadows = True
    engine.shadows.clear()
    plan = shading.plan_shading(scene, bpy.context.evaluated_depsgraph_get(), [obj], views.camera_view(scene),
                                bpy.data.images)
    cancelled = threading.Event()
    cancelled.set()
    assert plan.refine("draft", 0.05, lambda fraction: None, cancelled) is None
    assert not engine.shadows._occlusions
    assert shade_op(view="CAMERA") == {"FINISHED"} and len(engine.shadows._occlusions) == 1
