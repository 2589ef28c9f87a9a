"""The World: its node set-up read as a WorldSpec, and its pixels turned into a core Environment."""
import math

import numpy as np

from . import engine
from .engine import SetupError


class WorldSpec:
    """What the World asks for, read from its nodes without touching pixels (cheap: the live mode
    compares it every tick).  `key` identifies the image data, `transform` the rotation/strength."""

    __slots__ = ("kind", "image_name", "projection", "rotation", "strength", "color", "key")

    def __init__(self, kind, image_name=None, projection="equirect", rotation=0.0, strength=1.0,
                 color=None, key=()):
        self.kind = kind
        self.image_name = image_name
        self.projection = projection
        self.rotation = rotation
        self.strength = strength
        self.color = color
        self.key = key

    @property
    def signature(self):
        return (self.key, self.rotation, self.strength)

    def describe(self):
        if self.kind == "color":
            c = ", ".join(f"{v:.3g}" for v in self.color)
            return f"constant ({c}) x {self.strength:.3g}"
        proj = "mirror ball" if self.projection == "mirror_ball" else "equirectangular"
        return f"{self.image_name} ({proj}), rotation {math.degrees(self.rotation):.1f} deg, strength {self.strength:.3g}"


def _unlinked_value(socket, what):
    if socket.is_linked:
        raise SetupError(f"World: {what} is driven by a node link; only a plain value is supported")
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
        raise SetupError(f"World: the Environment Texture's Vector comes from '{node.name}'; "
                         "only a Mapping node (rotation about Z) is supported")
    if node.vector_type not in {"POINT", "VECTOR"}:
        raise SetupError(f"World: Mapping node '{node.name}' is of type {node.vector_type}; use Point or Vector")
    feed = source_node(node.inputs["Vector"])
    if feed is not None and not (feed.bl_idname == "ShaderNodeTexCoord"
                                 and node.inputs["Vector"].links[0].from_socket.name == "Generated"):
        raise SetupError(f"World: Mapping node '{node.name}' must be fed by Generated coordinates or nothing")
    rot = _unlinked_value(node.inputs["Rotation"], "the Mapping rotation")
    scale = _unlinked_value(node.inputs["Scale"], "the Mapping scale")
    if abs(rot[0]) > 1e-6 or abs(rot[1]) > 1e-6:
        raise SetupError(f"World: Mapping node '{node.name}' rotates about X or Y; only Z rotation is supported")
    if any(abs(s - 1.0) > 1e-6 for s in scale):
        raise SetupError(f"World: Mapping node '{node.name}' has scale {tuple(scale)}; only scale 1 is supported")
    return float(rot[2])


def _output_node(tree):
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    active = [n for n in outputs if n.is_active_output] or outputs
    return active[0] if active else None


def world_spec(world):
    """Reads the World's node set-up; raises SetupError with a user-facing message if it cannot be
    shaded (no World, no nodes, missing image, unsupported nodes)."""
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
    if bg.bl_idname != "ShaderNodeBackground":
        raise SetupError(f"World '{world.name}': the Surface comes from '{bg.name}'; only a Background node is supported")
    strength = float(_unlinked_value(bg.inputs["Strength"], "the Background strength"))
    if not math.isfinite(strength) or strength < 0:
        raise SetupError(f"World '{world.name}': Background strength {strength} must be >= 0")
    src = source_node(bg.inputs["Color"])
    if src is None:
        color = tuple(float(c) for c in bg.inputs["Color"].default_value[:3])
        return WorldSpec("color", color=color, strength=strength, key=("color", color))
    if src.bl_idname != "ShaderNodeTexEnvironment":
        raise SetupError(f"World '{world.name}': the Background colour comes from '{src.name}'; "
                         "only an Environment Texture (or a plain colour) is supported")
    image = src.image
    if image is None:
        raise SetupError(f"World '{world.name}': the Environment Texture '{src.name}' has no image")
    if image.source not in {"FILE", "GENERATED"}:
        raise SetupError(f"World image '{image.name}' is a {image.source.lower()}; only still images are supported")
    projection = {"EQUIRECTANGULAR": "equirect", "MIRROR_BALL": "mirror_ball"}[src.projection]
    rotation = _mapping_rotation(src)
    key = ("image", image.name, image.filepath_raw, image.packed_file is not None, tuple(image.size),
           image.colorspace_settings.name, projection)
    return WorldSpec("image", image_name=image.name, projection=projection, rotation=rotation,
                     strength=strength, key=key)


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


def image_note(spec, images):
    """A sentence when an 8-bit World image is in a colour space wenv does not decode (its stored
    values are then read as linear Rec.709), else None."""
    image = images.get(spec.image_name) if spec.kind == "image" else None
    if image is None or image.is_float:
        return None
    space = image.colorspace_settings.name
    if space in SRGB_SPACES or space in LINEAR_SPACES:
        return None
    return (f"World image '{image.name}' is 8-bit in colour space '{space}', which wenv does not decode: its "
            "values were read as linear Rec.709 (set it to sRGB or a linear space, or use a float image)")


def environment_from_spec(spec, images):
    """Core Environment for a WorldSpec (pixels read afresh); `images` is bpy.data.images."""
    if spec.kind == "color":
        px = np.empty((4, 8, 4), np.float32)
        px[...] = (*spec.color, 1.0)
        return engine.environment(px, projection="equirect", rotation=0.0, strength=spec.strength)
    image = images.get(spec.image_name)
    if image is None:
        raise SetupError(f"World image '{spec.image_name}' no longer exists")
    px = image_pixels(image)
    if not np.all(np.isfinite(px[..., :3])):
        raise SetupError(f"World image '{image.name}' holds NaN or infinite pixels")
    try:
        return engine.environment(px, projection=spec.projection, rotation=spec.rotation, strength=spec.strength)
    except ValueError as exc:
        raise SetupError(f"World image '{image.name}': {exc}") from None


def environment(spec, images):
    """The Environment a shading pass uses for a WorldSpec.  An image's pixels are read once and
    kept (untransformed) in engine.shaders, so turning the World or changing its strength is cheap."""
    try:
        if spec.kind == "color":
            return environment_from_spec(spec, images)
        untransformed = WorldSpec("image", spec.image_name, spec.projection, 0.0, 1.0, key=spec.key)
        return engine.shaders.environment(spec.key, spec.signature, spec.rotation, spec.strength,
                                          lambda: environment_from_spec(untransformed, images))
    except ValueError as exc:  # lighting the core refuses (a Strength beyond what it can shade)
        raise SetupError(f"World: {exc}") from None
