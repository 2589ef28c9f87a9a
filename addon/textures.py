"""Textures: a Principled BSDF's inputs (every one the core shades per vertex: Base Color, Roughness,
Metallic, Specular IOR Level and Tint, Coat Weight and Roughness, Sheen Weight, Roughness and Tint,
Alpha, Emission Color) read from their Image Texture nodes at each shaded vertex -- through the
node's UV map, in the image's colour space, with its interpolation and extension -- and filtered
over the vertex's share of the image (mip-mapped), so that a texture finer than the mesh averages
rather than aliases.  The core then shades each vertex with its own values (Shader.shade(...,
base_color=, roughness=, ...)): a colour at the cost of a multiply-add, the inputs that shape the
lobes through a family of materials.  What is not read yet is named, never used silently."""
import collections

import numpy as np

from . import ambient, bevel, closures, compat, engine, materials, meshes, nodes, world

# The sockets read from textures and the nodes between (nodes.py), by the core's keyword: every input
# the core shades per vertex (wenv.Principled.INPUTS' per_vertex).  A colour into a value socket is
# its luminance, as Cycles converts it.
TEXTURED_SOCKETS = {row["socket"]: row["name"] for row in engine.PRINCIPLED_INPUTS if row["per_vertex"]}
# those read as colours (the rest as values)
COLOUR_KEYWORDS = tuple(row["name"] for row in engine.PRINCIPLED_INPUTS if row["per_vertex"] and row["size"] == 3)
# The spaces of row_points a camera's turn or lens changes
CAMERA_SPACES = frozenset(("CAMERA", "WINDOW"))
# An Image Texture's extensions, each read as Cycles reads it (_wrap)
EXTENSIONS = ("REPEAT", "EXTEND", "CLIP", "MIRROR")


class Source:
    """Where an input comes from: an Image Texture node and the UV map it reads (None: the
    mesh's active render UV map, as Cycles reads an unlinked Vector); for a normal map, the space
    its Normal Map node reads the colour in."""

    __slots__ = ("node", "uv_map", "space")

    def __init__(self, node, uv_map, space="TANGENT"):
        self.node = node
        self.uv_map = uv_map
        self.space = space


def socket_textures(principled, socket):
    """(Image Texture nodes, notes) feeding a Principled BSDF's `socket` through nodes wenv evaluates
    (nodes.py), notes naming what of them is read otherwise than Cycles reads it; or (None, reason)
    with why the socket is not read (its unlinked value is then used), reason None when it is
    unlinked."""
    sock = principled.inputs[socket]
    return nodes.check(sock) if sock.is_linked else (None, None)


def socket_at_means(principled, socket):
    """The value a Principled socket takes when each texture feeding it reads its image's mean (the
    nodes between applied to it), and the images read; None when the socket is not read."""
    sock = principled.inputs[socket]
    if not sock.is_linked:
        return None
    ev = nodes.one_point(lambda node: np.float32([images.mean(node)]))
    try:
        out = ev.colour(sock) if TEXTURED_SOCKETS[socket] in COLOUR_KEYWORDS else ev.value(sock)
    except nodes.NeedsMesh as exc:  # (a material has no mesh to take an attribute's mean over)
        raise world.SetupError(f"it reads {exc}") from None
    except nodes.Unsupported:
        return None
    return out[0], [t.image.name for t in ev.textures]


# ---------------------------------------------------------------------------------------------
# Images, linear and mip-mapped, read once per content


class ImageCache:
    """Each image's mip pyramid (what Cycles samples of it: cycles_texels), level 0 the image, each
    next a 2 x 2 box of the last, to 1 x 1), kept while its pixels are the same.  Holds no Blender
    data."""

    def __init__(self):
        self._pyramids = {}  # (image name, unassociated) -> (fingerprint of its pixels and settings, levels, state)
        self._means = {}  # a state Image.mean checks -> the mean colour

    def clear(self):
        self._pyramids.clear()
        self._means = {}

    def mean(self, node):
        """An Image Texture node's image's mean (its pyramid's last level: RGB, or RGBA where it has
        alpha), read once per state a panel can check cheaply at each redraw -- its name, size, file,
        packing, whether it has unsaved edits and, for a sequence or movie, the frame shown -- rather
        than by its pixels."""
        image, frame, unassociated = node.image, frame_shown(node), nodes.unassociates_alpha(node)
        state = (image.name_full, tuple(image.size), image.filepath_raw, image.packed_file is not None,
                 image.is_dirty, image.colorspace_settings.name, image.alpha_mode, image.source,
                 tuple(t.number for t in image.tiles), frame, unassociated)
        means = self._means
        if state not in means:
            if len(means) > 64:
                means.clear()
            means[state] = tuple(float(c) for c in self.mean_of(image, frame, unassociated))
        return means[state]

    def levels(self, image, frame=None, unassociated=False):
        """The image's pyramid.  An image with no unsaved edits (a file or packed image as loaded)
        is known by its name, size, file and colour space, and its pixels are not read again; one
        with edits (painted, or set by a script) is read and known by its pixels.  frame: the Frame
        an image sequence or movie shows (frame_shown), read by Blender's own loader or decoder.
        unassociated: for a node whose colour Cycles divides by its alpha (cycles_texels)."""
        state = (tuple(image.size), image.filepath_raw, image.packed_file is not None, image.source,
                 image.colorspace_settings.name, image.alpha_mode, frame)
        name = (image.name_full, unassociated)
        held = self._pyramids.get(name)
        if held is not None and (frame is not None or not image.is_dirty) and held[2] == state:
            return held[1]
        is_float = None
        if frame is not None and image.source == "MOVIE":
            rgba = _movie_pixels(image, frame)
        elif frame is not None:
            rgba, is_float = _file_pixels(image, frame.path, "frame")
        else:
            rgba = world.image_pixels(image, "Texture image", as_stored=True)
        rgba = rgba[::-1]  # row 0 the bottom, as v = 0 is
        key = (engine.fingerprint(rgba), image.colorspace_settings.name, image.alpha_mode)
        if held is None or held[0] != key:
            if not np.isfinite(rgba).all():
                bad = np.argwhere(~np.isfinite(rgba).all(axis=2))[0]
                raise world.SetupError(f"Texture image '{image.name}' has a texel that is not finite (NaN or "
                                       f"infinite) at column {bad[1]}, row {bad[0]}: fix or replace the image")
            held = (key, _pyramid(cycles_texels(rgba, image, unassociated, is_float)), state)
            self._pyramids[name] = held
        elif held[2] != state:
            held = (held[0], held[1], state)
            self._pyramids[name] = held
        return held[1]

    def tiles(self, image, unassociated=False):
        """A UDIM image's pyramids, {tile number: levels}: its first tile as levels() reads the image
        (Blender hands out that tile's pixels, unsaved edits included), each other tile from its
        packed data or its file.  A tile neither packed nor found on disk is a SetupError naming
        its file; a generated tile past the first is nodes.Unsupported.  Where some tiles have alpha,
        every tile's pyramid has it."""
        numbers = tuple(t.number for t in image.tiles)
        packed = {p.tile_number: p for p in image.packed_files}
        state = (numbers, tuple(image.size), image.filepath_raw, tuple(sorted(packed)),
                 image.colorspace_settings.name, image.alpha_mode)
        held = self._pyramids.get(("tiles", image.name_full, unassociated))
        first = self.levels(image, unassociated=unassociated)
        if held is not None and held[0] == state and held[2] is first:
            return held[1]
        out = {numbers[0]: first}
        for tile in image.tiles[1:]:
            rgba, is_float = _tile_pixels(image, tile, packed.get(tile.number))
            out[tile.number] = _pyramid(cycles_texels(rgba[::-1], image, unassociated, is_float))
        if len({levels[0].shape[2] for levels in out.values()}) > 1:
            out = {number: [_opaque(level) for level in levels] for number, levels in out.items()}
        self._pyramids[("tiles", image.name_full, unassociated)] = (state, out, first)
        return out

    def mean_of(self, image, frame=None, unassociated=False):
        """levels()[-1] of an image, or the tiles' mean for a UDIM image (each tile a unit of UV)."""
        if image.source == "TILED":
            return np.mean([levels[-1][0, 0] for levels in self.tiles(image, unassociated).values()], axis=0)
        return self.levels(image, frame, unassociated)[-1][0, 0]


def _opaque(level):
    """An RGB level with alpha 1 (an RGBA one as it is)."""
    if level.shape[2] == 4:
        return level
    return np.concatenate([level, np.ones(level.shape[:2] + (1,), np.float32)], axis=2)


def cycles_texels(rgba, image, unassociated=False, is_float=None):
    """What Cycles samples of an image, from its RGBA as stored (world.image_pixels(as_stored=True)):
    scene-linear RGB where every texel is opaque (or its alpha is ignored), else RGBA with the colour
    associated with alpha as Cycles' loaders leave it -- a float image's as stored, a byte image's
    multiplied by alpha in 8-bit integers, (c * a) / 255, before its sRGB is decoded; data and
    channel-packed colours not at all.  unassociated: the texels for a node whose Alpha output is used,
    whose colour Cycles divides by alpha before decoding sRGB (svm_image_texture): a byte texel's
    colour is then that quotient decoded, times alpha, so that dividing the filtered colour by the
    filtered alpha gives it back.  is_float: the loaded pixels' (image.is_float unless given)."""
    is_float = image.is_float if is_float is None else is_float
    space = image.colorspace_settings.name
    srgb = not is_float and space in world.SRGB_SPACES
    rgb, alpha = rgba[..., :3], rgba[..., 3:4]
    if image.alpha_mode == "NONE" or (alpha == 1.0).all():
        return np.ascontiguousarray(world.srgb_to_linear(rgb) if srgb else rgb, np.float32)
    associates_bytes = not is_float and space not in world.DATA_SPACES and image.alpha_mode != "CHANNEL_PACKED"
    if associates_bytes:
        c, a = np.rint(rgb * 255.0), np.rint(alpha * 255.0)
        rgb = np.floor(c * a / 255.0) / 255.0
        if unassociated:
            rgb = np.where((a > 0.0) & (a < 255.0), rgb * (255.0 / np.maximum(a, 1.0)), rgb)
    rgb = world.srgb_to_linear(rgb) if srgb else rgb
    if associates_bytes and unassociated:
        rgb = rgb * alpha
    return np.ascontiguousarray(np.concatenate([rgb, alpha], axis=2), np.float32)


