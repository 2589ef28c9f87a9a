"""Bakes: the core's texels of a UV map and margin, and the add-on's bake of every texel of an image.

The texels a bake must shade are found here independently (each texel centre tested against each
UV triangle with numpy), their positions and normals interpolated with mathutils' data, and shaded
by fresh core shaders; the bake's pixels are compared with that."""
import json

import numpy as np
import pytest

import wenv

import bpy  # noqa: E402  (installed by scripts/setup.sh; missing, the tests fail rather than skip)

from addon import bake, bevel, compat, engine, lamps, materials, meshes, textures, views  # noqa: E402

from conftest import hdri_path  # noqa: E402
from test_addon import (as_the_interface_runs, animate_camera, attribute, env_world, image_sequence,  # noqa: E402,F401
                        principled_material, registered, scene, select_only)

SENTINEL = np.float32([0.123, 0.456, 0.789, 0.5])
BUMP = compat.BUMP_MAP_CORRECTION  # (the bump terminator of the Blender running)


# ---------------------------------------------------------------------------------------------
# The core: texels in UV triangles, and the margin


def grid_uv(n, seed=0):
    """UVs of an n x n grid of quads over [0, 1]^2, each split along a random diagonal, every other
    triangle wound the other way."""
    rng = np.random.default_rng(seed)
    g = np.linspace(0.0, 1.0, n + 1, dtype=np.float32)
    uv = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    tris = []
    for j in range(n):
        for i in range(n):
            a, b, c, d = j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i
            pair = [(a, b, c), (a, c, d)] if rng.random() < 0.5 else [(a, b, d), (b, c, d)]
            tris += [t if rng.random() < 0.5 else t[::-1] for t in pair]
    return uv, np.array(tris)


def centres(width, height):
    ys, xs = np.mgrid[0:height, 0:width]
    return np.stack([(xs + 0.5) / width, (ys + 0.5) / height], axis=-1)


def test_uv_texels_cover_every_texel_of_a_tiling_once():
    """A grid of triangles of both windings whose edges pass through texel centres (7 x 7 quads on 56
    and 35 texels): each centre belongs to exactly one triangle, and its weights give it back."""
    uv, tris = grid_uv(7)
    for width, height in ((56, 35), (64, 64), (1, 1)):
        tri, weights, covered, overlapped = wenv.uv_texels(uv, tris, width, height)
        assert tri.shape == (height, width) and weights.shape == (height, width, 2)
        assert covered == width * height and overlapped == 0 and (tri >= 0).all()
        corners = uv[tris[tri]]  # (h, w, 3, 2)
        w = np.concatenate([1.0 - weights.sum(axis=-1, keepdims=True), weights], axis=-1)
        np.testing.assert_allclose((w[..., None] * corners).sum(axis=2), centres(width, height), atol=1e-5)
        assert (w > -1e-5).all()


def test_uv_texels_border_is_the_ring_outside_on_its_neighbours_triangle():
    """border=True: the texels just outside an island (8-neighbours of one inside) hold a neighbour's
    triangle as -2 - t, and their weights in it give their centres back (extrapolated)."""
    uv = np.float32([[0.3, 0.3], [0.7, 0.3], [0.7, 0.7], [0.3, 0.7]])
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    plain = wenv.uv_texels(uv, tris, 20, 20)[0]
    tri, weights, covered, _ = wenv.uv_texels(uv, tris, 20, 20, border=True)
    inside = plain >= 0
    assert np.array_equal(tri[inside], plain[inside]) and covered == inside.sum()
    ring = np.zeros_like(inside)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            ring |= np.roll(np.roll(inside, dy, 0), dx, 1)
    ring &= ~inside
    assert np.array_equal(tri <= -2, ring) and (tri[~inside & ~ring] == -1).all()
    t = np.where(tri >= 0, tri, -2 - tri)[ring]
    w = weights[ring]
    w = np.column_stack([1.0 - w.sum(axis=1), w])
    np.testing.assert_allclose(np.einsum("kc,kcd->kd", w, uv[tris[t]]), centres(20, 20)[ring], atol=1e-5)
    assert (w.min(axis=1) < 0).all()


def test_uv_texels_count_overlaps_and_name_bad_input():
    """Islands laid over each other: the first keeps each texel, the others are counted.  Bad input
    is a ValueError or TypeError naming it."""
    uv = np.float32([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.1, 0.1]])
    tri, _, covered, overlapped = wenv.uv_texels(uv, [[0, 1, 2], [0, 1, 2], [3, 1, 2]], 16, 16)
    assert covered == (tri >= 0).sum() == 120 and (tri <= 0).all()  # 120 centres under the diagonal
    alone = wenv.uv_texels(uv, [[3, 1, 2]], 16, 16)[2]
    assert overlapped == covered + alone
    with pytest.raises(ValueError, match="at least one"):
        wenv.uv_texels(uv, [[0, 1, 2]], 0, 16)
    with pytest.raises(ValueError, match="memory budget"):
        wenv.uv_texels(uv, [[0, 1, 2]], 32768, 32768)
    with pytest.raises(ValueError, match="not finite"):
        wenv.uv_texels(np.float32([[0, 0], [1, np.nan], [0, 1]]), [[0, 1, 2]], 4, 4)
    with pytest.raises(ValueError, match=r"triangles\[1\]"):
        wenv.uv_texels(uv, [[0, 1, 2], [0, 1, 4]], 4, 4)
    with pytest.raises(ValueError, match="uv must have shape"):
        wenv.uv_texels(uv[:, :1], [[0, 1, 2]], 4, 4)
    with pytest.raises(TypeError, match="uv must be"):
        wenv.uv_texels("not an array", [[0, 1, 2]], 4, 4)
    # a triangle of no area covers nothing
    assert wenv.uv_texels(uv, [[0, 1, 1]], 8, 8)[2] == 0


