"""Shader nodes between Image Textures and a Principled BSDF's input, evaluated at each shaded vertex as
Cycles' SVM evaluates them (intern/cycles/kernel/svm/): Image Texture, RGB and Value, Mix (and the
older MixRGB) with its common blend modes, Math, Invert, ColorRamp, RGB Curves, Hue/Saturation/Value,
Gamma, Brightness/Contrast, Separate and Combine Color (RGB), the procedural textures, the mesh's
attributes (Color Attribute, and Attribute of the geometry), and on the way to a texture's Vector the
Texture Coordinate's and UV Map's UVs (an Image Texture's) or its Generated and Object coordinates or
an attribute (a procedural texture's) through Mapping and Vector Math.  Colours are (n, 3) float32,
values (n,), at the shaded rows; a texture's UVs are read at the face corners and its samples averaged
to the rows.  Any other node, output or mode raises Unsupported naming it, so that the caller uses the
socket's unlinked value and says so: nothing is used silently."""
import math

import numpy as np

from . import compat, engine, world

# How deep a chain may go: a loop of links (which Blender marks invalid, but a script may leave) ends
# here rather than in Python's recursion limit.
MAX_DEPTH = 64

# Blender's scene-linear (Rec.709) luminance, summing to 1 so that white reads 1
LUMINANCE = np.array([0.2126729, 0.7151522, 0.0721750]) / 1.0000001

# The Image Texture settings read as Cycles reads them; the others are read as Linear (noted).
INTERPOLATIONS = ("Linear", "Closest")
# The image sources read: a file (packed or not), a generated image, UDIM tiles, and an image
# sequence or a movie (the frame the scene's shows)
IMAGE_SOURCES = ("FILE", "GENERATED", "TILED", "SEQUENCE", "MOVIE")

# A procedural texture's inputs read as the core's settings: (keyword, socket identifier)
NOISE_INPUTS = (("w", "W"), ("scale", "Scale"), ("detail", "Detail"), ("roughness", "Roughness"),
                ("lacunarity", "Lacunarity"), ("offset", "Offset"), ("gain", "Gain"), ("distortion", "Distortion"))
VORONOI_INPUTS = (("w", "W"), ("scale", "Scale"), ("detail", "Detail"), ("roughness", "Roughness"),
                  ("lacunarity", "Lacunarity"), ("smoothness", "Smoothness"), ("exponent", "Exponent"),
                  ("randomness", "Randomness"))
BRICK_INPUTS = (("scale", "Scale"), ("mortar_size", "Mortar Size"), ("mortar_smooth", "Mortar Smooth"),
                ("bias", "Bias"), ("width", "Brick Width"), ("height", "Row Height"))
WAVE_INPUTS = (("scale", "Scale"), ("distortion", "Distortion"), ("detail", "Detail"), ("detail_scale", "Detail Scale"),
               ("detail_roughness", "Detail Roughness"), ("phase", "Phase Offset"))
# Where a procedural texture is read without a mesh (one_point: the panel's checks, the glossmeter's
# means): 16 x 16 x 16 points over the unit cube, which Generated coordinates span, averaged.
_side = (np.arange(16, dtype=np.float32) + 0.5) / 16.0
MEAN_POINTS = np.stack(np.meshgrid(_side, _side, _side, indexing="ij"), -1).reshape(-1, 3)


# ... and of a UV map (u, v, 0) over the unit square
MEAN_SQUARE = np.column_stack([MEAN_POINTS[:256, 1:], np.zeros(256, np.float32)])
# The Geometry node's Pointiness and Random Per Island, which Cycles computes from the mesh, asked of
# attribute() as names no attribute can have
POINTINESS, RANDOM_PER_ISLAND, PARAMETRIC = ("pointiness",), ("random per island",), ("parametric",)
# The Texture Coordinate node's outputs read (the rest are named)
TEXTURE_COORDINATES = ("Generated", "Object", "UV", "Normal", "Reflection", "Camera", "Window")


def group_means(values, index, count):
    """The mean of values ((m,) or (m, k)) over each of `count` groups, value j in group index[j]
    (float32; 0 for a group of none)."""
    flat = values.reshape(len(values), -1)
    n = np.bincount(index, minlength=count).astype(np.float64)
    total = np.stack([np.bincount(index, weights=flat[:, c], minlength=count) for c in range(flat.shape[1])], axis=1)
    return (total / np.maximum(n, 1.0)[:, None]).astype(np.float32).reshape((count,) + values.shape[1:])


def _same(values):
    return values


def _mean(values):
    return values.mean(axis=0, keepdims=True)


class Unsupported(Exception):
    """A node, output or setting the evaluation does not read (its message says which)."""


class UnreadAtRows(Unsupported):
    """What a node cannot read at these rows: a view's frame or any view, where the view shaded for
    has none; a texture's setting linked to values that vary from row to row.  Checking a material
    cannot tell, so the reading names it."""


def unit_rows(v):
    """Each row of v made unit; a zero row stays zero."""
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(length > 0.0, v / np.where(length > 0.0, length, 1.0), 0.0)


def luminance(rgb):
    """A colour's luminance (float32), as Cycles converts a colour into a value."""
    return (np.asarray(rgb, np.float64) @ LUMINANCE).astype(np.float32)


def source(socket):
    """(node, output socket) feeding `socket` through reroutes, or None when unlinked or muted."""
    while socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            return None
        if link.from_node.bl_idname != "NodeReroute":
            return link.from_node, link.from_socket
        socket = link.from_node.inputs[0]
    return None


def used(socket, depth=0):
    """Whether an output socket reaches an output node through its links (forward, through any node
    and into groups): what Cycles keeps of a graph after removing the nodes no output uses."""
    if depth > MAX_DEPTH:
        return False
    for link in socket.links:
        if not link.is_valid or link.is_muted:
            continue
        node = link.to_node
        if node.bl_idname in ("ShaderNodeOutputMaterial", "NodeGroupOutput"):
            return True
        if any(used(out, depth + 1) for out in node.outputs):
            return True
    return False


def unassociates_alpha(node):
    """Whether Cycles divides an Image Texture's colour by its alpha (svm_image_texture's
    NODE_IMAGE_ALPHA_UNASSOCIATE): its Alpha output is used and its image's alpha is associated (the
    image not data, its alpha neither channel-packed nor ignored).  An Environment Texture has no
    Alpha: its colour stays associated."""
    image, alpha = node.image, node.outputs.get("Alpha")
    return (image is not None and alpha is not None and image.colorspace_settings.name not in world.DATA_SPACES
            and image.alpha_mode not in ("CHANNEL_PACKED", "NONE") and used(alpha))


def property_rgba(owner, name):
    """Blender's find_property_rgba: `owner`'s custom property `name`, else the property at the RNA
    path `name`, as RGBA -- a number or a boolean (v, v, v, 1), an array of at most four numbers
    over (0, 0, 0, 1) -- or None (no such property, or one of another kind)."""
    keys = owner.keys() if hasattr(owner, "keys") else ()
    if name in keys:
        value = owner[name]
    else:
        try:
            value = owner.path_resolve(name)
        except (ValueError, TypeError):
            return None
    if isinstance(value, (bool, int, float)):
        return (float(value),) * 3 + (1.0,)
    if isinstance(value, str) or not hasattr(value, "__len__") or not 0 < len(value) <= 4:
        return None
    items = list(value)
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in items):
        return None
    out = [0.0, 0.0, 0.0, 1.0]
    out[:len(items)] = [float(v) for v in items]
    return tuple(out)


def _fed(socket, depth):
    """source(socket) for a chain `depth` nodes deep; None when unlinked (its own value is read)."""
    if depth > MAX_DEPTH:
        raise Unsupported("nodes in a cycle (or a chain deeper than 64)")
    fed = source(socket)
    if fed is None and socket.is_linked:
        raise Unsupported("a muted or invalid link")
    return fed


def _input(node, identifier):
    return next(s for s in node.inputs if s.identifier == identifier)


