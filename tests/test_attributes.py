"""A mesh's attributes (the Color Attribute and Attribute nodes), its object's (Object Info) and its
geometry's (Geometry's Position and Normal) against Cycles: a 4 m grid of 36 quads, its heights
rolling, seen from straight above by an orthographic camera that it fills, its Emission fed by the
node, one sample a pixel at the pixel's centre.  The add-on reads the node at each pixel's centre as a
bake reads it at a texel's (addon/textures.py attribute_reader and row_points): points, corners,
faces and edges, each data type Cycles reads, an attribute the mesh lacks, and each output of Object
Info."""
import numpy as np
import pytest

import bpy  # noqa: E402  (installed by scripts/setup.sh; missing, the tests fail rather than skip)

from addon import ambient, bake, bevel, meshes, nodes, textures, views  # noqa: E402
from tests.helpers.cycles_pixels import pixel_scene  # noqa: E402

N = 40


@pytest.fixture(scope="module")
def grid():
    return rolling_grid()


def rolling_grid(ngons=False):
    """compare(kind, output, configure) on the rolling grid; with `ngons`, some of its faces joined
    in pairs and threes (faces of 6 and 8 corners, which Blender and Cycles triangulate)."""
    shot = pixel_scene(bpy, N)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=6, y_subdivisions=6, size=4.0)
    obj = bpy.context.object
    obj.name = "Crate.004 – ÿ"  # (Random hashes the name's UTF-8 bytes)
    obj.location.z = 0.5  # (seen from above: the pixels still fall where they did)
    obj.color, obj.pass_index = (0.3, 0.6, 0.9, 0.4), 7
    mesh = obj.data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 2] = 1.2 * np.sin(1.3 * co[:, 0]) * np.cos(0.9 * co[:, 1])  # (slopes to about 60 degrees)
    mesh.vertices.foreach_set("co", co.ravel())
    import bmesh
    bm = bmesh.new()
    bm.from_mesh(mesh)
    # the middle column of faces apart: vertices on its sides twice (Pointiness welds them back)
    bmesh.ops.split_edges(bm, edges=[e for e in bm.edges if abs(e.verts[0].co.x - e.verts[1].co.x) < 1e-6
                                     and abs(abs(e.verts[0].co.x) - 2.0 / 3.0) < 1e-3])
    if ngons:  # three faces of column 0 joined (8 corners), and two of the middle island's (6)
        joined = ((-5.0 / 3.0, -2.0 / 3.0), (-5.0 / 3.0, 0.0), (0.0, 1.0))  # the edges' midpoints
        bmesh.ops.dissolve_edges(bm, edges=[e for e in bm.edges if any(
            abs(0.5 * (e.verts[0].co.x + e.verts[1].co.x) - x) < 1e-3 and
            abs(0.5 * (e.verts[0].co.y + e.verts[1].co.y) - y) < 1e-3 for x, y in joined)], use_verts=False)
    bm.to_mesh(mesh)
    bm.free()
    mesh.shade_smooth()
    mesh.update()
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    rng = np.random.default_rng(7)
    sizes = {"POINT": len(mesh.vertices), "CORNER": len(mesh.loops), "FACE": len(mesh.polygons),
             "EDGE": len(mesh.edges)}
    for name, kind, domain, prop, width in (
            ("paint", "BYTE_COLOR", "CORNER", "color", 4), ("tint", "FLOAT_COLOR", "POINT", "color", 4),
            ("wear", "FLOAT", "FACE", "value", 1), ("flow", "FLOAT_VECTOR", "POINT", "vector", 3),
            ("offset", "FLOAT2", "CORNER", "vector", 2), ("seam", "FLOAT", "EDGE", "value", 1),
            ("picked", "BOOLEAN", "FACE", "value", 1), ("step", "INT", "POINT", "value", 1)):
        attr = mesh.attributes.new(name, kind, domain)
        n = sizes[domain] * width
        values = (rng.random(n) < 0.5 if kind == "BOOLEAN" else rng.integers(-3, 4, n).astype(np.int32)
                  if kind == "INT" else rng.random(n).astype(np.float32) * 1.5)
        attr.data.foreach_set(prop, values)
    mesh.color_attributes.default_color_name = "paint"
    mat = bpy.data.materials.new("attribute")
    mat.pass_index = 3
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out, emission = tree.nodes.new("ShaderNodeOutputMaterial"), tree.nodes.new("ShaderNodeEmission")
    tree.links.new(emission.outputs[0], out.inputs["Surface"])
    mesh.materials.append(mat)
    # the pixels' centres as texel sites of a UV map over the grid (row 0 at the bottom, as a render's)
    corner_vert = meshes.corner_vertices(mesh)
    uv = (co[corner_vert, :2] + 2.0) / 4.0
    sites, _ = bake.texel_sites(uv, textures.triangle_corners(mesh), N, N, 1024)
    assert sites.count == N * N
    bpy.context.view_layer.update()
    normals = np.empty(len(mesh.loops) * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    world = np.array(obj.matrix_world)
    points = textures.row_points(obj, mesh, sites.at(co[corner_vert] @ world[:3, :3].T + world[:3, 3]),
                                 sites.at(normals.reshape(-1, 3)), views.camera_view(bpy.context.scene),
                                 lambda: textures.true_normals(obj, mesh, corner_vert, "TEXEL", sites))

    def compare(kind, output, configure):
        """Cycles' pixels and the add-on's reading at them of a `kind` node set by configure(node)."""
        for node in [n for n in tree.nodes if n not in (out, emission)]:
            tree.nodes.remove(node)
        node = tree.nodes.new(kind)
        configure(node)
        tree.links.new(next(o for o in node.outputs if o.identifier == output), emission.inputs["Color"])
        px = shot()
        notes = []
        depsgraph = bpy.context.evaluated_depsgraph_get()
        ev = nodes.Evaluator(N * N, None, lambda tex, uv, footprint, rows: textures.colours_at_rows(
                                 textures.pyramids(tex), textures.Source(tex, None), uv, footprint, rows, N * N),
                             points=points, owner=(obj, mat),
                             ambient=lambda p, n, d, inside, local, samples: ambient.shares(
                                 "grid", p, n, d, inside, ambient.blockers(depsgraph, obj, local), compare.rays),
                             bevel=lambda p, n, radius: bevel.normals(obj, depsgraph, p, n, radius),
                             attribute=textures.attribute_reader(mesh, corner_vert, "TEXEL", sites, notes),
                             footprint=textures.coordinate_footprint(mesh, corner_vert, "TEXEL", sites))
        compare.evaluator = ev
        return px[sites.texels], ev.colour(emission.inputs["Color"]), notes
    compare.texels = sites.texels  # (each row's pixel)
    compare.sites = sites
    compare.rays = ambient.TEXEL_RAYS
    compare.scene = bpy.context.scene
    compare.emission = emission
    return compare


def _named(name, kind="GEOMETRY"):
    def configure(node):
        if node.bl_idname == "ShaderNodeVertexColor":
            node.layer_name = name
        else:
            node.attribute_type, node.attribute_name = kind, name
    return configure


CASES = [("ShaderNodeVertexColor", "Color", ""), ("ShaderNodeVertexColor", "Alpha", "tint"),
         ("ShaderNodeVertexColor", "Color", "absent"), ("ShaderNodeVertexColor", "Alpha", "absent"),
         ("ShaderNodeAttribute", "Color", "paint"), ("ShaderNodeAttribute", "Fac", "tint"),
         ("ShaderNodeAttribute", "Alpha", "paint"), ("ShaderNodeAttribute", "Color", "wear"),
         ("ShaderNodeAttribute", "Vector", "flow"), ("ShaderNodeAttribute", "Fac", "flow"),
         ("ShaderNodeAttribute", "Vector", "offset"), ("ShaderNodeAttribute", "Fac", "offset"),
         ("ShaderNodeAttribute", "Fac", "seam"), ("ShaderNodeAttribute", "Color", "picked"),
         ("ShaderNodeAttribute", "Fac", "step"), ("ShaderNodeAttribute", "Alpha", "wear"),
         ("ShaderNodeAttribute", "Color", "absent"), ("ShaderNodeAttribute", "Alpha", "absent")]


@pytest.mark.parametrize("kind, output, name", CASES, ids=[f"{k[10:]}-{o}-{n or 'default'}" for k, o, n in CASES])
def test_attributes_read_as_cycles_renders_them(grid, kind, output, name):
    """Each pixel's colour in Cycles against the add-on's reading at the pixel's centre.  A face's
    value jumps at its edges: a pixel whose centre lies within float rounding of one may take the
    other face (none does on this grid)."""
    cycles, ours, notes = grid(kind, output, _named(name))
    assert ours.shape == cycles.shape and notes == []
    if name != "absent" and not (output == "Alpha" and name in ("wear",)):
        assert np.ptp(ours) > 0.1  # the attribute varies over the grid
    np.testing.assert_allclose(ours, cycles, atol=1e-5)


INFO = ["Location", "Color", "Alpha", "Object Index", "Material Index", "Random"]


@pytest.mark.parametrize("output", INFO)
def test_object_info_reads_as_cycles_renders_it(grid, output):
    """Each output of Object Info, Random hashed from the object's name as Cycles hashes it."""
    cycles, ours, _ = grid("ShaderNodeObjectInfo", output, lambda node: None)
    assert ours.any()
    np.testing.assert_allclose(ours, cycles, atol=1e-6)


@pytest.mark.parametrize("output", ["Position", "Normal", "True Normal", "Pointiness", "Random Per Island",
                                    "Parametric"])
def test_geometry_reads_as_cycles_renders_it(grid, output):
    """The Geometry node's world position, its smooth normal, interpolated over each triangle, each
    triangle's own normal (True Normal: the grid's quads are not flat, so each of their triangles
    has its own), where the point lies in its triangle (Parametric: Cycles' (1 - u - v, u, 0), the
    weights of the loop triangle's first two corners), its pointiness (the split vertices welded
    back) and the random value of each island of the grid (the middle column of faces is one, the
    sides two more)."""
    cycles, ours, notes = grid("ShaderNodeNewGeometry", output, lambda node: None)
    assert np.ptp(ours[:, 0]) > (0.02 if output == "Pointiness" else 0.5)
    if output in ("True Normal", "Parametric"):
        # a triangle's own value jumps at its edges, and the quads' diagonals run through pixel
        # centres here: those pixels may take either triangle
        inside = grid.sites.weights.min(axis=1) > 1e-4
        assert inside.mean() > 0.9
        ours, cycles = ours[inside], cycles[inside]
    if output == "True Normal":
        _, smooth, _ = grid("ShaderNodeNewGeometry", "Normal", lambda node: None)
        assert np.abs(smooth[inside] - ours).max() > 0.05  # (which is not the smooth normal)
    np.testing.assert_allclose(ours, cycles, atol=1e-5)
    assert notes == []


@pytest.mark.parametrize("kind, axis", [("ShaderNodeNewGeometry", None), ("ShaderNodeTangent", "X"),
                                        ("ShaderNodeTangent", "Y"), ("ShaderNodeTangent", "Z")])
def test_radial_tangents_read_as_cycles_renders_them(grid, kind, axis):
    """The Geometry's Tangent and the Tangent node's radial ones (about X, Y, Z of the texture space,
    made perpendicular to the smooth normal): within 1e-4 of Cycles' pixels."""
    def configure(node):
        if axis is not None:
            node.direction_type, node.axis = "RADIAL", axis
    cycles, ours, _ = grid(kind, "Tangent", configure)
    assert np.ptp(ours, axis=0).min() > 0.5
    np.testing.assert_allclose(ours, cycles, atol=1e-4)  # (float32 coordinates crossed and made unit)


@pytest.mark.parametrize("uv_map", ["", "UVMap", "absent"])
def test_uv_tangents_read_as_cycles_renders_them(grid, uv_map):
    """The Tangent node's UV map tangent (MikkTSpace, the active render map when unnamed, 0 for a map
    the mesh lacks), made perpendicular to the smooth normal: within 1e-4 of Cycles' pixels."""
    def configure(node):
        node.direction_type, node.uv_map = "UV_MAP", uv_map
    cycles, ours, notes = grid("ShaderNodeTangent", "Tangent", configure)
    assert notes == []
    if uv_map == "absent":
        assert not ours.any()
    else:
        assert np.ptp(ours, axis=0).max() > 0.5 and np.abs(np.linalg.norm(ours, axis=1) - 1.0).max() < 1e-5
    np.testing.assert_allclose(ours, cycles, atol=1e-4)


@pytest.mark.parametrize("output", ["Camera", "Window"])
def test_camera_and_window_coordinates_read_as_cycles_renders_them(grid, output):
    """A Texture Coordinate's Camera (the point in Cycles' camera space: depth along +Z) and Window
    (its place in the camera's frame, 0 to 1), seen by the orthographic camera above the grid:
    within 1e-5 of Cycles' pixels."""
    cycles, ours, notes = grid("ShaderNodeTexCoord", output, lambda node: None)
    assert notes == [] and np.ptp(ours[:, 0]) > (0.9 if output == "Window" else 3.5)
    if output == "Camera":
        assert ours[:, 2].min() > 3.0  # (in front of the camera, 5 m above the grid's middle)
    np.testing.assert_allclose(ours, cycles, atol=1e-5)


FACING = [("ShaderNodeLayerWeight", "Fresnel", dict(Blend=0.5)), ("ShaderNodeLayerWeight", "Fresnel", dict(Blend=0.2)),
          ("ShaderNodeLayerWeight", "Facing", dict(Blend=0.5)), ("ShaderNodeLayerWeight", "Facing", dict(Blend=0.15)),
          ("ShaderNodeLayerWeight", "Facing", dict(Blend=0.9)), ("ShaderNodeFresnel", "Fac", dict(IOR=1.45)),
          ("ShaderNodeFresnel", "Fac", dict(IOR=2.8)), ("ShaderNodeNewGeometry", "Incoming", {})]


@pytest.mark.parametrize("kind, output, inputs", FACING, ids=[f"{k[10:]}-{o}-{i}" for i, (k, o, _) in enumerate(FACING)])
def test_what_depends_on_the_view_reads_as_cycles_renders_it(grid, kind, output, inputs):
    """Layer Weight (Fresnel and Facing at several blends), Fresnel and the Geometry's Incoming, seen
    by the orthographic camera above the rolling grid: within 1e-5 of Cycles' pixels."""
    def configure(node):
        for name, value in inputs.items():
            node.inputs[name].default_value = value
    cycles, ours, _ = grid(kind, output, configure)
    assert kind.endswith("Geometry") or np.ptp(ours) > 0.005
    np.testing.assert_allclose(ours, cycles, atol=1e-5)


def _normal_dot(node):
    """The Normal node's Dot of the Geometry's normal against a tilted direction."""
    node.outputs["Normal"].default_value = (0.3, -0.4, 0.8)
    geometry = node.id_data.nodes.new("ShaderNodeNewGeometry")
    node.id_data.links.new(geometry.outputs["Normal"], node.inputs["Normal"])


def _grouped(node):
    """A node group (its input a Geometry's position, its Math inside scaling the input's x by its
    second input, 2.5, then a Color Ramp), nested in another group that passes both inputs on."""
    def group(name, build):
        tree = bpy.data.node_groups.new(name, "ShaderNodeTree")
        tree.interface.new_socket("Out", in_out="OUTPUT", socket_type="NodeSocketColor")
        tree.interface.new_socket("Where", in_out="INPUT", socket_type="NodeSocketVector")
        tree.interface.new_socket("Gain", in_out="INPUT", socket_type="NodeSocketFloat")
        g_in, g_out = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
        build(tree, g_in, g_out)
        return tree

    def inner(tree, g_in, g_out):
        sep, mul, ramp = (tree.nodes.new(k) for k in ("ShaderNodeSeparateXYZ", "ShaderNodeMath", "ShaderNodeValToRGB"))
        mul.operation = "MULTIPLY"
        tree.links.new(g_in.outputs[0], sep.inputs[0])
        tree.links.new(sep.outputs["X"], mul.inputs[0])
        tree.links.new(g_in.outputs[1], mul.inputs[1])
        tree.links.new(mul.outputs[0], ramp.inputs["Fac"])
        ramp.color_ramp.elements[0].color = (0.1, 0.3, 0.9, 1.0)
        tree.links.new(ramp.outputs["Color"], g_out.inputs[0])

    def outer(tree, g_in, g_out):
        held = tree.nodes.new("ShaderNodeGroup")
        held.node_tree = group("inner", inner)
        tree.links.new(g_in.outputs[0], held.inputs[0])
        tree.links.new(g_in.outputs[1], held.inputs[1])
        tree.links.new(held.outputs[0], g_out.inputs[0])
    node.node_tree = group("outer", outer)
    geometry = node.id_data.nodes.new("ShaderNodeNewGeometry")
    node.id_data.links.new(geometry.outputs["Position"], node.inputs[0])
    node.inputs[1].default_value = 0.25


def test_normal_node_and_node_groups_read_as_cycles_renders_them(grid):
    """The Normal node's Dot, and a chain inside a node group inside another (its inputs passed
    through): within 1e-5 of Cycles' pixels."""
    for kind, output, configure in (("ShaderNodeNormal", "Dot", _normal_dot), ("ShaderNodeGroup", "Socket_0",
                                                                                _grouped)):
        cycles, ours, _ = grid(kind, output, configure)
        assert np.ptp(ours) > 0.1
        np.testing.assert_allclose(ours, cycles, atol=1e-5)


def _white_noise(dimensions, source=None, w=0.0):
    """configure() of a White Noise Texture in `dimensions`, its Vector from `source` ((node type,
    output identifier) or None) and its W."""
    def configure(node):
        node.noise_dimensions = f"{dimensions}D"
        next(s for s in node.inputs if s.identifier == "W").default_value = w
        if source is not None:
            feed = node.id_data.nodes.new(source[0])
            node.id_data.links.new(next(o for o in feed.outputs if o.identifier == source[1]), node.inputs["Vector"])
    return configure


WHITE_NOISE = [(3, ("ShaderNodeObjectInfo", "Random"), 0.0, "Color"),
               (4, ("ShaderNodeObjectInfo", "Location"), 0.37, "Value"),
               (2, ("ShaderNodeObjectInfo", "Location"), 0.0, "Color"),
               (1, None, 1.7, "Color"),
               (3, ("ShaderNodeNewGeometry", "Random Per Island"), 0.0, "Color")]


@pytest.mark.parametrize("dimensions, source, w, output", WHITE_NOISE,
                         ids=[f"{d}D-{s[1] if s else 'W'}-{o}" for d, s, _, o in WHITE_NOISE])
def test_white_noise_of_exact_inputs_reads_as_cycles_renders_it(grid, dimensions, source, w, output):
    """The White Noise Texture hashes its input's bits: fed what wenv reads to the bit as Cycles does
    (an object's or island's Random, its Location, W), each pixel's value is Cycles' to the bit (the
    per-object or per-island colour it is used for); the islands differ."""
    cycles, ours, _ = grid("ShaderNodeTexWhiteNoise", output, _white_noise(dimensions, source, w))
    np.testing.assert_array_equal(ours, cycles)
    if source is not None and source[1] == "Random Per Island":
        assert len(np.unique(ours[:, 0])) == 3


def _image_through(projection, blend=0.0, coordinates="Object"):
    """configure() of an Image Texture of a smooth random 24 x 24 image through the Texture
    Coordinate's `coordinates` (mapped by a quarter, moved by a half), flat or a box."""
    def configure(node):
        tree = node.id_data
        image = bpy.data.images.get("smooth") or bpy.data.images.new("smooth", 24, 24, float_buffer=True)
        rng = np.random.default_rng(11)
        image.pixels.foreach_set(np.column_stack([rng.random((24 * 24, 3)), np.ones(24 * 24)]).astype(np.float32).ravel())
        node.image, node.projection, node.projection_blend = image, projection, blend
        coords, mapping = tree.nodes.new("ShaderNodeTexCoord"), tree.nodes.new("ShaderNodeMapping")
        mapping.inputs["Scale"].default_value = (0.25, 0.25, 0.25)
        mapping.inputs["Location"].default_value = (0.5, 0.5, 0.5)
        tree.links.new(coords.outputs[coordinates], mapping.inputs["Vector"])
        tree.links.new(mapping.outputs["Vector"], node.inputs["Vector"])
    return configure


@pytest.mark.parametrize("projection, blend, coordinates", [("FLAT", 0.0, "Object"), ("BOX", 0.0, "Object"),
                                                             ("BOX", 0.6, "Object"), ("BOX", 0.8, "Generated"),
                                                             ("SPHERE", 0.0, "Generated"), ("TUBE", 0.0, "Object")])
def test_an_image_through_coordinates_reads_as_cycles_renders_it(grid, projection, blend, coordinates):
    """An Image Texture through object or generated coordinates, flat, a box (its planes weighted by
    the rolling grid's object-space normals, blended), a sphere or a tube: within 1e-4 of Cycles'
    pixels (a sphere's or tube's seam aside, where a few pixels may fall either way).  The image's
    texels are larger than the pixels, so that Cycles' unfiltered lookup and wenv's footprint agree."""
    cycles, ours, _ = grid("ShaderNodeTexImage", "Color", _image_through(projection, blend, coordinates))
    assert np.ptp(ours) > 0.2
    off = np.abs(cycles - ours).max(axis=1) > 1e-4
    if projection == "TUBE":  # about its axis u turns a whole circle within a pixel: wenv filters, Cycles does not
        side = (np.arange(N) + 0.5) / N * 4.0 - 2.0
        x, y = np.meshgrid(side, side)
        off &= (np.hypot(x, y).ravel() > 0.3)[grid.texels]
    assert off.sum() <= 3, (off.sum(), np.abs(cycles - ours).max())


@pytest.mark.parametrize("projection, coordinates", [("EQUIRECTANGULAR", None), ("EQUIRECTANGULAR", "Reflection"),
                                                     ("MIRROR_BALL", "Normal")])
def test_an_environment_texture_reads_as_cycles_renders_it(grid, projection, coordinates):
    """An Environment Texture in an object's material: its Vector the position in the world (unlinked,
    as Cycles reads it on a surface), the view mirrored about the normal, or the object-space
    normal (turned a quarter), mapped equirectangularly or as a mirror ball: within 1e-4 of Cycles' pixels but a few
    where the direction turns within a pixel (wenv filters over the pixel, Cycles does not): about
    the map's pole, above the world's origin."""
    def configure(node):
        _image_through("FLAT")(node.id_data.nodes.new("ShaderNodeTexImage"))  # (makes the image)
        node.image, node.projection = bpy.data.images["smooth"], projection
        if coordinates is not None:  # turned a quarter about x: what the grid reflects sits on the map's equator
            tree = node.id_data
            coords, turn = tree.nodes.new("ShaderNodeTexCoord"), tree.nodes.new("ShaderNodeMapping")
            turn.vector_type = "VECTOR"
            turn.inputs["Rotation"].default_value = (np.pi / 2, 0.0, 0.0)
            tree.links.new(coords.outputs[coordinates], turn.inputs["Vector"])
            tree.links.new(turn.outputs["Vector"], node.inputs["Vector"])
    cycles, ours, notes = grid("ShaderNodeTexEnvironment", "Color", configure)
    assert np.ptp(ours) > 0.2 and notes == []
    off = np.abs(cycles - ours).max(axis=1) > 1e-4
    if coordinates is None:  # straight above the world's origin the directions reach the map's pole,
        side = (np.arange(N) + 0.5) / N * 4.0 - 2.0  # where u turns a whole circle within a pixel
        x, y = np.meshgrid(side, side)
        off &= (np.hypot(x, y).ravel() > 0.5)[grid.texels]
    assert off.sum() <= 3, (off.sum(), np.abs(cycles - ours).max())


def _image_with_alpha(is_float, alpha_mode="STRAIGHT", space=None, alpha_used=False):
    """configure() of an Image Texture (Closest) of a 24 x 24 image whose alpha runs from 0 to 1
    (a fifth of its texels 0, a fifth 1), read through object coordinates as _image_through reads
    them; alpha_used: its Alpha output also scales the Emission's Strength."""
    flat = _image_through("FLAT")

    def configure(node):
        name = f"alpha {is_float} {alpha_mode} {space}"
        image = bpy.data.images.get(name) or bpy.data.images.new(name, 24, 24, alpha=True, float_buffer=is_float)
        rng = np.random.default_rng(5)
        alpha = rng.choice([0.0, 1.0, 0.5], 24 * 24, p=[0.2, 0.2, 0.6])
        alpha = np.where(alpha == 0.5, rng.random(24 * 24), alpha)
        image.alpha_mode = alpha_mode
        if space is not None:  # (before the pixels: a generated image's are made afresh in a new space)
            image.colorspace_settings.name = space
        image.pixels.foreach_set(np.column_stack([rng.random((24 * 24, 3)), alpha]).astype(np.float32).ravel())
        flat(node)
        node.image, node.interpolation = image, "Closest"
        if alpha_used:
            node.id_data.links.new(node.outputs["Alpha"], grid_emission(node).inputs["Strength"])
    return configure


def grid_emission(node):
    return next(n for n in node.id_data.nodes if n.bl_idname == "ShaderNodeEmission")


@pytest.mark.parametrize("is_float, alpha_mode, space, output, alpha_used", [
    (False, "STRAIGHT", None, "Color", False), (False, "STRAIGHT", None, "Color", True),
    (False, "STRAIGHT", None, "Alpha", False), (True, "STRAIGHT", None, "Color", False),
    (True, "STRAIGHT", None, "Color", True), (False, "CHANNEL_PACKED", None, "Color", True),
    (False, "NONE", None, "Color", False), (False, "STRAIGHT", "Non-Color", "Color", True),
    (False, "PREMUL", None, "Color", False), (True, "CHANNEL_PACKED", None, "Color", True)])
def test_an_image_with_alpha_reads_as_cycles_renders_it(grid, is_float, alpha_mode, space, output, alpha_used):
    """An image with alpha as Cycles samples it: a byte image's colour associated with alpha in 8 bits
    before its sRGB is decoded, a float image's as stored; divided by alpha again where the node's
    Alpha output is used (here scaling the Emission), not where it is channel-packed or data; alpha
    ignored (1) where the image's alpha mode is None; a byte image of Premultiplied alpha mode
    associated as a straight one (Blender holds 8-bit colours straight).  Within 1e-4 of Cycles'
    pixels."""
    cycles, ours, _ = grid("ShaderNodeTexImage", output, _image_with_alpha(is_float, alpha_mode, space, alpha_used))
    if alpha_used:
        ours = ours * grid.evaluator.value(grid.emission.inputs["Strength"])[:, None]
    assert np.ptp(ours) > 0.2
    off = np.abs(cycles - ours).max(axis=1) > 1e-4
    assert off.sum() <= 3, (off.sum(), np.abs(cycles - ours).max())


@pytest.mark.parametrize("output", ["Normal", "Reflection"])
def test_texture_coordinates_of_the_normal_read_as_cycles_renders_them(grid, output):
    """The Texture Coordinate's Normal (in object space) and Reflection (the view mirrored about the
    normal, in the world) over the rolling grid: within 1e-5 of Cycles' pixels."""
    cycles, ours, _ = grid("ShaderNodeTexCoord", output, lambda node: None)
    assert np.ptp(ours) > 0.5
    np.testing.assert_allclose(ours, cycles, atol=1e-5)


@pytest.mark.parametrize("output", ["Is Camera Ray", "Is Shadow Ray", "Is Diffuse Ray", "Is Glossy Ray",
                                    "Ray Depth", "Transparent Depth"])
def test_light_path_reads_as_a_camera_ray_sees_it(grid, output):
    """The Light Path node as the camera's rays meet the grid (what wenv shades): within 1e-6 of
    Cycles' pixels (its Ray Length is read in a perspective view only, and named in this
    orthographic one)."""
    cycles, ours, _ = grid("ShaderNodeLightPath", output, lambda node: None)
    np.testing.assert_allclose(ours, cycles, atol=1e-6)
    with pytest.raises(nodes.Unsupported, match="Ray Length, which wenv reads in a perspective view only"):
        grid("ShaderNodeLightPath", "Ray Length", lambda node: None)


@pytest.fixture
def properties(grid):
    """Custom properties on the grid's object, mesh, view layer, scene and a World, and a string one,
    removed after."""
    obj, scene = bpy.data.objects["Crate.004 – ÿ"], bpy.context.scene
    scene.world = bpy.data.worlds.new("props")
    owners = (obj, obj.data, bpy.context.view_layer, scene, scene.world)
    values = ({"tint": [0.2, 0.5, 0.9], "wear": 0.7, "flags": [3, -2], "shown": True, "label": "x"},
              {"wear": 0.1, "rgba": [0.3, 0.2, 0.1, 0.6]}, {"layer": 0.35}, {"layer": 0.9, "sky": 4},
              {"sky": 2.0, "haze": [0.4, 0.5]})
    for owner, props in zip(owners, values):
        for key, value in props.items():
            owner[key] = value
    yield
    for owner, props in zip(owners, values):
        for key in props:
            del owner[key]
    bpy.data.worlds.remove(scene.world)


@pytest.mark.parametrize("kind, name, output", [
    ("OBJECT", "tint", "Color"), ("OBJECT", "wear", "Fac"), ("OBJECT", "rgba", "Alpha"), ("OBJECT", "rgba", "Color"),
    ("OBJECT", "flags", "Vector"), ("OBJECT", "shown", "Fac"), ("OBJECT", "color", "Color"),
    ("OBJECT", "location", "Fac"), ("OBJECT", "label", "Color"), ("OBJECT", "absent", "Alpha"),
    ("INSTANCER", "tint", "Color"), ("VIEW_LAYER", "layer", "Fac"), ("VIEW_LAYER", "sky", "Color"),
    ("VIEW_LAYER", "haze", "Color"), ("VIEW_LAYER", "frame_current", "Fac")])
def test_attributes_of_the_object_and_view_layer_read_as_cycles_renders_them(grid, properties, kind, name, output):
    """An Attribute of the object (or instancer) looked up on the object, then its mesh, and of the
    view layer on the layer, then the scene, then its World: a custom property first, then an RNA
    path, a number (or boolean) as a grey, an array of up to four over (0, 0, 0, 1), anything else or
    nothing as (0, 0, 0, 0), as Blender hands them to Cycles.  Within 1e-5 of Cycles' pixels."""
    cycles, ours, notes = grid("ShaderNodeAttribute", output, _named(name, kind))
    assert not notes
    np.testing.assert_allclose(ours, cycles, atol=1e-5)


@pytest.fixture
def lid(grid):
    """A box over a corner of the grid that the camera does not see but that blocks the grid's rays
    (as Cycles' shadow rays see it), removed after."""
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(-1.0, -1.0, 1.6))
    box = bpy.context.object
    box.visible_camera = False
    yield box
    bpy.data.objects.remove(box)