def test_extend_margin_fills_rings_and_nothing_beyond():
    """Margin m reaches exactly the texels within m steps (8-neighbours) of the island; an island of
    one colour extends that colour; farther texels keep theirs; margin 0 changes nothing."""
    px = np.tile(SENTINEL, (20, 20, 1))
    filled = np.zeros((20, 20), bool)
    px[8:12, 8:12] = (0.5, 0.25, 1.0, 1.0)
    filled[8:12, 8:12] = True
    before = px.copy()
    assert wenv.extend_margin(px, filled.copy(), 0) == 0 and np.array_equal(px, before)
    island = filled.copy()
    added = wenv.extend_margin(px, filled, 3)
    ys, xs = np.mgrid[0:20, 0:20]
    distance = np.maximum(np.maximum(8 - ys, ys - 11), np.maximum(8 - xs, xs - 11))
    ring = (distance >= 1) & (distance <= 3)
    assert added == ring.sum() and np.array_equal(filled, island | ring)
    np.testing.assert_allclose(px[ring], np.tile(np.float32([0.5, 0.25, 1.0, 1.0]), (ring.sum(), 1)), rtol=1e-6)
    assert np.array_equal(px[distance > 3], before[distance > 3])
    with pytest.raises(TypeError, match="pixels must be a C-contiguous float32"):
        wenv.extend_margin(px.astype(np.float64), filled, 1)


def margin_by_rings(px, filled, margin):
    """The Extend margin as its definition reads: each ring, every unfilled texel touching a filled
    one takes the mean of those it touches (summed in the 8-neighbours' row order), all at once."""
    px, filled = px.copy(), filled.copy()
    h, w = filled.shape
    for _ in range(margin):
        ring = []
        for y in range(h):
            for x in range(w):
                if filled[y, x]:
                    continue
                near = [(b, a) for b in range(max(y - 1, 0), min(y + 2, h)) for a in range(max(x - 1, 0), min(x + 2, w))
                        if filled[b, a]]
                if near:
                    total = np.zeros(px.shape[2], np.float32)
                    for b, a in near:
                        total += px[b, a]
                    ring.append((y, x, total / np.float32(len(near))))
        for y, x, value in ring:
            px[y, x], filled[y, x] = value, True
    return px, filled


@pytest.mark.parametrize("seed", range(4))
def test_extend_margin_equals_the_ring_rule_on_scattered_islands(seed):
    """Islands of random texels, shapes and channel counts: the margin the core fills ring by ring
    (visiting only each ring's texels) is the definition's, to the bit, and so is the count."""
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(5, 40, 2))
    channels = int(rng.integers(1, 5))
    px = rng.random((h, w, channels)).astype(np.float32)
    filled = rng.random((h, w)) < (0.02, 0.1, 0.3, 0.0)[seed]
    margin = int(rng.integers(1, 7))
    want_px, want_filled = margin_by_rings(px, filled, margin)
    got_px, got_filled = px.copy(), filled.copy()
    added = wenv.extend_margin(got_px, got_filled, margin)
    assert added == int(want_filled.sum() - filled.sum())
    assert np.array_equal(got_filled, want_filled) and np.array_equal(got_px, want_px)


def test_corner_values_at_sums_as_numpy_does_and_names_bad_corners():
    """Values per face corner read at barycentric points: each point's three terms summed in corner
    order as numpy sums them -- float32 values in float32, float64 ones in float64 rounded to
    float32 -- to the bit, for one column and several."""
    rng = np.random.default_rng(3)
    weights = rng.normal(0.33, 0.4, (500, 3)).astype(np.float32)  # outside the triangle too (the border ring)
    corners = rng.integers(0, 50, (500, 3))
    for values in (rng.normal(size=(50, 3)), rng.normal(size=(50, 1)), rng.normal(size=(50, 4)).astype(np.float32),
                   rng.normal(size=(50, 1)).astype(np.float32)):
        v = values
        want = (weights[:, :1] * v[corners[:, 0]] + weights[:, 1:2] * v[corners[:, 1]]
                + weights[:, 2:] * v[corners[:, 2]]).astype(np.float32)
        got = wenv.corner_values_at(values, corners, weights)
        assert got.dtype == np.float32 and np.array_equal(got, want)
        if values.dtype == np.float32:  # not the float64 sum: the test tells the two apart
            assert not np.array_equal(got, wenv.corner_values_at(values.astype(np.float64), corners, weights))
    with pytest.raises(ValueError, match=r"corners\[1\] names a row past the 50 values"):
        wenv.corner_values_at(rng.normal(size=(50, 3)), [[0, 1, 2], [0, 50, 2]], np.ones((2, 3), np.float32))
    with pytest.raises(ValueError, match="corners and weights"):
        wenv.corner_values_at(rng.normal(size=(50, 3)), [[0, 1, 2]], np.ones((2, 3), np.float32))
    with pytest.raises(TypeError, match="values"):
        wenv.corner_values_at("not an array", [[0, 1, 2]], np.ones((1, 3), np.float32))


# ---------------------------------------------------------------------------------------------
# The add-on: independent texel centres


def mesh_corners(obj):
    """World positions, world normals (inverse transpose, normalised later) and UVs per face corner,
    and the loop triangles' corners, read with mathutils."""
    me = obj.data
    m = obj.matrix_world
    nm = m.to_3x3().inverted().transposed()
    p = np.array([tuple(m @ me.vertices[l.vertex_index].co) for l in me.loops], np.float64)
    n = np.array([tuple(nm @ c.vector) for c in me.corner_normals], np.float64)
    uv = np.array([tuple(d.uv) for d in me.uv_layers.active.data], np.float64)
    tris = np.array([tuple(t.loops) for t in me.loop_triangles])
    return p, n, uv, tris


def independent_texels(uv, tris, width, height):
    """(texel flat indices, corners (k, 3), barycentric weights (k, 3)) of the texel centres inside a
    UV triangle or on its edge (the first triangle found keeps a centre on an edge two share: both
    give the same point there)."""
    found = {}
    for t in tris:
        q = uv[t] * (width, height)
        lo, hi = np.floor(q.min(axis=0)).astype(int), np.ceil(q.max(axis=0)).astype(int)
        xs, ys = np.meshgrid(np.arange(max(lo[0], 0), min(hi[0] + 1, width)), np.arange(max(lo[1], 0), min(hi[1] + 1, height)))
        cx, cy = xs + 0.5, ys + 0.5
        area = (q[1, 0] - q[0, 0]) * (q[2, 1] - q[0, 1]) - (q[2, 0] - q[0, 0]) * (q[1, 1] - q[0, 1])
        if abs(area) < 1e-12:
            continue
        wb = ((cx - q[0, 0]) * (q[2, 1] - q[0, 1]) - (q[2, 0] - q[0, 0]) * (cy - q[0, 1])) / area
        wc = ((q[1, 0] - q[0, 0]) * (cy - q[0, 1]) - (cx - q[0, 0]) * (q[1, 1] - q[0, 1])) / area
        wa = 1.0 - wb - wc
        inside = (wa >= -1e-9) & (wb >= -1e-9) & (wc >= -1e-9)
        for x, y, a, b, c in zip(xs[inside], ys[inside], wa[inside], wb[inside], wc[inside]):
            found.setdefault(y * width + x, (t, (a, b, c)))
    texels = np.array(sorted(found))
    return texels, np.array([found[k][0] for k in texels]), np.array([found[k][1] for k in texels])