def _tile_pixels(image, tile, packed):
    """_file_pixels of a UDIM tile past the first, from its packed data or
    its file (<UDIM> or <UVTILE> in the path)."""
    import os
    import tempfile

    import bpy

    u, v = (tile.number - 1001) % 10, (tile.number - 1001) // 10
    path = bpy.path.abspath(image.filepath_raw.replace("<UDIM>", str(tile.number))
                            .replace("<UVTILE>", f"u{u + 1}_v{v + 1}"), library=image.library)
    what = f"tile {tile.number}"
    if packed is not None and packed.packed_file is not None:
        fd, scratch = tempfile.mkstemp(suffix=os.path.splitext(packed.filepath)[1] or ".png")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(packed.packed_file.data)
            return _file_pixels(image, scratch, what)
        finally:
            os.remove(scratch)
    if not os.path.isfile(path) and (getattr(tile, "is_generated_tile", False) or not image.filepath_raw):
        raise nodes.Unsupported(f"'{image.name}', whose generated tile {tile.number} wenv does not read")
    return _file_pixels(image, path, what)


def _file_pixels(image, path, what):
    """(RGBA (H, W, 4) as stored, row 0 the top; whether it is float) of the file at `path` read for
    `image` (a UDIM tile, a sequence's frame: `what` names it) by Blender's own loader in the image's
    colour space, into a datablock removed at once.  A file that is missing, unreadable or holds a texel that is not finite
    is a SetupError naming it."""
    import os

    import bpy

    if not os.path.isfile(path):
        raise world.SetupError(f"Texture image '{image.name}': {what} could not be loaded: {path}")
    loaded = None
    try:
        loaded = bpy.data.images.load(path, check_existing=False)
        loaded.colorspace_settings.name = image.colorspace_settings.name
        rgba = world.image_pixels(loaded, f"Texture image '{image.name}' {what}", as_stored=True)
        is_float = loaded.is_float
    except RuntimeError as exc:
        raise world.SetupError(f"Texture image '{image.name}': {what} could not be loaded: {path} "
                               f"({exc})") from None
    finally:
        if loaded is not None:
            bpy.data.images.remove(loaded)
    if not np.isfinite(rgba).all():
        raise world.SetupError(f"Texture image '{image.name}' has a texel that is not finite (NaN or infinite) in "
                               f"{what}: fix or replace the image")
    return rgba, is_float


def _movie_pixels(image, frame):
    """RGBA (H, W, 4) as stored, row 0 the top, of a movie's `frame` (a Frame) as Blender decodes it.
    Image.pixels hands out the frame Blender last decoded for the image, and only a texture's image
    user (whose frame a script may set) asks for a given one: a texture datablock, removed at once,
    asks for it.  A movie Blender cannot open is a SetupError naming its file."""
    import bpy

    reader = bpy.data.textures.new(".wenv movie frame", "IMAGE")
    try:
        reader.image = image
        reader.image_user.frame_current = frame.number
        reader.evaluate((0.0, 0.0, 0.0))
        rgba = world.image_pixels(image, "Texture movie", as_stored=True)
    finally:
        bpy.data.textures.remove(reader)
    if not np.isfinite(rgba).all():
        raise world.SetupError(f"Texture image '{image.name}' has a texel that is not finite (NaN or infinite) in "
                               f"frame {frame.number}: fix or replace the movie")
    return rgba


# The frame an image sequence or movie shows: the file read (a sequence's frame's own file, or the
# movie) and the frame's number
Frame = collections.namedtuple("Frame", "path number")


def user_frame(user, scene_frame):
    """The frame of an image sequence or movie an Image Texture's image user shows at the scene's
    frame, as Blender's BKE_image_user_frame_get computes it (Cycles asks it at every render): counted
    from the user's Start Frame, cycled over its Frames or held at their ends, then moved by its
    Offset.  (A movie's frame past its ends shows its first or last, as Blender decodes it.)"""
    length = user.frame_duration
    if length == 0:
        return 0
    frame = scene_frame - user.frame_start + 1
    if user.use_cyclic:
        frame %= length  # Python's modulo is never negative
        frame = frame or length
    else:
        frame = min(max(frame, 0), length)
    return frame + user.frame_offset


def sequence_path(filepath, frame):
    """The file of a sequence's `frame`: the last run of digits in the file's name (before its
    extension) replaced by the frame, at least as wide as that run, as Blender's BLI_path_sequence_*
    do (a name without digits takes the frame before its extension)."""
    import os

    folder, name = os.path.split(filepath)
    stem, ext = os.path.splitext(name)
    end = len(stem)
    while end and not stem[end - 1].isdigit():
        end -= 1
    start = end
    while start and stem[start - 1].isdigit():
        start -= 1
    width = end - start
    # C's "%.*d": at least `width` digits, a sign before them (none at all for 0 with width 0)
    digits = f"{abs(frame):0{width}d}" if width else (str(abs(frame)) if frame else "")
    number = ("-" if frame < 0 else "") + digits
    return os.path.join(folder, stem[:start] + number + stem[end:] + ext)


def frame_shown(node):
    """The Frame an Image Texture node's image sequence or movie shows at the current scene frame
    (its file an absolute path), or None for any other image."""
    image = node.image
    if image is None or image.source not in ("SEQUENCE", "MOVIE"):
        return None
    import bpy

    scene = bpy.context.scene
    number = user_frame(node.image_user, scene.frame_current if scene is not None else 1)
    path = sequence_path(image.filepath_raw, number) if image.source == "SEQUENCE" else image.filepath_raw
    return Frame(bpy.path.abspath(path, library=image.library), number)


def frames_shown(obj):
    """(material, node, Frame) of every image node in obj's materials (node groups included) whose
    image sequence or movie shows a frame: what a bake of obj read of them."""
    out, seen = [], set()

    def walk(tree, owner):
        if tree is None or tree.name_full in seen:
            return
        seen.add(tree.name_full)
        for node in tree.nodes:
            if node.bl_idname in ("ShaderNodeTexImage", "ShaderNodeTexEnvironment"):
                frame = frame_shown(node)
                if frame is not None:
                    out.append((owner, node.name, frame))
            elif node.bl_idname == "ShaderNodeGroup":
                walk(node.node_tree, owner)

    for slot in obj.material_slots:
        if slot.material is not None:
            walk(slot.material.node_tree, slot.material.name)
    return sorted(out)


def _pyramid(rgb):
    levels = [rgb]
    while max(levels[-1].shape[:2]) > 1:
        a = levels[-1]
        h, w = a.shape[:2]
        # an odd side keeps its last row or column in the last box
        a = a[:h - h % 2 or h, :w - w % 2 or w] if min(h, w) > 1 else a
        if a.shape[0] > 1 and a.shape[1] > 1:
            a = 0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])
        elif a.shape[0] > 1:
            a = 0.5 * (a[0::2] + a[1::2])
        else:
            a = 0.5 * (a[:, 0::2] + a[:, 1::2])
        levels.append(np.ascontiguousarray(a, np.float32))
    return levels


images = ImageCache()


def pyramids(node):
    """What sample_image reads of an Image Texture node's image: its pyramid (an image sequence's or
    movie's at the frame shown), or a UDIM image's tiles'."""
    image, unassociated = node.image, nodes.unassociates_alpha(node)
    if image.source == "TILED":
        return images.tiles(image, unassociated)
    return images.levels(image, frame_shown(node), unassociated)


# ---------------------------------------------------------------------------------------------
# Sampling


def _wrap(i, n, extension):
    """Texel indices i (int) of a side of n under the node's extension; -1 outside for CLIP."""
    if extension == "REPEAT":
        return np.mod(i, n)
    if extension == "MIRROR":
        period = np.mod(i, 2 * n)
        return np.where(period < n, period, 2 * n - 1 - period)
    inside = (i >= 0) & (i < n)
    clamped = np.clip(i, 0, n - 1)
    return clamped if extension == "EXTEND" else np.where(inside, clamped, -1)


def _bilinear(level, uv, extension):
    h, w = level.shape[:2]
    x = uv[:, 0] * w - 0.5  # texel centres at (i + 0.5) / w, as Cycles places them
    y = uv[:, 1] * h - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None].astype(np.float32), (y - y0)[:, None].astype(np.float32)
    out = np.zeros((len(uv), level.shape[2]), np.float32)
    for dx, dy, wgt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        i, j = _wrap(x0 + dx, w, extension), _wrap(y0 + dy, h, extension)
        inside = (i >= 0) & (j >= 0)
        out += np.where(inside[:, None], wgt * level[np.maximum(j, 0), np.maximum(i, 0)], 0.0)
    return out


def sample(levels, uv, footprint, interpolation, extension):
    """The levels' RGB or RGBA (n, 3 or 4) at UVs (n, 2): Closest reads the nearest texel of the image; otherwise
    bilinear between the two mip levels about each point's footprint (its side in texels of the
    image, n), blended by where it falls between them."""
    base = levels[0]
    h, w = base.shape[:2]
    if interpolation == "Closest":
        i = _wrap(np.floor(uv[:, 0] * w).astype(np.int64), w, extension)
        j = _wrap(np.floor(uv[:, 1] * h).astype(np.int64), h, extension)
        inside = (i >= 0) & (j >= 0)
        return np.where(inside[:, None], base[np.maximum(j, 0), np.maximum(i, 0)], 0.0).astype(np.float32)
    lod = np.clip(np.log2(np.maximum(footprint, 1.0)), 0.0, len(levels) - 1)
    lo = np.floor(lod).astype(np.int64)
    out = np.zeros((len(uv), base.shape[2]), np.float32)
    for k in np.unique(lo):
        rows = lo == k
        t = (lod[rows] - k)[:, None].astype(np.float32)
        near = _bilinear(levels[k], uv[rows], extension)
        far = _bilinear(levels[min(k + 1, len(levels) - 1)], uv[rows], extension)
        out[rows] = (1 - t) * near + t * far
    return out


def sample_image(pyramids, uv, footprint, interpolation, extension):
    """sample() of an image's pyramid, or of a UDIM image's tiles ({number: levels}) as Cycles reads
    them: the tile 1001 + floor(u) + 10 floor(v) (u in [0, 10), v >= 0) at the UVs' offset into it,
    under the node's extension; a point on no tile reads Cycles' missing-image magenta.  footprint:
    each point's side in UV units (times the image's texels per unit here)."""
    if not isinstance(pyramids, dict):
        h, w = pyramids[0].shape[:2]
        return sample(pyramids, uv, footprint * np.sqrt(w * h), interpolation, extension)
    cell = np.floor(uv).astype(np.int64)
    number = np.where((cell[:, 0] >= 0) & (cell[:, 0] < 10) & (cell[:, 1] >= 0),
                      1001 + cell[:, 0] + 10 * cell[:, 1], -1)
    out = np.tile(MISSING_TILE[:next(iter(pyramids.values()))[0].shape[2]], (len(uv), 1))
    for tile, levels in pyramids.items():
        rows = number == tile
        if rows.any():
            h, w = levels[0].shape[:2]
            out[rows] = sample(levels, uv[rows] - cell[rows], footprint[rows] * np.sqrt(w * h), interpolation,
                               extension)
    return out


