"""Blender's procedural textures against Cycles: a 4 m plane seen from straight above by an
orthographic camera that it fills, its Emission coloured by a texture node, one sample a pixel at the
pixel's centre.  Cycles' pixels against wenv.noise_texture at those points, for each dimension and type,
with distortion and without normalisation, and through the plane's Generated coordinates; and against
the add-on's reading of the node (addon/nodes.py) for the Noise, Wave, Checker and Gradient Textures,
through Object coordinates or the plane's UV map.
Then bad input."""
import numpy as np
import pytest

import wenv

import bpy  # noqa: E402  (installed by scripts/setup.sh; missing, the tests fail rather than skip)

from addon import nodes  # noqa: E402
from tests.helpers.cycles_pixels import pixel_scene  # noqa: E402

N = 48
DEFAULTS = dict(scale=5.0, detail=2.0, roughness=0.5, lacunarity=2.0, offset=0.0, gain=1.0, distortion=0.0, w=0.0)
SOCKETS = dict(scale="Scale", detail="Detail", roughness="Roughness", lacunarity="Lacunarity", offset="Offset",
               gain="Gain", distortion="Distortion", w="W")


@pytest.fixture(scope="module")
def plane():
    shot = pixel_scene(bpy, N, at=(0.5, -0.25))
    bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0.5, -0.25, 0.0))
    obj = bpy.context.object
    mat = bpy.data.materials.new("noise")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    out, emission = tree.nodes.new("ShaderNodeOutputMaterial"), tree.nodes.new("ShaderNodeEmission")
    noise, coords = tree.nodes.new("ShaderNodeTexNoise"), tree.nodes.new("ShaderNodeTexCoord")
    others = {"ShaderNodeMapping": tree.nodes.new("ShaderNodeMapping")}
    tree.links.new(emission.outputs[0], out.inputs["Surface"])
    obj.data.materials.append(mat)
    side = (np.arange(N) + 0.5) / N * 4.0 - 2.0
    x, y = np.meshgrid(side, side)  # the pixels' centres in the plane's object space, row 0 at the bottom
    local = np.stack([x.ravel(), y.ravel(), np.zeros(N * N)], 1)

    def render_node(kind, output, configure):
        """Cycles' pixels and the add-on's reading of a `kind` node, set up by configure(node,
        mapping), fed Object coordinates through a Mapping node."""
        for link in list(tree.links):
            if link.to_node != out:
                tree.links.remove(link)
        for old in [n for n in tree.nodes if n.bl_idname == kind and n != noise]:
            tree.nodes.remove(old)  # a fresh node each time: every setting at its default
        node, mapping = noise if kind == "ShaderNodeTexNoise" else tree.nodes.new(kind), others["ShaderNodeMapping"]
        tree.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
        for name, value in (("Location", (0.0, 0.0, 0.0)), ("Rotation", (0.0, 0.0, 0.0)), ("Scale", (1.0, 1.0, 1.0))):
            mapping.inputs[name].default_value = value
        configure(node, mapping)
        vector = next((s for s in node.inputs if s.identifier == "Vector"), None)
        if vector is not None and vector.enabled:
            tree.links.new(mapping.outputs["Vector"], vector)
        tree.links.new(next(o for o in node.outputs if o.identifier == output), emission.inputs["Color"])
        uv = ((local[:, :2] + 2.0) / 4.0).astype(np.float32)  # the plane's UV map at the pixels' centres
        ev = nodes.Evaluator(N * N, lambda uv_map: (uv, np.ones(N * N, np.float32), np.arange(N * N)), None,
                             points=lambda space, other: local.astype(np.float32))
        return shot(), ev.colour(emission.inputs["Color"])

    def render(settings, output, vector="Object"):
        for link in list(tree.links):
            if link.to_node != out:
                tree.links.remove(link)
        if vector:  # (by identifier: a socket unavailable in 1D is not found by name)
            tree.links.new(coords.outputs[vector], next(s for s in noise.inputs if s.identifier == "Vector"))
        tree.links.new(noise.outputs[output], emission.inputs["Color"])
        noise.noise_dimensions = f"{settings.get('dimensions', 3)}D"
        noise.noise_type = settings.get("type", "FBM")
        noise.normalize = settings.get("normalize", True)
        for key, name in SOCKETS.items():
            socket = next(s for s in noise.inputs if s.identifier == name)
            socket.default_value = settings.get(key, DEFAULTS[key])
        return shot()
    return obj, local, render, render_node


CASES = [dict(), dict(type="MULTIFRACTAL", detail=3.5), dict(type="RIDGED_MULTIFRACTAL", offset=1.0, gain=2.0),
         dict(type="HYBRID_MULTIFRACTAL", detail=4.3, offset=0.5, gain=1.5), dict(type="HETERO_TERRAIN", offset=0.7),
         dict(dimensions=2, distortion=1.3, scale=3.0), dict(dimensions=4, w=0.37, detail=5.0, roughness=0.7),
         dict(dimensions=1, w=1.7), dict(distortion=0.8, detail=2.5, normalize=False, lacunarity=2.5)]