def expected_radiance(obj, width, height, shader, eye, lit=()):
    """The core's shading of the texel centres independent_texels finds (with the lamps `lit`):
    (texels, radiance)."""
    p, n, uv, tris = mesh_corners(obj)
    texels, corners, w = independent_texels(uv, tris, width, height)
    points = np.einsum("kc,kcd->kd", w, p[corners]).astype(np.float32)
    normals = np.einsum("kc,kcd->kd", w, n[corners])
    normals = (normals / np.linalg.norm(normals, axis=1, keepdims=True)).astype(np.float32)
    return texels, shader.shade_mesh(points, normals, eye, lamps=list(lit)), (points, normals, uv, corners, w)


def filled_image(name, width, height, float_buffer=True):
    image = bpy.data.images.new(name, width, height, alpha=True, float_buffer=float_buffer)
    image.pixels.foreach_set(np.tile(SENTINEL, width * height))
    return image


def pixels(image):
    px = np.empty(image.size[0] * image.size[1] * 4, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(-1, 4)


def bake_now(scene, obj, image, margin=0, uv_map=None, progress=None):
    return bake.bake(scene, bpy.context.evaluated_depsgraph_get(), obj, image, views.camera_view(scene), bpy.data,
                     uv_map=uv_map, margin=margin, progress=progress, view_source="CAMERA")


def draft_shader(material, hdri="sunset"):
    return wenv.Shader(wenv.load_environment(hdri_path(hdri)), material, quality="draft")


def grid(cuts=8, size=4.0, material=None):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts + 1, y_subdivisions=cuts + 1, size=size)
    plane = bpy.context.object
    plane.data.shade_smooth()
    plane.data.materials.append(material or principled_material("paint", roughness=0.4))
    select_only(plane)
    return plane


def principled_of(mat, **changes):
    node = mat.node_tree.nodes["Principled BSDF"]
    inputs = dict(base_color=tuple(node.inputs["Base Color"].default_value)[:3],
                  roughness=node.inputs["Roughness"].default_value, metallic=node.inputs["Metallic"].default_value,
                  ior=node.inputs["IOR"].default_value)
    inputs.update(changes)
    return wenv.Principled(**inputs)


# ---------------------------------------------------------------------------------------------
# The add-on: what a bake writes


@pytest.mark.parametrize("shape", ["plane", "sphere", "plane under lamps"])
def test_a_bake_equals_the_core_at_the_texel_centres(scene, shape):
    """Every texel of a plane's and a UV sphere's islands is the core's shading at the point of the
    mesh under its centre (position and smooth normal interpolated over its triangle), the scene's
    lamps too (a point lamp near the plane: each texel's own distance to it); the texels outside the
    islands keep what they held (margin 0)."""
    env_world(scene, "sunset")
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    lit = []
    if shape == "plane under lamps":
        light = bpy.data.objects["Light"]
        light.hide_render, light.location = False, (0.5, -0.4, 0.8)
        light.data.type, light.data.energy, light.data.shadow_soft_size = "POINT", 300.0, 0.1
        bpy.context.view_layer.update()
        settings, notes = lamps.read_lamps(scene)
        assert len(settings) == 1 and not notes
        lit = engine.make_lamps(settings)
    if shape.startswith("plane"):
        obj = grid()
        width, height = 32, 32
    else:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=1.5)
        obj = bpy.context.object
        obj.data.shade_smooth()
        obj.data.materials.append(principled_material("metal", base=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.3))
        width, height = 96, 48
    image = filled_image("bake", width, height)
    count, notes = bake_now(scene, obj, image)
    assert not notes
    eye = tuple(scene.camera.matrix_world.translation)
    texels, want, _ = expected_radiance(obj, width, height, draft_shader(principled_of(obj.active_material)), eye,
                                        lit)
    if lit:  # (the lamp near the plane: most of its light, and far from even over it)
        world_only = expected_radiance(obj, width, height, draft_shader(principled_of(obj.active_material)), eye)[1]
        assert np.mean(want) > 2 * np.mean(world_only) and np.ptp(want[:, 0]) > np.mean(want[:, 0])
    got = pixels(image)
    baked = ~np.all(got == SENTINEL, axis=1)
    assert np.array_equal(np.flatnonzero(baked), texels) and count == len(texels)
    if shape.startswith("plane"):
        assert count == width * height
    np.testing.assert_allclose(got[texels, :3], want, rtol=2e-4, atol=1e-5)
    assert (got[texels, 3] == 1.0).all()
    assert obj.data.uv_layers.active.name == image.wenv.uv_map and image.wenv.texels == count


def test_margin_reaches_only_the_margin(scene):
    """UVs in the middle quarter of the image: a margin of 3 changes the texels within 3 of the
    island and no other; its first ring is the plane continued past the island's edge, shaded
    there."""
    env_world(scene, "sunset")
    plane = grid(cuts=2)
    for d in plane.data.uv_layers.active.data:
        d.uv = 0.25 + 0.5 * d.uv[0], 0.25 + 0.5 * d.uv[1]
    image = filled_image("margin", 40, 40)
    count, _ = bake_now(scene, plane, image, margin=3)
    assert count == 20 * 20
    got = pixels(image)
    changed = ~np.all(got == SENTINEL, axis=1).reshape(40, 40)
    ys, xs = np.mgrid[0:40, 0:40]
    distance = np.maximum(np.maximum(10 - ys, ys - 29), np.maximum(10 - xs, xs - 29))
    assert np.array_equal(changed, distance <= 3)
    ring = (distance == 1).ravel()
    c = centres(40, 40).reshape(-1, 2)[ring]
    points = np.column_stack([(c - 0.5) * 8.0, np.zeros(len(c))]).astype(np.float32)  # UV 0.25..0.75 over 4 units
    eye = tuple(scene.camera.matrix_world.translation)
    want = draft_shader(principled_of(plane.active_material)).shade_mesh(points, np.tile(np.float32([0, 0, 1]),
                                                                                         (len(c), 1)), eye)
    np.testing.assert_allclose(got[ring, :3], want, rtol=2e-4, atol=1e-5)