class Evaluator:
    """Evaluates sockets for one object's shaded rows.  `texture(node, uv, footprint)` samples an
    Image Texture node at the corners (textures.py gives it); `uv(uv_map)` gives (uv, footprint,
    rows) of the mesh's UV map (None: the active render one), or None without one."""

    def __init__(self, count, uv, texture, checking=False, points=None, progress=None, attribute=None, owner=None,
                 footprint=None, ambient=None, bevel=None):
        self.count = count
        # bevel(positions, normals, radius) -> the Bevel node's unit normals at the rows (bevel.py),
        # None where the surface about them is not read (no mesh, or a Bump node's height)
        self._bevel = bevel
        # ambient(positions, normals, distance, inside, only_local, samples) -> the rows' unoccluded shares
        # (ambient.py), None where no rays are cast (no scene, or a Bump node's height)
        self._ambient = ambient
        self._uv = uv
        self._texture = texture
        # attribute(name, colour) -> (values (count, k), Cycles' type) of a mesh attribute at the rows,
        # or (None, None) where the mesh has none of that name; None: no mesh (one_point)
        self._attribute = attribute
        self._owner = owner  # (object, material) the rows are of (Object Info); None: none (one_point)
        # footprint(coords (count, 2)) -> each row's side in those coordinates (an Image Texture read
        # through coordinates other than a UV map); None: read at the point
        self._footprint = footprint
        # points(space, other): the rows' 'GENERATED' or 'OBJECT' coordinates ((count, 3), `other`'s
        # object space where given), 'WORLD' positions or 'NORMAL' (unit, world); None: MEAN_POINTS,
        # averaged (one_point)
        self._points = points
        self.spaces = set()  # the coordinates read
        self.read_light_path = False  # a Light Path node read (as a camera ray's hit)
        # something read that depends on where the rows lie, not on the mesh alone: world positions or
        # directions, the view, the object (Object Info, its attributes, its transform): what an
        # instance of the mesh elsewhere would read otherwise
        self.placed = False
        # progress(fraction) while a procedural texture is evaluated (a bake's million texels), which
        # may cancel (CancelledError, raised by it or by the core when it returns True)
        self.progress = progress
        self.checking = checking  # only whether every node is read: no tables made, no texel read
        self._groups = []  # the group nodes being evaluated through, innermost last
        self.textures = []  # the Image Texture nodes read
        self.notes = []  # what of them is read otherwise than Cycles reads it

    # -- conversions at sockets, as Cycles converts
    def colour(self, socket, depth=0):
        out = self.evaluate(socket, depth)
        return out if out.ndim == 2 else np.repeat(out[:, None], 3, axis=1)

    def value(self, socket, depth=0):
        out = self.evaluate(socket, depth)
        if out.ndim == 1:
            return out
        fed = source(socket)
        if fed is not None and fed[1].type == "VECTOR":  # a vector's average, a colour's luminance
            return ((out[:, 0] + out[:, 1]) + out[:, 2]) * np.float32(1.0 / 3.0)
        return luminance(out)

    def value_within(self, socket, groups):
        """value() of a socket inside node groups (the group nodes it lies in, outermost first): its
        Group Inputs read the sockets those group nodes are fed by."""
        held, self._groups = self._groups, list(groups)
        try:
            return self.value(socket)
        finally:
            self._groups = held

    def evaluate(self, socket, depth=0):
        """The socket's value at every row: its node's output, or its own (unlinked) value."""
        fed = _fed(socket, depth)
        if fed is None:
            value = socket.default_value
            if isinstance(value, float):
                return np.full(self.count, value, np.float32)
            return np.tile(np.float32(tuple(value)[:3]), (self.count, 1))
        node, output = fed
        method = getattr(self, "_" + node.bl_idname, None)
        if method is None:
            raise Unsupported(f"'{node.name}', a node wenv does not evaluate yet")
        return method(node, output, depth + 1)

    # -- sources
    def _ShaderNodeTexImage(self, node, output, depth):
        image = node.image
        if image is None:
            raise Unsupported(f"'{node.name}', which has no image")
        if image.source not in IMAGE_SOURCES:
            raise Unsupported(f"'{node.name}', whose {image.source.lower()} image wenv does not read yet")
        try:
            if node.projection != "FLAT":
                raise _NotUV()
            uv, footprint, rows = self.vector(node.inputs["Vector"], depth)
            samples = [(None, uv, footprint, rows)]
        except _NotUV:  # coordinates of the rows: a plane of them, or a box's three
            samples = self._image_coordinates(node, depth)
        return self._sampled(node, output, samples)

    def _sampled(self, node, output, samples):
        """An image node's output from its image sampled at `samples` ([(weight per row or None, uv,
        footprint, rows)], summed): its colour, associated with alpha as Cycles samples it (divided
        again where the Alpha output is used), or its alpha."""
        image = node.image
        self.textures.append(node)
        if node.interpolation not in INTERPOLATIONS:
            self.notes.append(f"'{node.name}': {node.interpolation} interpolation is read as Linear")
        space = image.colorspace_settings.name
        if not image.is_float and space not in world.SRGB_SPACES and space not in world.LINEAR_SPACES:
            self.notes.append(f"'{node.name}': 8-bit colour space '{space}' is not decoded: its values are read as "
                              "linear")
        alpha, unassociated = output.identifier == "Alpha", unassociates_alpha(node)
        out = None
        for weight, uv, footprint, rows in samples:
            got = self._texture(node, uv, footprint, rows)  # RGB, or RGBA where the image has alpha
            if alpha:
                got = got[:, 3] if got.shape[1] == 4 else np.ones(len(got), np.float32)
            elif got.shape[1] == 4:  # associated, as Cycles samples it: divided where the Alpha is used
                a = got[:, 3:]
                got = np.where((a != 0.0) & (a != 1.0), got[:, :3] / np.where(a != 0.0, a, 1.0),
                               got[:, :3]) if unassociated else got[:, :3]
            got = got if weight is None else (weight if alpha else weight[:, None]) * got
            out = got if out is None else out + got
        return out.astype(np.float32)

    def _ShaderNodeTexEnvironment(self, node, output, depth):
        """An image of the directions (svm_node_tex_environment): its Vector (the position in the world
        when unlinked, as Cycles reads it on a surface) made unit and mapped equirectangularly (u =
        0.5 - atan2(y, x) / 2 pi, v = 1 - acos(z) / pi) or as a mirror ball, the image repeating."""
        image = node.image
        if image is None:
            raise Unsupported(f"'{node.name}', which has no image")
        if image.source not in IMAGE_SOURCES:
            raise Unsupported(f"'{node.name}', whose {image.source.lower()} image wenv does not read yet")
        if node.projection not in ("EQUIRECTANGULAR", "MIRROR_BALL"):
            raise Unsupported(f"'{node.name}''s {node.projection.lower()} projection")
        socket = node.inputs["Vector"]
        if self._points is None and not socket.is_linked:  # no mesh: the image's mean
            return self._sampled(node, output, [(None, np.zeros((1, 2), np.float32), np.ones(1, np.float32),
                                                 np.zeros(1, np.int64))])
        d = (self.colour(socket, depth) if socket.is_linked else self._coordinates("WORLD", node=node)[0])
        d = d.astype(np.float64)
        length = np.linalg.norm(d, axis=1, keepdims=True)
        d = np.where(length > 0.0, d / np.where(length > 0.0, length, 1.0), 0.0)
        if node.projection == "EQUIRECTANGULAR":
            u = np.where(length[:, 0] > 0.0, 0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2.0 * np.pi), 0.0)
            v = np.where(length[:, 0] > 0.0, 1.0 - np.arccos(np.clip(d[:, 2], -1.0, 1.0)) / np.pi, 0.0)
        else:  # the mirror ball seen along +y (direction_to_mirrorball)
            d[:, 1] -= 1.0
            div = 2.0 * np.sqrt(np.maximum(-0.5 * d[:, 1], 0.0))
            d = np.where(div[:, None] > 0.0, d / np.where(div > 0.0, div, 1.0)[:, None], d)
            u, v = 0.5 * (d[:, 0] + 1.0), 0.5 * (d[:, 2] + 1.0)
        uv = np.ascontiguousarray(np.column_stack([u, v]), np.float32)
        footprint = (self._footprint(uv, node.projection == "EQUIRECTANGULAR") if self._footprint
                     else np.zeros(self.count, np.float32))
        return self._sampled(node, output, [(None, uv, footprint, np.arange(self.count))])

    def _image_coordinates(self, node, depth):
        """[(weight per row or None, uv, footprint, rows)] of an Image Texture whose Vector is not a UV
        map: the plane of its x and y (flat), or the box's three planes weighted by the object-space
        normal as Cycles' svm_node_tex_image_box weighs them."""
        p, _reduce = self.points(node.inputs["Vector"], depth)  # (per row: a UV map goes through vector())
        rows = np.arange(self.count)
        if self._points is None:  # no mesh: the image's mean
            return [(None, np.zeros((1, 2), np.float32), np.ones(1, np.float32), np.zeros(1, np.int64))]

        def plane(u, v, wrap=False):
            uv = np.ascontiguousarray(np.stack([u, v], axis=1), np.float32)
            return uv, (self._footprint(uv, wrap) if self._footprint else np.zeros(self.count, np.float32)), rows
        if node.projection == "FLAT":
            return [(None,) + plane(p[:, 0], p[:, 1])]
        if node.projection in ("SPHERE", "TUBE"):
            return [(None,) + plane(*_wrapped(p, node.projection), wrap=True)]
        signed = self._coordinates("OBJECT_NORMAL", node=node)[0]
        weight = _box_weights(signed, np.float32(node.projection_blend))
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        one = np.float32(1.0)
        planes = (plane(np.where(signed[:, 0] < 0.0, one - y, y), z),
                  plane(np.where(signed[:, 1] > 0.0, one - x, x), z),
                  plane(np.where(signed[:, 2] > 0.0, one - y, y), x))
        return [(weight[:, k],) + planes[k] for k in range(3) if (weight[:, k] > 0.0).any()]

    def _procedural_inputs(self, node, depth, output, table):
        """A procedural texture node's inputs of `table` ((keyword, socket identifier)) as the core's
        settings (_setting); Unsupported for an output other than Fac or Color (output None: checked by
        the caller) or the node's own texture mapping."""
        if output is not None and output.identifier not in ("Fac", "Color"):  # (Fac is named Factor from 5.0)
            raise Unsupported(f"'{node.name}''s {output.name} output")
        _identity_mapping(node)
        kw = {}
        for key, name in table:
            socket = next((x for x in node.inputs if x.identifier == name), None)
            if socket is None or not socket.enabled:  # (an unavailable socket is not found by name)
                continue
            kw[key] = self._setting(node, socket, depth)
        return kw

    def _setting(self, node, socket, depth):
        """A texture's setting, which the core takes one for all the rows: the socket's unlinked value,
        or the linked one where it is the same at every row (a Value node's, a group's input);
        UnreadAtRows where it varies from row to row."""
        vector = socket.type in ("VECTOR", "RGBA")
        if not socket.is_linked:
            value = socket.default_value
            return tuple(float(c) for c in value) if vector else float(value)
        got = self.colour(socket, depth) if vector else self.value(socket, depth)
        if len(got) and np.ptp(got, axis=0).max() > 0.0:
            raise UnreadAtRows(f"'{node.name}''s {socket.name}, linked to values that vary from point to point "
                               "(wenv's textures take one for all)")
        first = got[0] if len(got) else np.zeros(got.shape[1:], np.float32)
        return tuple(float(c) for c in first) if vector else float(first)

    def _ShaderNodeTexNoise(self, node, output, depth):
        kw = self._procedural_inputs(node, depth, output, NOISE_INPUTS)
        dims = int(node.noise_dimensions[0])
        points, reduce = self.points(_input(node, "Vector"), depth) if dims > 1 else self._no_points()
        if self.checking:
            return np.zeros((self.count, 3) if output.identifier == "Color" else self.count, np.float32)
        colour = output.identifier == "Color"  # (Fac alone is a third of the work)
        return reduce(engine.noise_texture(points, dimensions=dims, type=node.noise_type, normalize=node.normalize,
                                           color=colour, progress=self.progress, **kw)[1 if colour else 0])

    def _ShaderNodeTexVoronoi(self, node, output, depth):
        which = output.identifier
        kw = self._procedural_inputs(node, depth, None, VORONOI_INPUTS)
        dims = int(node.voronoi_dimensions[0])
        points, reduce = self.points(_input(node, "Vector"), depth) if dims > 1 else self._no_points()
        colour, position = which == "Color", which in ("Position", "W")
        if self.checking:
            return np.zeros((self.count, 3) if which in ("Color", "Position") else self.count, np.float32)
        got = engine.voronoi_texture(points, dimensions=dims, feature=node.feature, distance=node.distance,
                                     normalize=node.normalize, color=colour, position=position, progress=self.progress,
                                     cell_hash=compat.VORONOI_CELL_HASH, **kw)
        if position:  # the cell's point, (x, y, z, W)
            return reduce(np.ascontiguousarray(got[2][:, :3] if which == "Position" else got[2][:, 3]))
        return reduce(got[1 if colour else 0])

    def _ShaderNodeTexWhiteNoise(self, node, output, depth):
        _identity_mapping(node)
        dims = int(node.noise_dimensions[0])
        w = _input(node, "W")
        w = self._setting(node, w, depth) if w.enabled else float(w.default_value)
        points, reduce = self.points(_input(node, "Vector"), depth) if dims > 1 else self._no_points()
        colour = output.identifier == "Color"
        if self.checking:
            return np.zeros((self.count, 3) if colour else self.count, np.float32)
        got = engine.white_noise_texture(points, w, dimensions=dims, color=colour, progress=self.progress)
        return reduce(got[1 if colour else 0])

    def _ShaderNodeTexMagic(self, node, output, depth):
        kw = self._procedural_inputs(node, depth, output, (("scale", "Scale"), ("distortion", "Distortion")))
        points, reduce = self.points(_input(node, "Vector"), depth)
        if self.checking:
            return self._grey(np.zeros(self.count, np.float32), output)
        colour = reduce(_magic(points, kw["scale"], node.turbulence_depth, kw["distortion"]))
        if output.identifier == "Color":
            return colour
        return ((colour[:, 0] + colour[:, 1]) + colour[:, 2]) * np.float32(1.0 / 3.0)  # Cycles' average()

    def _ShaderNodeTexGabor(self, node, output, depth):
        _identity_mapping(node)
        kw = {}
        for key, name in (("scale", "Scale"), ("frequency", "Frequency"), ("anisotropy", "Anisotropy"),
                          ("orientation_2d", "Orientation 2D"), ("orientation_3d", "Orientation 3D")):
            socket = _input(node, name)
            if socket.enabled:
                kw[key] = self._setting(node, socket, depth)
        points, reduce = self.points(_input(node, "Vector"), depth)
        if self.checking:
            return np.zeros(self.count, np.float32)
        got = engine.gabor_texture(points, dimensions=int(node.gabor_type[0]), progress=self.progress, **kw)
        return reduce(got[("Value", "Phase", "Intensity").index(output.identifier)])

    def _ShaderNodeTexWave(self, node, output, depth):
        kw = self._procedural_inputs(node, depth, output, WAVE_INPUTS)
        points, reduce = self.points(_input(node, "Vector"), depth)
        if self.checking:
            return self._grey(np.zeros(self.count, np.float32), output)
        direction = node.bands_direction if node.wave_type == "BANDS" else node.rings_direction
        return self._grey(reduce(engine.wave_texture(points, wave_type=node.wave_type, direction=direction,
                                                     profile=node.wave_profile, progress=self.progress, **kw)), output)

    def _ShaderNodeTexChecker(self, node, output, depth):
        scale = self._procedural_inputs(node, depth, output, (("scale", "Scale"),))["scale"]
        p, reduce = self.points(_input(node, "Vector"), depth)
        p = (p * np.float32(scale) + np.float32(1e-6)) * np.float32(0.999999)
        cell = np.abs(np.floor(p).astype(np.int64)) % 2
        # (over a vertex's corners or the unit cube: the share of Color1)
        fac = reduce(((cell[:, 0] == cell[:, 1]).astype(np.int64) == cell[:, 2]).astype(np.float32))
        if output.identifier == "Fac":
            return fac
        one, two = self.colour(_input(node, "Color1"), depth), self.colour(_input(node, "Color2"), depth)
        return (fac[:, None] * one + (1.0 - fac[:, None]) * two).astype(np.float32)

    def _ShaderNodeTexBrick(self, node, output, depth):
        kw = self._procedural_inputs(node, depth, output, BRICK_INPUTS)
        f32 = np.float32
        p, reduce = self.points(_input(node, "Vector"), depth)
        p = p.astype(np.float32) * f32(kw["scale"])
        width, height = f32(kw["width"]), f32(kw["height"])
        row = np.floor(p[:, 1] / height).astype(np.int64)
        width = np.full(len(p), width, np.float32)
        offset = np.zeros(len(p), np.float32)
        if node.offset_frequency and node.squash_frequency:
            width = np.where(row % node.squash_frequency != 0, width, width * f32(node.squash)).astype(np.float32)
            offset = np.where(row % node.offset_frequency != 0, f32(0.0), width * f32(node.offset)).astype(np.float32)
        brick = np.floor((p[:, 0] + offset) / width).astype(np.int64)
        x = (p[:, 0] + offset) - width * brick.astype(np.float32)
        y = p[:, 1] - height * row.astype(np.float32)
        tint = np.clip(_brick_noise(((row << 16) + (brick & 0xFFFF)) & 0xFFFFFFFF) + f32(kw["bias"]), 0.0, 1.0)
        nearest = np.minimum(np.minimum(x, y), np.minimum(width - x, height - y))
        size, smooth = f32(kw["mortar_size"]), f32(kw["mortar_smooth"])
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip((f32(1.0) - nearest / size) / smooth, 0.0, 1.0).astype(np.float32)
            eased = f32(3.0) * t * t - f32(2.0) * t * t * t  # Cycles' smoothstepf
        mortar = np.where(nearest >= size, f32(0.0), f32(1.0) if smooth == 0.0 else eased).astype(np.float32)
        if output.identifier == "Fac":
            return reduce(mortar)
        # the colour is each colour by a weight: their means over a vertex's corners (or the unit cube)
        weights = reduce(np.column_stack([(1.0 - mortar) * (1.0 - tint), (1.0 - mortar) * tint, mortar]))
        return (weights[:, :1] * self.colour(_input(node, "Color1"), depth)
                + weights[:, 1:2] * self.colour(_input(node, "Color2"), depth)
                + weights[:, 2:] * self.colour(_input(node, "Mortar"), depth)).astype(np.float32)

    def _ShaderNodeTexGradient(self, node, output, depth):
        self._procedural_inputs(node, depth, output, ())
        p, reduce = self.points(_input(node, "Vector"), depth)
        x, y, z = (np.ascontiguousarray(c, np.float32) for c in p.T)
        kind = node.gradient_type
        if kind == "LINEAR":
            f = x
        elif kind == "QUADRATIC":
            f = np.maximum(x, 0.0) ** 2
        elif kind == "EASING":
            r = np.clip(x, 0.0, 1.0)
            f = 3.0 * r * r - 2.0 * r * r * r
        elif kind == "DIAGONAL":
            f = (x + y) * np.float32(0.5)
        elif kind == "RADIAL":
            f = np.arctan2(y, x) / np.float32(2.0 * math.pi) + np.float32(0.5)
        else:  # spherical: biased so that a unit vector gives exactly 0
            r = np.maximum(np.float32(0.999999) - np.sqrt(x * x + y * y + z * z), 0.0)
            f = r * r if kind == "QUADRATIC_SPHERE" else r
        return self._grey(reduce(np.clip(f, 0.0, 1.0).astype(np.float32)), output)

    def _grey(self, fac, output):
        """A texture's Fac as its output: itself, or its Color (Fac in each channel)."""
        return np.repeat(fac[:, None], 3, axis=1) if output.identifier == "Color" else fac

    # -- mesh attributes, as Cycles' svm_node_vertex_color and svm_node_attr read them
    def _ShaderNodeVertexColor(self, node, output, depth):
        got, kind = self._mesh_attribute(node, node.layer_name, True)
        alpha = output.identifier == "Alpha"
        if got is None:  # no such attribute: black and transparent
            return np.zeros(self.count if alpha else (self.count, 3), np.float32)
        if kind not in ("RGBA", "FLOAT4"):
            raise Unsupported(f"'{node.name}', whose '{node.layer_name}' is not a colour attribute")
        return np.ascontiguousarray(got[:, 3] if alpha else got[:, :3])

    def _ShaderNodeAttribute(self, node, output, depth):
        if node.attribute_type != "GEOMETRY":
            rgba = np.float32(self._uniform_attribute(node))
            got, kind = np.tile(rgba, (self.count, 1)), "RGBA"
        else:
            got, kind = self._mesh_attribute(node, node.attribute_name, False)
        which = output.identifier
        if which == "Alpha":
            return (np.ascontiguousarray(got[:, 3]) if kind in ("RGBA", "FLOAT4")
                    else np.ones(self.count, np.float32))
        if got is None:  # no such attribute: 0
            return np.zeros(self.count if which == "Fac" else (self.count, 3), np.float32)
        if which == "Fac":  # a value's own, a pair's first, a vector's or colour's average
            return np.ascontiguousarray(got[:, 0]) if kind in ("FLOAT", "FLOAT2") else got[:, :3].mean(axis=1)
        if kind == "FLOAT":
            return np.repeat(got, 3, axis=1)
        if kind == "FLOAT2":
            return np.column_stack([got, np.zeros(self.count, np.float32)])
        return np.ascontiguousarray(got[:, :3])

    def _uniform_attribute(self, node):
        """An Attribute node's RGBA of the object (or instancer: wenv shades objects, not instances),
        looked up on the object then its data, or of the view layer, then the scene, then its World,
        as Blender's BKE_object_dupli_find_rgba_attribute and BKE_view_layer_find_rgba_attribute
        look it up for Cycles; (0, 0, 0, 0) where none has it."""
        import bpy

        name = node.attribute_name
        if node.attribute_type == "VIEW_LAYER":
            scene = bpy.context.scene
            owners = (bpy.context.view_layer, scene, scene.world if scene is not None else None)
        elif self._owner is None:
            if not self.checking:
                raise NeedsMesh(f"'{node.name}', an attribute of the object, which has no value without an object")
            owners = ()
        else:
            obj = self._owner[0]
            owners = (obj, obj.data)
            self.placed = True
        for owner in owners:
            found = property_rgba(owner, name) if owner is not None else None
            if found is not None:
                return found
        return (0.0, 0.0, 0.0, 0.0)

    # -- the object's and the geometry's, as Cycles' svm_node_object_info and svm_node_geometry give them
    def _ShaderNodeObjectInfo(self, node, output, depth):
        which = output.identifier
        self.placed = True
        if self._owner is None:
            if not self.checking:
                raise NeedsMesh(f"'{node.name}', an object's {output.name}, which has no value without an object")
            value = (0.0, 0.0, 0.0) if which in ("Location", "Color") else 0.0
        else:
            obj, mat = self._owner
            value = {"Location": lambda: tuple(obj.matrix_world.translation), "Color": lambda: tuple(obj.color)[:3],
                     "Alpha": lambda: obj.color[3], "Object Index": lambda: obj.pass_index,
                     "Material Index": lambda: mat.pass_index if mat is not None else 0,
                     "Random": lambda: object_random(obj.name)}[which]()
        if isinstance(value, tuple):
            return np.tile(np.float32(value), (self.count, 1))
        return np.full(self.count, value, np.float32)

    def _ShaderNodeNewGeometry(self, node, output, depth):
        if output.identifier in ("Incoming", "Backfacing"):
            incoming, _normal, back = self._towards_viewer(node)
            return incoming if output.identifier == "Incoming" else back.astype(np.float32)
        if output.identifier in ("Pointiness", "Random Per Island"):
            got, _kind = self._mesh_attribute(node, POINTINESS if output.identifier == "Pointiness"
                                              else RANDOM_PER_ISLAND, False)
            return np.ascontiguousarray(got[:, 0])
        if output.identifier == "Tangent":
            return self._radial_tangent(node, "Z")
        if output.identifier == "Parametric":  # (where the point lies in its triangle)
            note = (f"'{node.name}''s Parametric is read at a bake's texels; at a vertex, which lies in several "
                    "triangles, it reads 0")
            if note not in self.notes:
                self.notes.append(note)
            got, _kind = self._mesh_attribute(node, PARAMETRIC, False)
            return np.zeros((self.count, 3), np.float32) if got is None else np.ascontiguousarray(got[:, :3])
        spaces = {"Position": "WORLD", "Normal": "NORMAL", "True Normal": "TRUE_NORMAL"}
        if output.identifier not in spaces:
            raise Unsupported(f"'{node.name}''s {output.name} output")
        return self._coordinates(spaces[output.identifier], node=node)[0]

    def _ShaderNodeTangent(self, node, output, depth):
        if node.direction_type == "RADIAL":
            return self._radial_tangent(node, node.axis)
        # the UV map's MikkTSpace tangent (its active render one where unnamed), 0 where the mesh has
        # no such map, as Cycles reads its tangent attribute
        got, _kind = self._mesh_attribute(node, UVTangent(node.uv_map), False)
        if got is None or self._owner is None:
            return np.zeros((self.count, 3), np.float32)
        return self._surface_tangent(node, got[:, :3].astype(np.float64))

    def _radial_tangent(self, node, axis):
        """The tangent about an axis of the texture space through the row (svm_node_tangent, radial;
        the Geometry's Tangent is about Z): the Generated coordinates turned a quarter about the axis."""
        g = self._coordinates("GENERATED", node=node)[0].astype(np.float64) - 0.5
        if self._owner is None:  # (no mesh: only checked)
            return np.zeros((self.count, 3), np.float32)
        zero = np.zeros(len(g))
        t = {"X": (zero, -g[:, 2], g[:, 1]), "Y": (-g[:, 2], zero, g[:, 0]), "Z": (-g[:, 1], g[:, 0], zero)}[axis]
        return self._surface_tangent(node, np.column_stack(t))

    def _surface_tangent(self, node, t):
        """An object-space tangent `t` at each row carried into the world as a normal is, and made
        perpendicular to the shading normal (svm_node_tangent)."""
        self.placed = True
        to_world = np.array(self._owner[0].matrix_world.to_3x3().inverted_safe(), np.float64)
        t = t @ to_world  # (the inverse transpose, as a row vector)
        n = self._coordinates("NORMAL", node=node)[0].astype(np.float64)
        return np.cross(n, unit_rows(np.cross(t, n))).astype(np.float32)

    def _ShaderNodeAmbientOcclusion(self, node, output, depth):
        # a linked Normal is the axis of the rays' hemisphere (svm_node_ao), the point's normal otherwise
        given = self.colour(node.inputs["Normal"], depth) if node.inputs["Normal"].is_linked else None
        distance = constant_value(node.inputs["Distance"])
        if distance is None:
            raise Unsupported(f"'{node.name}''s Distance, linked to values that vary from point to point")
        if self._ambient is None:
            if not self.checking:
                raise Unsupported(f"'{node.name}', which casts rays: read into a material's inputs and factors, "
                                  "not here")
            share = np.ones(self.count, np.float32)
        else:
            normal = self._coordinates("NORMAL", node=node)[0]
            if given is not None:  # (one of no length keeps the point's)
                given = unit_rows(given)
                normal = np.where(given.any(axis=1, keepdims=True), given, normal).astype(np.float32)
            share = self._ambient(self._coordinates("WORLD", node=node)[0], normal, distance, node.inside,
                                  node.only_local, node.samples)
        if output.identifier == "AO":
            return share
        return self.colour(node.inputs["Color"], depth) * share[:, None]

    def _ShaderNodeBevel(self, node, output, depth):
        radius = node.inputs["Radius"]
        radius = self.value(radius, depth) if radius.is_linked else float(radius.default_value)
        if self._bevel is None:
            if not self.checking:
                raise Unsupported(f"'{node.name}', which reads the surface about each point: read into a material's "
                                  "inputs, factors and Normal, not here")
            return np.zeros((self.count, 3), np.float32)
        if not np.isfinite(radius).all():
            raise engine.SetupError(f"'{node.name}''s Radius is not finite (NaN or infinite) where the nodes give it")
        normal = self._coordinates("NORMAL", node=node)[0]
        got = self._bevel(self._coordinates("WORLD", node=node)[0], normal, radius)
        if node.inputs["Normal"].is_linked:  # that normal turned as the bevel turns the mesh's (svm_node_bevel)
            got = unit_rows(self.colour(node.inputs["Normal"], depth) + (got - normal))
        return got.astype(np.float32)

    # -- node groups, evaluated through: a group's output is its inner node's, a Group Input the socket
    # the group node is fed by
    def _ShaderNodeGroup(self, node, output, depth):
        tree = node.node_tree
        inner = None if tree is None else next(
            (n for n in tree.nodes if n.bl_idname == "NodeGroupOutput" and n.is_active_output), None)
        if inner is None:
            raise Unsupported(f"'{node.name}', a group with no output")
        self._groups.append(node)
        try:
            return self.evaluate(next(s for s in inner.inputs if s.identifier == output.identifier), depth)
        finally:
            self._groups.pop()

    def _NodeGroupInput(self, node, output, depth):
        if not self._groups:
            raise Unsupported(f"'{node.name}', a group's input read outside its group")
        outer = self._groups.pop()
        try:
            return self.evaluate(next(s for s in outer.inputs if s.identifier == output.identifier), depth)
        finally:
            self._groups.append(outer)

    def _ShaderNodeVectorRotate(self, node, output, depth):
        v = self.colour(_input(node, "Vector"), depth).astype(np.float64)
        centre = self.colour(_input(node, "Center"), depth).astype(np.float64)
        p = v - centre
        if node.rotation_type == "EULER_XYZ":
            rotation = self.colour(_input(node, "Rotation"), depth).astype(np.float64)
            m = np.stack([_euler_xyz(r) for r in rotation]) if np.ptp(rotation, axis=0).any() else \
                np.broadcast_to(_euler_xyz(rotation[0]), (self.count, 3, 3))
            turned = np.einsum("nji,nj->ni" if node.invert else "nij,nj->ni", m, p)
            return (turned + centre).astype(np.float32)
        if node.rotation_type == "AXIS_ANGLE":
            axis = self.colour(_input(node, "Axis"), depth).astype(np.float64)
        else:
            axis = np.tile(np.eye(3)["XYZ".index(node.rotation_type[0])], (self.count, 1))
        length = np.linalg.norm(axis, axis=1, keepdims=True)
        angle = self.value(_input(node, "Angle"), depth).astype(np.float64) * (-1.0 if node.invert else 1.0)
        k = np.where(length > 0.0, axis / np.where(length > 0.0, length, 1.0), 0.0)
        cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
        # Rodrigues' rotation, as Cycles' rotate_around_axis
        turned = p * cos + np.cross(k, p) * sin + k * np.sum(k * p, axis=1, keepdims=True) * (1.0 - cos)
        return np.where(length > 0.0, turned + centre, v).astype(np.float32)

    def _ShaderNodeBlackbody(self, node, output, depth):
        return _blackbody(self.value(node.inputs["Temperature"], depth))

    def _ShaderNodeWavelength(self, node, output, depth):
        return _wavelength(self.value(node.inputs["Wavelength"], depth))

    def _ShaderNodeNormal(self, node, output, depth):
        direction = np.float32(tuple(node.outputs["Normal"].default_value))
        direction = direction / np.float32(max(float(np.linalg.norm(direction)), 1e-30))
        if output.identifier == "Normal":
            return np.tile(direction, (self.count, 1))
        n = self.colour(node.inputs["Normal"], depth).astype(np.float32)
        unit = unit_rows(n)
        return (unit @ direction).astype(np.float32)

    # -- what depends on the view: the direction towards the viewer at each row
    def _towards_viewer(self, node):
        """(unit directions towards the viewer (count, 3), unit shading normals facing it, whether the
        row's face looks away) at the rows, as Cycles' sd->wi, sd->N (flipped on a back face) and
        SD_BACKFACING are."""
        self.placed = True
        if self._points is None:
            if self.checking:
                zeros = np.zeros((self.count, 3), np.float32)
                return zeros, zeros, np.zeros(self.count, bool)
            raise NeedsMesh(f"'{node.name}', which depends on the view, which has no value without a mesh")
        incoming = self._points("INCOMING", None)
        if incoming is None:
            raise UnreadAtRows(f"'{node.name}', which depends on the view (here read without one)")
        normal = self._points("NORMAL", None)
        back = np.einsum("ij,ij->i", incoming, normal) < 0.0
        return incoming, np.where(back[:, None], -normal, normal), back

    def _ShaderNodeLightPath(self, node, output, depth):
        """What a camera ray's hit reads (wenv shades what the camera or viewport sees): Is Camera Ray
        1, every other kind and depth 0, and Ray Length the distance from a perspective view's eye."""
        which = output.identifier
        self.read_light_path = self.placed = True
        if which == "Is Camera Ray":
            return np.ones(self.count, np.float32)
        if which != "Ray Length" or (self._points is None and self.checking):
            return np.zeros(self.count, np.float32)
        if self._points is None:
            raise NeedsMesh(f"'{node.name}''s Ray Length, which has no value without a mesh")
        view = self._points("VIEW", None)
        if view is None or not view.perspective:
            raise Unsupported(f"'{node.name}''s Ray Length, which wenv reads in a perspective view only")
        eye = np.asarray(view.eye, np.float64)
        return np.linalg.norm(self._points("WORLD", None).astype(np.float64) - eye, axis=1).astype(np.float32)

    def _facing_normal(self, node, depth, normal):
        socket = node.inputs["Normal"]
        return self.colour(socket, depth) if socket.is_linked else normal

    def _ShaderNodeLayerWeight(self, node, output, depth):
        incoming, normal, back = self._towards_viewer(node)
        blend = self.value(node.inputs["Blend"], depth)
        cos = np.einsum("ij,ij->i", incoming, self._facing_normal(node, depth, normal)).astype(np.float32)
        f32 = np.float32
        if output.identifier == "Fresnel":
            eta = np.maximum(f32(1.0) - blend, f32(1e-5))
            return _fresnel_dielectric_cos(cos, np.where(back, eta, f32(1.0) / eta))
        f = np.abs(cos)
        b = np.clip(blend, 0.0, 1.0 - 1e-5).astype(f32)
        power = np.where(b < 0.5, f32(2.0) * b, f32(0.5) / (f32(1.0) - b))
        return (f32(1.0) - np.where(blend != 0.5, np.power(f, power), f)).astype(f32)

    def _ShaderNodeFresnel(self, node, output, depth):
        incoming, normal, back = self._towards_viewer(node)
        eta = np.maximum(self.value(node.inputs["IOR"], depth), np.float32(1e-5))
        cos = np.einsum("ij,ij->i", incoming, self._facing_normal(node, depth, normal)).astype(np.float32)
        return _fresnel_dielectric_cos(cos, np.where(back, np.float32(1.0) / eta, eta))

    def _mesh_attribute(self, node, name, colour):
        """(values (count, k) float32, Cycles' type) of the mesh attribute `name` (a Color Attribute
        node's empty name: the default colour attribute), or (None, None) where the mesh has none."""
        if self._attribute is not None:
            return self._attribute(name, colour)
        if self.checking:
            return np.zeros((self.count, 4), np.float32), "RGBA"
        raise NeedsMesh(f"'{node.name}', a mesh attribute, which has no value without a mesh")

    def _ShaderNodeRGB(self, node, output, depth):
        return np.tile(np.float32(tuple(output.default_value)[:3]), (self.count, 1))

    def _ShaderNodeValue(self, node, output, depth):
        return np.full(self.count, output.default_value, np.float32)

    # -- colour and value operations
    def _ShaderNodeMix(self, node, output, depth):
        if node.data_type not in ("FLOAT", "RGBA", "VECTOR"):
            raise Unsupported(f"'{node.name}' mixing {node.data_type.lower()}s")
        uniform = node.data_type != "VECTOR" or node.factor_mode == "UNIFORM"
        t = (self.value(_input(node, "Factor_Float"), depth) if uniform
             else self.colour(_input(node, "Factor_Vector"), depth))
        if node.clamp_factor:
            t = np.clip(t, 0.0, 1.0)
        if node.data_type == "VECTOR":
            a, b = self.colour(_input(node, "A_Vector"), depth), self.colour(_input(node, "B_Vector"), depth)
            return (a + (t[:, None] if uniform else t) * (b - a)).astype(np.float32)
        if node.data_type == "FLOAT":
            a, b = self.value(_input(node, "A_Float"), depth), self.value(_input(node, "B_Float"), depth)
            return (a + t * (b - a)).astype(np.float32)
        a, b = self.colour(_input(node, "A_Color"), depth), self.colour(_input(node, "B_Color"), depth)
        out = _blend(node.name, node.blend_type, t[:, None], a, b)
        return np.clip(out, 0.0, 1.0) if node.clamp_result else out

    def _ShaderNodeMixRGB(self, node, output, depth):
        t = np.clip(self.value(node.inputs["Fac"], depth), 0.0, 1.0)[:, None]
        out = _blend(node.name, node.blend_type, t, self.colour(node.inputs["Color1"], depth),
                     self.colour(node.inputs["Color2"], depth))
        return np.clip(out, 0.0, 1.0) if node.use_clamp else out

    def _ShaderNodeMath(self, node, output, depth):
        args = [self.value(s, depth) for s in node.inputs[:3] if s.enabled]
        out = _math(node.name, node.operation, *args)
        return np.clip(out, 0.0, 1.0).astype(np.float32) if node.use_clamp else out.astype(np.float32)

    def _ShaderNodeInvert(self, node, output, depth):
        t = self.value(node.inputs["Fac"], depth)[:, None]
        c = self.colour(node.inputs["Color"], depth)
        return (c + t * ((1.0 - c) - c)).astype(np.float32)

    def _ShaderNodeGamma(self, node, output, depth):
        c = self.colour(node.inputs["Color"], depth)
        g = self.value(node.inputs["Gamma"], depth)[:, None]
        return np.where(c > 0.0, np.power(np.maximum(c, 0.0), g), c).astype(np.float32)

    def _ShaderNodeBrightContrast(self, node, output, depth):
        c = self.colour(node.inputs["Color"], depth)
        bright = self.value(node.inputs["Bright"], depth)[:, None]
        contrast = self.value(node.inputs["Contrast"], depth)[:, None]
        return np.maximum((1.0 + contrast) * c + (bright - 0.5 * contrast), 0.0).astype(np.float32)

    def _ShaderNodeHueSaturation(self, node, output, depth):
        c = self.colour(node.inputs["Color"], depth)
        hue, sat, val, fac = (self.value(node.inputs[k], depth) for k in ("Hue", "Saturation", "Value", "Fac"))
        h, s, v = _rgb_to_hsv(c)
        h = np.mod(h + hue + 0.5, 1.0)
        s = np.clip(s * sat, 0.0, 1.0)
        shifted = _hsv_to_rgb(h, s, v * val)
        return np.maximum(c + fac[:, None] * (shifted - c), 0.0).astype(np.float32)

    def _ShaderNodeValToRGB(self, node, output, depth):
        t = np.clip(self.value(node.inputs["Fac"], depth), 0.0, 1.0)
        if self.checking:
            return np.zeros((self.count, 3) if output.identifier == "Color" else self.count, np.float32)
        # the ramp read through Blender's own evaluation on a fine table, as Cycles bakes it to one
        ramp = node.color_ramp
        x = np.linspace(0.0, 1.0, 1025)
        table = np.array([ramp.evaluate(float(p)) for p in x], np.float32)
        column = range(3) if output.name == "Color" else (3,)
        out = np.stack([np.interp(t, x, table[:, k]) for k in column], axis=1).astype(np.float32)
        return out if output.name == "Color" else out[:, 0]

    def _ShaderNodeRGBCurve(self, node, output, depth):
        c = self.colour(node.inputs["Color"], depth)
        fac = self.value(node.inputs["Fac"], depth)[:, None]
        if self.checking:
            return c
        x, combined = _curve_table(node.mapping, 3)
        out = np.empty_like(c)
        for k in range(3):
            out[:, k] = np.interp(np.interp(c[:, k], x, combined), x, _curve_table(node.mapping, k)[1])
        return (c + fac * (out - c)).astype(np.float32)

    def _ShaderNodeFloatCurve(self, node, output, depth):
        v = self.value(_input(node, "Value"), depth)
        fac = self.value(_input(node, "Factor"), depth)
        if self.checking:
            return v
        x, curve = _curve_table(node.mapping, 0)
        return (v + fac * (np.interp(v, x, curve) - v)).astype(np.float32)

    def _ShaderNodeSeparateColor(self, node, output, depth):
        c = self.colour(node.inputs["Color"], depth)
        if node.mode == "HSV":
            c = np.stack(_rgb_to_hsv(c), axis=1)
        elif node.mode == "HSL":
            c = _rgb_to_hsl(c)
        return np.ascontiguousarray(c[:, ("Red", "Green", "Blue").index(output.identifier)], np.float32)

    def _ShaderNodeSeparateRGB(self, node, output, depth):
        return self.colour(node.inputs["Image"], depth)[:, ("R", "G", "B").index(output.name)].copy()

    def _ShaderNodeCombineColor(self, node, output, depth):
        c = np.stack([self.value(_input(node, k), depth) for k in ("Red", "Green", "Blue")], axis=1)
        if node.mode == "HSV":
            c = _hsv_to_rgb(c[:, 0], c[:, 1], c[:, 2])
        elif node.mode == "HSL":
            c = _hsl_to_rgb(c)
        return c.astype(np.float32)

    def _ShaderNodeCombineRGB(self, node, output, depth):
        return np.stack([self.value(node.inputs[k], depth) for k in ("R", "G", "B")], axis=1)

    # -- coordinates as values (a texture's own Vector reads them through points() and vector())
    def _ShaderNodeTexCoord(self, node, output, depth):
        if output.name not in TEXTURE_COORDINATES:
            raise Unsupported(f"'{node.name}''s {output.name}, which wenv does not evaluate yet")
        return self._as_values(node, lambda: self._texture_coordinates(node, output))

    def _texture_coordinates(self, node, output):
        """(points, reduce) of a Texture Coordinate's output, as svm_node_tex_coord gives them: the UV
        map's, the Generated or Object coordinates, the normal in object space (Normal), the view's
        direction mirrored about the normal in the world (Reflection: 2 (N.I) N - I, the normal
        facing the viewer), the point in the view's camera space (Camera) or its place in the
        camera's or viewport's frame (Window: (x, y, 0) from 0 to 1 across it)."""
        if output.name == "UV":
            return self._uv_points(None)
        if output.name in ("Camera", "Window"):
            got = self._coordinates(output.name.upper(), node=node)
            if got[0] is None:
                raise UnreadAtRows(f"'{node.name}''s {output.name}, which a view given by a matrix alone (or a "
                                "panoramic camera's) does not have")
            return got
        if output.name == "Normal":
            return self._coordinates("OBJECT_NORMAL", node=node)
        if output.name == "Reflection":
            incoming, normal, _back = self._towards_viewer(node)
            cos = np.einsum("ij,ij->i", normal, incoming)[:, None]
            return (np.float32(2.0) * cos * normal - incoming).astype(np.float32), _same
        return self._coordinates(output.name.upper(), node.object if output.name == "Object" else None)

    def _ShaderNodeUVMap(self, node, output, depth):
        return self._as_values(node, lambda: self._uv_points(node.uv_map or None))

    def _ShaderNodeMapping(self, node, output, depth):
        if node.vector_type not in ("POINT", "TEXTURE", "VECTOR"):
            raise Unsupported(f"'{node.name}' of type {node.vector_type.lower()}")
        return self._mapped(node, self.colour(node.inputs["Vector"], depth).astype(np.float64)).astype(np.float32)

    def _as_values(self, node, points):
        """points()'s coordinates at the rows, for a node whose value passes on; without a mesh only
        checked (a mean of what follows them is not their mean's)."""
        if self._points is None:
            if self.checking:
                return np.zeros((self.count, 3), np.float32)
            raise NeedsMesh(f"'{node.name}''s coordinates, which have no value without a mesh")
        p, reduce = points()
        return reduce(p)

    def _ShaderNodeMapRange(self, node, output, depth):
        vector = node.data_type == "FLOAT_VECTOR"
        names = (("Vector", "From_Min_FLOAT3", "From_Max_FLOAT3", "To_Min_FLOAT3", "To_Max_FLOAT3", "Steps_FLOAT3")
                 if vector else ("Value", "From Min", "From Max", "To Min", "To Max", "Steps"))
        read = self.colour if vector else self.value
        x, lo, hi, to_lo, to_hi, steps = (read(_input(node, k), depth).astype(np.float32) for k in names)
        f32 = np.float32
        with np.errstate(divide="ignore", invalid="ignore"):
            if node.interpolation_type in ("LINEAR", "STEPPED"):
                factor = np.where(hi != lo, (x - lo) / np.where(hi != lo, hi - lo, f32(1.0)), f32(0.0))
                if node.interpolation_type == "STEPPED":
                    factor = np.where((hi != lo) & (steps > 0.0), np.floor(factor * (steps + f32(1.0))) /
                                      np.where(steps > 0.0, steps, f32(1.0)), f32(0.0))
            else:
                step = _smoothstep if node.interpolation_type == "SMOOTHSTEP" else _smootherstep
                factor = np.where(lo > hi, f32(1.0) - step(hi, lo, x), step(lo, hi, x))
        out = (to_lo + factor * (to_hi - to_lo)).astype(f32)
        if node.clamp and node.interpolation_type in ("LINEAR", "STEPPED"):
            out = np.clip(out, np.minimum(to_lo, to_hi), np.maximum(to_lo, to_hi))
        return out

    def _ShaderNodeClamp(self, node, output, depth):
        x, a, b = (self.value(node.inputs[k], depth) for k in ("Value", "Min", "Max"))
        if node.clamp_type == "RANGE":
            return np.clip(x, np.minimum(a, b), np.maximum(a, b)).astype(np.float32)
        return np.minimum(np.maximum(x, a), b).astype(np.float32)

    def _ShaderNodeRGBToBW(self, node, output, depth):
        return luminance(self.colour(node.inputs["Color"], depth))

    def _ShaderNodeSeparateXYZ(self, node, output, depth):
        return self.colour(node.inputs["Vector"], depth)[:, "XYZ".index(output.identifier)].copy()

    def _ShaderNodeCombineXYZ(self, node, output, depth):
        return np.stack([self.value(node.inputs[k], depth) for k in "XYZ"], axis=1).astype(np.float32)

    def _ShaderNodeVectorMath(self, node, output, depth):
        a, b, c = (self.colour(_input(node, k), depth).astype(np.float32)
                   for k in ("Vector", "Vector_001", "Vector_002"))
        scale = self.value(_input(node, "Scale"), depth)[:, None]
        out = _vector_math(node.name, node.operation, a, b, c, scale)
        if output.identifier == "Value":
            return out if out.ndim == 1 else np.zeros(self.count, np.float32)
        return out if out.ndim == 2 else np.zeros((self.count, 3), np.float32)

    # -- a texture's Vector: UVs at the face corners, and what scales their footprint
    def vector(self, socket, depth):
        """(uv (corners, 2), footprint (corners,), rows) of a Vector input: the UV map a Texture
        Coordinate's UV or a UV Map node names (unlinked: the active render one), through Mapping and
        Vector Math nodes."""
        fed = _fed(socket, depth)
        if fed is None:
            return self._uvs(None)
        node, output = fed
        if node.bl_idname == "ShaderNodeTexCoord" and output.name == "UV":
            return self._uvs(None)
        if node.bl_idname == "ShaderNodeUVMap":
            return self._uvs(node.uv_map or None)
        if node.bl_idname == "ShaderNodeMapping":
            return self._mapping(node, depth)
        if node.bl_idname == "ShaderNodeVectorMath":
            return self._vector_math(node, depth)
        raise _NotUV()  # other coordinates: points() reads them

    # -- a procedural texture's Vector: coordinates at the rows, or where they are read for them
    def points(self, socket, depth):
        """(points (m, 3) float32, reduce) of a procedural texture's Vector input: Generated where
        unlinked, a Texture Coordinate's Generated, Object or UV, a UV Map node's or an Attribute's
        vector, a Geometry node's Position or Normal or an Object Info's Location or Color, through
        Mapping and Vector Math nodes.  reduce(values at the points) gives the values
        at the rows: the points are the rows' own, or a UV map's at each vertex's face corners (a seam's
        two sides, whose values a vertex averages as it does an image's), or, without a mesh
        (one_point), over the unit cube (Generated and Object) or square (UV) for their mean."""
        fed = _fed(socket, depth)
        if fed is None:
            return self._coordinates("GENERATED")
        node, output = fed
        if node.bl_idname == "ShaderNodeTexCoord" and output.name in TEXTURE_COORDINATES:
            return self._texture_coordinates(node, output)
        if node.bl_idname == "ShaderNodeUVMap":
            return self._uv_points(node.uv_map or None)
        if node.bl_idname == "ShaderNodeAttribute" and output.identifier in ("Color", "Vector"):
            return self._ShaderNodeAttribute(node, output, depth + 1), _same
        if node.bl_idname == "ShaderNodeNewGeometry" and output.identifier in ("Position", "Normal"):
            return self._coordinates("WORLD" if output.identifier == "Position" else "NORMAL", node=node)
        if node.bl_idname == "ShaderNodeObjectInfo" and output.identifier in ("Location", "Color"):
            return self._ShaderNodeObjectInfo(node, output, depth + 1), _same
        if node.bl_idname == "ShaderNodeMapping":
            if node.vector_type not in ("POINT", "TEXTURE", "VECTOR"):
                raise Unsupported(f"'{node.name}' of type {node.vector_type.lower()}")
            p, reduce = self.points(node.inputs["Vector"], depth + 1)
            return self._mapped(node, p.astype(np.float64)).astype(np.float32), reduce
        if node.bl_idname == "ShaderNodeVectorMath" and _of_constants(node):
            op = _vector_op(node)
            p, reduce = self.points(node.inputs[0], depth + 1)
            return op(p.astype(np.float64))[0].astype(np.float32), reduce
        if node.bl_idname == "ShaderNodeTexCoord":
            raise Unsupported(f"a texture's Vector from '{node.name}''s {output.name}, which wenv does not "
                              "evaluate yet")
        if self._points is None and not self.checking:  # (a chain's mean is not its texture's at a mean)
            raise NeedsMesh(f"'{node.name}' into a procedural texture's Vector, which has no mean without a mesh")
        got = self.evaluate(socket, depth)  # any other value or colour, as Cycles makes it a vector
        return np.ascontiguousarray(got if got.ndim == 2 else np.repeat(got[:, None], 3, axis=1), np.float32), _same

    def _coordinates(self, space, other=None, node=None):
        self.spaces.add(space)
        # (the mesh's own texture spaces are the same wherever it lies)
        self.placed |= space not in ("GENERATED", "OBJECT", "OBJECT_NORMAL") or other is not None
        if self._points is not None:
            return self._points(space, other), _same
        if space in ("GENERATED", "OBJECT"):
            return MEAN_POINTS, _mean
        if self.checking:  # (the world's positions and normals have no cube to average over)
            return np.zeros((self.count, 3), np.float32), _same
        raise NeedsMesh(f"'{node.name}', the geometry's {space.lower().replace('_', ' ')}, which has no value without "
                        "a mesh")

    def _uv_points(self, uv_map):
        """points() of a UV map's (u, v, 0), as Cycles' UV output reads it."""
        if self._points is None:
            return MEAN_SQUARE, _mean
        uv, _footprint, rows = self._uvs(uv_map)
        p = np.column_stack([uv, np.zeros(len(uv), np.float32)]).astype(np.float32)
        if len(rows) == self.count and np.array_equal(rows, np.arange(self.count)):
            return p, _same
        return p, lambda values: group_means(values, rows, self.count)  # each row's mean over its corners

    def _no_points(self):
        """points() of a 1D texture, which reads W alone: one point, its value at every row."""
        return np.zeros((1, 3), np.float32), lambda values: np.repeat(values, self.count, axis=0)

    def _uvs(self, uv_map):
        got = self._uv(uv_map)
        if got is None:
            raise MissingUV(uv_map)
        uv, footprint, rows = got
        return uv, footprint, rows

    def _constant_vector(self, socket, what):
        if socket.is_linked:
            raise Unsupported(f"{what}, linked")
        return np.array(tuple(socket.default_value), np.float64)

    def _mapping(self, node, depth):
        if node.vector_type not in ("POINT", "TEXTURE"):
            raise Unsupported(f"'{node.name}' of type {node.vector_type.lower()}")
        uv, footprint, rows = self.vector(node.inputs["Vector"], depth + 1)
        out = self._mapped(node, np.column_stack([uv.astype(np.float64), np.zeros(len(uv))]))
        scale = self._constant_vector(node.inputs["Scale"], f"'{node.name}''s Scale")
        if node.vector_type == "POINT":
            stretch = math.sqrt(abs(scale[0] * scale[1]))
        else:
            stretch = 1.0 / math.sqrt(abs(scale[0] * scale[1])) if scale[0] * scale[1] != 0.0 else 1.0
        return out[:, :2].astype(np.float32), (footprint * stretch).astype(np.float32), rows

    def _mapped(self, node, p):
        """Points p (n, 3) through a Mapping node of type point, texture or vector, as Cycles maps them."""
        rot = self._constant_vector(node.inputs["Rotation"], f"'{node.name}''s Rotation")
        scale = self._constant_vector(node.inputs["Scale"], f"'{node.name}''s Scale")
        m = _euler_xyz(rot)
        if node.vector_type == "VECTOR":  # a direction: scaled and turned, not moved
            return (p * scale) @ m.T
        loc = self._constant_vector(node.inputs["Location"], f"'{node.name}''s Location")
        if node.vector_type == "POINT":  # scale, rotate, then move
            return (p * scale) @ m.T + loc
        return ((p - loc) @ m) / np.where(scale == 0.0, 1.0, scale)  # the inverse: the texture moved

    def _vector_math(self, node, depth):
        op = _vector_op(node)
        uv, footprint, rows = self.vector(node.inputs[0], depth + 1)
        out, stretch = op(np.column_stack([uv.astype(np.float64), np.zeros(len(uv))]))
        return out[:, :2].astype(np.float32), (footprint * stretch).astype(np.float32), rows