@pytest.mark.parametrize("settings", CASES, ids=lambda c: ",".join(f"{k}={v}" for k, v in c.items()) or "defaults")
def test_noise_matches_cycles(plane, settings):
    """Fac and Color within float rounding of Cycles' (a wrong hash or octave is off by 0.1 or more)."""
    _, local, render, _ = plane
    fac, colour = wenv.noise_texture(local.astype(np.float32), **settings)
    assert fac.std() > 0.01 or settings.get("dimensions") == 1  # a texture that varies over the plane
    np.testing.assert_allclose(render(settings, "Fac")[:, 0], fac, atol=5e-4, rtol=0)
    np.testing.assert_allclose(render(settings, "Color"), colour, atol=5e-4, rtol=0)


def test_generated_coordinates_are_the_texture_space(plane):
    """An unlinked Vector reads Generated coordinates: the mesh's texture space's box onto the unit
    cube (a flat plane's z size taken as 1, as Blender takes it)."""
    obj, local, render, _ = plane
    loc, size = np.array(obj.data.texspace_location), np.array(obj.data.texspace_size)
    assert size[2] == 1.0
    generated = ((local - loc) / (2.0 * size) + 0.5).astype(np.float32)
    fac, _ = wenv.noise_texture(generated)
    np.testing.assert_allclose(render({}, "Fac", vector=None)[:, 0], fac, atol=5e-4, rtol=0)


def _set(node, **values):
    for name, value in values.items():
        if name.isupper() or " " in name or name[0].isupper():
            next(s for s in node.inputs if s.identifier == name).default_value = value
        else:
            setattr(node, name, value)


def _uv_coordinates(mapping, uv_map=None):
    """Feeds a Mapping node the plane's UV map: the Texture Coordinate's UV, or a UV Map node's."""
    tree = mapping.id_data
    if uv_map is None:
        coords = mapping.inputs["Vector"].links[0].from_node
        tree.links.new(coords.outputs["UV"], mapping.inputs["Vector"])
    else:
        node = tree.nodes.new("ShaderNodeUVMap")
        node.uv_map = uv_map
        tree.links.new(node.outputs["UV"], mapping.inputs["Vector"])


