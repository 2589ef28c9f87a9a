"""A mesh's attributes (the Color Attribute and Attribute nodes) against Cycles: a 4 m grid of 36 quads
seen from straight above by an orthographic camera that it fills, its Emission fed by the node,
one sample a pixel at the pixel's centre.  The add-on reads the attribute at each pixel's centre as a
bake reads it at a texel's (addon/textures.py attribute_reader): points, corners, faces and edges, each
data type Cycles reads, and an attribute the mesh lacks."""
import tempfile

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from addon import bake, meshes, nodes, textures  # noqa: E402

N = 40


@pytest.fixture(scope="module")
def grid():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 1
    sc.cycles.use_denoising = False
    sc.cycles.filter_width = 0.01  # the sample at the pixel's centre
    sc.render.resolution_x = sc.render.resolution_y = N
    sc.view_settings.view_transform = "Standard"
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.filepath = f"{tempfile.mkdtemp(prefix='wenv-attributes-')}/attribute.exr"
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=6, y_subdivisions=6, size=4.0)
    obj = bpy.context.object
    mesh = obj.data
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    sc.collection.objects.link(cam)
    sc.camera = cam
    cam.data.type, cam.data.ortho_scale = "ORTHO", 4.0
    cam.location = (0.0, 0.0, 5.0)
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
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out, emission = tree.nodes.new("ShaderNodeOutputMaterial"), tree.nodes.new("ShaderNodeEmission")
    tree.links.new(emission.outputs[0], out.inputs["Surface"])
    mesh.materials.append(mat)
    # the pixels' centres as texel sites of a UV map over the grid (row 0 at the bottom, as a render's)
    corner_vert = meshes.corner_vertices(mesh)
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    uv = (co.reshape(-1, 3)[corner_vert, :2] + 2.0) / 4.0
    sites, _ = bake.texel_sites(uv, textures.triangle_corners(mesh), N, N, 1024)
    assert sites.count == N * N

    def compare(kind, output, configure):
        """Cycles' pixels and the add-on's reading at them of a `kind` node set by configure(node)."""
        for node in [n for n in tree.nodes if n not in (out, emission)]:
            tree.nodes.remove(node)
        node = tree.nodes.new(kind)
        configure(node)
        tree.links.new(next(o for o in node.outputs if o.identifier == output), emission.inputs["Color"])
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(sc.render.filepath)
        px = np.array(img.pixels[:], np.float32).reshape(N * N, 4)[:, :3]
        bpy.data.images.remove(img)
        notes = []
        ev = nodes.Evaluator(N * N, None, None, attribute=textures.attribute_reader(mesh, corner_vert, "TEXEL",
                                                                                   sites, notes))
        return px[sites.texels], ev.colour(emission.inputs["Color"]), notes
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


def test_what_is_not_read_is_named(grid):
    """An attribute of the object (not the mesh) is named and not read; wenv's own shading is read as
    no attribute, and said so."""
    with pytest.raises(nodes.Unsupported, match="attribute of the object"):
        grid("ShaderNodeAttribute", "Color", _named("paint", "OBJECT"))
    mesh = bpy.data.objects["Grid"].data
    meshes.write_colors(mesh, "POINT", np.ones((len(mesh.vertices), 3), np.float32))
    try:
        cycles, ours, notes = grid("ShaderNodeAttribute", "Color", _named(meshes.ATTRIBUTE))
        assert not ours.any() and notes == [f"'{meshes.ATTRIBUTE}' is wenv's own shading: read as no attribute (0)"]
    finally:
        meshes.remove_colors(mesh)