@pytest.mark.parametrize("distance, inside, only_local, output, tilted", [
    (1.0, False, False, "AO", False), (0.5, False, False, "AO", False), (2.5, False, True, "AO", False),
    (2.0, True, False, "Color", False), (1.0, False, False, "AO", True)])
def test_ambient_occlusion_reads_as_cycles_renders_it(grid, lid, distance, inside, only_local, output, tilted):
    """The Ambient Occlusion node over the rolling grid, a box hovering over one corner: the share of a
    cosine-weighted hemisphere whose rays run the Distance free of the scene's meshes (the grid's
    alone with Only Local; the hemisphere below with Inside; about a Normal fed to it, tilted 50
    degrees towards the box, instead of the point's), against Cycles converged (256 samples a
    pixel of 64 rays each): within its noise and wenv's own (256 rays a point here) -- the mean within
    0.003, the RMS difference within 0.015 (both about 0.001 and 0.008 here), where uniform rays are
    off by 0.06-0.12 and the distance ignored by 0.02-0.2."""
    def configure(node):
        node.samples, node.inside, node.only_local = 64, inside, only_local
        node.inputs["Distance"].default_value = distance
        node.inputs["Color"].default_value = (0.9, 0.5, 0.2, 1.0)
        if tilted:
            axis = node.id_data.nodes.new("ShaderNodeCombineXYZ")
            # (a unit one: on one of another length Cycles 4.2 differs from 5.0, whose rays wenv casts)
            axis.inputs["X"].default_value = axis.inputs["Y"].default_value = -0.5494
            axis.inputs["Z"].default_value = 0.6296
            node.id_data.links.new(axis.outputs[0], node.inputs["Normal"])
    grid.scene.cycles.samples, grid.rays = 256, 256
    try:
        cycles, ours, _ = grid("ShaderNodeAmbientOcclusion", output, configure)
    finally:
        grid.scene.cycles.samples, grid.rays = 1, ambient.TEXEL_RAYS
    if output == "Color":
        cycles, ours = cycles / np.float32([0.9, 0.5, 0.2]), ours / np.float32([0.9, 0.5, 0.2])
    assert ours.std() > 0.02 and ours.min() < 0.9  # rays blocked, and unevenly
    diff = (cycles - ours)[:, 0]
    assert abs(diff.mean()) < 0.003 and np.sqrt(np.mean(diff ** 2)) < 0.015, (diff.mean(), np.sqrt(np.mean(diff ** 2)))