NODE_CASES = [
    ("ShaderNodeTexNoise", "Color", lambda n, m: _set(n, noise_type="RIDGED_MULTIFRACTAL", Detail=3.0, Gain=1.5)),
    ("ShaderNodeTexWave", "Fac", lambda n, m: _set(n, wave_type="BANDS", bands_direction="DIAGONAL",
                                                   wave_profile="SIN", Scale=2.0)),
    ("ShaderNodeTexWave", "Color", lambda n, m: _set(n, wave_type="RINGS", rings_direction="Z", wave_profile="SAW",
                                                     Distortion=4.0, Detail=3.0, **{"Detail Scale": 1.5})),
    ("ShaderNodeTexWave", "Fac", lambda n, m: _set(n, wave_type="RINGS", rings_direction="SPHERICAL",
                                                   wave_profile="TRI", **{"Phase Offset": 1.2})),
    ("ShaderNodeTexChecker", "Color", lambda n, m: _set(n, Scale=3.0, Color1=(0.9, 0.2, 0.1, 1.0),
                                                        Color2=(0.1, 0.3, 0.8, 1.0))),
    ("ShaderNodeTexChecker", "Fac", lambda n, m: (_set(n, Scale=2.5), _set(m, Rotation=(0.0, 0.0, 0.4)))),
] + [("ShaderNodeTexVoronoi", output, lambda n, m, kw=kw: _set(n, **kw)) for output, kw in (
    ("Distance", dict()),
    ("Color", dict(feature="F2", distance="MANHATTAN", Scale=3.0)),
    ("Distance", dict(feature="SMOOTH_F1", Smoothness=0.6, Detail=2.5, Roughness=0.6, normalize=True)),
    ("Color", dict(feature="SMOOTH_F1", Smoothness=0.4, Randomness=0.7)),
    ("Distance", dict(feature="DISTANCE_TO_EDGE", Detail=1.5, normalize=True)),
    ("Radius", dict(feature="N_SPHERE_RADIUS", voronoi_dimensions="2D")),
    ("Distance", dict(distance="MINKOWSKI", Exponent=1.5, Detail=3.0, normalize=True)),
    ("Color", dict(distance="CHEBYCHEV", voronoi_dimensions="4D", W=0.3)),
    ("Distance", dict(feature="F2", voronoi_dimensions="1D", W=2.7)),
    ("Distance", dict(feature="DISTANCE_TO_EDGE", voronoi_dimensions="2D", Randomness=0.5)),
    ("Position", dict()),
    ("Position", dict(feature="F2", distance="MANHATTAN", Detail=2.5, Roughness=0.6)),
    ("Position", dict(feature="SMOOTH_F1", Smoothness=0.5, Randomness=0.8)),
    ("Position", dict(voronoi_dimensions="2D", Detail=1.0)),
    ("W", dict(voronoi_dimensions="4D", W=0.6, feature="SMOOTH_F1", Smoothness=0.3)),
    ("W", dict(voronoi_dimensions="1D", W=1.7, Detail=2.0)),
)] + [
    ("ShaderNodeTexBrick", "Color", lambda n, m: _set(n, Scale=2.0, Bias=0.2, Color1=(0.8, 0.3, 0.2, 1.0),
                                                      Mortar=(0.9, 0.9, 0.85, 1.0), **{"Mortar Smooth": 0.3})),
    ("ShaderNodeTexBrick", "Fac", lambda n, m: (_set(n, Scale=1.0, offset=0.3, offset_frequency=3, squash=0.6,
                                                     squash_frequency=2, **{"Mortar Size": 0.03}),
                                                _set(m, Location=(-1.3, -2.2, 0.0)))),
] + [
    ("ShaderNodeTexNoise", "Fac", lambda n, m: (_set(n, Scale=7.0), _uv_coordinates(m))),
    ("ShaderNodeTexChecker", "Color", lambda n, m: (_set(n, Scale=5.0), _uv_coordinates(m, "UVMap"))),
] + [
    ("ShaderNodeTexMagic", "Color", lambda n, m: _set(n, Scale=1.5)),
    ("ShaderNodeTexMagic", "Color", lambda n, m: _set(n, turbulence_depth=10, Scale=0.5, Distortion=1.2)),
    ("ShaderNodeTexMagic", "Fac", lambda n, m: _set(n, turbulence_depth=6, Scale=0.7, Distortion=1.5)),
    ("ShaderNodeTexMagic", "Color", lambda n, m: _set(n, turbulence_depth=0, Distortion=0.0)),
] + [
    ("ShaderNodeTexGabor", "Value", lambda n, m: None),
    ("ShaderNodeTexGabor", "Phase", lambda n, m: _set(n, Anisotropy=0.3, Frequency=3.0, Scale=2.0)),
    ("ShaderNodeTexGabor", "Intensity", lambda n, m: _set(n, gabor_type="3D", Anisotropy=0.5, Scale=3.0,
                                                         **{"Orientation 3D": (0.2, 0.5, 0.8)})),
    ("ShaderNodeTexGabor", "Value", lambda n, m: _set(n, gabor_type="3D", Frequency=1.5, Scale=4.0)),
] + [("ShaderNodeTexGradient", "Fac", lambda n, m, g=g: (_set(n, gradient_type=g),
                                                          _set(m, Scale=(0.4, 0.4, 0.4), Rotation=(0.0, 0.0, 0.0))))
     for g in ("LINEAR", "QUADRATIC", "EASING", "DIAGONAL", "SPHERICAL", "QUADRATIC_SPHERE", "RADIAL")]


# (the nodes of this Blender: the Gabor Texture came with 4.3)
NODE_CASES = [case for case in NODE_CASES if hasattr(bpy.types, case[0])]


@pytest.mark.parametrize("kind, output, configure", NODE_CASES,
                         ids=[f"{k[13:]}-{o}-{i}" for i, (k, o, _) in enumerate(NODE_CASES)])
def test_the_addon_reads_procedural_textures_as_cycles_renders_them(plane, kind, output, configure):
    """The add-on's evaluation of the node (through a Mapping node of Object coordinates) against
    Cycles' pixels.  A checker's or a saw's jump falls between two pixels' values only where a pixel's
    centre lies within float rounding of it: a handful of pixels may take the other side."""
    _, _, _, render_node = plane
    cycles, ours = render_node(kind, output, configure)
    assert ours.shape == cycles.shape and (ours.std() > 0.02 or "1D" in str(configure.__defaults__))
    off = np.abs(cycles - ours).max(axis=1) > 1e-4
    assert off.sum() <= 3, (off.sum(), np.abs(cycles - ours).max())


def _distorted_by_noise(node, mapping):
    """Feeds the Mapping node a Noise Texture's Color (of Object coordinates): the distortion chain of
    many procedural materials."""
    tree = mapping.id_data
    coords, noise = mapping.inputs["Vector"].links[0].from_node, tree.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 2.0
    tree.links.new(coords.outputs["Object"], noise.inputs["Vector"])
    tree.links.new(noise.outputs["Color"], mapping.inputs["Vector"])
    _set(mapping, Scale=(3.0, 3.0, 3.0))