def _of_constants(node):
    """Whether a Vector Math node is one _vector_op reads (its first vector carried through it)."""
    second = node.inputs["Scale"] if node.operation == "SCALE" else node.inputs[1]
    return node.operation in ("SCALE", "ADD", "SUBTRACT", "MULTIPLY", "DIVIDE") and not second.is_linked


def _vector_op(node):
    """A Vector Math node of a constant second operand as op(p) -> (p', how much it stretches a
    footprint in the first two axes); Unsupported for other operations or a linked operand."""
    if node.operation == "SCALE":
        s = node.inputs["Scale"]
        if s.is_linked:
            raise Unsupported(f"'{node.name}''s Scale, linked")
        k = float(s.default_value)
        return lambda p: (p * k, abs(k))
    ops = {"ADD": lambda a, b: a + b, "SUBTRACT": lambda a, b: a - b, "MULTIPLY": lambda a, b: a * b,
           "DIVIDE": lambda a, b: np.where(b != 0.0, a / np.where(b != 0.0, b, 1.0), 0.0)}
    if node.operation not in ops:
        raise Unsupported(f"'{node.name}' ({node.operation.lower()})")
    second = node.inputs[1]
    if second.is_linked:
        raise Unsupported(f"'{node.name}''s second vector, linked")
    b = np.array(tuple(second.default_value), np.float64)
    stretch = math.sqrt(abs(b[0] * b[1])) if node.operation == "MULTIPLY" else (
        1.0 / math.sqrt(abs(b[0] * b[1])) if node.operation == "DIVIDE" and b[0] * b[1] != 0.0 else 1.0)
    return lambda p: (ops[node.operation](p, b), stretch)


