"""The World: its node set-up read as a WorldSpec, and its pixels turned into a core Environment."""
import math

import numpy as np

from . import engine
from .engine import SetupError


class WorldSpec:
    """What the World asks for, read from its nodes without touching pixels (cheap: the live mode
    compares it every tick).  `key` identifies the image data, `transform` the rotation/strength."""

    __slots__ = ("kind", "image_name", "projection", "rotation", "strength", "color", "key", "world_name", "reason")

    def __init__(self, kind, image_name=None, projection="equirect", rotation=0.0, strength=1.0,
                 color=None, key=(), world_name=None, reason=None):
        self.kind = kind  # "color", "image", or "rendered" (any other set-up: Cycles renders it)
        self.image_name = image_name
        self.projection = projection
        self.rotation = rotation
        self.strength = strength
        self.color = color
        self.key = key
        self.world_name = world_name  # (rendered) the World datablock
        self.reason = reason  # (rendered) what in it the image path does not read

    @property
    def signature(self):
        return (self.key, self.rotation, self.strength)

    def describe(self):
        if self.kind == "rendered":
            return (f"'{self.world_name}' as Cycles renders it ({RENDER_WIDTH} x {RENDER_WIDTH // 2}, "
                    f"{RENDER_SAMPLES} samples a pixel): {self.reason}")
        if self.kind == "color":
            c = ", ".join(f"{v:.3g}" for v in self.color)
            return f"constant ({c}) x {self.strength:.3g}"
        proj = "mirror ball" if self.projection == "mirror_ball" else "equirectangular"
        return f"{self.image_name} ({proj}), rotation {math.degrees(self.rotation):.1f} deg, strength {self.strength:.3g}"


class _NotPlain(Exception):
    """A World set-up read otherwise than as an image or a colour: Cycles renders it (the message
    says what)."""


def _unlinked_value(socket, what):
    if socket.is_linked:
        raise _NotPlain(f"{what} is driven by a node link")
    return socket.default_value


def source_node(socket):
    """The node feeding `socket`, following reroutes; None when unlinked (materials.py uses it too)."""
    while socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            return None
        node = link.from_node
        if node.bl_idname != "NodeReroute":
            return node
        socket = node.inputs[0]
    return None


def _mapping_rotation(env_node):
    """Z rotation of a Mapping node feeding the Environment Texture (0 without one).  Only what the
    core can reproduce is accepted: a rotation about Z, no X/Y rotation, scale 1."""
    node = source_node(env_node.inputs["Vector"])
    if node is None or node.bl_idname == "ShaderNodeTexCoord":
        return 0.0
    if node.bl_idname != "ShaderNodeMapping":
        raise _NotPlain(f"the Environment Texture's Vector comes from '{node.name}'")
    if node.vector_type not in {"POINT", "VECTOR"}:
        raise _NotPlain(f"Mapping node '{node.name}' is of type {node.vector_type.lower()}")
    feed = source_node(node.inputs["Vector"])
    if feed is not None and not (feed.bl_idname == "ShaderNodeTexCoord"
                                 and node.inputs["Vector"].links[0].from_socket.name == "Generated"):
        raise _NotPlain(f"Mapping node '{node.name}' is fed by other than Generated coordinates")
    rot = _unlinked_value(node.inputs["Rotation"], "the Mapping rotation")
    scale = _unlinked_value(node.inputs["Scale"], "the Mapping scale")
    if abs(rot[0]) > 1e-6 or abs(rot[1]) > 1e-6:
        raise _NotPlain(f"Mapping node '{node.name}' rotates about X or Y")
    if any(abs(s - 1.0) > 1e-6 for s in scale):
        raise _NotPlain(f"Mapping node '{node.name}' scales by {tuple(round(v, 4) for v in scale)}")
    return float(rot[2])


def _output_node(tree):
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    active = [n for n in outputs if n.is_active_output] or outputs
    return active[0] if active else None