@pytest.mark.parametrize("radius, linked, flat", [(0.3, False, False), (0.12, False, False), (0.3, True, False),
                                                  (0.3, False, True), ("0.175 x", False, False)])
def test_bevel_reads_as_cycles_renders_it(grid, radius, linked, flat):
    """The Bevel node's normal over the rolling grid (its quads folded along their diagonals, the
    middle column's sides cut apart), smooth or flat, with a Normal fed to it (that normal turned
    as the bevel turns the mesh's), and with a Radius from the nodes, 0.175 times the point's x
    (below 0 on the grid's left half, where it keeps its own normal, as Cycles), against Cycles
    converged (256 samples a pixel of 16 rays each): wenv integrates over the surface what Cycles'
    rays estimate.  Within 0.002 RMS (0.0003-0.0005 here), where the mesh's own normal is 0.016-0.4
    away."""
    def configure(node):
        node.samples = 16
        if radius == "0.175 x":
            tree = node.id_data
            split, scale = tree.nodes.new("ShaderNodeSeparateXYZ"), tree.nodes.new("ShaderNodeMath")
            scale.operation, scale.inputs[1].default_value = "MULTIPLY", 0.175
            tree.links.new(tree.nodes.new("ShaderNodeNewGeometry").outputs["Position"], split.inputs[0])
            tree.links.new(split.outputs["X"], scale.inputs[0])
            tree.links.new(scale.outputs[0], node.inputs["Radius"])
        else:
            node.inputs["Radius"].default_value = radius
        if linked:
            normal = node.id_data.nodes.new("ShaderNodeCombineXYZ")
            normal.inputs["X"].default_value, normal.inputs["Z"].default_value = 0.3, 1.0
            node.id_data.links.new(normal.outputs[0], node.inputs["Normal"])
    mesh = bpy.data.meshes["Grid"]
    if flat:
        mesh.shade_flat()
    grid.scene.cycles.samples = 256
    try:
        cycles, ours, _ = grid("ShaderNodeBevel", "Normal", configure)
        own = grid("ShaderNodeNewGeometry", "True Normal" if flat else "Normal", lambda node: None)[1]
    finally:
        grid.scene.cycles.samples = 1
        mesh.shade_smooth()
    unlike = np.sqrt(np.mean((cycles - own) ** 2))
    assert unlike > (0.008 if radius == "0.175 x" else 0.015)  # (it bevels: one half of the grid, there)
    if radius == "0.175 x":
        left = grid("ShaderNodeNewGeometry", "Position", lambda node: None)[1][:, 0] < -0.01
        assert left.mean() > 0.4
        np.testing.assert_array_equal(ours[left], own[left])
    diff = np.abs(cycles - ours)
    assert np.sqrt(np.mean(diff ** 2)) < 0.002 and np.percentile(diff, 99) < 0.008, (
        np.sqrt(np.mean(diff ** 2)), np.percentile(diff, 99), unlike)