def _magic(p, scale, depth, distortion):
    """Cycles' svm_magic at points p (n, 3): float32 throughout, each sine and cosine rounded from
    double as sinf and cosf round."""
    f32 = np.float32

    def sin(v):
        return np.sin(v.astype(np.float64)).astype(f32)

    def cos(v):
        return np.cos(v.astype(np.float64)).astype(f32)
    px, py, pz = (np.fmod(np.ascontiguousarray(p[:, k], f32), f32(2.0 * math.pi)) for k in range(3))
    five, d = f32(5.0), f32(distortion)
    x = sin((px + py + pz) * five * f32(scale))
    y = cos((-px + py - pz) * five * f32(scale))
    z = -cos((-px - py + pz) * five * f32(scale))
    if depth > 0:
        x, y, z = x * d, y * d, z * d
        y = -cos(x - y + z) * d
    # the turbulence's later steps: (which of x, y, z it sets, from what, negated)
    steps = ((0, lambda x, y, z: cos(x - y - z)), (2, lambda x, y, z: sin(-x - y - z)),
             (0, lambda x, y, z: -cos(-x + y - z)), (1, lambda x, y, z: -sin(-x + y + z)),
             (1, lambda x, y, z: -cos(-x + y + z)), (0, lambda x, y, z: cos(x + y + z)),
             (2, lambda x, y, z: sin(x + y - z)), (0, lambda x, y, z: -cos(-x - y + z)),
             (1, lambda x, y, z: -sin(x - y + z)))
    xyz = [x, y, z]
    for axis, step in steps[:max(depth - 1, 0)]:
        xyz[axis] = step(*xyz) * d
    x, y, z = xyz
    if distortion != 0.0:
        twice = d * f32(2.0)
        x, y, z = x / twice, y / twice, z / twice
    return np.stack([f32(0.5) - x, f32(0.5) - y, f32(0.5) - z], axis=1).astype(f32)