# What Cycles reads where an image has no tile: its missing-image colour
MISSING_TILE = np.float32([1.0, 0.0, 1.0, 1.0])


# ---------------------------------------------------------------------------------------------
# A mesh's UVs


def uv_layer(mesh, uv_map):
    """The mesh's UV map named uv_map, or with None its active render one (Cycles' default); None
    when it has no such map."""
    layers = mesh.uv_layers
    return layers.get(uv_map) if uv_map else next((l for l in layers if l.active_render), None)


def corner_uvs(mesh, layer):
    """(nl, 2) float32 UVs of a mesh's UV layer, one per face corner; SetupError naming the corner
    of a coordinate that is not finite."""
    nl = len(mesh.loops)
    uv = np.empty(nl * 2, np.float32)
    layer.uv.foreach_get("vector", uv)
    uv = uv.reshape(nl, 2)
    if not np.isfinite(uv).all():
        corner = int(np.argwhere(~np.isfinite(uv).all(axis=1))[0, 0])
        raise world.SetupError(f"UV map '{layer.name}' of mesh '{mesh.name}' has a coordinate that is not finite "
                               f"(NaN or infinite) at face corner {corner}")
    return uv


def triangle_corners(mesh):
    """(m, 3) int32: the face corners of each of the mesh's loop triangles."""
    tris = mesh.loop_triangles
    loops = np.empty(len(tris) * 3, np.int32)
    tris.foreach_get("loops", loops)
    return loops.reshape(-1, 3)


def uv_rows(mesh, uv_map, domain, corner_vert):
    """(uv, footprint, corner rows) of a mesh's UV map (None: the active render one) for its shaded
    rows: per corner -- with each corner's row (itself, or its vertex for the POINT domain) -- and
    each corner's share of UV space, the area of the UV triangles about its vertex over three (its
    side, in UV units, is the footprint's).  None when the mesh has no such UV map."""
    layer = uv_layer(mesh, uv_map)
    if layer is None:
        return None
    uv = corner_uvs(mesh, layer)
    share = vertex_shares(uv, triangle_corners(mesh), corner_vert, len(mesh.vertices))
    rows = corner_vert if domain == "POINT" else np.arange(len(uv))
    return uv, np.sqrt(share[corner_vert]).astype(np.float32), rows


def vertex_shares(uv, loops, corner_vert, n_vertices, wrap=False):
    """Each vertex's share of the 2D area of its triangles (a third of each), their corners'
    coordinates `uv` ((corners, 2)); with wrap, the first coordinate is a turn (read the short way
    round)."""
    a, b, c = uv[loops[:, 0]], uv[loops[:, 1]], uv[loops[:, 2]]
    if wrap:
        b, c = a + _turned(b - a, wrap), a + _turned(c - a, wrap)
    area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))
    return np.bincount(corner_vert[loops].ravel(), weights=np.repeat(area / 3.0, 3), minlength=n_vertices)


def _turned(d, wrap):
    """Steps d (n, 2) with their first coordinate, a turn, taken the short way round where wrap."""
    if wrap:
        d = d.copy()
        d[:, 0] = (d[:, 0] + 0.5) % 1.0 - 0.5
    return d


def data_uv_rows(mesh, uv_map, data, corner_vert):
    """uv_rows for the rows of `data` (meshes.MeshData): its vertices or corners, or, for a bake's
    texels (data.sites), the UV map at each texel's centre, each texel its own row, its footprint
    the texel's side carried into that map."""
    if data.sites is None:
        return uv_rows(mesh, uv_map, data.domain, corner_vert)
    layer = uv_layer(mesh, uv_map)
    if layer is None:
        return None
    uv = corner_uvs(mesh, layer)
    return data.sites.at(uv), data.sites.footprint_in(uv), np.arange(data.count)


def colours_at_rows(levels, source, uv, footprint, rows, n_rows):
    """The colour of each shaded row: its corners' samples of the image's pyramid (or UDIM tiles:
    pyramids()), averaged where a vertex has several (a UV seam)."""
    rgb = sample_image(levels, uv, footprint, source.node.interpolation, extension_of(source.node))
    return nodes.group_means(rgb, rows, n_rows)


def extension_of(node):
    """An image node's extension: an Image Texture's own; an Environment Texture's images repeat."""
    return getattr(node, "extension", "REPEAT")


# (object name, slot, socket) -> (what the colours were read from, the colours, the pyramid they were
# read from: held, so that its id in the key is not another's)
_colours_kept = {}


def _colours_memo(key, levels, source, got, n_rows):
    """colours_at_rows, kept while the image's pyramid, the node's settings and the UVs are the same:
    a new view samples nothing."""
    made_of = (id(levels), source.node.interpolation, extension_of(source.node), n_rows, engine.fingerprint(*got))
    held = _colours_kept.get(key)
    if held is None or held[0] != made_of:
        if len(_colours_kept) > 256:
            _colours_kept.clear()
        held = (made_of, colours_at_rows(levels, source, *got, n_rows), levels)
        _colours_kept[key] = held
    return held[1]


def _principled_slots(obj, depsgraph, find):
    """(slot, material, what find(Principled BSDF node) gives, mesh, corner vertices) for each of
    obj's material slots of the Principled model for which find's first value is not None; the
    mesh (meshes.shaded_mesh) read once, at the first."""
    mesh = corner_vert = None
    for s, slot in enumerate(obj.material_slots):
        mat = slot.material
        # a Principled BSDF mixed with other nodes is read at its unlinked values (closures.py)
        one = mat is not None and mat.wenv.model == "PRINCIPLED" and closures.is_one_principled(mat)
        node = materials.principled_node(mat) if one else None
        found = find(node) if node is not None else (None, None)
        if found[0] is None:
            continue
        if mesh is None:
            mesh = meshes.shaded_mesh(obj, depsgraph)[0]
            corner_vert = meshes.corner_vertices(mesh)
        yield s, mat, found, mesh, corner_vert


def _no_uv_map(obj, uv_map, what, instead):
    return (f"'{obj.name}' has no UV map {repr(uv_map) if uv_map else 'to render with'} for {what}: {instead}")


def _slot_rows(obj, data, s):
    """Which of data's rows belong to material slot s (the slots past the last read as the last)."""
    return np.clip(data.slots, 0, len(obj.material_slots) - 1) == s


def _textured(node):
    """What _principled_slots finds of a Principled BSDF some of whose TEXTURED_SOCKETS are linked."""
    return (node, None) if any(node.inputs[s].is_linked for s in TEXTURED_SOCKETS) else (None, None)


def _rows_evaluator(obj, depsgraph, data, mesh, corner_vert, mat, tag, notes, occlusion, progress=None):
    """An Evaluator of `mat`'s sockets at data's rows of obj (its mesh and corners): images sampled
    once per content and `tag` (what in the material reads them), and the scene's rays (occlusion:
    ambient_reader's) and obj's surface (the Bevel node) read where nodes ask."""
    return nodes.Evaluator(
        data.count, lambda uv_map: data_uv_rows(mesh, uv_map, data, corner_vert),
        lambda tex, uv, footprint, rows: _colours_memo((obj.name, data.domain) + tag + (tex.name,), pyramids(tex),
                                                       Source(tex, None), (uv, footprint, rows), data.count),
        points=row_points(obj, mesh, data.positions, data.normals, data.view,
                          lambda: true_normals(obj, mesh, corner_vert, data.domain, data.sites)),
        progress=progress, attribute=attribute_reader(mesh, corner_vert, data.domain, data.sites, notes),
        owner=(obj, mat), footprint=coordinate_footprint(mesh, corner_vert, data.domain, data.sites),
        ambient=occlusion, bevel=bevel_reader(obj, depsgraph, progress, data.sites))


def read_inputs(obj, depsgraph, data, progress=None):
    """Sets data.inputs (meshes.MeshData) for the rows of the material slots whose Principled BSDF
    takes an input of TEXTURED_SOCKETS from Image Textures through nodes wenv evaluates
    (data.textured[keyword]: those slots): Base Color as linear RGB, Roughness and Metallic as
    values (a colour's luminance).  Returns notes: a missing UV map (that slot keeps the unlinked
    value).  What a chain wenv does not evaluate is materials.principled_notes' to name.
    progress(fraction) while procedural textures are evaluated may cancel (as nodes.Evaluator's)."""
    notes = []
    occlusion = ambient_reader(obj, depsgraph, data.domain, progress)
    for s, mat, (node, _), mesh, corner_vert in _principled_slots(obj, depsgraph, _textured):
        for socket, keyword in TEXTURED_SOCKETS.items():
            sock = node.inputs[socket]
            if not sock.is_linked:
                continue
            ev = _rows_evaluator(obj, depsgraph, data, mesh, corner_vert, mat, (s,), notes, occlusion, progress)
            try:
                values = ev.colour(sock) if keyword in COLOUR_KEYWORDS else ev.value(sock)
            except nodes.MissingUV as exc:
                notes.append(_no_uv_map(obj, exc.uv_map, f"'{socket}' ('{mat.name}')",
                                        f"its {socket}'s unlinked value is used"))
                continue
            except nodes.UnreadAtRows as exc:
                _note(notes, f"'{obj.name}': '{socket}' ('{mat.name}') reads {exc}: its unlinked value is used")
                continue
            except nodes.Unsupported:
                continue  # named by materials.principled_notes, the unlinked value used
            data.reads_camera |= bool(ev.spaces & CAMERA_SPACES)
            data.reads_placement |= ev.placed
            if "GENERATED" in ev.spaces and deformed(obj):
                note = (f"'{obj.name}': '{socket}' ('{mat.name}') reads Generated coordinates on the deformed mesh "
                        "(Cycles reads them undeformed: its shape keys or deforming modifiers move the texture)")
                if note not in notes:
                    notes.append(note)
            if not np.isfinite(values).all():
                row = int(np.argwhere(~np.isfinite(values.reshape(len(values), -1)).all(axis=1))[0, 0])
                raise world.SetupError(f"Material '{mat.name}': its nodes give '{socket}' a value that is not "
                                       f"finite (NaN or infinite) at element {row} of '{obj.name}'")
            if keyword in COLOUR_KEYWORDS:
                values = at_least_zero(values, sock, f"'{obj.name}' ('{mat.name}')", notes)
            if keyword not in data.inputs:
                data.inputs[keyword] = np.zeros((data.count, 3) if keyword in COLOUR_KEYWORDS else data.count,
                                                np.float32)
                data.textured[keyword] = set()
            rows = _slot_rows(obj, data, s)
            data.inputs[keyword][rows] = values[rows]
            data.textured[keyword].add(s)
        mine = {k: a for k, a in data.inputs.items() if s in data.textured[k]}
        notes += _within_family_limits(mine, _slot_rows(obj, data, s), f"'{mat.name}'")
    return notes