def test_a_texture_of_another_texture_reads_as_cycles_renders_it(plane):
    """A Voronoi Texture whose Vector is a Noise Texture's Color (through a Mapping node): the noise
    is within 1e-4 of Cycles (above), and so is the distance it gives."""
    _, _, _, render_node = plane
    cycles, ours = render_node("ShaderNodeTexVoronoi", "Distance", _distorted_by_noise)
    assert ours.std() > 0.05
    np.testing.assert_allclose(ours, cycles, atol=1e-4)


def _vector_math(operation, **inputs):
    """configure() of a Vector Math node: its operation and its other inputs' values."""
    return lambda n, m: (_set(n, operation=operation), _set(n, **inputs))


def _mapped_into(identifier, **settings):
    """configure() linking the Mapping node into the node's input `identifier`."""
    def configure(node, mapping):
        _set(node, **settings)
        mapping.id_data.links.new(mapping.outputs["Vector"], next(s for s in node.inputs if s.identifier == identifier))
    return configure


def _averaged(node, mapping):
    """A Math node adding 0 to a Vector Math's vector: the vector read as a value (its average)."""
    tree = node.id_data
    vm = tree.nodes.new("ShaderNodeVectorMath")
    vm.operation = "MULTIPLY"
    vm.inputs[1].default_value = (0.5, -1.0, 2.0)
    tree.links.new(mapping.outputs["Vector"], vm.inputs[0])
    tree.links.new(vm.outputs["Vector"], node.inputs[0])
    node.inputs[1].default_value = 0.0


B = (0.3, -0.7, 0.5)
VECTOR_CASES = [
    ("CROSS_PRODUCT", "Vector", dict(Vector_001=B)), ("PROJECT", "Vector", dict(Vector_001=B)),
    ("REFLECT", "Vector", dict(Vector_001=B)), ("FACEFORWARD", "Vector", dict(Vector_001=B, Vector_002=(1, 0.2, 0))),
    ("MULTIPLY_ADD", "Vector", dict(Vector_001=B, Vector_002=(0.1, 0.2, 0.3))), ("NORMALIZE", "Vector", {}),
    ("DOT_PRODUCT", "Value", dict(Vector_001=B)), ("DISTANCE", "Value", dict(Vector_001=B)), ("LENGTH", "Value", {}),
    ("SCALE", "Vector", dict(Scale=-1.7)), ("DIVIDE", "Vector", dict(Vector_001=(0.5, 0.0, 2.0))),
    ("SNAP", "Vector", dict(Vector_001=(0.3, 0.45, 1.0))), ("MODULO", "Vector", dict(Vector_001=(0.7, 0.4, 0.0))),
    ("WRAP", "Vector", dict(Vector_001=(1.0, 0.5, 1.0), Vector_002=(-0.5, -0.8, 0.0))),
    ("FRACTION", "Vector", {}), ("ABSOLUTE", "Vector", {}), ("MINIMUM", "Vector", dict(Vector_001=B)),
    ("SINE", "Vector", {}), ("TANGENT", "Vector", {}), ("CEIL", "Vector", {})]
VECTOR_NODES = [("ShaderNodeVectorMath", out, _vector_math(op, **kw)) for op, out, kw in VECTOR_CASES] + [
    ("ShaderNodeSeparateXYZ", "Y", lambda n, m: None),
    ("ShaderNodeVectorRotate", "Vector", lambda n, m: _set(n, rotation_type="AXIS_ANGLE", Axis=(0.3, -0.5, 0.8),
                                                          Angle=1.1, Center=(0.2, 0.1, 0.0))),
    ("ShaderNodeVectorRotate", "Vector", lambda n, m: _set(n, rotation_type="Z_AXIS", invert=True, Angle=0.7)),
    ("ShaderNodeVectorRotate", "Vector", lambda n, m: _set(n, rotation_type="EULER_XYZ", Rotation=(0.4, -0.9, 1.3),
                                                          Center=(0.0, 0.3, 0.5))),
    ("ShaderNodeVectorRotate", "Vector", lambda n, m: _set(n, rotation_type="EULER_XYZ", invert=True,
                                                          Rotation=(0.4, -0.9, 1.3))),
    ("ShaderNodeMix", "Result_Vector", lambda n, m: (_set(n, data_type="VECTOR", factor_mode="NON_UNIFORM"),
                                                     _set(n, Factor_Vector=(0.2, 0.7, 1.0), B_Vector=B),
                                                     _mapped_into("A_Vector")(n, m))),
    ("ShaderNodeCombineXYZ", "Vector", lambda n, m: (_set(n, X=0.3, Z=-0.2), _mapped_into("Y")(n, m))),
    ("ShaderNodeMath", "Value", _averaged)]


@pytest.mark.parametrize("kind, output, configure", VECTOR_NODES,
                         ids=[f"{k[10:]}-{c[0] if k.endswith('VectorMath') else o}"
                              for (k, o, _), c in zip(VECTOR_NODES, VECTOR_CASES + [("",)] * 8)])