def _vector_math(name, op, a, b, c, scale):
    """Cycles' svm_vector_math: a vector (n, 3), or a value (n,) for a dot product, distance or
    length; float32 as Cycles computes."""
    f32 = np.float32

    def dot(u, v):
        return (u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1]) + u[:, 2] * v[:, 2]

    def divide(u, v):
        return np.where(v != 0.0, u / np.where(v != 0.0, v, f32(1.0)), f32(0.0)).astype(f32)

    def unit(u):
        length = np.sqrt(dot(u, u))[:, None]
        return np.where(length != 0.0, u / np.where(length != 0.0, length, f32(1.0)), f32(0.0)).astype(f32)
    ops = {
        "ADD": lambda: a + b, "SUBTRACT": lambda: a - b, "MULTIPLY": lambda: a * b, "DIVIDE": lambda: divide(a, b),
        "MULTIPLY_ADD": lambda: a * b + c, "CROSS_PRODUCT": lambda: np.cross(a, b),
        "PROJECT": lambda: divide(dot(a, b)[:, None] * b, np.repeat(dot(b, b)[:, None], 3, axis=1)),
        "REFLECT": lambda: a - f32(2.0) * unit(b) * dot(a, unit(b))[:, None],
        "FACEFORWARD": lambda: np.where((dot(c, b) < 0.0)[:, None], a, -a),
        "DOT_PRODUCT": lambda: dot(a, b), "DISTANCE": lambda: np.sqrt(dot(a - b, a - b)),
        "LENGTH": lambda: np.sqrt(dot(a, a)), "SCALE": lambda: a * scale, "NORMALIZE": lambda: unit(a),
        "SNAP": lambda: np.floor(divide(a, b)) * b, "FLOOR": lambda: np.floor(a), "CEIL": lambda: np.ceil(a),
        "MODULO": lambda: np.where(b != 0.0, np.fmod(a, np.where(b != 0.0, b, f32(1.0))), f32(0.0)),
        "FRACTION": lambda: a - np.floor(a), "ABSOLUTE": lambda: np.abs(a),
        "MINIMUM": lambda: np.minimum(a, b), "MAXIMUM": lambda: np.maximum(a, b),
        "WRAP": lambda: np.where(b - c != 0.0, a - (b - c) * np.floor(divide(a - c, b - c)), c),
        "SINE": lambda: np.sin(a), "COSINE": lambda: np.cos(a), "TANGENT": lambda: np.tan(a)}
    if op not in ops:
        raise Unsupported(f"'{name}' ({op.lower().replace('_', ' ')})")
    with np.errstate(all="ignore"):
        return ops[op]().astype(f32)