def ambient_reader(obj, depsgraph, domain, progress=None):
    """An Evaluator's ambient() for obj's rows (ambient.shares against the scene's meshes): the node's
    Samples rays a point, at least VERTEX_RAYS at vertices or corners and TEXEL_RAYS at a bake's texels.
    The meshes are read once per reader (one per object and pass), however many sockets read the node."""
    least = ambient.TEXEL_RAYS if domain == "TEXEL" else ambient.VERTEX_RAYS
    read_meshes = {}

    def read(positions, normals, distance, inside, only_local, samples):
        rays = max(least, samples)
        if only_local not in read_meshes:
            read_meshes[only_local] = ambient.blockers(depsgraph, obj, only_local)
        return ambient.shares((obj.name, domain, distance, inside, only_local, rays), positions, normals, distance,
                              inside, read_meshes[only_local], rays, progress)
    return read


def bevel_reader(obj, depsgraph, progress=None, sites=None):
    """An Evaluator's bevel() for obj's rows (bevel.normals: its own surface about each row; a bake's
    texels at `sites`)."""
    return lambda positions, normals, radius: bevel.normals(obj, depsgraph, positions, normals, radius, progress,
                                                            sites)


# The inputs read at their mean first when more vary smoothly than a vertex may mix (the core's
# wenv.Principled.PER_VERTEX): those whose detail shows least first, Roughness last.
SMOOTH_ORDER = ("roughness", "specular_ior_level", "coat_roughness", "coat_weight", "sheen_roughness",
                "sheen_weight", "specular_tint", "sheen_tint")


def _at_most_distinct(rows, limit):
    """Whether `rows` (m, k) hold at most `limit` distinct rows: a pass per distinct row found, not a
    sort (a bake's million texels)."""
    rest = rows
    for _ in range(limit):
        rest = rest[np.any(rest != rest[0], axis=1)]
        if not len(rest):
            return True
    return False


def _within_family_limits(inputs, rows, where):
    """Keeps inputs ({core keyword: array over a mesh's rows}, read at `rows`) within what the core
    shades per vertex: values of a few distinct materials, or at most PER_VERTEX["smooth_channels"]
    channels varying smoothly.  Past that, inputs of SMOOTH_ORDER from its end are set to their mean
    over the rows (in place), each named."""
    limits = engine.PER_VERTEX_LIMITS
    mine = [k for k in SMOOTH_ORDER if k in inputs]
    count = int(rows.sum())
    if not mine or not count:
        return []
    columns = np.column_stack([inputs[k][rows].reshape(count, -1) for k in mine])
    if _at_most_distinct(columns, limits["exact_materials"]):
        return []
    notes = []
    varying = {k: int(np.count_nonzero(np.ptp(inputs[k][rows].reshape(count, -1), axis=0))) for k in mine}
    for k in reversed(mine):
        if sum(varying.values()) <= limits["smooth_channels"]:
            break
        if varying[k]:
            inputs[k][rows] = inputs[k][rows].mean(axis=0)
            varying[k] = 0
            socket = next(sock for sock, name in TEXTURED_SOCKETS.items() if name == k)
            notes.append(f"'{socket}' ({where}) is read at its mean: more inputs vary smoothly per vertex than "
                         f"wenv mixes at once (at most {limits['smooth_channels']} values a vertex)")
    return notes


# ---------------------------------------------------------------------------------------------
# Normal maps, at the vertices


# The Normal Map node's spaces, as Cycles' svm_node_normal_map reads them
NORMAL_MAP_SPACES = ("TANGENT", "OBJECT", "WORLD", "BLENDER_OBJECT", "BLENDER_WORLD")


# How the panel's note on a normal map or Bump node read at the vertices ends (a bake reads them per texel)
AT_VERTICES = "is read at the vertices: detail finer than the mesh is lost"


class NormalChain:
    """What bends a Principled BSDF's Normal, as wenv reads it: a Normal Map node (`map`, a Source,
    with `map_strength`) and/or a Bump node over it (`bump`, the node, with its Strength and
    Distance, Distance negated when inverted: unlinked, or the same at every point,
    nodes.constant_value); and/or a Bevel node over them (`bevel`, with its unlinked Radius, or its
    Radius socket where linked: read at the rows)."""

    __slots__ = ("map", "map_strength", "bump", "bump_strength", "distance", "bevel", "bevel_radius")

    def __init__(self):
        self.map = self.bump = self.bevel = None
        self.map_strength = self.bump_strength = self.distance = self.bevel_radius = 0.0

    def note(self):
        what = " over ".join(w for w, on in (("a Bevel node", self.bevel), ("a Bump node", self.bump),
                                             ("a normal map", self.map)) if on is not None)
        return f"'Normal' from {what} {AT_VERTICES}"


def _normal_map(node, chain):
    """Reads a Normal Map node into chain; None, or why it is not read."""
    if node.space not in NORMAL_MAP_SPACES:
        return f"'{node.name}' in {node.space.lower().replace('_', ' ')} space, which wenv does not read yet"
    strength = nodes.constant_value(node.inputs["Strength"])
    if strength is None:
        return f"'{node.name}', whose Strength is linked to values that vary from point to point"
    tex = world.source_node(node.inputs["Color"])
    if tex is None or tex.bl_idname != "ShaderNodeTexImage" or tex.image is None or tex.projection != "FLAT":
        return f"'{node.name}', whose Color is not an Image Texture wenv reads"
    if world.source_node(tex.inputs["Vector"]) is not None or tex.image.source not in nodes.IMAGE_SOURCES:
        return f"'{tex.name}', whose Vector or image source wenv does not read yet"
    chain.map = Source(tex, node.uv_map or None, node.space)
    chain.map_strength = max(strength, 0.0)
    return None


def _bump(node, chain):
    """Reads a Bump node (and a Normal Map feeding its Normal) into chain; None, or why not."""
    strength, distance = (nodes.constant_value(node.inputs[name]) for name in ("Strength", "Distance"))
    if strength is None or distance is None:
        return (f"'{node.name}', whose {'Strength' if strength is None else 'Distance'} is linked to values that "
                "vary from point to point")
    if node.inputs["Height"].is_linked:
        read, why = nodes.check(node.inputs["Height"])
        if read is None:
            return f"'{node.name}', whose Height comes from {why}"
    below = node.inputs["Normal"]
    if below.is_linked:
        inner = world.source_node(below)
        if inner is None or inner.bl_idname != "ShaderNodeNormalMap":
            return f"'{node.name}', whose Normal is not a Normal Map node"
        why = _normal_map(inner, chain)
        if why is not None:
            return why
    chain.bump = node
    chain.bump_strength = max(strength, 0.0)
    chain.distance = distance * (-1.0 if node.invert else 1.0)
    return None


def _bevel(node, chain):
    """Reads a Bevel node (and a Normal Map or Bump node feeding its Normal) into chain; None, or why
    not."""
    if node.inputs["Normal"].is_linked:
        inner = world.source_node(node.inputs["Normal"])
        kind = inner.bl_idname if inner is not None else None
        if kind not in ("ShaderNodeNormalMap", "ShaderNodeBump"):
            return f"'{node.name}', whose Normal is not a Normal Map or Bump node"
        why = (_normal_map if kind == "ShaderNodeNormalMap" else _bump)(inner, chain)
        if why is not None:
            return why
    radius = node.inputs["Radius"]
    if radius.is_linked:
        read, why = nodes.check(radius)
        if read is None:
            return f"'{node.name}', whose Radius comes from {why}"
        chain.bevel_radius = radius
    else:
        chain.bevel_radius = max(float(radius.default_value), 0.0)
    chain.bevel = node
    return None


def reads_per_point(mat):
    """Whether read_inputs, read_term_weights or read_shading_normals read something of `mat` at each
    row: a linked input of its lone Principled BSDF that wenv reads, a Normal from a normal map, bump
    or bevel, or a mixture's textured factor, weight or input."""
    if mat is None or mat.wenv.model != "PRINCIPLED" or mat.node_tree is None:
        return False
    if closures.is_one_principled(mat):
        node = materials.principled_node(mat)
        return node is not None and (_textured(node)[0] is not None or bends_normals(mat))
    found, _ = closures.terms(mat)
    return bool(found) and not closures.one_principled(found) and any(
        t.factors or t.weight_socket is not None or t.linked for t in found)


def normal_source(principled):
    """(NormalChain, None) when a Principled BSDF's Normal comes from a Normal Map node (any of
    NORMAL_MAP_SPACES, its Color an Image Texture), a Bump node (its Height from nodes wenv
    evaluates, its Normal unlinked or such a Normal Map) or a Bevel node (its Normal unlinked, its
    Radius from nodes wenv evaluates); else (None, reason) with why it is not read, reason None when Normal is unlinked."""
    sock = principled.inputs["Normal"]
    if not sock.is_linked:
        return None, None
    node = world.source_node(sock)
    chain = NormalChain()
    if node is None:
        why = "a muted link"
    elif node.bl_idname == "ShaderNodeNormalMap":
        why = _normal_map(node, chain)
    elif node.bl_idname == "ShaderNodeBump":
        why = _bump(node, chain)
    elif node.bl_idname == "ShaderNodeBevel":
        why = _bevel(node, chain)
    else:
        why = f"'{node.name}', a node wenv does not evaluate yet"
    return (chain, None) if why is None else (None, why)


def _unit_rows(v):
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(length > 1e-20, v / np.maximum(length, 1e-20), 0.0).astype(np.float32)


def _mapped_normals(mesh, corner_vert, source, strength, object_n, normal, to_world, sites=None):
    """The normal a normal map gives at each corner, or with `sites` at each baked texel (world
    space, blended towards the mesh's `normal` by strength; object_n the mesh's in object space, at
    the same points), or None without its UV map.  At a texel the tangent frame is the corners'
    interpolated, as Cycles interpolates the tangent attribute."""
    got = (uv_rows(mesh, source.uv_map, "CORNER", corner_vert) if sites is None
           else data_uv_rows(mesh, source.uv_map, _SitesOnly(sites), corner_vert))
    if got is None:
        return None
    colour = sample_image(pyramids(source.node), got[0], got[1], source.node.interpolation,
                          source.node.extension)[:, :3]
    c = 2.0 * colour - 1.0
    space = source.space
    if space == "TANGENT":
        tangent, sign = corner_tangents(mesh, uv_layer(mesh, source.uv_map), corner_vert)
        if sites is not None:
            tangent, sign = sites.at(tangent), np.where(sites.at(sign) < 0.0, -1.0, 1.0).astype(np.float32)
        bitangent = sign[:, None] * np.cross(object_n, tangent)
        mapped = _unit_rows(c[:, :1] * tangent + c[:, 1:2] * bitangent + c[:, 2:3] * object_n)
    else:
        if space.startswith("BLENDER_"):  # Blender's own convention: Y and Z flipped
            c = c * np.float32([1.0, -1.0, -1.0])
        mapped = _unit_rows(c)
    if space not in ("WORLD", "BLENDER_WORLD"):
        mapped = _unit_rows(mapped @ to_world)
    # blended in the world towards the mesh's normal by Strength, as Cycles blends them
    return mapped if strength == 1.0 else _unit_rows(normal + (mapped - normal) * strength)