def world_spec(world):
    """Reads the World's node set-up: an Environment Texture's image (turned about Z by a Mapping
    node) or a plain colour, times the Background's Strength, read as they are; any other set-up
    (a Sky Texture, mixed textures, a turn about X...) as Cycles renders it (kind "rendered", keyed
    by everything in its nodes).  Raises SetupError with a user-facing message for a World that
    cannot be shaded (none, no nodes or output, nothing connected, an image missing, a negative
    Strength)."""
    if world is None:
        raise SetupError("The scene has no World: add one with an Environment Texture or a Background colour")
    tree = world.node_tree
    if tree is None:
        raise SetupError(f"World '{world.name}' has no nodes: add a Background node")
    out = _output_node(tree)
    if out is None:
        raise SetupError(f"World '{world.name}' has no World Output node")
    bg = source_node(out.inputs["Surface"])
    if bg is None:
        raise SetupError(f"World '{world.name}': nothing is connected to the World Output's Surface")
    try:
        return _plain_spec(world, bg)
    except _NotPlain as exc:
        return WorldSpec("rendered", key=("rendered", world.name_full, tree_key(tree)), world_name=world.name,
                         reason=str(exc))


def _plain_spec(world, bg):
    if bg.bl_idname != "ShaderNodeBackground":
        raise _NotPlain(f"the Surface comes from '{bg.name}'")
    strength = float(_unlinked_value(bg.inputs["Strength"], "the Background strength"))
    if not math.isfinite(strength) or strength < 0:
        raise SetupError(f"World '{world.name}': Background strength {strength} must be >= 0")
    src = source_node(bg.inputs["Color"])
    if src is None:
        color = tuple(float(c) for c in bg.inputs["Color"].default_value[:3])
        return WorldSpec("color", color=color, strength=strength, key=("color", color))
    if src.bl_idname != "ShaderNodeTexEnvironment":
        raise _NotPlain(f"the Background colour comes from '{src.name}'")
    image = src.image
    if image is None:
        raise SetupError(f"World '{world.name}': the Environment Texture '{src.name}' has no image")
    if image.source not in {"FILE", "GENERATED"}:
        raise _NotPlain(f"World image '{image.name}' is a {image.source.lower()}")
    projection = {"EQUIRECTANGULAR": "equirect", "MIRROR_BALL": "mirror_ball"}[src.projection]
    rotation = _mapping_rotation(src)
    key = ("image", image.name, image.filepath_raw, image.packed_file is not None, tuple(image.size),
           image.colorspace_settings.name, projection)
    return WorldSpec("image", image_name=image.name, projection=projection, rotation=rotation,
                     strength=strength, key=key)


# What tree_key leaves out of a node: where it is drawn and what it is called, nothing it computes
_LAYOUT = {"rna_type", "name", "label", "location", "location_absolute", "width", "height", "dimensions", "select",
           "show_options", "show_preview", "show_texture", "hide", "parent", "use_custom_color", "color",
           "color_tag", "warning_propagation", "inputs", "outputs", "internal_links", "type"}


def _id_key(value, depth):
    """What of an ID a node points at changes a World's light: an image's file and state, a node
    group's nodes, an object's place."""
    kind = type(value).__name__
    if kind == "Image":
        return (kind, value.name_full, value.filepath_raw, value.packed_file is not None, tuple(value.size),
                value.is_dirty, value.source, value.colorspace_settings.name, value.alpha_mode)
    if hasattr(value, "nodes") and depth < 8:
        return (kind, value.name_full, tree_key(value, depth + 1))
    if hasattr(value, "matrix_world"):
        return (kind, value.name_full, tuple(tuple(r) for r in value.matrix_world))
    return (kind, value.name_full)


def _rna_key(struct, depth):
    """Every property of a node (or of a struct it holds: a ColorRamp, curves, a texture mapping)
    that is not layout, as a tuple."""
    out = []
    for prop in struct.bl_rna.properties:
        ident = prop.identifier
        if ident in _LAYOUT or ident.startswith("bl_"):
            continue
        value = getattr(struct, ident, None)
        if prop.type == "POINTER":
            if value is None:
                out.append((ident, None))
            elif hasattr(value, "name_full"):  # an ID
                out.append((ident, _id_key(value, depth)))
            elif depth < 3:
                out.append((ident, _rna_key(value, depth + 1)))
        elif prop.type == "COLLECTION":
            if depth < 3:
                out.append((ident, tuple(_rna_key(item, depth + 1) for item in value)))
        else:
            try:
                value = tuple(value) if not isinstance(value, str) else value
            except TypeError:
                pass
            out.append((ident, value))
    return tuple(out)