def _brick_noise(n):
    """Cycles' brick_noise: a fast integer noise of n (int64 holding uint32 words), in [0, 1)."""
    n = (n + 1013) & 0x7FFFFFFF
    n = ((n >> 13) ^ n).astype(np.uint64)
    nn = (n * ((n * n * 60493 + 19990303) & 0xFFFFFFFF) + 1376312589) & 0x7FFFFFFF  # uint32 wrap-around
    return (np.float32(0.5) * (nn.astype(np.float32) / np.float32(1073741824.0))).astype(np.float32)


def _identity_mapping(node):
    """Unsupported when a texture node's own Mapping (its hidden texture_mapping) is not the identity."""
    tm = getattr(node, "texture_mapping", None)
    if tm is None:
        return
    same = (tuple(tm.translation) == (0.0, 0.0, 0.0) and tuple(tm.rotation) == (0.0, 0.0, 0.0)
            and tuple(tm.scale) == (1.0, 1.0, 1.0) and not tm.use_min and not tm.use_max
            and (tm.mapping_x, tm.mapping_y, tm.mapping_z) == ("X", "Y", "Z") and tm.mapping == "FLAT")
    if not same:
        raise Unsupported(f"'{node.name}''s own texture mapping")


class NeedsMesh(Unsupported):
    """A node whose value only a mesh or object gives (an attribute, a position, an object's colour),
    read without one (one_point's means)."""


class _NotUV(Unsupported):
    """An Image Texture's Vector that is not a UV map (its coordinates are read as points)."""


class UVTangent:
    """The name an Evaluator's attribute(name, colour) reads a UV map's tangents by (None or "": the
    active render UV map)."""

    __slots__ = ("uv_map",)

    def __init__(self, uv_map):
        self.uv_map = uv_map or None


class MissingUV(Unsupported):
    """The mesh has no UV map of that name (None: no render UV map)."""

    def __init__(self, uv_map):
        super().__init__(uv_map)
        self.uv_map = uv_map


def _mix(a, b, c):
    """lookup3's final mix of three 32-bit words (Cycles' util/hash.h)."""
    def rot(x, k):
        return ((x << k) | (x >> (32 - k))) & 0xFFFFFFFF
    for x, y, k in ((2, 1, 14), (0, 2, 11), (1, 0, 25), (2, 1, 16), (0, 2, 4), (1, 0, 14), (2, 1, 24)):
        words = [a, b, c]
        words[x] = ((words[x] ^ words[y]) - rot(words[y], k)) & 0xFFFFFFFF
        a, b, c = words
    return c


def object_random(name):
    """Object Info's Random for an object (not an instance) of that name, as Cycles makes it:
    hash_uint2(hash_string(name), 0) over 0xFFFFFFFF."""
    h = 0
    for byte in name.encode("utf-8"):
        h = (h * 37 + byte) & 0xFFFFFFFF
    start = (0xDEADBEEF + (2 << 2) + 13) & 0xFFFFFFFF
    return float(np.float32(_mix((start + h) & 0xFFFFFFFF, start, start)) * np.float32(1.0 / 0xFFFFFFFF))


def _fresnel_dielectric_cos(cos, eta):
    """Cycles' fresnel_dielectric_cos: the unpolarised Fresnel reflectance at |cos| for relative
    index eta, 1 past the critical angle."""
    f32 = np.float32
    c = np.abs(cos).astype(f32)
    g = eta * eta - f32(1.0) + c * c
    root = np.sqrt(np.maximum(g, f32(0.0)))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (root - c) / (root + c)
        b = (c * (root + c) - f32(1.0)) / (c * (root - c) + f32(1.0))
        r = f32(0.5) * a * a * (f32(1.0) + b * b)
    return np.where(g > 0.0, r, f32(1.0)).astype(f32)


def _curve_table(mapping, k):
    """(x, y) of curve k of a CurveMapping sampled finely over [-1, 2] through Blender's own
    evaluation (Cycles' table spans the curves' range; values outside extrapolate flat)."""
    mapping.initialize()
    x = np.linspace(-1.0, 2.0, 3073)
    return x, np.array([mapping.evaluate(mapping.curves[k], float(p)) for p in x], np.float32)


# Cycles' fit of a black body's Rec.709 colour by temperature (kernel/tables.h): per range, red and
# green a / t + b t + c, blue ((a t + b) t + c) t + d
_BLACKBODY_FROM = np.float32([965.0, 1167.0, 1449.0, 1902.0, 3315.0, 6365.0])
_BLACKBODY_R = np.float32([[1.61919106e+03, -2.05010916e-03, 5.02995757e+00],
                           [2.48845471e+03, -1.11330907e-03, 3.22621544e+00],
                           [3.34143193e+03, -4.86551192e-04, 1.76486769e+00],
                           [4.09461742e+03, -1.27446582e-04, 7.25731635e-01],
                           [4.67028036e+03, 2.91258199e-05, 1.26703442e-01],
                           [4.59509185e+03, 2.87495649e-05, 1.50345020e-01],
                           [3.78717450e+03, 9.35907826e-06, 3.99075871e-01]])