def corner_tangents(mesh, layer, corner_vert):
    """The UV `layer`'s MikkTSpace tangents ((nl, 3) float32, object space) and bitangent signs ((nl,)
    float32, +-1) at each face corner, as Cycles makes them for a normal map and the Tangent node.
    Cycles computes them over the mesh's loop triangles; Blender's calc_tangents over its faces (a
    quad whole, up to 0.14 away from Cycles' on a curved grid, and no face of more corners).  So
    they are read from a copy made of the loop triangles, each corner then the mean of its
    triangles'.  Kept while the mesh's points, corners, UVs and normals are the same."""
    nl = len(mesh.loops)
    normals = np.empty(nl * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    uv = corner_uvs(mesh, layer)
    made_of = engine.fingerprint(co, corner_vert, uv, normals)
    held = _tangents_kept.get((mesh.name, layer.name))
    if held is None or held[0] != made_of:
        if len(_tangents_kept) > 16:
            _tangents_kept.clear()
        held = (made_of, _triangle_tangents(mesh, co, corner_vert, uv, normals.reshape(nl, 3)))
        _tangents_kept[(mesh.name, layer.name)] = held
    return held[1]


# (mesh name, UV map) -> (what its tangents were made of, (tangents, signs))
_tangents_kept = {}


def _triangle_tangents(mesh, co, corner_vert, uv, normals):
    """corner_tangents made by Blender over a copy of the mesh's loop triangles."""
    import bpy

    nl = len(mesh.loops)
    tris = triangle_corners(mesh).ravel()
    copy = bpy.data.meshes.new(".wenv tangents")  # removed before returning: nothing the file keeps
    try:
        copy.vertices.add(len(mesh.vertices))
        copy.vertices.foreach_set("co", co)
        copy.loops.add(len(tris))
        copy.attributes[".corner_vert"].data.foreach_set("value", corner_vert[tris])
        copy.polygons.add(len(tris) // 3)
        copy.polygons.foreach_set("loop_start", np.arange(0, len(tris), 3, dtype=np.int32))
        copy.update(calc_edges=True)
        copy.uv_layers.new(name="UVMap").uv.foreach_set("vector", uv[tris].ravel())
        # the mesh's own normals (a triangle's normals are not its face's), as Cycles reads them
        vertex_normals = None
        if mesh.normals_domain == "POINT":
            vertex_normals = np.empty(len(mesh.vertices) * 3, np.float32)
            mesh.vertex_normals.foreach_get("vector", vertex_normals)
            vertex_normals = vertex_normals.reshape(-1, 3)
        compat.set_corner_normals(copy, normals[tris], vertex_normals)
        copy.calc_tangents(uvmap="UVMap")
        tangent = np.empty(len(tris) * 3, np.float32)
        sign = np.empty(len(tris), np.float32)
        copy.loops.foreach_get("tangent", tangent)
        copy.loops.foreach_get("bitangent_sign", sign)
    finally:
        bpy.data.meshes.remove(copy)
    count = np.bincount(tris, minlength=nl).astype(np.float64)
    mean = np.stack([np.bincount(tris, weights=tangent[k::3], minlength=nl) for k in range(3)], axis=1)
    mean /= np.maximum(count, 1.0)[:, None]
    signs = np.bincount(tris, weights=sign, minlength=nl)
    return mean.astype(np.float32), np.where(signs < 0.0, -1.0, 1.0).astype(np.float32)


class _SitesOnly:
    """What data_uv_rows reads of a bake's rows: its sites and their count."""

    __slots__ = ("sites", "count")

    def __init__(self, sites):
        self.sites = sites
        self.count = sites.count


def triangle_gradients(p0, p1, p2, h):
    """Per triangle, the world-space gradient of a quantity linear over it with values h (m, 3) at
    its corners p0, p1, p2 (m, 3 each), and the triangle's area (0 for a degenerate one, whose
    gradient is 0)."""
    n = np.cross(p1 - p0, p2 - p0)
    twice_area = np.linalg.norm(n, axis=1)
    ok = twice_area > 1e-30
    unit = n / np.where(ok, twice_area, 1.0)[:, None]
    # the gradient of a corner's barycentric weight is the unit normal x its opposite edge / (2 area)
    grad = (h[:, :1] * np.cross(unit, p2 - p1) + h[:, 1:2] * np.cross(unit, p0 - p2) +
            h[:, 2:3] * np.cross(unit, p1 - p0)) / np.where(ok, twice_area, 1.0)[:, None]
    return grad, np.where(ok, 0.5 * twice_area, 0.0)


def height_gradients(points, corner_vert, tri_loops, height, n_vertices):
    """Each vertex's gradient of a height given at the face corners: over each triangle the height
    is linear between its corners' values (so a UV seam's two sides each count their own), and a
    vertex takes its triangles' gradients weighted by their areas."""
    v = corner_vert[tri_loops]
    grad, weight = triangle_gradients(points[v[:, 0]], points[v[:, 1]], points[v[:, 2]],
                                      height[tri_loops].astype(np.float64))
    total = np.zeros((n_vertices, 3))
    area = np.bincount(v.ravel(), weights=np.repeat(weight, 3), minlength=n_vertices)
    for k in range(3):
        total[:, k] = np.bincount(v.ravel(), weights=np.repeat(weight * grad[:, k], 3), minlength=n_vertices)
    return total / np.maximum(area, 1e-300)[:, None]


def bumped_normals(normal, gradient, distance, strength):
    """Cycles' Bump node at a point whose height has the world-space `gradient`: the normal tilted
    against the height's gradient along the surface, normalize(N - Distance x grad), then blended
    towards N by Strength (Cycles' surface gradient over its determinant is that gradient)."""
    along = gradient - np.sum(gradient * normal, axis=1, keepdims=True) * normal
    out = _unit_rows(normal - distance * along)
    return out if strength == 1.0 else _unit_rows(strength * out + (1.0 - strength) * normal)


def world_points(mesh, m):
    """The mesh's vertices in the world (float64), `m` the object's matrix_world."""
    nv = len(mesh.vertices)
    co = np.empty(nv * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    m = np.array(m, np.float64)
    return co.reshape(nv, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]


# Modifiers that move a mesh's vertices (Generated coordinates stay where the undeformed mesh has them)
DEFORMING_MODIFIERS = {"ARMATURE", "CAST", "CURVE", "DISPLACE", "HOOK", "LAPLACIANDEFORM", "LATTICE", "MESH_DEFORM",
                       "SHRINKWRAP", "SIMPLE_DEFORM", "SMOOTH", "CORRECTIVE_SMOOTH", "LAPLACIANSMOOTH",
                       "SURFACE_DEFORM", "WARP", "WAVE", "MESH_CACHE", "MESH_SEQUENCE_CACHE", "NODES"}


def deformed(obj):
    """Whether shape keys or a modifier move obj's mesh from where its Generated coordinates lie."""
    keys = getattr(obj.data, "shape_keys", None)
    return (keys is not None and len(keys.key_blocks) > 1) or any(
        m.type in DEFORMING_MODIFIERS and m.show_render for m in obj.modifiers)


def row_points(obj, mesh, positions, normals, view=None, face_normals=None):
    """An Evaluator's points(space, other) for rows at world `positions` ((n, 3)) with world
    `normals`: their coordinates in `other`'s object space ('OBJECT'; obj's own without one) or in
    the mesh's texture space ('GENERATED', as Cycles maps it: the texture space's box onto the unit
    cube), in the view's camera space ('CAMERA') or frame ('WINDOW'; None without them), the
    positions themselves ('WORLD'), the unit normals ('NORMAL', or in object space:
    'OBJECT_NORMAL'), the faces' normals (`face_normals()`, 'TRUE_NORMAL'), the unit directions
    towards the viewer of `view` ('INCOMING'; None without one) or the view itself ('VIEW')."""
    def points(space, other=None):
        if space == "WORLD":
            return np.ascontiguousarray(positions, np.float32)
        if space == "TRUE_NORMAL":
            return face_normals()
        if space == "VIEW":  # (the view itself)
            return view
        if space in ("CAMERA", "WINDOW"):  # (None where the view has no such matrix)
            m = None if view is None else view.camera if space == "CAMERA" else view.window
            if m is None:
                return None
            p = np.asarray(positions, np.float64) @ m[:3, :3].T + m[:3, 3]
            if space == "CAMERA":
                return p.astype(np.float32)
            w = (np.asarray(positions, np.float64) @ m[3, :3] + m[3, 3])[:, None]
            # as Cycles' transform_perspective: 0 where the point lies in the eye's plane
            ndc = np.where(w != 0.0, p[:, :2] / np.where(w != 0.0, w, 1.0) * 0.5 + 0.5, 0.0)
            return np.column_stack([ndc, np.zeros(len(p))]).astype(np.float32)
        if space == "INCOMING":
            if view is None:
                return None
            if view.perspective:
                return _unit_rows(np.array(view.eye, np.float64) - np.asarray(positions, np.float64)).astype(np.float32)
            return np.tile(np.asarray(view.direction, np.float32), (len(positions), 1))
        if space == "NORMAL":
            return _unit_rows(np.asarray(normals, np.float64)).astype(np.float32)
        if space == "OBJECT_NORMAL":  # (a normal back into object space: times the object's matrix)
            m = np.array(obj.matrix_world, np.float64)
            return _unit_rows(np.asarray(normals, np.float64) @ m[:3, :3]).astype(np.float32)
        inverse = np.array((other or obj).matrix_world.inverted_safe(), np.float64)
        local = positions.astype(np.float64) @ inverse[:3, :3].T + inverse[:3, 3]
        if space == "GENERATED":
            loc, size = np.array(mesh.texspace_location, np.float64), np.array(mesh.texspace_size, np.float64)
            scale = np.where(size != 0.0, 0.5 / np.where(size != 0.0, size, 1.0), 0.0)
            local = local * scale - (loc * scale - 0.5)
        return local.astype(np.float32)
    return points


def triangle_normals(obj, positions, triangles):
    """Each triangle's normal in the world times twice its area ((m, 3) float64, `positions` the
    world's, `triangles` indices into them), on its winding's side as Cycles' Ng: a mirrored
    object's turned back."""
    p = positions
    cross = np.cross(p[triangles[:, 1]] - p[triangles[:, 0]], p[triangles[:, 2]] - p[triangles[:, 0]])
    return -cross if np.linalg.det(np.array(obj.matrix_world, np.float64)[:3, :3]) < 0.0 else cross


def true_normals(obj, mesh, corner_vert, domain, sites=None):
    """The faces' own normal at each shaded row (world, unit), as Cycles' Ng: a texel's (`sites`)
    triangle's, a face corner's face's, and at a vertex, which has no one face, its faces' mean
    weighted by their areas.  The winding's side, as the Normal's (a back face's is not turned), and
    a mirrored object's turned back as Cycles turns it."""
    tris = triangle_corners(mesh)
    cross = triangle_normals(obj, world_points(mesh, obj.matrix_world), corner_vert[tris])

    def summed(index, weights, count):
        return np.stack([np.bincount(index, weights=weights[:, k], minlength=count) for k in range(3)], axis=1)
    if domain == "TEXEL":
        return _unit_rows(cross[sites.triangle])
    face = np.empty(len(tris), np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", face)
    starts = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_start", starts)
    corner_face = np.repeat(np.arange(len(starts)), np.diff(starts, append=len(corner_vert)))
    faces = summed(face, cross, len(starts))  # each face's normal times twice its area
    if domain == "POINT":  # each face's, whole, to each of its vertices
        return _unit_rows(summed(corner_vert, faces[corner_face], len(mesh.vertices)))
    return _unit_rows(faces)[corner_face]


# A mesh attribute's data type -> (its values' property, width, dtype read, Cycles' type of it)
ATTRIBUTE_TYPES = {"FLOAT": ("value", 1, np.float32, "FLOAT"), "INT": ("value", 1, np.int32, "FLOAT"),
                   "INT8": ("value", 1, np.int32, "FLOAT"), "BOOLEAN": ("value", 1, bool, "FLOAT"),
                   "FLOAT2": ("vector", 2, np.float32, "FLOAT2"), "INT32_2D": ("value", 2, np.int32, "FLOAT2"),
                   "FLOAT_VECTOR": ("vector", 3, np.float32, "FLOAT3"),
                   # colours in scene linear (a byte colour's sRGB decoded, its alpha not), as Cycles keeps them
                   "FLOAT_COLOR": ("color", 4, np.float32, "RGBA"), "BYTE_COLOR": ("color", 4, np.float32, "RGBA"),
                   "QUATERNION": ("value", 4, np.float32, "FLOAT4")}


def corner_attribute(mesh, attr, corner_vert):
    """A mesh attribute's values at each face corner ((nl, k) float32), as Cycles spreads them over
    the triangles: a point's at its corners, a face's at all of its, an edge's averaged at its two
    vertices."""
    prop, width, dtype, _ = ATTRIBUTE_TYPES[attr.data_type]
    values = np.empty(len(attr.data) * width, dtype)
    attr.data.foreach_get(prop, values)
    values = values.reshape(-1, width).astype(np.float32)
    if attr.domain == "POINT":
        return values[corner_vert]
    if attr.domain == "CORNER":
        return values
    if attr.domain == "FACE":
        starts = np.empty(len(mesh.polygons), np.int32)
        mesh.polygons.foreach_get("loop_start", starts)
        return values[np.repeat(np.arange(len(starts)), np.diff(starts, append=len(corner_vert)))]
    ends = np.empty(len(mesh.edges) * 2, np.int32)  # 'EDGE'
    mesh.edges.foreach_get("vertices", ends)
    return nodes.group_means(np.repeat(values, 2, axis=0), ends, len(mesh.vertices))[corner_vert]


def welded_vertices(co):
    """Each vertex's representative among the vertices at (nearly) its position, as Cycles welds
    them for Pointiness: in the order of their coordinates' float sums (ties: the higher index
    first), a vertex joins the first later one whose sum is within 3 FLT_EPSILON and whose squared
    distance is under FLT_EPSILON, and chains of them end at one."""
    eps = np.float32(np.finfo(np.float32).eps)
    out = np.arange(len(co))
    # Only a vertex with another closer than sqrt(eps) on every axis can join or be joined: such a
    # pair shares a cell of side 1e-3 in one of the eight grids shifted by half a cell per axis.
    # The scan below skips the others, which changes no join (they would match nothing).
    near = np.zeros(len(co), bool)
    for shift in np.ndindex(2, 2, 2):
        cell = np.floor(co.astype(np.float64) / 1e-3 + 0.5 * np.array(shift)).astype(np.int64)
        order = np.lexsort(cell.T)
        same = np.flatnonzero((cell[order[1:]] == cell[order[:-1]]).all(axis=1))
        near[order[same]] = near[order[same + 1]] = True
    some = np.flatnonzero(near)
    if not len(some):
        return out
    c = co[some]
    sums = (c[:, 0] + c[:, 1]) + c[:, 2]  # (float32, summed as Cycles sums them)
    order = np.lexsort((-some, sums))
    s, p = sums[order], c[order]
    joined = np.full(len(c), -1, np.int64)  # in sorted positions
    open_ = np.arange(len(c) - 1)  # those whose window may still hold another
    k = 1
    while len(open_):
        open_ = open_[s[open_ + k] - s[open_] <= 3 * eps]
        d = p[open_ + k] - p[open_]
        hit = np.einsum("ij,ij->i", d, d) < eps
        joined[open_[hit]] = open_[hit] + k
        open_ = open_[~hit & (open_ + k + 1 < len(c))]
        k += 1
    root = np.where(joined >= 0, joined, np.arange(len(c)))
    while True:  # follow the chains to their ends
        nxt = root[root]
        if np.array_equal(nxt, root):
            break
        root = nxt
    out[some[order]] = some[order[root]]
    return out


def pointiness(mesh):
    """The Geometry node's Pointiness at each vertex, as Cycles' attr_create_pointiness makes it:
    the angle between the (welded) vertex normal and the mean direction of its edges, over pi, then
    averaged with its neighbours' once.  Kept while the mesh's positions, edges and normals are the
    same."""
    nv = len(mesh.vertices)
    co = np.empty(nv * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(nv, 3)
    ends = np.empty(len(mesh.edges) * 2, np.int32)
    mesh.edges.foreach_get("vertices", ends)
    normals = np.empty(nv * 3, np.float32)
    mesh.vertex_normals.foreach_get("vector", normals)
    normals = normals.reshape(nv, 3)
    return _kept(_pointiness_kept, mesh.name, engine.fingerprint(co, ends, normals),
                 lambda: _pointiness(co, ends, normals))


def _pointiness(co, ends, normals):
    nv = len(co)
    root = welded_vertices(co)
    n = np.stack([np.bincount(root, normals[:, c], nv) for c in range(3)], axis=1)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    edges = np.sort(root[ends.reshape(-1, 2)], axis=1)
    edges = edges[edges[:, 0] != edges[:, 1]]  # (a collapsed edge has no direction)
    pair = np.unique(edges[:, 0] * np.int64(nv) + edges[:, 1])  # each welded edge once
    v0, v1 = pair // nv, pair % nv
    direction = (co[v1] - co[v0]).astype(np.float64)
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-300)
    accum = np.stack([np.bincount(v0, direction[:, c], nv) - np.bincount(v1, direction[:, c], nv)
                      for c in range(3)], axis=1)
    count = (np.bincount(v0, minlength=nv) + np.bincount(v1, minlength=nv)).astype(np.float64)
    cosine = np.einsum("ij,ij->i", n, accum) / np.maximum(count, 1.0)
    raw = np.where(count > 0, np.arccos(np.clip(cosine, -1.0, 1.0)) / np.pi, 0.0)
    raw[root != np.arange(nv)] = 0.0  # (a welded duplicate takes its representative's, below)
    blurred = (raw + np.bincount(v0, raw[v1], nv) + np.bincount(v1, raw[v0], nv)) / (count + 1.0)
    return blurred[root].astype(np.float32)


# mesh name -> (what its value was made of, the value): Pointiness and Random Per Island, made again
# only when what they are made of changes
_pointiness_kept, _islands_kept = {}, {}


def _kept(store, name, key, make):
    """make()'s value for the mesh `name`, kept in `store` while `key` is the same (16 meshes at most)."""
    held = store.get(name)
    if held is None or held[0] != key:
        if len(store) > 16:
            store.clear()
        held = store[name] = (key, make())
    return held[1]


def island_random(mesh):
    """The Geometry node's Random Per Island at each vertex, as Cycles makes it: the vertices joined
    along the edges, in the edges' order, by Cycles' disjoint set (union by rank, the first edge
    end's root kept on a tie), and each island's root hashed (hash_uint_to_float).  Kept while the
    edges are the same."""
    ends = np.empty(len(mesh.edges) * 2, np.int32)
    mesh.edges.foreach_get("vertices", ends)
    nv = len(mesh.vertices)
    return _kept(_islands_kept, mesh.name, engine.fingerprint(ends, np.int64([nv])), lambda: _island_random(ends, nv))


def _island_random(ends, nv):
    parents, ranks = list(range(nv)), [0] * nv

    def find(x):
        root = x
        while parents[root] != root:
            root = parents[root]
        while parents[x] != root:
            parents[x], x = root, parents[x]
        return root
    for a, b in ends.reshape(-1, 2).tolist():  # (the disjoint set's order is what picks each root)
        ra, rb = find(a), find(b)
        if ra == rb:
            continue
        if ranks[ra] < ranks[rb]:
            ra, rb = rb, ra
        parents[rb] = ra
        if ranks[ra] == ranks[rb]:
            ranks[ra] += 1
    roots = np.array([find(v) for v in range(nv)], np.int64)
    return _hash_uint(roots).astype(np.float32) * np.float32(2.0 ** -32)  # (Cycles' uint_to_float_incl)


def _hash_uint(k):
    """Cycles' hash_uint (lookup3 of one word) of each of k (int64 holding uint32)."""
    def rot(x, r):
        return ((x << np.uint64(r)) | (x >> np.uint64(32 - r))) & np.uint64(0xFFFFFFFF)
    start = np.uint64((0xDEADBEEF + (1 << 2) + 13) & 0xFFFFFFFF)
    words = [(k.astype(np.uint64) + start) & np.uint64(0xFFFFFFFF), np.full(len(k), start), np.full(len(k), start)]
    for x, y, r in ((2, 1, 14), (0, 2, 11), (1, 0, 25), (2, 1, 16), (0, 2, 4), (1, 0, 14), (2, 1, 24)):
        words[x] = ((words[x] ^ words[y]) - rot(words[y], r)) & np.uint64(0xFFFFFFFF)
    return words[2]


def attribute_reader(mesh, corner_vert, domain, sites=None, notes=None):
    """An Evaluator's attribute(name, colour) for rows of `domain` ('POINT': the vertices, each the
    mean of its corners' values where they differ; 'CORNER': the face corners) or, with `sites`, a
    bake's texels (linear over each triangle, as Cycles interpolates): (values (rows, k) float32,
    Cycles' type), or (None, None) where the mesh has no such attribute, which Cycles reads as 0.  An
    empty name with `colour` is the mesh's default colour attribute (Cycles' render colour).  Reading
    otherwise than Cycles appends to `notes`."""
    def read(name, colour):
        if name is nodes.POINTINESS:
            return _to_rows(pointiness(mesh)[corner_vert, None], "FLOAT")
        if name is nodes.PARAMETRIC:  # at a texel, Cycles' (1 - u - v, u, 0) of its triangle; none elsewhere
            if sites is None:
                return None, None
            w = sites.weights  # (u weighs the loop triangle's second corner)
            return np.column_stack([w[:, 0], w[:, 1], np.zeros(len(w))]).astype(np.float32), "FLOAT3"
        if name is nodes.RANDOM_PER_ISLAND:  # (one value a triangle: not interpolated, as Cycles keeps it)
            values = island_random(mesh)[corner_vert, None]
            return (values[sites.corners[:, 0]], "FLOAT") if sites is not None else _to_rows(values, "FLOAT")
        if isinstance(name, nodes.UVTangent):
            layer = uv_layer(mesh, name.uv_map)
            return (None, None) if layer is None else _to_rows(corner_tangents(mesh, layer, corner_vert)[0], "FLOAT3")
        if colour and not name:
            name = mesh.color_attributes.default_color_name
        attr = mesh.attributes.get(name) if name else None
        if attr is not None and name == meshes.ATTRIBUTE:
            _note(notes, f"'{name}' is wenv's own shading: read as no attribute (0)")
            attr = None
        if attr is not None and attr.data_type not in ATTRIBUTE_TYPES:
            _note(notes, f"'{name}' holds {attr.data_type.lower()} values, which wenv does not read: read as 0")
            attr = None
        if attr is None:
            return None, None
        return _to_rows(corner_attribute(mesh, attr, corner_vert), ATTRIBUTE_TYPES[attr.data_type][3])

    def _to_rows(corners, kind):
        if sites is not None:
            return sites.at(corners), kind
        if domain == "CORNER":
            return corners, kind
        return nodes.group_means(corners, corner_vert, len(mesh.vertices)), kind
    return read


def _note(notes, note):
    if notes is not None and note not in notes:
        notes.append(note)


def coordinate_footprint(mesh, corner_vert, domain, sites=None):
    """An Evaluator's footprint(coords): each row's side in 2D coordinates given at its rows (an
    Image Texture read through Generated or Object coordinates), as uv_rows measures a UV map's: the
    area of the coordinates' triangles about each vertex over three; at a bake's texels (`sites`),
    from the coordinates of the next texels along the image's rows and columns (the smaller of the
    steps either way, so that a step across an island's edge is not read).  With wrap, the first
    coordinate is an angle's turn (a sphere's or tube's u): steps are read the short way round."""
    if sites is not None:
        def at_texels(co, wrap=False):
            where = np.full(sites.width * sites.height, -1, np.int64)
            where[sites.texels] = np.arange(sites.count)
            steps = []
            for step, edge in ((1, sites.texels % sites.width), (sites.width, sites.texels // sites.width)):
                last = sites.width - 1 if step == 1 else sites.height - 1
                ahead = np.where(edge < last, where[np.minimum(sites.texels + step, len(where) - 1)], -1)
                behind = np.where(edge > 0, where[np.maximum(sites.texels - step, 0)], -1)
                d_ahead = np.where((ahead >= 0)[:, None], _turned(co[np.maximum(ahead, 0)] - co, wrap), np.inf)
                d_behind = np.where((behind >= 0)[:, None], _turned(co - co[np.maximum(behind, 0)], wrap), np.inf)
                pick = np.linalg.norm(d_ahead, axis=1) <= np.linalg.norm(d_behind, axis=1)
                steps.append(np.where(pick[:, None], d_ahead, d_behind))
            (du, dv) = steps
            area = np.abs(du[:, 0] * dv[:, 1] - du[:, 1] * dv[:, 0])
            return np.where(np.isfinite(area), np.sqrt(np.where(np.isfinite(area), area, 0.0)), 0.0).astype(np.float32)
        return at_texels
    def at_rows(co, wrap=False):  # (the triangles read only when an image is read so: not at every plan)
        uv = co[corner_vert] if domain == "POINT" else co
        side = np.sqrt(vertex_shares(uv, triangle_corners(mesh), corner_vert, len(mesh.vertices), wrap))
        side = side.astype(np.float32)
        return side if domain == "POINT" else side[corner_vert]
    return at_rows


def _height_reader(obj, s, mesh, corner_vert, where, count, progress=None, notes=None):
    """An Evaluator of a Bump node's Height at `where`'s points: the face corners (where None) or
    a bake's texel sites."""
    rows = ((lambda uv_map: uv_rows(mesh, uv_map, "CORNER", corner_vert)) if where is None else
            (lambda uv_map: data_uv_rows(mesh, uv_map, _SitesOnly(where), corner_vert)))
    tag = ("height", "CORNER") if where is None else ("height", "TEXEL", where.shift)

    def points(space, other=None):
        corners = world_points(mesh, obj.matrix_world)[corner_vert]
        normals = np.empty(len(corner_vert) * 3, np.float32)
        mesh.corner_normals.foreach_get("vector", normals)
        normals = normals.reshape(-1, 3) @ np.array(obj.matrix_world.to_3x3().inverted_safe(), np.float32)
        if where is not None:
            corners, normals = where.at(corners), where.at(normals)
        return row_points(obj, mesh, corners, normals,
                          face_normals=lambda: true_normals(obj, mesh, corner_vert,
                                                            "CORNER" if where is None else "TEXEL", where))(space, other)
    return nodes.Evaluator(count, rows,
                           lambda tex, uv, footprint, rows_: _colours_memo((obj.name, s) + tag + (tex.name,),
                                                                           pyramids(tex), Source(tex, None),
                                                                           (uv, footprint, rows_), count),
                           points=points, progress=progress,
                           attribute=attribute_reader(mesh, corner_vert, "CORNER", where, notes),
                           owner=(obj, obj.material_slots[s].material),
                           footprint=coordinate_footprint(mesh, corner_vert, "CORNER", where))


def _bump_gradients(obj, s, mat, chain, mesh, corner_vert, m, sites, notes, progress=None):
    """The world gradient of a Bump node's Height at each corner (linear over each triangle,
    height_gradients) or, with `sites`, at each baked texel: the height read there and one texel
    along the bake's u and v, through the UV map's own gradients over the triangle.  None without
    the Height's UV map (noted)."""
    socket = chain.bump.inputs["Height"]
    try:
        if sites is None:
            height = _height_reader(obj, s, mesh, corner_vert, None, len(mesh.loops), progress,
                                    notes).value(socket)
            heights = [height]
        else:
            heights = [_height_reader(obj, s, mesh, corner_vert, at, sites.count, progress, notes).value(socket)
                       for at in (sites, sites.shifted(1.0, 0.0), sites.shifted(0.0, 1.0))]
    except nodes.MissingUV as exc:
        notes.append(_no_uv_map(obj, exc.uv_map, f"the Bump node of '{mat.name}'", "it is not used"))
        return None
    except nodes.Unsupported as exc:  # (what reads the scene about each point: not at a height's points)
        notes.append(f"'{obj.name}': the Bump node of '{mat.name}' takes its Height from {exc}: it is not used")
        return None
    if not all(np.isfinite(h).all() for h in heights):
        raise world.SetupError(f"Material '{mat.name}': its Bump node's Height is not finite (NaN or "
                               f"infinite) on '{obj.name}'")
    points = world_points(mesh, m)
    if sites is None:
        return height_gradients(points, corner_vert, triangle_corners(mesh), heights[0], len(mesh.vertices))[corner_vert]
    grad_u, grad_v = sites.uv_gradients(points[corner_vert])
    h, hu, hv = (x.astype(np.float64) for x in heights)
    return (hu - h)[:, None] * sites.width * grad_u + (hv - h)[:, None] * sites.height * grad_v


def _mapped_rows(obj, s, mat, chain, mesh, corner_vert, m, data, notes, progress):
    """The world normals (per row of data) a chain's normal map and Bump node bend slot s's rows to,
    or None where they bend nothing (no UV map, an unlinked Height)."""
    nl = len(mesh.loops)
    normal = np.empty(nl * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", normal)
    normal = normal.reshape(nl, 3)
    sites = data.sites
    if sites is not None:
        normal = _unit_rows(sites.at(normal))
    # into the world by the inverse transpose, as read_mesh turns the normals
    to_world = np.array(m.to_3x3().inverted_safe(), np.float32)
    world_n = _unit_rows(normal @ to_world)
    bent = False
    if chain.map is not None:
        mapped = _mapped_normals(mesh, corner_vert, chain.map, chain.map_strength, normal, world_n, to_world, sites)
        if mapped is None:
            notes.append(_no_uv_map(obj, chain.map.uv_map, f"the normal map of '{mat.name}'",
                                    "the mesh's normals are used"))
        else:
            world_n, bent = mapped, True
    if chain.bump is not None and chain.bump.inputs["Height"].is_linked:
        gradient = _bump_gradients(obj, s, mat, chain, mesh, corner_vert, m, sites, notes, progress)
        if gradient is not None:
            world_n = bumped_normals(world_n, gradient, chain.distance, chain.bump_strength)
            bent = True
    if not bent:
        return None
    if sites is None:
        rows = corner_vert if data.domain == "POINT" else np.arange(nl)
        world_n = _unit_rows(np.stack([np.bincount(rows, weights=world_n[:, k], minlength=data.count)
                                       for k in range(3)], axis=1))
    return world_n


def read_shading_normals(obj, depsgraph, data, progress=None):
    """Sets data.shading_normals (world space, per shaded row) for the material slots whose
    Principled BSDF's Normal comes from a normal map or a Bump node, as Cycles makes them: a Normal
    Map's 2 x colour - 1 in the UV map's tangent frame (MikkTSpace), in the object's space or the
    world's (Blender's own object and world spaces with Y and Z flipped), blended towards the mesh's
    normal by Strength; a Bump node's normal tilted against its Height's gradient over the surface
    (bumped_normals).  At the vertices the height is linear between the corners and detail finer than
    the mesh is lost; a bake (data.sites) reads both at each texel.  Sets data.bump_map_correction
    from the bent materials' Bump Map Correction (Cycles' bump terminator, which the core applies to
    the bent rows' Lambertian part).  Returns notes."""
    notes = []
    ob_eval = obj.evaluated_get(depsgraph)
    corrections = {}  # bent material -> its Bump Map Correction
    for s, mat, (chain, _), mesh, corner_vert in _principled_slots(obj, depsgraph, normal_source):
        mine = _slot_rows(obj, data, s)
        # a normal map's or Bump node's normals at the rows, or None where they bend nothing
        bent = (_mapped_rows(obj, s, mat, chain, mesh, corner_vert, ob_eval.matrix_world, data, notes, progress)
                if chain.map is not None or chain.bump is not None else None)
        if chain.bevel is not None:  # read where the rows are: their own positions and normals
            radius = chain.bevel_radius
            if not isinstance(radius, float):  # (linked: each row's, from the nodes)
                socket = radius
                try:
                    radius = _rows_evaluator(obj, depsgraph, data, mesh, corner_vert, mat, (s, "radius"), notes,
                                             ambient_reader(obj, depsgraph, data.domain, progress),
                                             progress).value(socket)
                except nodes.Unsupported as exc:  # (a missing UV map, what varies where it may not)
                    radius = max(float(socket.default_value), 0.0)
                    instead = f"its unlinked value, {radius:g}, is used"
                    notes.append(_no_uv_map(obj, exc.uv_map, f"the Bevel node's Radius ('{mat.name}')", instead)
                                 if isinstance(exc, nodes.MissingUV) else
                                 f"'{obj.name}': the Bevel node's Radius ('{mat.name}') reads {exc}: {instead}")
                _check_finite(radius, mat, "its Bevel node's Radius", obj)
            rounded = bevel.normals(obj, depsgraph, data.positions, data.normals, radius, progress, data.sites)
            if bent is not None:  # (svm_node_bevel keeps its Normal: what the bevel turns, added to it)
                rounded = _unit_rows(bent + (rounded - _unit_rows(data.normals)))
            bent = rounded
        if bent is None:
            continue
        if data.shading_normals is None:
            data.shading_normals = data.normals.copy()
        data.shading_normals[mine] = bent[mine]
        # Cycles' own setting (on by default, and where Cycles is not loaded)
        corrections[mat.name] = bool(getattr(getattr(mat, "cycles", None), "use_bump_map_correction", True))
    # one call shades the object's bent rows: a mixture of settings is read as on, and named
    # (the correction of the Blender running: its Cycles' microfacet term from 4.5, Chiang et al.'s before)
    data.bump_map_correction = (compat.BUMP_MAP_CORRECTION if not corrections or any(corrections.values())
                                else False)
    if len(set(corrections.values())) > 1:
        off = ", ".join(f"'{m}'" for m, on in sorted(corrections.items()) if not on)
        notes.append(f"'{obj.name}': Bump Map Correction is off for {off} but on for its other bent materials: "
                     "read as on for all")
    return notes


# ---------------------------------------------------------------------------------------------
# A mixture's weights per vertex


def read_term_weights(obj, depsgraph, data, progress=None):
    """Sets data.term_weights[slot] for the material slots whose shader nodes are a mixture
    (closures.py): each term's weight, (3,) where it is constant, else (n, 3) over data's rows, its
    textured Mix Shader factors (and a Glossy BSDF's textured Color) read at each vertex; and
    data.term_inputs[slot]: each term's inputs read from textures, {core keyword: (n,) or (n, 3)}, as
    read_inputs reads a lone Principled BSDF's.  Returns notes: a missing UV map (that input's
    unlinked value is used)."""
    notes = []
    mesh = corner_vert = None
    occlusion = ambient_reader(obj, depsgraph, data.domain, progress)
    for s, slot in enumerate(obj.material_slots):
        mat = slot.material
        if mat is None or mat.wenv.model != "PRINCIPLED" or mat.node_tree is None:
            continue
        found, _ = closures.terms(mat)
        if found is None or closures.one_principled(found):
            continue
        weights, term_inputs = [], []
        for t, term in enumerate(found):
            colour = np.float32(term.colour)
            reads = term.factors or term.weight_socket is not None or term.linked
            if reads and mesh is None:
                mesh = meshes.shaded_mesh(obj, depsgraph)[0]
                corner_vert = meshes.corner_vertices(mesh)
            ev = (_rows_evaluator(obj, depsgraph, data, mesh, corner_vert, mat, (s, t), notes, occlusion, progress)
                  if reads else None)
            weight, fac = colour, np.ones((data.count, 1), np.float32)
            if term.factors:
                try:
                    fac = closures._factor_values(ev, term.factors, rows=True)
                except (nodes.MissingUV, nodes.UnreadAtRows) as exc:
                    _note(notes, _no_uv_map(obj, exc.uv_map, f"a Mix Shader's Fac ('{mat.name}')",
                                            "its unlinked value is used") if isinstance(exc, nodes.MissingUV) else
                                 f"'{obj.name}': a Mix Shader's Fac ('{mat.name}') reads {exc}: its unlinked value "
                                 "is used")
                    fac = _unlinked_factor(term) * np.ones(data.count, np.float32)
                _check_finite(fac, mat, "a Mix Shader's Fac", obj)
                fac = fac[:, None]
                weight = fac * colour[None, :]
            if term.weight_socket is not None:
                tint = _term_input(ev, term.weight_socket, True, obj, mat, term.label, notes)
                if tint is not None:  # in place of the node's unlinked Color in the term's colour
                    weight = (fac * np.float32(term.outer) * np.maximum(tint, 0.0)).astype(np.float32)
            weights.append(weight)
            inputs = {}
            for keyword, socket in term.linked.items():
                got = _term_input(ev, socket, keyword in COLOUR_KEYWORDS, obj, mat, term.label, notes)
                if got is not None:
                    inputs[keyword] = got
            if ev is not None:
                data.reads_camera |= bool(ev.spaces & CAMERA_SPACES)
                data.reads_placement |= ev.placed
            notes += _within_family_limits(inputs, np.ones(data.count, bool), f"'{term.label}' in '{mat.name}'")
            term_inputs.append(inputs)
        data.term_weights[s] = weights
        data.term_inputs[s] = term_inputs
    return notes


def read_instanced(obj, depsgraph, data, rows):
    """Sets data's inputs and term weights (read_inputs', read_term_weights') for instances of mesh
    object `obj` whose rows lie one after another in data (`rows`: each instance's count) from
    obj's own rows, read once: an instance reads at each row what the object reads there when
    nothing read depends on where it lies (a UV map, the mesh's attributes, its Generated or Object
    coordinates, nodes of these).  Returns notes, or None where that does not hold (reads of the
    world, the view or the object; a normal map, which bends the rows with the instance; other
    rows than the object's)."""
    if (obj is None or not rows or any(r != rows[0] for r in rows)
            or any(bends_normals(slot.material) for slot in obj.material_slots)):
        return None
    own = meshes.read_mesh(obj, depsgraph)
    if own.domain != data.domain or own.count != rows[0]:
        return None
    own.view = data.view
    notes = read_inputs(obj, depsgraph, own) + read_term_weights(obj, depsgraph, own)
    if own.reads_placement:
        return None
    copies = len(rows)

    def tiled(a):
        return np.tile(a, (copies,) + (1,) * (a.ndim - 1)) if a.ndim and len(a) == own.count else a
    data.inputs = {k: tiled(a) for k, a in own.inputs.items()}
    data.textured = {k: set(v) for k, v in own.textured.items()}
    data.term_weights = {s: [tiled(w) if w.ndim == 2 else w for w in ws] for s, ws in own.term_weights.items()}
    data.term_inputs = {s: [{k: tiled(a) for k, a in t.items()} for t in ts] for s, ts in own.term_inputs.items()}
    return notes


def bends_normals(mat):
    """Whether read_shading_normals bends the rows of `mat`: its lone Principled BSDF's Normal from a
    normal map, a Bump or a Bevel node."""
    if mat is None or mat.wenv.model != "PRINCIPLED" or mat.node_tree is None or not closures.is_one_principled(mat):
        return False
    node = materials.principled_node(mat)
    return node is not None and normal_source(node)[0] is not None


def unlinked_term_weights(mats, data):
    """Sets data.term_weights as read_term_weights does for the material slots `mats` (materials or
    None), each term's weight at its nodes' unlinked values (a Mix Shader's Fac too): what sends the
    light of an instance, whose rows wenv reads no textures at."""
    for s, mat in enumerate(mats):
        if mat is None or mat.wenv.model != "PRINCIPLED" or mat.node_tree is None:
            continue
        found, _ = closures.terms(mat)
        if found is None or closures.one_principled(found):
            continue
        data.term_weights[s] = [np.float32(term.colour) * (_unlinked_factor(term) if term.factors else np.float32(1.0))
                                for term in found]
        data.term_inputs[s] = [{} for _ in found]


def _unlinked_factor(term):
    """A mixture term's Mix Shader factors at their nodes' unlinked values (float32)."""
    unlinked = nodes.one_point(lambda node: np.zeros((1, 3), np.float32))
    return np.float32(closures._factor_values(unlinked, term.factors)[0])


def _check_finite(values, mat, what, obj):
    if not np.isfinite(values).all():
        raise world.SetupError(f"Material '{mat.name}': {what} is not finite (NaN or infinite) on '{obj.name}'")


def _term_input(ev, socket, colour, obj, mat, label, notes):
    """A mixture term's linked input read at each vertex, or None where the nodes between are not
    evaluated (materials.principled_notes names them) or the UV map is missing (noted here)."""
    try:
        values = ev.colour(socket) if colour else ev.value(socket)
    except nodes.MissingUV as exc:
        notes.append(_no_uv_map(obj, exc.uv_map, f"'{socket.name}' of '{label}' ('{mat.name}')",
                                "its unlinked value is used"))
        return None
    except nodes.UnreadAtRows as exc:
        _note(notes, f"'{obj.name}': '{socket.name}' of '{label}' ('{mat.name}') reads {exc}: its unlinked value "
                     "is used")
        return None
    except nodes.Unsupported:
        return None
    _check_finite(values, mat, f"'{label}''s '{socket.name}'", obj)
    if colour:
        values = at_least_zero(values, socket, f"'{obj.name}' ('{label}' in '{mat.name}')", notes)
    return np.ascontiguousarray(values, np.float32)


# The colours Cycles' Principled BSDF clamps at 0 (svm_node_closure_bsdf).  Any other colour below 0
# (a Diffuse BSDF's, an emission's) takes light away in Cycles, which the core does not shade.
CLAMPED_AT_ZERO = ("Base Color", "Specular Tint", "Sheen Tint", "Coat Tint")


def at_least_zero(values, socket, where, notes):
    """A colour input's `values` with what lies below 0 read as 0, noted where Cycles reads it
    otherwise."""
    if not (values < 0.0).any():
        return values
    if not (socket.node.bl_idname == "ShaderNodeBsdfPrincipled" and socket.name in CLAMPED_AT_ZERO):
        _note(notes, f"{where}: '{socket.name}' of '{socket.node.name}' is below 0 in places, where Cycles "
                     "takes light away: read as 0")
    return np.maximum(values, 0.0).astype(np.float32)