def test_what_is_not_read_is_named(grid):
    """wenv's own shading is read as no attribute, and said so; an Ambient Occlusion node's Distance
    linked to a value that varies from point to point is named, one from a Value node read as that
    value."""
    def varying_distance(node):
        tree = node.id_data
        split = tree.nodes.new("ShaderNodeSeparateXYZ")
        tree.links.new(tree.nodes.new("ShaderNodeNewGeometry").outputs["Position"], split.inputs[0])
        tree.links.new(split.outputs["X"], node.inputs["Distance"])
    with pytest.raises(nodes.Unsupported, match="Distance, linked to values that vary"):
        grid("ShaderNodeAmbientOcclusion", "AO", varying_distance)

    def value_distance(node):
        value = node.id_data.nodes.new("ShaderNodeValue")
        value.outputs[0].default_value = 0.8
        node.id_data.links.new(value.outputs[0], node.inputs["Distance"])

    def plain_distance(node):
        node.inputs["Distance"].default_value = 0.8
    _, from_value, _ = grid("ShaderNodeAmbientOcclusion", "AO", value_distance)
    _, plain, _ = grid("ShaderNodeAmbientOcclusion", "AO", plain_distance)
    np.testing.assert_array_equal(from_value, plain)
    assert np.ptp(plain) > 0.1
    mesh = bpy.data.meshes["Grid"]
    meshes.write_colors(mesh, "POINT", np.ones((len(mesh.vertices), 3), np.float32))
    try:
        cycles, ours, notes = grid("ShaderNodeAttribute", "Color", _named(meshes.ATTRIBUTE))
        assert not ours.any() and notes == [f"'{meshes.ATTRIBUTE}' is wenv's own shading: read as no attribute (0)"]
    finally:
        meshes.remove_colors(mesh)