def test_textures_and_normal_maps_are_read_at_each_texel(scene):
    """On a plane of four vertices, a Base Color image of 4 x 4 squares and a tangent-space normal map
    of two halves tilted apart (both Closest): each texel is shaded with its own square's colour and
    its own half's normal -- detail the vertices could not hold."""
    env_world(scene, "sunset")
    mat = principled_material("textured", roughness=0.4)
    tree = mat.node_tree
    squares = bpy.data.images.new("squares", 4, 4, float_buffer=True)
    colours = np.random.default_rng(3).uniform(0.05, 0.95, (4, 4, 3)).astype(np.float32)
    squares.pixels.foreach_set(np.concatenate([colours, np.ones((4, 4, 1), np.float32)], axis=2).ravel())
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = squares, "Closest"
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    tilts = bpy.data.images.new("tilts", 2, 1, float_buffer=True)
    tilts.colorspace_settings.name = "Non-Color"  # first: setting it remakes a generated image's pixels
    left, right = np.float32([0.4, 0.0, np.sqrt(0.84)]), np.float32([-0.3, 0.2, np.sqrt(0.87)])
    tilts.pixels.foreach_set(np.concatenate([0.5 * left + 0.5, [1.0], 0.5 * right + 0.5, [1.0]]).astype(np.float32))
    normal_tex = tree.nodes.new("ShaderNodeTexImage")
    normal_tex.image, normal_tex.interpolation = tilts, "Closest"
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(normal_tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], tree.nodes["Principled BSDF"].inputs["Normal"])
    plane = grid(cuts=0, material=mat)
    image = filled_image("textured bake", 32, 32)
    count, notes = bake_now(scene, plane, image)
    assert count == 32 * 32 and not any(n.endswith("detail finer than the mesh is lost") for n in notes)
    c = centres(32, 32).reshape(-1, 2)
    base = colours[np.floor(c[:, 1] * 4).astype(int), np.floor(c[:, 0] * 4).astype(int)]
    normal = np.where((c[:, :1] < 0.5), left, right).astype(np.float32)  # u along +X, v along +Y: the tangent frame is the world's
    points = np.column_stack([(c - 0.5) * 4.0, np.zeros(len(c))]).astype(np.float32)
    eye = tuple(scene.camera.matrix_world.translation)
    up = np.tile(np.float32([0, 0, 1]), (len(c), 1))  # the plane's own, which the map bends
    want = draft_shader(principled_of(mat)).shade_mesh(points, normal, eye, base_color=base, smooth_normals=up,
                                                       bump_map_correction=BUMP)
    np.testing.assert_allclose(pixels(image)[:, :3], want, rtol=2e-4, atol=1e-5)


def test_a_bump_node_is_read_at_each_texel(scene):
    """A Bump node whose Height rises linearly along u (a ramp image, Linear, Extend): away from the
    ramp's ends each texel's normal is tilted against the height's gradient, Cycles' normalize(N -
    Distance x grad h), as a finite difference of one texel reads it."""
    env_world(scene, "sunset")
    mat = principled_material("bumped", roughness=0.4)
    tree = mat.node_tree
    ramp = bpy.data.images.new("ramp", 64, 1, float_buffer=True)
    ramp.colorspace_settings.name = "Non-Color"
    values = (np.arange(64, dtype=np.float32) + 0.5) / 64
    ramp.pixels.foreach_set(np.column_stack([values, values, values, np.ones(64)]).astype(np.float32).ravel())
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.extension = ramp, "EXTEND"
    bump = tree.nodes.new("ShaderNodeBump")
    bump.inputs["Distance"].default_value = 2.0
    tree.links.new(tex.outputs["Color"], bump.inputs["Height"])
    tree.links.new(bump.outputs["Normal"], tree.nodes["Principled BSDF"].inputs["Normal"])
    plane = grid(cuts=0, material=mat)
    image = filled_image("bumped bake", 32, 32)
    bake_now(scene, plane, image)
    c = centres(32, 32).reshape(-1, 2)
    inside = (c[:, 0] > 0.1) & (c[:, 0] < 0.85)
    # height u over a plane 4 units wide: grad h = (1/4, 0, 0)
    normal = np.tile(np.float32([-2.0 * 0.25, 0.0, 1.0]) / np.hypot(0.5, 1.0), (len(c), 1))
    points = np.column_stack([(c - 0.5) * 4.0, np.zeros(len(c))]).astype(np.float32)
    eye = tuple(scene.camera.matrix_world.translation)
    up = np.tile(np.float32([0, 0, 1]), (len(c), 1))  # the plane's own, which the Bump node bends
    want = draft_shader(principled_of(mat)).shade_mesh(points, normal.astype(np.float32), eye, smooth_normals=up,
                                                       bump_map_correction=BUMP)
    np.testing.assert_allclose(pixels(image)[inside, :3], want[inside], rtol=1e-3, atol=1e-5)