def test_vector_nodes_read_as_cycles_renders_them(plane, kind, output, configure):
    """Vector Math (each operation), Separate and Combine XYZ, Vector Rotate (each type), a Mix of
    vectors, and a vector read as a value, of the pixels' Object coordinates: within 1e-4 of Cycles' pixels (relative past 1), a
    floor's or modulo's step aside (a handful of pixels whose centre lies within rounding of one)."""
    _, _, _, render_node = plane
    cycles, ours = render_node(kind, output, configure)
    assert ours.shape == cycles.shape and ours.std() > 0.02
    off = (np.abs(cycles - ours) > 1e-4 * np.maximum(1.0, np.abs(cycles))).any(axis=1)  # (a tangent's: relative)
    assert off.sum() <= 3, (off.sum(), np.abs(cycles - ours).max())


def _colour_of_points(node, mapping, into="A_Color"):
    """Links the Mapping node into a colour input, the plane's points mapped into [0, 1]."""
    _set(mapping, Scale=(0.25, 0.2, 0.3), Location=(0.5, 0.4, 0.6))
    mapping.id_data.links.new(mapping.outputs["Vector"], next(s for s in node.inputs if s.identifier == into))


def _blending(mode):
    return lambda n, m: (_set(n, data_type="RGBA", blend_type=mode, Factor_Float=0.7,
                              B_Color=(0.9, 0.35, 0.1, 1.0)), _colour_of_points(n, m))


BLENDS = ["EXCLUSION", "DODGE", "BURN", "SOFT_LIGHT", "LINEAR_LIGHT", "HUE", "SATURATION", "VALUE", "COLOR",
          "OVERLAY", "SCREEN", "DIVIDE"]
COLOUR_NODES = [("ShaderNodeMix", "Result_Color", _blending(mode)) for mode in BLENDS] + [
    ("ShaderNodeSeparateColor", out, lambda n, m, mode=mode: (_set(n, mode=mode), _colour_of_points(n, m, "Color")))
    for mode, out in (("HSV", "Red"), ("HSL", "Green"), ("HSL", "Blue"))] + [
    ("ShaderNodeCombineColor", "Color", lambda n, m, mode=mode: (_set(n, mode=mode, Green=0.8, Blue=0.45),
                                                                 _colour_of_points(n, m, "Red")))
    for mode in ("HSV", "HSL")]


@pytest.mark.parametrize("kind, output, configure", COLOUR_NODES,
                         ids=[f"{k[10:]}-{b}" for k, b in zip([k for k, _, _ in COLOUR_NODES],
                                                               BLENDS + ["HSV", "HSL-S", "HSL-L", "HSV", "HSL"])])
def test_colour_nodes_read_as_cycles_renders_them(plane, kind, output, configure):
    """The Mix node's blend modes, and Separate and Combine Color in HSV and HSL, of colours made
    from the pixels' points: within 1e-4 of Cycles' pixels."""
    _, _, _, render_node = plane
    cycles, ours = render_node(kind, output, configure)
    assert ours.shape == cycles.shape and ours.std() > 0.02
    # (Cycles before 5.0 gives a wavelength's colour up to 1.8e-4 otherwise)
    off = np.abs(cycles - ours).max(axis=1) > (3e-4 if kind == "ShaderNodeWavelength" and bpy.app.version < (5, 0, 0)
                                               else 1e-4)
    assert off.sum() <= 3, (off.sum(), np.abs(cycles - ours).max())


def _math_of_points(operation, b=0.35, c=0.2):
    """configure() of a Math node on the mean of the pixel's mapped point, its other inputs b and c."""
    def configure(node, mapping):
        _set(node, operation=operation)
        node.inputs[1].default_value, node.inputs[2].default_value = b, c
        _set(mapping, Scale=(3.0, 2.5, 2.0) if operation == "TRUNC" else (0.6, 0.5, 0.4))  # (whole steps)
        node.id_data.links.new(mapping.outputs["Vector"], node.inputs[0])
    return configure


MATHS = [("LOGARITHM", 2.5, 0.0), ("INVERSE_SQRT", 0.0, 0.0), ("EXPONENT", 0.0, 0.0), ("SIGN", 0.0, 0.0),
         ("COMPARE", 0.1, 0.2), ("SMOOTH_MIN", 0.1, 0.3), ("SMOOTH_MAX", -0.1, 0.4), ("TRUNC", 0.0, 0.0),
         ("MODULO", 0.3, 0.0), ("FLOORED_MODULO", 0.3, 0.0), ("WRAP", 0.4, -0.3), ("PINGPONG", 0.25, 0.0),
         ("ARCSINE", 0.0, 0.0), ("ARCCOSINE", 0.0, 0.0), ("ARCTANGENT", 0.0, 0.0), ("ARCTAN2", 0.3, 0.0),
         ("SINH", 0.0, 0.0), ("TANH", 0.0, 0.0), ("DEGREES", 0.0, 0.0), ("TANGENT", 0.0, 0.0)]