def tree_key(tree, depth=0):
    """Everything in a node tree that changes what it gives: each node's settings and unlinked
    inputs, and the links (cheap enough for the live mode's tick: a World has a few nodes)."""
    nodes = []
    for node in sorted(tree.nodes, key=lambda n: n.name):
        inputs = []
        for socket in node.inputs:
            value = getattr(socket, "default_value", None)
            try:
                value = tuple(value) if not isinstance(value, (str, float, int, bool)) and value is not None else value
            except TypeError:
                value = None
            inputs.append((socket.identifier, socket.enabled, value))
        nodes.append((node.bl_idname, node.name, node.mute, tuple(inputs), _rna_key(node, depth)))
    links = sorted((link.from_node.name, link.from_socket.identifier, link.to_node.name, link.to_socket.identifier,
                    link.is_muted, link.is_valid) for link in tree.links)
    return (tuple(nodes), tuple(links))


def srgb_to_linear(x):
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def image_pixels(image, what="World image", as_stored=False):
    """RGBA float32 (H, W, 4), row 0 the top: one bulk copy out of Blender.  RGB linear, alpha 1;
    as_stored: the values as Blender holds them (a byte image's display-encoded, a float image's
    associated with alpha) with the image's alpha (a two-channel image's second, else 1)."""
    w, h = image.size  # reading the size loads the image
    if w == 0 or h == 0:
        where = image.filepath_raw or "(no file)"
        raise SetupError(f"{what} '{image.name}' could not be loaded: {where}")
    channels = image.channels
    buf = np.empty(w * h * channels, np.float32)
    image.pixels.foreach_get(buf)
    px = buf.reshape(h, w, channels)[::-1]  # Blender stores the bottom row first
    rgba = np.ones((h, w, 4), np.float32)
    if channels >= 3:
        rgba[..., :3] = px[..., :3]
    else:
        rgba[..., :3] = px[..., :1]
    if as_stored:
        if channels in (2, 4):
            rgba[..., 3] = px[..., channels - 1]
        return rgba
    # Float images come linear; byte images hand out their stored, display-encoded values.
    if not image.is_float and image.colorspace_settings.name in SRGB_SPACES:
        rgba[..., :3] = srgb_to_linear(rgba[..., :3])
    return rgba


# The colour spaces of an 8-bit World image that image_pixels reads as Blender does: sRGB decoded,
# the linear Rec.709 ones (and data) as stored.  Blender converts float images itself.
SRGB_SPACES = {"sRGB", "sRGB EOTF"}
LINEAR_SPACES = {"Linear Rec.709", "scene_linear", "Non-Color", "Linear", "Raw"}
# The colour spaces whose values Cycles reads as data (colorspace_is_data): never associated with alpha
DATA_SPACES = {"Non-Color", "Raw"}


def world_note(spec, images):
    """A sentence when the World is rendered by Cycles (what for, and what of it is not read: its
    Volume, a Light Path node, seen as a camera ray sees it), or when an 8-bit World image is in a
    colour space wenv does not decode (its stored values are then read as linear Rec.709), else
    None."""
    if spec.kind == "rendered":
        import bpy

        world = bpy.data.worlds.get(spec.world_name)
        tree = world.node_tree if world is not None else None
        unread = []
        if tree is not None:
            out = _output_node(tree)
            if out is not None and out.inputs["Volume"].is_linked:
                unread.append("its Volume is not shaded")
            if any(n.bl_idname == "ShaderNodeLightPath" for n in tree.nodes):
                unread.append("its Light Path node reads as a camera ray (Cycles' lighting may differ)")
        return (f"World '{spec.world_name}' is shaded as Cycles renders it ({spec.reason}): an equirectangular "
                f"{RENDER_WIDTH} x {RENDER_WIDTH // 2} image at {RENDER_SAMPLES} samples a pixel, rendered again "
                "when its nodes change (an image's unsaved edits are not seen)"
                + ("; " + "; ".join(unread) if unread else ""))
    image = images.get(spec.image_name) if spec.kind == "image" else None
    if image is None or image.is_float:
        return None
    space = image.colorspace_settings.name
    if space in SRGB_SPACES or space in LINEAR_SPACES:
        return None
    return (f"World image '{image.name}' is 8-bit in colour space '{space}', which wenv does not decode: its "
            "values were read as linear Rec.709 (set it to sRGB or a linear space, or use a float image)")