def test_a_bevel_node_rounds_a_fold_at_each_texel(scene):
    """A grid folded along x = 0 (its right half tilted), flat, whose Principled Normal is a Bevel
    node: each texel is shaded at the core's bevelled normal of its centre (wenv.Occluders.bevel over
    the fold's triangles, each its own normal), bent from the face's own."""
    env_world(scene, "sunset")
    scene.wenv.shadows = False
    mat = principled_material("bevelled", roughness=0.4)
    tree = mat.node_tree
    node = tree.nodes.new("ShaderNodeBevel")
    node.inputs["Radius"].default_value = 0.5
    tree.links.new(node.outputs["Normal"], tree.nodes["Principled BSDF"].inputs["Normal"])
    plane = grid(cuts=1, material=mat)
    mesh = plane.data
    co = np.array([tuple(v.co) for v in mesh.vertices], np.float32)
    co[:, 2] = 0.8 * np.maximum(co[:, 0], 0.0)
    mesh.vertices.foreach_set("co", co.ravel())
    mesh.shade_flat()
    mesh.update()
    bpy.context.view_layer.update()
    image = filled_image("bevelled bake", 32, 32)
    bake_now(scene, plane, image)
    c = centres(32, 32).reshape(-1, 2)
    x, y = (c[:, 0] - 0.5) * 4.0, (c[:, 1] - 0.5) * 4.0
    points = np.column_stack([x, y, 0.8 * np.maximum(x, 0.0)]).astype(np.float32)
    tilted = np.float32([-0.8, 0.0, 1.0]) / np.float32(np.hypot(0.8, 1.0))
    own = np.where((x < 0.0)[:, None], np.float32([0.0, 0.0, 1.0]), tilted).astype(np.float32)
    triangles = np.array([tuple(t.vertices) for t in mesh.loop_triangles])
    left = co[triangles].mean(axis=1)[:, 0] < 0.0
    corner_normals = np.repeat(np.where(left[:, None], np.float32([0.0, 0.0, 1.0]), tilted), 3, axis=0)
    bent = wenv.Occluders(co, triangles).bevel(points, corner_normals.astype(np.float32), 0.5)
    eye = tuple(scene.camera.matrix_world.translation)
    shader = draft_shader(principled_of(mat))
    want = shader.shade_mesh(points, bent, eye, smooth_normals=own, bump_map_correction=BUMP)
    np.testing.assert_allclose(pixels(image)[:, :3], want, rtol=1e-3, atol=1e-5)
    unbent = shader.shade_mesh(points, own, eye)
    near = np.abs(x) < 0.3
    assert np.abs(want - unbent)[near].mean() > 0.05 * unbent[near].mean()  # (it bevels)
    # at the vertices (each face's corners: the mesh is flat), the same normals at the corners, and
    # the report says where it is read
    select_only(plane)
    assert bpy.ops.wenv.shade(view="CAMERA") == {"FINISHED"}
    corner = np.array([mesh.loops[k].vertex_index for k in range(len(mesh.loops))])
    face_of = np.concatenate([[f.index] * f.loop_total for f in mesh.polygons])
    left_face = np.array([f.center.x for f in mesh.polygons]) < 0.0
    face_normal = np.where(left_face[:, None], np.float32([0.0, 0.0, 1.0]), tilted)[face_of].astype(np.float32)
    at_corners = wenv.Occluders(co, triangles).bevel(co[corner], corner_normals.astype(np.float32), 0.5)
    domain, shaded = attribute(plane)
    assert domain == "CORNER"
    np.testing.assert_allclose(shaded, shader.shade_mesh(co[corner], at_corners, eye, smooth_normals=face_normal,
                                                         bump_map_correction=BUMP),
                               rtol=1e-3, atol=1e-5)
    assert any("'Normal' from a Bevel node is read at the vertices" in n for n in materials.principled_notes(mat))
    # a Radius from the nodes, 0.5 + 0.1 y: each texel bevelled at its own
    split, radius = tree.nodes.new("ShaderNodeSeparateXYZ"), tree.nodes.new("ShaderNodeMath")
    radius.operation = "MULTIPLY_ADD"
    radius.inputs[1].default_value, radius.inputs[2].default_value = 0.1, 0.5
    tree.links.new(tree.nodes.new("ShaderNodeNewGeometry").outputs["Position"], split.inputs[0])
    tree.links.new(split.outputs["Y"], radius.inputs[0])
    tree.links.new(radius.outputs[0], node.inputs["Radius"])
    bake_now(scene, plane, image)
    varied = wenv.Occluders(co, triangles).bevel(points, corner_normals.astype(np.float32),
                                                 (0.5 + 0.1 * points[:, 1]).astype(np.float32))
    np.testing.assert_allclose(pixels(image)[:, :3], shader.shade_mesh(points, varied, eye, smooth_normals=own,
                                                                       bump_map_correction=BUMP),
                               rtol=1e-3, atol=1e-5)
    assert np.abs(varied - bent).max() > 0.01
    assert not any("Bevel" in n and "Radius" in n for n in materials.principled_notes(mat))