_BLACKBODY_G = np.float32([[-4.88999748e+02, 6.04330754e-04, -7.55807526e-02],
                           [-7.55994277e+02, 3.16730098e-04, 4.78306139e-01],
                           [-1.02363977e+03, 1.20223470e-04, 9.36662319e-01],
                           [-1.26571316e+03, 4.87340896e-06, 1.27054498e+00],
                           [-1.42529332e+03, -4.01150431e-05, 1.43972784e+00],
                           [-1.17554822e+03, -2.16378048e-05, 1.30408023e+00],
                           [-5.00799571e+02, -4.59832026e-06, 1.09098763e+00]])
_BLACKBODY_B = np.float32([[5.96945309e-11, -4.85742887e-08, -9.70622247e-05, -4.07936148e-03],
                           [2.40430366e-11, 5.55021075e-08, -1.98503712e-04, 2.89312858e-02],
                           [-1.40949732e-11, 1.89878968e-07, -3.56632824e-04, 9.10767778e-02],
                           [-3.61460868e-11, 2.84822009e-07, -4.93211319e-04, 1.56723440e-01],
                           [-1.97075738e-11, 1.75359352e-07, -2.50542825e-04, -2.22783266e-02],
                           [-1.61997957e-13, -1.64216008e-08, 3.86216271e-04, -7.38077418e-01],
                           [6.72650283e-13, -2.73078809e-08, 4.24098264e-04, -7.52335691e-01]])


def _blackbody(t):
    """Cycles' svm_node_blackbody: the Rec.709 colour of a black body at temperature t (K), clamped
    at 0 (the scene's linear space taken as Rec.709)."""
    t = np.asarray(t, np.float32)
    i = np.searchsorted(_BLACKBODY_FROM, t, side="right")
    r, g, b = _BLACKBODY_R[i], _BLACKBODY_G[i], _BLACKBODY_B[i]
    inv = np.float32(1.0) / np.maximum(t, np.float32(1.0))
    out = np.stack([r[:, 0] * inv + r[:, 1] * t + r[:, 2], g[:, 0] * inv + g[:, 1] * t + g[:, 2],
                    ((b[:, 0] * t + b[:, 1]) * t + b[:, 2]) * t + b[:, 3]], axis=1)
    out = np.where((t >= 12000.0)[:, None], np.float32([0.8262954810464208, 0.9945080501520986, 1.566307710274283]),
                   out)
    out = np.where((t < 800.0)[:, None], np.float32([5.413294490189271, -0.20319390035873933, -0.0822535242887164]),
                   out)
    return np.maximum(out, 0.0).astype(np.float32)


# The CIE 1931 2-degree standard observer's colour matching functions (x, y, z) from 380 to 780 nm
# every 5 nm, to four places: the table Cycles' svm_math_wavelength_color_xyz interpolates
_CIE_1931 = np.float32([
    [0.0014, 0.0000, 0.0065], [0.0022, 0.0001, 0.0105], [0.0042, 0.0001, 0.0201], [0.0076, 0.0002, 0.0362],
    [0.0143, 0.0004, 0.0679], [0.0232, 0.0006, 0.1102], [0.0435, 0.0012, 0.2074], [0.0776, 0.0022, 0.3713],
    [0.1344, 0.0040, 0.6456], [0.2148, 0.0073, 1.0391], [0.2839, 0.0116, 1.3856], [0.3285, 0.0168, 1.6230],
    [0.3483, 0.0230, 1.7471], [0.3481, 0.0298, 1.7826], [0.3362, 0.0380, 1.7721], [0.3187, 0.0480, 1.7441],
    [0.2908, 0.0600, 1.6692], [0.2511, 0.0739, 1.5281], [0.1954, 0.0910, 1.2876], [0.1421, 0.1126, 1.0419],
    [0.0956, 0.1390, 0.8130], [0.0580, 0.1693, 0.6162], [0.0320, 0.2080, 0.4652], [0.0147, 0.2586, 0.3533],
    [0.0049, 0.3230, 0.2720], [0.0024, 0.4073, 0.2123], [0.0093, 0.5030, 0.1582], [0.0291, 0.6082, 0.1117],
    [0.0633, 0.7100, 0.0782], [0.1096, 0.7932, 0.0573], [0.1655, 0.8620, 0.0422], [0.2257, 0.9149, 0.0298],
    [0.2904, 0.9540, 0.0203], [0.3597, 0.9803, 0.0134], [0.4334, 0.9950, 0.0087], [0.5121, 1.0000, 0.0057],
    [0.5945, 0.9950, 0.0039], [0.6784, 0.9786, 0.0027], [0.7621, 0.9520, 0.0021], [0.8425, 0.9154, 0.0018],
    [0.9163, 0.8700, 0.0017], [0.9786, 0.8163, 0.0014], [1.0263, 0.7570, 0.0011], [1.0567, 0.6949, 0.0010],
    [1.0622, 0.6310, 0.0008], [1.0456, 0.5668, 0.0006], [1.0026, 0.5030, 0.0003], [0.9384, 0.4412, 0.0002],
    [0.8544, 0.3810, 0.0002], [0.7514, 0.3210, 0.0001], [0.6424, 0.2650, 0.0000], [0.5419, 0.2170, 0.0000],
    [0.4479, 0.1750, 0.0000], [0.3608, 0.1382, 0.0000], [0.2835, 0.1070, 0.0000], [0.2187, 0.0816, 0.0000],
    [0.1649, 0.0610, 0.0000], [0.1212, 0.0446, 0.0000], [0.0874, 0.0320, 0.0000], [0.0636, 0.0232, 0.0000],
    [0.0468, 0.0170, 0.0000], [0.0329, 0.0119, 0.0000], [0.0227, 0.0082, 0.0000], [0.0158, 0.0057, 0.0000],
    [0.0114, 0.0041, 0.0000], [0.0081, 0.0029, 0.0000], [0.0058, 0.0021, 0.0000], [0.0041, 0.0015, 0.0000],
    [0.0029, 0.0010, 0.0000], [0.0020, 0.0007, 0.0000], [0.0014, 0.0005, 0.0000], [0.0010, 0.0004, 0.0000],
    [0.0007, 0.0002, 0.0000], [0.0005, 0.0002, 0.0000], [0.0003, 0.0001, 0.0000], [0.0002, 0.0001, 0.0000],
    [0.0002, 0.0001, 0.0000], [0.0001, 0.0000, 0.0000], [0.0001, 0.0000, 0.0000], [0.0001, 0.0000, 0.0000],
    [0.0000, 0.0000, 0.0000]])
# CIE XYZ (D65) to Blender's scene linear, Rec.709: Blender's colour configuration's matrix (Cycles
# reaches it through ACES2065-1, whose two matrices there cancel to this within 1e-6)
_XYZ_TO_REC709 = np.float32([[3.2409699, -1.5373832, -0.4986108], [-0.9692436, 1.8759675, 0.0415551],
                             [0.0556301, -0.2039770, 1.0569715]])


def _wavelength(nm):
    """Cycles' svm_node_wavelength: the CIE 1931 colour of light of wavelength nm, interpolated every
    5 nm (black outside 380-780 nm), in scene linear, scaled by 1 / 2.52 and clamped at 0."""
    t = (np.asarray(nm, np.float32) - np.float32(380.0)) * np.float32(0.2)
    i = np.trunc(t).astype(np.int64)  # (float_to_int truncates towards 0)
    inside = (i >= 0) & (i < 80)
    k = np.clip(i, 0, 79)
    f = (t - i)[:, None]
    xyz = (np.float32(1.0) - f) * _CIE_1931[k] + f * _CIE_1931[k + 1]
    rgb = (xyz @ _XYZ_TO_REC709.T) * np.float32(1.0 / 2.52)
    return np.where(inside[:, None], np.maximum(rgb, 0.0), 0.0).astype(np.float32)


def _smoothstep(lo, hi, x):
    """Cycles' smoothstep (0 below lo, 1 from hi on)."""
    t = (x - lo) / np.where(hi != lo, hi - lo, np.float32(1.0))
    return np.where(x < lo, 0.0, np.where(x >= hi, 1.0, (np.float32(3.0) - np.float32(2.0) * t) * (t * t)))


def _smootherstep(lo, hi, x):
    """Cycles' smootherstep."""
    t = np.clip(np.where(hi != lo, (x - lo) / np.where(hi != lo, hi - lo, np.float32(1.0)), 0.0), 0.0, 1.0)
    return t * t * t * (t * (t * np.float32(6.0) - np.float32(15.0)) + np.float32(10.0))