# A World other than an image or a colour, as Cycles renders it (world_render.py): an
# equirectangular image of this width (and half its height), each pixel the mean of this many
# samples over its area, and a sun's few pixels again at world_render.SUN_SAMPLES so that they keep
# its energy (without, a sun of half a degree gave a plane 1-2 % too little light at 16 samples and
# 5 % too much at 8; with it, 8 and 16 agree to 1e-6, the sky being smooth)
RENDER_WIDTH = 1024
RENDER_SAMPLES = 8


def render_world(world, frame=None, width=None, samples=None):
    """RGBA float32 (width / 2, width, 4), row 0 the top, scene linear: `world` as Cycles renders it
    (world_render.py; RENDER_WIDTH and RENDER_SAMPLES unless given) at the scene frame `frame` (the current one if None), in a Blender process of
    its own -- Blender's own binary, or this Python where bpy is a module -- from the World written
    to a file of its own (images by absolute path, packed ones packed; an image's unsaved edits are
    not seen), so that nothing of the user's file changes.  SetupError if the render fails."""
    import os
    import shutil
    import subprocess
    import sys
    import tempfile

    import bpy

    width, samples = width or RENDER_WIDTH, samples or RENDER_SAMPLES
    if frame is None:
        frame = bpy.context.scene.frame_current if bpy.context.scene is not None else 1
    folder = tempfile.mkdtemp(prefix="wenv-world-")
    try:
        blend, out = os.path.join(folder, "world.blend"), os.path.join(folder, "world.npy")
        bpy.data.libraries.write(blend, {world}, path_remap="ABSOLUTE", fake_user=True)
        script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "world_render.py")
        launch = ([bpy.app.binary_path, "-b", "--factory-startup", "--python", script] if bpy.app.binary_path
                  else [sys.executable, script])
        done = subprocess.run(launch + ["--", blend, world.name, out, str(width), str(samples), str(int(frame))],
                              capture_output=True, text=True, timeout=900)
        if done.returncode != 0 or not os.path.exists(out):
            tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
            raise SetupError(f"World '{world.name}' could not be rendered by Cycles: " + " / ".join(tail))
        px = np.load(out)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return np.ascontiguousarray(px[::-1], np.float32)


def environment_from_spec(spec, images):
    """Core Environment for a WorldSpec (pixels read afresh, or rendered); `images` is bpy.data.images."""
    if spec.kind == "color":
        px = np.empty((4, 8, 4), np.float32)
        px[...] = (*spec.color, 1.0)
        return engine.environment(px, projection="equirect", rotation=0.0, strength=spec.strength)
    if spec.kind == "rendered":
        import bpy

        world = bpy.data.worlds.get(spec.world_name)
        if world is None:
            raise SetupError(f"World '{spec.world_name}' no longer exists")
        return _lit_by(render_world(world), f"World '{world.name}'", "equirect", 0.0, 1.0)
    image = images.get(spec.image_name)
    if image is None:
        raise SetupError(f"World image '{spec.image_name}' no longer exists")
    return _lit_by(image_pixels(image), f"World image '{image.name}'", spec.projection, spec.rotation, spec.strength)


def _lit_by(px, what, projection, rotation, strength):
    """engine.environment of pixels, a SetupError naming `what` for pixels not finite or lighting the
    core refuses."""
    if not np.all(np.isfinite(px[..., :3])):
        raise SetupError(f"{what} holds NaN or infinite pixels")
    try:
        return engine.environment(px, projection=projection, rotation=rotation, strength=strength)
    except ValueError as exc:
        raise SetupError(f"{what}: {exc}") from None


def environment(spec, images):
    """The Environment a shading pass uses for a WorldSpec.  An image's pixels are read once and
    kept (untransformed) in engine.shaders, so turning the World or changing its strength is cheap."""
    try:
        if spec.kind == "color":
            return environment_from_spec(spec, images)
        if spec.kind == "rendered":  # rendered once per state of its nodes
            return engine.shaders.environment(spec.key, spec.signature, 0.0, 1.0,
                                              lambda: environment_from_spec(spec, images))
        untransformed = WorldSpec("image", spec.image_name, spec.projection, 0.0, 1.0, key=spec.key)
        return engine.shaders.environment(spec.key, spec.signature, spec.rotation, spec.strength,
                                          lambda: environment_from_spec(untransformed, images))
    except ValueError as exc:  # lighting the core refuses (a Strength beyond what it can shade)
        raise SetupError(f"World: {exc}") from None