def test_a_bevel_on_a_dense_mesh_is_interpolated_from_its_vertices(scene):
    """The fold of a grid of 0.1 m quads, smooth, bevelled at a Radius of 0.5: a bake's texels read
    the normal interpolated from their triangle's corners where it turns linearly over the triangle
    (bevel.LINEAR_DEGREES at its centre), within 0.5 degrees of each texel's own integral (0.34
    here)."""
    plane = grid(cuts=39)
    mesh = plane.data
    co = np.array([tuple(v.co) for v in mesh.vertices], np.float32)
    co[:, 2] = 0.8 * np.maximum(co[:, 0], 0.0)
    mesh.vertices.foreach_set("co", co.ravel())
    mesh.update()
    bpy.context.view_layer.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    corner_vert = meshes.corner_vertices(mesh)
    sites, _ = bake.texel_sites(textures.corner_uvs(mesh, mesh.uv_layers.active), textures.triangle_corners(mesh),
                                128, 128, 1024)
    normals = np.empty(len(mesh.loops) * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    points, own = sites.at(co[corner_vert]), sites.at(normals.reshape(-1, 3))
    got = bevel.normals(plane, depsgraph, points, own, 0.5, sites=sites)
    direct = bevel.normals(plane, depsgraph, points, own, 0.5)
    apart = np.degrees(np.arccos(np.clip((got * direct).sum(axis=1), -1.0, 1.0)))
    assert (apart > 1e-3).mean() > 0.02  # (texels about the fold interpolated: not each its own)
    assert apart.max() < 0.5, apart.max()
    turned = np.degrees(np.arccos(np.clip((direct * own).sum(axis=1) / np.linalg.norm(own, axis=1), -1.0, 1.0)))
    assert turned.max() > 5.0  # (the fold is rounded)


def world_vertices(obj):
    """World positions and normals per vertex, and the loop triangles' vertices, read with mathutils."""
    m = obj.matrix_world
    nm = m.to_3x3().inverted().transposed()
    p = np.array([tuple(m @ v.co) for v in obj.data.vertices], np.float32)
    n = np.array([tuple((nm @ v.normal).normalized()) for v in obj.data.vertices], np.float32)
    return p, n, np.array([tuple(t.vertices) for t in obj.data.loop_triangles])


@pytest.mark.parametrize("bounce", [False, True])
def test_each_texel_casts_its_own_shadow_rays(scene, bounce):
    """With shadows on, every texel of a plane under a ball is the core's shading at its centre with
    its own occlusion against the plane and the ball (point rays), direct light alone or with what
    the rays meet sending its vertices' diffuse light (each mesh's own, with its own shadows), plus
    what its coarser masks miss: 65,536 texels cast 11 x 11 rays (the finest within 2^23), each
    2 x 2 block of the flat plane's texels the mask of its first, the plane's 16 vertices 16 x 16,
    and the vertices' shading with 16 x 16 masks less that with 11 x 11 ones (point rays both) is
    added, interpolated over the triangle.  The shadow is the texels', not the plane's few
    vertices'."""
    env_world(scene, "sunset")
    bpy.data.objects.remove(bpy.data.objects["Cube"])
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=0.6, location=(0.3, 0.0, 0.8))
    ball = bpy.context.object
    ball.data.shade_smooth()
    ball.data.materials.append(principled_material("metal", base=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.3))
    plane = grid(cuts=3, size=6.0)
    scene.wenv.shadows, scene.wenv.bounce_light, scene.wenv.glossy_bounce = True, bounce, False
    size = 256
    image = filled_image("shadowed bake", size, size)
    count, _ = bake_now(scene, plane, image)
    got = pixels(image)[:, :3]

    (pp, pn, pt), (bp, bn, bt) = world_vertices(plane), world_vertices(ball)
    occluders = wenv.Occluders(np.vstack([pp, bp]), np.vstack([pt, bt + len(pp)]))
    eye = tuple(scene.camera.matrix_world.translation)
    plane_shader = draft_shader(principled_of(plane.active_material))
    texels, _, (points, normals, _, corners, w) = expected_radiance(plane, size, size, plane_shader, eye)
    assert count == len(texels) == size * size
    light = None
    if bounce:
        ball_shader = draft_shader(principled_of(ball.active_material))
        light = np.vstack([plane_shader.diffuse_light(pn, occlusion=occluders.occlusion(pp, pn, resolution=16)),
                           ball_shader.diffuse_light(bn, occlusion=occluders.occlusion(bp, bn, resolution=16))])
    # the plane is one flat island filling the image: every 2 x 2 block shares its first texel's mask
    x, y = texels % size, texels // size
    first = np.searchsorted(texels, (y - y % 2) * size + x - x % 2)
    shared = occluders.occlusion(points, normals, resolution=11, point_rays=True, masks_from=first)
    assert shared.blocked_vertices == len(texels) // 4
    want = plane_shader.shade_mesh(points, normals, eye, bounce=light, occlusion=shared)
    at_vertices = [plane_shader.shade_mesh(pp, pn, eye, bounce=light,
                                           occlusion=occluders.occlusion(pp, pn, resolution=r, point_rays=True))
                   for r in (16, 11)]
    corner_vertex = np.array([loop.vertex_index for loop in plane.data.loops])
    missed = np.einsum("kc,kcd->kd", w, (at_vertices[0] - at_vertices[1])[corner_vertex[corners]])
    assert np.abs(missed).max() > 1e-4  # the masks' sides tell apart here
    np.testing.assert_allclose(got[texels], np.maximum(want + missed, 0.0), rtol=1e-3, atol=1e-5)
    # the ball's shadow: far darker than the open sky beside it, over texels between the plane's vertices
    open_sky = plane_shader.shade_mesh(points, normals, eye)
    under = np.linalg.norm(points[:, :2] - (0.3, 0.0), axis=1) < 0.3
    assert under.sum() >= 9 and (got[texels][under].sum(axis=1) < 0.85 * open_sky[under].sum(axis=1)).all()