def _wrapped(co, projection):
    """Cycles' map_to_sphere or map_to_tube of coordinates co (n, 3) remapped from the unit box to
    [-1, 1]: (u, v)."""
    f32 = np.float32
    c = ((co.astype(f32) - f32(0.5)) * f32(2.0)).astype(f32)
    x, y, z = c[:, 0], c[:, 1], c[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        if projection == "TUBE":
            length = np.sqrt(x * x + y * y)
            ok = length > 0.0
            u = (f32(1.0) - np.arctan2(x / length, y / length) / f32(math.pi)) * f32(0.5)
            v = (z + f32(1.0)) * f32(0.5)
            return np.where(ok, u, f32(0.0)), np.where(ok, v, f32(0.0))
        square = x * x + y * y + z * z
        ok = square > 0.0
        u = np.where((x == 0.0) & (y == 0.0), f32(0.0), f32(0.5) - np.arctan2(x, y) * f32(0.5 / math.pi))
        v = f32(1.0) - np.arccos(np.clip(z / np.sqrt(square), -1.0, 1.0)) * f32(1.0 / math.pi)
        return np.where(ok, u, f32(0.0)).astype(f32), np.where(ok, v, f32(0.0)).astype(f32)


def _box_weights(n, blend):
    """Cycles' svm_node_tex_image_box's weights (n, 3) of the x, y and z planes for object-space
    normals n (n, 3) and the node's Blend, in float32 as Cycles computes them."""
    f32 = np.float32
    a = np.abs(n.astype(f32))
    a = a / (a[:, 0] + a[:, 1] + a[:, 2])[:, None]
    x, y, z = a[:, 0], a[:, 1], a[:, 2]
    limit = f32(0.5) * (f32(1.0) + blend)
    w = np.zeros_like(a)
    left = np.ones(len(a), bool)

    def take(cond, values):
        nonlocal left
        cond = cond & left
        for k, v in enumerate(values):
            if v is not None:
                w[cond, k] = (v if np.ndim(v) == 0 else v[cond])
        left = left & ~cond
    take((x > limit * (x + y)) & (x > limit * (x + z)), (f32(1.0), None, None))
    take((y > limit * (x + y)) & (y > limit * (y + z)), (None, f32(1.0), None))
    take((z > limit * (x + z)) & (z > limit * (y + z)), (None, None, f32(1.0)))
    if blend > 0.0:
        with np.errstate(divide="ignore", invalid="ignore"):
            def ramp(share):
                return np.clip((share - f32(0.5) * (f32(1.0) - blend)) / blend, f32(0.0), f32(1.0))
            xy, yz, xz = ramp(x / (x + y)), ramp(y / (y + z)), ramp(x / (x + z))
            take(z < (f32(1.0) - limit) * (y + x), (xy, f32(1.0) - xy, None))
            take(x < (f32(1.0) - limit) * (y + z), (None, yz, f32(1.0) - yz))
            take(y < (f32(1.0) - limit) * (x + z), (xz, None, f32(1.0) - xz))
            three = [((f32(2.0) - limit) * c + (limit - f32(1.0))) / (f32(2.0) * limit - f32(1.0))
                     for c in (x, y, z)]
            take(np.ones(len(a), bool), three)
    else:
        take(np.ones(len(a), bool), (f32(1.0), None, None))  # Cycles' fallback to one side
    return w


def _euler_xyz(r):
    """Blender's XYZ Euler rotation matrix (radians)."""
    cx, cy, cz = np.cos(r)
    sx, sy, sz = np.sin(r)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _blend(name, mode, t, a, b):
    """Cycles' svm_mix for the blend modes it shares with most painting programs."""
    if mode == "MIX":
        out = a + t * (b - a)
    elif mode == "ADD":
        out = a + t * b
    elif mode == "MULTIPLY":
        out = a * (1.0 - t + t * b)
    elif mode == "SUBTRACT":
        out = a - t * b
    elif mode == "SCREEN":
        out = 1.0 - (1.0 - t + t * (1.0 - b)) * (1.0 - a)
    elif mode == "DIVIDE":
        out = np.where(b != 0.0, (1.0 - t) * a + t * a / np.where(b != 0.0, b, 1.0), a)
    elif mode == "DIFFERENCE":
        out = a + t * (np.abs(a - b) - a)
    elif mode == "DARKEN":
        out = a + t * (np.minimum(a, b) - a)
    elif mode == "LIGHTEN":
        out = a + t * (np.maximum(a, b) - a)
    elif mode == "OVERLAY":
        out = np.where(a < 0.5, a * (1.0 - t + 2.0 * t * b), 1.0 - (1.0 - t + 2.0 * t * (1.0 - b)) * (1.0 - a))
    elif mode == "EXCLUSION":
        out = np.maximum(a + t * (a + b - 2.0 * a * b - a), 0.0)
    elif mode == "DODGE":
        with np.errstate(divide="ignore", invalid="ignore"):
            lift = 1.0 - t * b
            out = np.where(a == 0.0, a, np.where(lift <= 0.0, 1.0, np.minimum(a / lift, 1.0)))
    elif mode == "BURN":
        with np.errstate(divide="ignore", invalid="ignore"):
            fall = 1.0 - t + t * b
            out = np.where(fall <= 0.0, 0.0, np.clip(1.0 - (1.0 - a) / fall, 0.0, 1.0))
    elif mode == "SOFT_LIGHT":
        out = (1.0 - t) * a + t * ((1.0 - a) * b * a + a * (1.0 - (1.0 - b) * (1.0 - a)))
    elif mode == "LINEAR_LIGHT":
        out = a + t * (2.0 * b - 1.0)
    elif mode in ("HUE", "SATURATION", "VALUE", "COLOR"):
        out = _blend_hsv(mode, t, a, b)
    else:
        raise Unsupported(f"'{name}' blending by {mode.lower().replace('_', ' ')}")
    return out.astype(np.float32)


def _blend_hsv(mode, t, a, b):
    """Cycles' svm_mix_hue, _sat, _val and _color: a's hue, saturation or value (or hue and
    saturation) towards b's."""
    t = np.broadcast_to(t, a.shape)[:, 0]
    h, s, v = _rgb_to_hsv(a)
    h2, s2, v2 = _rgb_to_hsv(b)
    if mode == "VALUE":
        return _hsv_to_rgb(h, s, (1.0 - t) * v + t * v2)
    if mode == "SATURATION":
        return np.where((s != 0.0)[:, None], _hsv_to_rgb(h, (1.0 - t) * s + t * s2, v), a)
    turned = _hsv_to_rgb(h2, s2 if mode == "COLOR" else s, v)
    return np.where((s2 != 0.0)[:, None], a + t[:, None] * (turned - a), a)


def _safe_divide(a, b):
    return np.where(b != 0.0, a / np.where(b != 0.0, b, 1.0), 0.0)


def _math(name, op, a, b=None, c=None):
    """Cycles' svm_math: every operation, made safe where Cycles makes it so (division, power,
    logarithm, square roots, modulo, the arcs)."""
    def wrap(v, high, low):
        span = high - low
        return np.where(span != 0.0, v - span * np.floor(_safe_divide(v - low, span)), low)

    def smooth_min(x, y, k):
        h = np.maximum(k - np.abs(x - y), 0.0) / np.where(k != 0.0, k, 1.0)
        return np.where(k != 0.0, np.minimum(x, y) - h * h * h * k * np.float32(1.0 / 6.0), np.minimum(x, y))
    simple = {
        "ADD": lambda: a + b, "SUBTRACT": lambda: a - b, "MULTIPLY": lambda: a * b,
        "DIVIDE": lambda: _safe_divide(a, b), "MULTIPLY_ADD": lambda: a * b + c,
        "MINIMUM": lambda: np.minimum(a, b), "MAXIMUM": lambda: np.maximum(a, b),
        "LESS_THAN": lambda: (a < b).astype(np.float32), "GREATER_THAN": lambda: (a > b).astype(np.float32),
        "ABSOLUTE": lambda: np.abs(a), "SQRT": lambda: np.where(a > 0.0, np.sqrt(np.maximum(a, 0.0)), 0.0),
        "ROUND": lambda: np.floor(a + 0.5), "FLOOR": lambda: np.floor(a), "CEIL": lambda: np.ceil(a),
        "FRACT": lambda: a - np.floor(a), "SINE": lambda: np.sin(a), "COSINE": lambda: np.cos(a),
        "SNAP": lambda: np.where(b != 0.0, np.floor(_safe_divide(a, b)) * b, 0.0),
        "POWER": lambda: _power(a, b),
        "LOGARITHM": lambda: np.where((a > 0.0) & (b > 0.0), _safe_divide(np.log(np.maximum(a, 1e-38)),
                                                                         np.log(np.maximum(b, 1e-38))), 0.0),
        "INVERSE_SQRT": lambda: np.where(a > 0.0, 1.0 / np.sqrt(np.maximum(a, 1e-38)), 0.0),
        "EXPONENT": lambda: np.exp(a), "SIGN": lambda: np.sign(a),
        "RADIANS": lambda: a * np.float32(math.pi / 180.0), "DEGREES": lambda: a * np.float32(180.0 / math.pi),
        "COMPARE": lambda: ((a == b) | (np.abs(a - b) <= np.maximum(c, np.finfo(np.float32).eps))).astype(np.float32),
        "SMOOTH_MIN": lambda: smooth_min(a, b, c), "SMOOTH_MAX": lambda: -smooth_min(-a, -b, c),
        "TRUNC": lambda: np.trunc(a), "MODULO": lambda: np.where(b != 0.0, np.fmod(a, np.where(b != 0.0, b, 1.0)), 0.0),
        "FLOORED_MODULO": lambda: np.where(b != 0.0, a - np.floor(_safe_divide(a, b)) * b, 0.0),
        "WRAP": lambda: wrap(a, b, c),
        "PINGPONG": lambda: np.where(b != 0.0, np.abs((_safe_divide(a - b, b * 2.0) - np.floor(
            _safe_divide(a - b, b * 2.0))) * b * 2.0 - b), 0.0),
        "TANGENT": lambda: np.tan(a), "ARCSINE": lambda: np.arcsin(np.clip(a, -1.0, 1.0)),
        "ARCCOSINE": lambda: np.arccos(np.clip(a, -1.0, 1.0)), "ARCTANGENT": lambda: np.arctan(a),
        "ARCTAN2": lambda: np.arctan2(a, b), "SINH": lambda: np.sinh(a), "COSH": lambda: np.cosh(a),
        "TANH": lambda: np.tanh(a),
    }
    if op not in simple:
        raise Unsupported(f"'{name}' ({op.lower().replace('_', ' ')})")
    with np.errstate(all="ignore"):
        return np.asarray(simple[op](), np.float32)


def _power(a, b):
    """Cycles' safe_powf: a negative base only to an integer power, else 0."""
    whole = b == np.floor(b)
    out = np.where(a >= 0.0, np.power(np.abs(a), b), np.where(whole, np.power(np.abs(a), b) * np.where(
        np.mod(b, 2.0) == 1.0, -1.0, 1.0), 0.0))
    return np.where(np.isfinite(out), out, 0.0)


def _rgb_to_hsv(c):
    r, g, b = c[:, 0], c[:, 1], c[:, 2]
    v = np.max(c, axis=1)
    delta = v - np.min(c, axis=1)
    s = np.where(v != 0.0, delta / np.where(v != 0.0, v, 1.0), 0.0)
    safe = np.where(delta != 0.0, delta, 1.0)
    cr, cg, cb = (v - r) / safe, (v - g) / safe, (v - b) / safe
    h = np.where(r == v, cb - cg, np.where(g == v, 2.0 + cr - cb, 4.0 + cg - cr)) / 6.0
    h = np.where(h < 0.0, h + 1.0, h)
    return np.where(s != 0.0, h, 0.0), s, v


def _rgb_to_hsl(c):
    """Cycles' rgb_to_hsl of each row of c (n, 3)."""
    r, g, b = c[:, 0], c[:, 1], c[:, 2]
    high, low = np.max(c, axis=1), np.min(c, axis=1)
    light = np.minimum(1.0, (high + low) / 2.0)
    delta = high - low
    grey = delta == 0.0
    safe = np.where(grey, 1.0, delta)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(light > 0.5, delta / (2.0 - high - low), delta / (high + low))
    h = np.where(high == r, (g - b) / safe + np.where(g < b, 6.0, 0.0),
                 np.where(high == g, (b - r) / safe + 2.0, (r - g) / safe + 4.0))
    return np.stack([np.where(grey, 0.0, h / 6.0), np.where(grey, 0.0, s), light], axis=1)


def _hsl_to_rgb(c):
    """Cycles' hsl_to_rgb of each row of c (n, 3)."""
    h, s, light = c[:, 0], c[:, 1], c[:, 2]
    n = np.clip(np.stack([np.abs(h * 6.0 - 3.0) - 1.0, 2.0 - np.abs(h * 6.0 - 2.0), 2.0 - np.abs(h * 6.0 - 4.0)],
                         axis=1), 0.0, 1.0)
    chroma = (1.0 - np.abs(2.0 * light - 1.0)) * s
    return (n - 0.5) * chroma[:, None] + light[:, None]


def _hsv_to_rgb(h, s, v):
    h6 = np.where(h == 1.0, 0.0, h) * 6.0
    i = np.floor(h6)
    f = h6 - i
    p, q, t = v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f))
    i = i.astype(np.int64) % 6
    r = np.choose(i, [v, q, p, p, t, v])
    g = np.choose(i, [t, v, v, q, p, p])
    b = np.choose(i, [p, p, t, v, v, q])
    grey = s == 0.0
    return np.stack([np.where(grey, v, r), np.where(grey, v, g), np.where(grey, v, b)], axis=1)


def one_point(texture, checking=False):
    """An Evaluator of a single point at UV (0, 0): texture(node) gives each Image Texture's (1, 3)
    colour there, or (1, 4) with its alpha (what a socket reads without a mesh: the panel's checks, the glossmeter's means)."""
    return Evaluator(1, lambda uv_map: (np.zeros((1, 2), np.float32), np.ones(1, np.float32), np.zeros(1, np.int64)),
                     lambda node, uv, footprint, rows: texture(node), checking)


def constant_value(socket, camera_ray=True):
    """The value of `socket` where it is the same at every point: its unlinked value, or what nodes
    that read nothing varying over a mesh give it (a Value node, Math on such values); None where they
    read a texture, coordinates or the mesh, or wenv does not evaluate them.  Without `camera_ray`,
    None where a Light Path node is read too (elsewhere read as a camera ray's hit)."""
    if not socket.is_linked:
        return float(socket.default_value)
    got = _constant(socket, False, camera_ray)
    return None if got is None else float(got[0])


def constant_colour(socket, camera_ray=True):
    """constant_value of a colour socket: (r, g, b) (a Blackbody of a constant temperature, RGB and Mix
    nodes of constants), or None."""
    if not socket.is_linked:
        return tuple(float(c) for c in socket.default_value[:3])
    got = _constant(socket, True, camera_ray)
    return None if got is None else tuple(float(c) for c in got[0])


def _constant(socket, colour, camera_ray):
    ev = one_point(lambda node: np.zeros((1, 3), np.float32))
    try:
        got = ev.colour(socket) if colour else ev.value(socket)
    except (Unsupported, NeedsMesh):
        return None
    if ev.textures or ev.spaces or (ev.read_light_path and not camera_ray) or not np.isfinite(got).all():
        return None
    return got


def check(principled_socket, groups=()):
    """(textures, notes) when every node feeding a Principled socket (inside `groups`, the group nodes
    it lies in, outermost first) is evaluated -- the Image Texture nodes read, and what of them is
    read otherwise than Cycles reads it -- or (None, why not)."""
    ev = one_point(lambda node: np.zeros((1, 3), np.float32), checking=True)
    try:
        ev.value_within(principled_socket, groups)
    except Unsupported as exc:
        return None, str(exc)
    return ev.textures, ev.notes