def test_pointiness_welds_vertices_as_cycles_scans_them():
    """textures.welded_vertices against Cycles' scan written out plainly (attr_create_pointiness's
    step 1): random points, some repeated exactly (welded) and some moved by 1e-5 (whose coordinate
    sums then differ by more than Cycles' window: not welded)."""
    rng = np.random.default_rng(0)
    co = rng.random((1500, 3)).astype(np.float32)
    co = np.vstack([co, co[:200] + rng.normal(0.0, 1e-5, (200, 3)).astype(np.float32), co[:60], co[:20]])
    sums = (co[:, 0] + co[:, 1]) + co[:, 2]
    order = sorted(range(len(co)), key=lambda i: (sums[i], -i))
    eps = np.float32(np.finfo(np.float32).eps)
    orig = list(range(len(co)))
    for a, i in enumerate(order):
        for j in order[a + 1:]:
            if sums[j] - sums[i] > 3 * eps:
                break
            d = co[j] - co[i]
            if float(np.dot(d, d)) < eps:
                orig[i] = j
                break
    for i in range(len(co)):
        while orig[i] != orig[orig[i]]:
            orig[i] = orig[orig[i]]
    got = textures.welded_vertices(co)
    np.testing.assert_array_equal(got, orig)
    assert (got != np.arange(len(co))).sum() >= 80