def test_texels_share_masks_within_a_face_not_across_seams_or_creases(scene):
    """A cube's default UV map lays its six faces out as islands that touch in the image: a 2 x 2
    block of texels shares one mask only where its texels lie next to each other on one face, never
    across a seam to another island or round one of the cube's edges; on the faces, nearly all do."""
    cube = bpy.data.objects["Cube"]
    mesh, _ = meshes.shaded_mesh(cube, bpy.context.evaluated_depsgraph_get())
    layer = textures.uv_layer(mesh, None)
    size = 125  # odd: the islands' edges fall inside blocks
    sites, _ = bake.texel_sites(textures.corner_uvs(mesh, layer), textures.triangle_corners(mesh), size, size, 1024)
    data = bake.texel_data(cube, bpy.context.evaluated_depsgraph_get(), mesh, sites, shadows=True)
    from_ = engine.masks_from(data.mask_blocks)
    sharer = from_ != np.arange(data.count)
    assert sharer.mean() > 0.7  # three of each four texels, but where blocks straddle an island's edge
    face = np.argmax(np.abs(data.normals), axis=1) * 2 + (data.normals.max(axis=1) > 0.5)  # the cube's six faces
    np.testing.assert_array_equal(face[sharer], face[from_[sharer]])
    step = 2.0 / np.sqrt(np.bincount(face, minlength=6)[face])  # a texel's side on the cube's 2 x 2 faces
    assert (np.linalg.norm(data.positions - data.positions[from_], axis=1) <= 3.0 * step).all()
    # across a seam: the texels of a block whose first lies on another face read their own masks
    x, y = sites.texels % size, sites.texels // size
    block = (y // 2) * ((size + 1) // 2) + x // 2
    ids, first = np.unique(block, return_index=True)
    mixed = face != face[first[np.searchsorted(ids, block)]]
    assert mixed.sum() > 0 and not sharer[mixed].any()


def test_bake_is_one_undo_step_that_undo_takes_back(scene):
    """The operator into an existing image and into a new one: one undo gives the image as it was
    (Blender's undo holds no pixels: the add-on puts them back), one redo the bake."""
    env_world(scene, "sunset")
    plane = grid(cuts=2)
    scene.wenv.bake_show = False
    existing = filled_image("existing", 16, 16)
    scene.wenv.bake_image = existing
    bpy.ops.ed.undo_push(message="start")
    assert as_the_interface_runs(bpy.ops.wenv.bake, view="CAMERA") == {"FINISHED"}
    baked = pixels(bpy.data.images["existing"])
    assert not np.array_equal(baked, np.tile(SENTINEL, (256, 1)))
    bpy.ops.ed.undo()
    np.testing.assert_array_equal(pixels(bpy.data.images["existing"]), np.tile(SENTINEL, (256, 1)))
    bpy.ops.ed.redo()
    np.testing.assert_array_equal(pixels(bpy.data.images["existing"]), baked)
    # a second bake of another look, undone to the first
    bpy.data.materials["paint"].node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.8
    bpy.ops.ed.undo_push(message="rougher")
    assert as_the_interface_runs(bpy.ops.wenv.bake, view="CAMERA") == {"FINISHED"}
    second = pixels(bpy.data.images["existing"])
    assert not np.array_equal(second, baked)
    bpy.ops.ed.undo()
    bpy.ops.ed.undo()
    np.testing.assert_array_equal(pixels(bpy.data.images["existing"]), baked)
    bpy.ops.ed.redo()
    bpy.ops.ed.redo()
    np.testing.assert_array_equal(pixels(bpy.data.images["existing"]), second)

    # into a new image, made by the operator: undo removes it, redo brings it back baked
    scene = bpy.context.scene
    scene.wenv.bake_image = None
    scene.wenv.bake_resolution = 8
    bpy.ops.ed.undo_push(message="no image")
    assert as_the_interface_runs(bpy.ops.wenv.bake, view="CAMERA") == {"FINISHED"}
    name = bpy.context.scene.wenv.bake_image.name
    made = pixels(bpy.data.images[name])
    bpy.ops.ed.undo()
    assert name not in bpy.data.images and bpy.context.scene.wenv.bake_image is None
    bpy.ops.ed.redo()
    np.testing.assert_array_equal(pixels(bpy.data.images[name]), made)


def test_a_bake_is_marked_stale_by_what_changes_it(scene):
    """After a bake the panel calls it current; a World, material, lamp, object or camera change calls
    it stale with what changed, and a new bake current again.  A view change of a viewport bake is
    the panel's to see (no data changes); the camera's is seen the same way."""
    env_world(scene, "sunset")
    bpy.data.objects["Light"].hide_render = False  # a lamp the bake shades (the fixture hides it)
    plane = grid(cuts=2)
    image = filled_image("watched", 8, 8)

    def settle():
        bpy.context.view_layer.update()  # runs the depsgraph handlers, as a redraw would
        return bake.staleness(bpy.data.images["watched"], bpy.context.scene)

    bake_now(scene, plane, image)
    assert settle() is None
    changes = [
        (lambda: setattr(scene.world.node_tree.nodes["Background"].inputs["Strength"], "default_value", 2.0),
         "the World changed"),
        (lambda: setattr(plane.active_material.node_tree.nodes["Principled BSDF"].inputs["Roughness"],
                         "default_value", 0.7), "a material changed"),
        (lambda: setattr(bpy.data.lights["Light"], "energy", 500.0), "a lamp changed"),
        (lambda: setattr(plane, "location", (0.0, 0.0, 0.5)), "the object moved or its mesh changed"),
        (lambda: setattr(scene.camera, "location", (1.0, -8.0, 4.0)), "the camera moved"),
        (lambda: setattr(scene.wenv, "quality", "DEFAULT"), "the scene's wenv settings changed"),
    ]
    for change, words in changes:
        change()
        assert settle() == words
        bake_now(scene, plane, bpy.data.images["watched"])
        assert settle() is None, words
    # the add-on's own writes do not: shading the plane's vertices, showing the bake
    select_only(plane)
    assert bpy.ops.wenv.shade(view="CAMERA") == {"FINISHED"}
    bake.show_in_materials(plane, image)
    assert settle() is None


def test_a_bake_that_read_other_meshes_is_stale_when_they_change(scene):
    """A bake with Shadows, or with an Ambient Occlusion node that reaches the scene, is stale when
    another mesh moves, hides or is added, or an instance is placed or moved, or with Bounce Light
    when an instanced material changes (its light); one that read only its own mesh is not, nor is
    one whose node is Only Local."""
    env_world(scene, "sunset")
    plane = grid(cuts=2)
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(0.0, 0.0, 1.0))
    cube = bpy.context.object
    filled_image("about", 8, 8)
    words = "another mesh that shadows or lights it changed"

    def settle():
        bpy.context.view_layer.update()
        return bake.staleness(bpy.data.images["about"], bpy.context.scene)

    def bake_again():
        bake_now(scene, plane, bpy.data.images["about"])
        assert settle() is None

    scene.wenv.shadows = True
    bake_again()
    changes = [lambda: setattr(cube, "location", (0.5, 0.0, 1.0)), lambda: cube.hide_set(True),
               lambda: cube.hide_set(False), lambda: setattr(cube.wenv, "casts_shadows", False),
               lambda: bpy.ops.mesh.primitive_uv_sphere_add(radius=0.2, location=(1.0, 1.0, 0.5))]
    for k, change in enumerate(changes):
        change()
        assert settle() == words, k
        bake_again()
    # an instance of a collection, placed and then moved
    blocks = bpy.data.collections.new("blocks")
    look = principled_material("look", roughness=0.4)
    block = bpy.data.objects.new("block", cube.data.copy())
    block.data.materials.append(look)
    blocks.objects.link(block)
    instancer = bpy.data.objects.new("instancer", None)
    instancer.instance_type, instancer.instance_collection = "COLLECTION", blocks
    instancer.location = (-0.5, 0.5, 1.0)
    scene.collection.objects.link(instancer)
    assert settle() == words
    bake_again()
    instancer.location = (-0.5, -0.5, 1.0)
    assert settle() == words
    bake_again()
    assert scene.wenv.bounce_light
    look.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.1, 0.5, 0.1, 1.0)
    assert settle() == words
    bake_again()
    bpy.data.materials.new("other").diffuse_color = (1.0, 0.0, 0.0, 1.0)  # a material no mesh uses
    assert settle() is None

    scene.wenv.shadows = False
    bake_again()
    cube.location = (0.0, 0.5, 1.0)
    assert settle() is None  # the bake read no other mesh
    tree = plane.active_material.node_tree
    ao = tree.nodes.new("ShaderNodeAmbientOcclusion")
    tree.links.new(ao.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    bake_again()
    cube.location = (0.0, 0.0, 1.0)
    assert settle() == words
    ao.only_local = True
    bake_again()
    cube.location = (0.5, 0.5, 1.0)
    assert settle() is None


def test_a_bake_of_an_image_sequence_is_stale_on_another_frame(scene, tmp_path):
    """A Base Color from an image sequence (frames 1-3): a frame change that shows another file calls
    the bake stale, one past the sequence's end (held at its last frame) does not, and a bake made
    before the add-on recorded sequences is not called stale for lacking the record."""
    env_world(scene, "sunset")
    plane = grid(cuts=2)
    mat = plane.active_material
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image_sequence(tmp_path, {1: (0.8, 0.2, 0.2), 2: (0.2, 0.8, 0.2), 3: (0.2, 0.2, 0.8)})
    tex.image_user.frame_duration = 3
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    image = filled_image("sequenced", 8, 8)
    scene.frame_set(3)
    bake_now(scene, plane, image)
    assert bake.staleness(image, scene) is None
    scene.frame_set(5)  # held at frame 3: the same file
    assert bake.staleness(image, scene) is None
    scene.frame_set(2)
    assert bake.staleness(image, scene) == "an image sequence or movie shows another frame"
    record = json.loads(image.wenv.state_key)
    del record["frames"]
    image.wenv.state_key = json.dumps(record)
    assert bake.staleness(image, scene) is None


def test_a_bake_shows_in_solid_mode_and_material_preview(scene):
    """Bake with Show Bake: each material gets the image in an Image Texture node, the active one
    (Solid mode's Texture colour), emitted into a Material Output for EEVEE alone; Cycles' output and
    what wenv reads of the material are unchanged.  Hide Bake removes the nodes."""
    env_world(scene, "sunset")
    plane = grid(cuts=2)
    mat = plane.active_material
    key_before = materials.slot_material_keys(plane)
    scene.wenv.bake_resolution = 16
    assert bpy.ops.wenv.bake(view="CAMERA") == {"FINISHED"}
    image = scene.wenv.bake_image
    nodes = mat.node_tree.nodes
    tex, out = nodes[bake.BAKE_NODE], nodes[bake.OUTPUT_NODE]
    assert tex.image == image and nodes.active == tex and out.target == "EEVEE"
    assert out.inputs["Surface"].links[0].from_node.inputs["Color"].links[0].from_node == tex
    cycles_out = [n for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.target == "ALL"]
    assert cycles_out and cycles_out[0].inputs["Surface"].links[0].from_node.bl_idname == "ShaderNodeBsdfPrincipled"
    assert materials.slot_material_keys(plane) == key_before
    assert bpy.ops.wenv.bake_hide() == {"FINISHED"}
    assert not any(n.name.startswith("wenv bake") for n in nodes)


def test_frame_changes_bake_again_from_the_camera(scene):
    """With Shade on Frame Change and the image's Bake on Frame Change, each frame bakes the image
    again from the camera where its animation puts it."""
    env_world(scene, "sunset")
    plane = grid(cuts=2)
    image = filled_image("per frame", 16, 16)
    animate_camera(scene.camera)
    scene.frame_set(1)
    bake_now(scene, plane, image)
    first = pixels(image).copy()
    scene.wenv.shade_on_frame_change = True
    image.wenv.bake_on_frame_change = True
    scene.frame_set(10)
    assert image.wenv.frame == 10 and not np.array_equal(pixels(image), first)
    eye = tuple(scene.camera.matrix_world.translation)
    texels, want, _ = expected_radiance(plane, 16, 16, draft_shader(principled_of(plane.active_material)), eye)
    np.testing.assert_allclose(pixels(image)[texels, :3], want, rtol=2e-4, atol=1e-5)


def test_byte_images_are_written_in_their_colour_space(scene):
    """A byte image in sRGB holds the sRGB curve of the radiance, in Non-Color the radiance itself,
    each clipped at 1 (said); another colour space is refused by name."""
    env_world(scene, "sunset")
    plane = grid(cuts=0)
    floats = filled_image("linear", 8, 8)
    bake_now(scene, plane, floats)
    linear = pixels(floats)[:, :3]
    for space in ("sRGB", "Non-Color"):
        image = bpy.data.images.new(f"bytes {space}", 8, 8, alpha=True)
        image.colorspace_settings.name = space
        image.pixels.foreach_set(np.tile(SENTINEL, 64))
        _, notes = bake_now(scene, plane, image)
        want = np.clip(linear, 0.0, 1.0)
        if space == "sRGB":
            want = np.where(want <= 0.0031308, 12.92 * want, 1.055 * want ** (1 / 2.4) - 0.055)
        np.testing.assert_allclose(pixels(image)[:, :3], want, atol=1.0 / 255)
        assert (linear > 1.0).any(axis=1).sum() == 0 or any("clipped" in n for n in notes)
    other = bpy.data.images.new("bytes other", 8, 8)
    other.colorspace_settings.name = "Linear CIE-XYZ E"
    with pytest.raises(engine.SetupError, match="Linear CIE-XYZ E"):
        bake_now(scene, plane, other)


def test_bad_bakes_are_named_errors_and_leave_the_image(scene):
    """Not a mesh, no UV map, no pixels, over the memory budget, cancelled: each a named error, the
    image untouched; overlapping islands are baked with a warning."""
    env_world(scene, "sunset")
    image = filled_image("kept", 8, 8)
    with pytest.raises(engine.SetupError, match="'Camera' is not a mesh"):
        bake_now(scene, scene.camera, image)
    plane = grid(cuts=1)
    plane.data.uv_layers.remove(plane.data.uv_layers[0])
    with pytest.raises(engine.SetupError, match="has no UV map"):
        bake_now(scene, plane, image)
    plane = grid(cuts=1)
    with pytest.raises(engine.SetupError, match="has no UV map 'nope'"):
        bake_now(scene, plane, image, uv_map="nope")
    missing = bpy.data.images.new("missing", 4, 4)
    missing.source, missing.filepath = "FILE", "/nonexistent/wenv-missing.png"  # a file gone: 0 x 0
    with pytest.raises(engine.SetupError, match="has no pixels"):
        bake_now(scene, plane, missing)
    with pytest.raises(engine.SetupError, match="over the memory budget"):
        bake.check_size(32768, 32768, scene.wenv.memory_budget)
    scene.wenv.bake_image = None
    scene.wenv.bake_resolution = 32768
    images = len(bpy.data.images)
    with pytest.raises(RuntimeError, match="32768 x 32768 bake needs .* over the memory budget"):
        bpy.ops.wenv.bake(view="CAMERA")  # an operator's error is a RuntimeError in Python
    assert len(bpy.data.images) == images
    with pytest.raises(engine.CancelledError):
        bake_now(scene, plane, image, progress=lambda fraction: fraction > 0.3)
    np.testing.assert_array_equal(pixels(image), np.tile(SENTINEL, (64, 1)))
    uv = plane.data.uv_layers.active.data
    for face in plane.data.polygons:  # every quad onto the whole square: islands overlap
        corner = np.min([tuple(uv[k].uv) for k in face.loop_indices], axis=0)
        for k in face.loop_indices:
            uv[k].uv = tuple((np.array(uv[k].uv) - corner) * 2.0)
    _, notes = bake_now(scene, plane, image)
    assert any("islands overlap" in n for n in notes)