@pytest.mark.parametrize("operation, b, c", MATHS, ids=[m[0] for m in MATHS])
def test_math_operations_read_as_cycles_renders_them(plane, operation, b, c):
    """The Math node's operations (those test_addon.py does not hold to Cycles already) of a value
    that varies over the plane: within 1e-4 of Cycles' pixels (relative past 1), a step's pixels
    aside."""
    _, _, _, render_node = plane
    cycles, ours = render_node("ShaderNodeMath", "Value", _math_of_points(operation, b, c))
    assert ours.shape == cycles.shape and ours.std() > 0.02
    off = (np.abs(cycles - ours) > 1e-4 * np.maximum(1.0, np.abs(cycles))).any(axis=1)
    assert off.sum() <= 3, (off.sum(), np.abs(cycles - ours).max())


def _value_of_points(settings, into="Value", **inputs):
    """configure() of a node of `settings` and inputs whose `into` input is the pixel's mapped point
    (a vector read as a value: its average)."""
    def configure(node, mapping):
        _set(node, **settings)
        _set(node, **inputs)
        _set(mapping, Scale=(0.6, 0.5, 0.4), Location=(0.1, 0.0, 0.0))
        if into is not None:
            node.id_data.links.new(mapping.outputs["Vector"], next(s for s in node.inputs if s.identifier == into))
    return configure


def _curved(node, mapping):
    """A Float Curve (Factor 0.8) or RGB Curves (Fac 0.9) whose curves are bent by a point each (RGB
    Curves: the combined curve and red's), fed the pixel's mapped point."""
    curves = node.mapping.curves
    for k, (x, y) in ((0, (0.3, 0.7)), (3, (0.6, 0.35))) if len(curves) > 1 else ((0, (0.3, 0.7)),):
        curves[k].points.new(x, y)
    node.mapping.update()
    _set(mapping, Scale=(0.25, 0.2, 0.3), Location=(0.5, 0.4, 0.6))
    into = "Value" if node.bl_idname == "ShaderNodeFloatCurve" else "Color"
    node.inputs["Factor" if into == "Value" else "Fac"].default_value = 0.8 if into == "Value" else 0.9
    node.id_data.links.new(mapping.outputs["Vector"], node.inputs[into])


def _kelvin(node, mapping):
    """A Blackbody whose Temperature is the pixel's mapped point, from 500 K to 14,000 K (every range
    of Cycles' fit, and past both ends)."""
    _set(mapping, Scale=(10200.0, 0.0, 0.0), Location=(21750.0, 0.0, 0.0))  # (a vector read as its mean)
    node.id_data.links.new(mapping.outputs["Vector"], node.inputs["Temperature"])


def _nanometres(node, mapping):
    """A Wavelength whose Wavelength is the pixel's mapped point, from 300 to 860 nm (past both ends of
    the table)."""
    _set(mapping, Scale=(420.0, 0.0, 0.0), Location=(1740.0, 0.0, 0.0))  # (a vector read as its mean)
    node.id_data.links.new(mapping.outputs["Vector"], node.inputs["Wavelength"])


RANGE = {"From Min": -0.3, "From Max": 0.4, "To Min": 0.2, "To Max": 1.3}
RANGE3 = {"From_Min_FLOAT3": (-0.3, -0.5, 0.0), "From_Max_FLOAT3": (0.4, 0.6, 1.0), "To_Min_FLOAT3": (0.2, 0.0, 1.0),
          "To_Max_FLOAT3": (1.3, 1.0, -1.0)}
VALUE_NODES = [
    ("ShaderNodeMapRange", "Result", _value_of_points(dict(interpolation_type="LINEAR", clamp=True), **RANGE)),
    ("ShaderNodeMapRange", "Result", _value_of_points(dict(interpolation_type="LINEAR", clamp=False), **RANGE)),
    ("ShaderNodeMapRange", "Result", _value_of_points(dict(interpolation_type="STEPPED"), Steps=4.0, **RANGE)),
    ("ShaderNodeMapRange", "Result", _value_of_points(dict(interpolation_type="SMOOTHSTEP"), **RANGE)),
    ("ShaderNodeMapRange", "Result", _value_of_points(dict(interpolation_type="SMOOTHERSTEP"),
                                                      **{**RANGE, "From Min": 0.4, "From Max": -0.3})),
    ("ShaderNodeMapRange", "Vector", _value_of_points(dict(data_type="FLOAT_VECTOR", interpolation_type="LINEAR",
                                                           clamp=True), into=None, **RANGE3)),
    ("ShaderNodeMapRange", "Vector", _value_of_points(dict(data_type="FLOAT_VECTOR", interpolation_type="SMOOTHSTEP"),
                                                      into=None, **RANGE3)),
    ("ShaderNodeClamp", "Result", _value_of_points(dict(clamp_type="MINMAX"), Min=-0.1, Max=0.2)),
    ("ShaderNodeClamp", "Result", _value_of_points(dict(clamp_type="RANGE"), Min=0.2, Max=-0.1)),
    ("ShaderNodeRGBToBW", "Val", _value_of_points({}, into="Color")),
    ("ShaderNodeFloatCurve", "Value", _curved),
    ("ShaderNodeBlackbody", "Color", _kelvin),
    ("ShaderNodeWavelength", "Color", _nanometres),
    ("ShaderNodeRGBCurve", "Color", _curved),
]