def test_true_normals_at_vertices_and_corners_are_their_faces():
    """A cube mirrored in x and turned: at a face corner its face's normal (the mesh's own polygon
    normal carried into the world), at a vertex the mean of its three faces', as Cycles turns a
    mirrored object's back to the winding's side."""
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(3.0, 0.0, 0.0), rotation=(0.3, 0.2, 0.1))
    cube = bpy.context.object
    cube.scale = (-1.0, 1.5, 1.0)
    bpy.context.view_layer.update()
    mesh = cube.data
    corner_vert = meshes.corner_vertices(mesh)
    to_world = np.array(cube.matrix_world.to_3x3().inverted_safe().transposed(), np.float64)
    faces = np.array([p.normal for p in mesh.polygons], np.float64) @ to_world.T
    faces /= np.linalg.norm(faces, axis=1, keepdims=True)
    corner_face = np.concatenate([[p.index] * p.loop_total for p in mesh.polygons])
    at_corners = textures.true_normals(cube, mesh, corner_vert, "CORNER")
    np.testing.assert_allclose(at_corners, faces[corner_face], atol=1e-6)
    # each vertex on three faces, weighted by their areas in the world (parallelograms)
    m = np.array(cube.matrix_world.to_3x3(), np.float64)
    co = np.array([v.co for v in mesh.vertices], np.float64) @ m.T
    areas = np.array([np.linalg.norm(np.cross(co[p.vertices[1]] - co[p.vertices[0]], co[p.vertices[3]] - co[p.vertices[0]]))
                      for p in mesh.polygons])
    assert np.ptp(areas) > 1.0
    at_vertices = textures.true_normals(cube, mesh, corner_vert, "POINT")
    for v in range(len(mesh.vertices)):
        own = sorted({corner_face[c] for c in np.flatnonzero(corner_vert == v)})
        mean = (areas[own, None] * faces[own]).sum(axis=0)
        np.testing.assert_allclose(at_vertices[v], mean / np.linalg.norm(mean), atol=1e-6)
    bpy.data.objects.remove(cube)