@pytest.mark.parametrize("kind, output, configure", VALUE_NODES,
                         ids=[f"{k[10:]}-{i}" for i, (k, _, _) in enumerate(VALUE_NODES)])
def test_value_nodes_read_as_cycles_renders_them(plane, kind, output, configure):
    """Map Range (each interpolation, clamped or not, of values and vectors), Clamp, RGB to BW, Float
    Curve and RGB Curves (curves bent by a point) of the pixels' points: within 1e-4 of Cycles'
    pixels, a step's pixels aside."""
    _, _, _, render_node = plane
    cycles, ours = render_node(kind, output, configure)
    assert ours.shape == cycles.shape and ours.std() > 0.02
    # (Cycles before 5.0 gives a wavelength's colour up to 1.8e-4 otherwise)
    off = np.abs(cycles - ours).max(axis=1) > (3e-4 if kind == "ShaderNodeWavelength" and bpy.app.version < (5, 0, 0)
                                               else 1e-4)
    assert off.sum() <= 3, (off.sum(), np.abs(cycles - ours).max())


@pytest.mark.parametrize("kwargs, error, words", [
    (dict(type="CELLS"), ValueError, "type must be"),
    (dict(dimensions=5), ValueError, "dimensions must be 1, 2, 3 or 4"),
    (dict(scale=float("nan")), ValueError, "scale must be finite"),
    (dict(w=np.zeros(3, np.float32)), ValueError, "w must be a number or have shape"),
    (dict(w="x"), TypeError, "w"),
])
def test_bad_noise_input_is_named(kwargs, error, words):
    """Each bad argument gets an error that names it."""
    with pytest.raises(error, match=words):
        wenv.noise_texture(np.zeros((4, 3), np.float32), **kwargs)
    with pytest.raises(ValueError, match=r"vectors must have shape \(n, 3\)"):
        wenv.noise_texture(np.zeros((4, 2), np.float32))


def test_colour_on_request_progress_and_cancel():
    """Fac alone (color=False) is the Fac of both; progress reports blocks of points up to 1, and a
    progress that returns True cancels."""
    points = np.random.default_rng(3).random((20000, 3)).astype(np.float32)
    fac, colour = wenv.noise_texture(points, detail=3.0)
    alone, none = wenv.noise_texture(points, detail=3.0, color=False)
    assert none is None and np.array_equal(alone, fac) and np.array_equal(colour[:, 0], fac)
    seen = []
    wenv.noise_texture(points, progress=lambda f: seen.append(f) and False)
    assert seen and seen[-1] == 1.0 and seen == sorted(seen)
    with pytest.raises(wenv.CancelledError):
        wenv.noise_texture(points, progress=lambda f: True)
    with pytest.raises(TypeError, match="progress must be callable"):
        wenv.noise_texture(points, progress=3)


def test_bad_wave_input_is_named():
    """The Wave Texture's settings are checked as the Noise Texture's are."""
    points = np.zeros((4, 3), np.float32)
    with pytest.raises(ValueError, match="direction must be one of X"):
        wenv.wave_texture(points, direction="SPHERICAL")  # a rings direction, given to bands
    with pytest.raises(ValueError, match="profile must be one of"):
        wenv.wave_texture(points, profile="SQUARE")
    with pytest.raises(ValueError, match="phase must be finite"):
        wenv.wave_texture(points, phase=float("inf"))
    with pytest.raises(wenv.CancelledError):
        wenv.wave_texture(np.zeros((10000, 3), np.float32), progress=lambda f: True)


def test_white_noise_input_and_cancel():
    """The White Noise Texture's core: bad dimensions and points named, W per point or one for all,
    the colour's first channel is the value, its values spread over [0, 1], and a cancel."""
    points = np.random.default_rng(6).random((4000, 3)).astype(np.float32)
    with pytest.raises(ValueError, match="dimensions must be 1, 2, 3 or 4"):
        wenv.white_noise_texture(points, dimensions=5)
    with pytest.raises(ValueError, match=r"vectors must have shape \(n, 3\)"):
        wenv.white_noise_texture(points[:, :2])
    with pytest.raises(ValueError, match="w must be a number or have shape"):
        wenv.white_noise_texture(points, np.zeros(3, np.float32), dimensions=4)
    with pytest.raises(wenv.CancelledError):
        wenv.white_noise_texture(np.zeros((100000, 3), np.float32), progress=lambda f: True)
    value, colour = wenv.white_noise_texture(points, 0.25, dimensions=4)
    each, _ = wenv.white_noise_texture(points, np.full(len(points), 0.25, np.float32), dimensions=4, color=False)
    assert np.array_equal(value, each) and np.array_equal(colour[:, 0], value)
    assert 0.0 <= colour.min() and colour.max() <= 1.0 and abs(colour.mean() - 0.5) < 0.02
    assert not np.array_equal(wenv.white_noise_texture(points, 0.5, dimensions=4)[0], value)


def test_bad_gabor_input_is_named():
    """The Gabor Texture's core: each bad setting named, three outputs consistent with each other,
    and a cancel."""
    points = np.random.default_rng(8).random((500, 3)).astype(np.float32)
    with pytest.raises(ValueError, match="dimensions must be 2 or 3"):
        wenv.gabor_texture(points, dimensions=4)
    with pytest.raises(ValueError, match="frequency must be finite"):
        wenv.gabor_texture(points, frequency=float("inf"))
    with pytest.raises(ValueError, match="orientation_3d must not be zero"):
        wenv.gabor_texture(points, dimensions=3, orientation_3d=(0.0, 0.0, 0.0))
    with pytest.raises(TypeError):
        wenv.gabor_texture(points, orientation_3d=(1.0, 2.0))
    with pytest.raises(wenv.CancelledError):
        wenv.gabor_texture(np.zeros((20000, 3), np.float32), progress=lambda f: True)
    value, phase, intensity = wenv.gabor_texture(points, anisotropy=0.4)
    assert 0.0 <= phase.min() and phase.max() <= 1.0 and (intensity >= 0.0).all()
    # the value is the phasor's sine part: within the intensity of one half either way
    assert (np.abs(value - 0.5) <= 0.5 * intensity + 1e-6).all() and value.std() > 0.02


def test_bad_voronoi_input_is_named():
    """The Voronoi Texture's settings are checked as the others' are; Color on request."""
    points = np.random.default_rng(5).random((300, 3)).astype(np.float32)
    with pytest.raises(ValueError, match="feature must be one of F1"):
        wenv.voronoi_texture(points, feature="F3")
    with pytest.raises(ValueError, match="distance must be one of EUCLIDEAN"):
        wenv.voronoi_texture(points, distance="HAMMING")
    with pytest.raises(ValueError, match="randomness must be finite"):
        wenv.voronoi_texture(points, randomness=float("nan"))
    with pytest.raises(ValueError, match="dimensions must be 1, 2, 3 or 4"):
        wenv.voronoi_texture(points, dimensions=0)
    with pytest.raises(ValueError, match="cell_hash must be one of PCG"):
        wenv.voronoi_texture(points, cell_hash="MD5")
    # the cells of Blender before 5.0 (each release against its own Cycles above): 1D's the same
    for dims in (1, 2, 3, 4):
        same = np.array_equal(wenv.voronoi_texture(points, dimensions=dims, w=points[:, 0].copy())[0],
                              wenv.voronoi_texture(points, dimensions=dims, w=points[:, 0].copy(),
                                                   cell_hash="LOOKUP3")[0])
        assert same == (dims == 1), dims
    with pytest.raises(wenv.CancelledError):
        wenv.voronoi_texture(np.zeros((10000, 3), np.float32), progress=lambda f: True)
    distance, colour, no_position = wenv.voronoi_texture(points)
    alone, none, _ = wenv.voronoi_texture(points, color=False)
    assert no_position is None
    assert none is None and np.array_equal(alone, distance) and colour.shape == (300, 3)


def test_the_addon_can_cancel_a_procedural_texture(plane):
    """An Evaluator's progress reaches the core's texture calls: returning True stops them (a bake
    cancelled while it reads a million texels' Voronoi)."""
    mat = bpy.data.materials.new("cells")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    tree = mat.node_tree
    cells, emission = tree.nodes.new("ShaderNodeTexVoronoi"), tree.nodes.new("ShaderNodeEmission")
    tree.links.new(cells.outputs["Distance"], emission.inputs["Color"])
    points = np.random.default_rng(9).random((20000, 3)).astype(np.float32)
    seen = []
    ev = nodes.Evaluator(len(points), None, None, points=lambda space, other: points,
                         progress=lambda f: seen.append(f) and False)
    assert ev.value(emission.inputs["Color"]).shape == (20000,) and seen[-1] == 1.0
    ev = nodes.Evaluator(len(points), None, None, points=lambda space, other: points, progress=lambda f: True)
    with pytest.raises(wenv.CancelledError):
        ev.value(emission.inputs["Color"])
