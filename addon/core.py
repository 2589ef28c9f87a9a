"""Glue between Blender data and the `wenv` core: World -> wenv.Environment, material settings ->
wenv material, evaluated mesh -> world-space arrays, radiance -> colour attribute.

Nothing here keeps a reference to Blender data between calls (undo and file loads free it); caches
are keyed by names and plain values.
"""
import math
import threading

import numpy as np
import wenv

ATTRIBUTE = "wenv_radiance"
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)
QUALITIES = ("draft", "default", "high")
GEOMETRIES = (20, 60, 85)


class SetupError(Exception):
    """A scene set-up the add-on cannot shade; the message is shown to the user as it is."""


# ---------------------------------------------------------------------------------------------
# World -> environment


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


def _source_node(socket):
    """The node feeding `socket`, following reroutes; None when unlinked."""
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
    node = _source_node(env_node.inputs["Vector"])
    if node is None or node.bl_idname == "ShaderNodeTexCoord":
        return 0.0
    if node.bl_idname != "ShaderNodeMapping":
        raise SetupError(f"World: the Environment Texture's Vector comes from '{node.name}'; "
                         "only a Mapping node (rotation about Z) is supported")
    if node.vector_type not in {"POINT", "VECTOR"}:
        raise SetupError(f"World: Mapping node '{node.name}' is of type {node.vector_type}; use Point or Vector")
    feed = _source_node(node.inputs["Vector"])
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
    bg = _source_node(out.inputs["Surface"])
    if bg is None:
        raise SetupError(f"World '{world.name}': nothing is connected to the World Output's Surface")
    if bg.bl_idname != "ShaderNodeBackground":
        raise SetupError(f"World '{world.name}': the Surface comes from '{bg.name}'; only a Background node is supported")
    strength = float(_unlinked_value(bg.inputs["Strength"], "the Background strength"))
    if not math.isfinite(strength) or strength < 0:
        raise SetupError(f"World '{world.name}': Background strength {strength} must be >= 0")
    src = _source_node(bg.inputs["Color"])
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


def _srgb_to_linear(x):
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def image_pixels(image):
    """RGBA float32 (H, W, 4), row 0 the top, linear: one bulk copy out of Blender."""
    w, h = image.size  # reading the size loads the image
    if w == 0 or h == 0:
        where = image.filepath_raw or "(no file)"
        raise SetupError(f"World image '{image.name}' could not be loaded: {where}")
    channels = image.channels
    buf = np.empty(w * h * channels, np.float32)
    image.pixels.foreach_get(buf)
    px = buf.reshape(h, w, channels)[::-1]  # Blender stores the bottom row first
    rgba = np.ones((h, w, 4), np.float32)
    if channels >= 3:
        rgba[..., :3] = px[..., :3]
    else:
        rgba[..., :3] = px[..., :1]
    # Float images come linear; byte images hand out their stored, display-encoded values.
    if not image.is_float and image.colorspace_settings.name in {"sRGB", "sRGB EOTF"}:
        rgba[..., :3] = _srgb_to_linear(rgba[..., :3])
    return rgba


def environment_from_spec(spec, images):
    """wenv.Environment for a WorldSpec; `images` is bpy.data.images."""
    if spec.kind == "color":
        px = np.empty((4, 8, 4), np.float32)
        px[...] = (*spec.color, 1.0)
        return wenv.Environment(px, projection="equirect", rotation=0.0, strength=spec.strength)
    image = images.get(spec.image_name)
    if image is None:
        raise SetupError(f"World image '{spec.image_name}' no longer exists")
    px = image_pixels(image)
    if not np.all(np.isfinite(px[..., :3])):
        raise SetupError(f"World image '{image.name}' holds NaN or infinite pixels")
    try:
        return wenv.Environment(px, projection=spec.projection, rotation=spec.rotation, strength=spec.strength)
    except ValueError as exc:
        raise SetupError(f"World image '{image.name}': {exc}") from None


# ---------------------------------------------------------------------------------------------
# Materials

DEFAULT_GREY = (0.8, 0.8, 0.8)


def material_key(settings):
    """Plain tuple of every value the wenv material depends on (for caches and the live mode)."""
    if settings is None:
        return ("default",)
    lobes = tuple((tuple(l.specular), l.roughness, l.ior, l.distribution) for l in settings.lobes)
    return (settings.model, tuple(settings.diffuse), settings.shadowing, lobes)


def material_from_key(key):
    """wenv material for a material_key(); a missing material is Blender's default grey, Lambertian."""
    if key[0] == "default":
        return wenv.Lambert(DEFAULT_GREY)
    model, diffuse, shadowing, lobes = key
    if model == "LAMBERT":
        return wenv.Lambert(diffuse)
    return wenv.CookTorrance(
        diffuse=diffuse,
        lobes=[{"specular": s, "roughness": r, "ior": n, "distribution": d.lower()} for s, r, n, d in lobes],
        shadowing=shadowing.lower())


def _input_value(node, name, warnings):
    sock = node.inputs.get(name)
    if sock is None:
        return None
    if sock.is_linked:
        warnings.append(f"'{name}' is linked; its unlinked value was used")
    return sock.default_value


def _ior_for_reflectance(f0):
    """Dielectric index whose normal-incidence Fresnel reflectance is f0 (capped at the core's max)."""
    s = math.sqrt(min(max(f0, 1e-4), 0.99))
    return min((1 + s) / (1 - s), 10.0)


def _fresnel0(n):
    return ((n - 1) / (n + 1)) ** 2


def principled_lobes(base, metallic, roughness, ior, spec_level=0.5, spec_tint=(1, 1, 1),
                     coat=0.0, coat_roughness=0.03, coat_ior=1.5):
    """wenv settings (diffuse, lobes) for Principled BSDF values.  See README "From Principled BSDF".

    - roughness r -> GGX alpha r^2 (as Cycles), floored at 1e-4 (a perfect mirror has no lobe width);
    - dielectric part (weight 1 - metallic): diffuse = base colour, one GGX lobe of index IOR,
      scaled by Specular Tint and 2 x Specular IOR Level (0.5 keeps Fresnel unchanged);
    - metallic part: a GGX lobe coloured base / F0(n_m) with n_m the index whose normal-incidence
      reflectance is the brightest base channel, so it reflects the base colour head-on and rises
      towards grazing like a conductor;
    - Coat Weight > 0 adds a clear lobe (Coat Roughness^2, Coat IOR) on top.
    """
    base = [min(max(float(c), 0.0), 1.0) for c in base[:3]]
    t = min(max(float(metallic), 0.0), 1.0)
    alpha = max(float(roughness) ** 2, 1e-4)
    ior = min(max(float(ior), 1.0001), 10.0)
    diffuse = tuple(c * (1 - t) for c in base)
    lobes = []
    if t < 1:
        scale = (1 - t) * 2 * float(spec_level)
        if scale > 0:
            lobes.append({"specular": tuple(scale * float(c) for c in spec_tint[:3]), "roughness": alpha,
                          "ior": ior, "distribution": "GGX"})
    if t > 0:
        n_m = _ior_for_reflectance(max(base))
        f0 = _fresnel0(n_m)
        lobes.append({"specular": tuple(t * c / f0 for c in base), "roughness": alpha, "ior": n_m,
                      "distribution": "GGX"})
    if coat > 0:
        lobes.append({"specular": (float(coat),) * 3, "roughness": max(float(coat_roughness) ** 2, 1e-4),
                      "ior": min(max(float(coat_ior), 1.0001), 10.0), "distribution": "GGX"})
    return diffuse, lobes


def principled_node(material):
    tree = material.node_tree
    if tree is None:
        return None
    out = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    out = [n for n in out if n.is_active_output] or out
    if out:
        node = _source_node(out[0].inputs["Surface"])
        if node is not None and node.bl_idname == "ShaderNodeBsdfPrincipled":
            return node
    return next((n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"), None)


def fill_from_principled(material):
    """Sets material.wenv from its Principled BSDF (or, without one, from the viewport colour,
    Lambertian).  Returns a list of warnings for the user."""
    warnings = []
    st = material.wenv
    node = principled_node(material)
    if node is None:
        st.model = "LAMBERT"
        st.diffuse = tuple(material.diffuse_color[:3])
        st.lobes.clear()
        warnings.append(f"'{material.name}' has no Principled BSDF: Lambertian with its viewport colour")
        st.initialized = True
        return warnings
    v = {name: _input_value(node, name, warnings) for name in
         ("Base Color", "Metallic", "Roughness", "IOR", "Specular IOR Level", "Specular Tint",
          "Coat Weight", "Coat Roughness", "Coat IOR")}
    diffuse, lobes = principled_lobes(
        v["Base Color"], v["Metallic"], v["Roughness"], v["IOR"],
        spec_level=v["Specular IOR Level"] if v["Specular IOR Level"] is not None else 0.5,
        spec_tint=v["Specular Tint"] if v["Specular Tint"] is not None else (1, 1, 1),
        coat=v["Coat Weight"] or 0.0,
        coat_roughness=v["Coat Roughness"] if v["Coat Roughness"] is not None else 0.03,
        coat_ior=v["Coat IOR"] if v["Coat IOR"] is not None else 1.5)
    st.model = "COOK_TORRANCE"
    st.shadowing = "SMITH"
    st.diffuse = diffuse
    st.lobes.clear()
    for lobe in lobes:
        item = st.lobes.add()
        item.specular = lobe["specular"]
        item.roughness = lobe["roughness"]
        item.ior = lobe["ior"]
        item.distribution = lobe["distribution"]
    st.active_lobe = 0
    st.initialized = True
    return warnings


def ensure_material_settings(material):
    """A material shaded for the first time takes its settings from its Principled BSDF."""
    if material is not None and not material.wenv.initialized:
        return fill_from_principled(material)
    return []


# ---------------------------------------------------------------------------------------------
# Glossmeter readings, memoised on the material values


_gloss_memo = {}


def gloss_readings(key):
    """{20: GU, 60: GU, 85: GU} for a material_key, or a string naming the problem."""
    hit = _gloss_memo.get(key)
    if hit is None:
        try:
            hit = dict(zip(GEOMETRIES, wenv.gloss(material_from_key(key), GEOMETRIES)))
        except (ValueError, RuntimeError) as exc:
            hit = str(exc)
        if len(_gloss_memo) > 256:
            _gloss_memo.clear()
        _gloss_memo[key] = hit
    return hit


def instrument_geometry(gloss60):
    """The geometry an instrument reports for a 60 degree reading (ISO 2813 rule of thumb)."""
    if gloss60 > 70:
        return 20
    if gloss60 < 10:
        return 85
    return 60


def fit_roughness(settings, target, geometry):
    """Roughness giving `target` GU for a one-lobe Cook-Torrance material (wenv.fit_roughness)."""
    if settings.model != "COOK_TORRANCE" or len(settings.lobes) != 1:
        raise SetupError("Set roughness for a target gloss needs a Cook-Torrance material with exactly one lobe")
    lobe = settings.lobes[0]
    try:
        return wenv.fit_roughness(target, geometry=geometry, diffuse=tuple(settings.diffuse),
                                  specular=tuple(lobe.specular), ior=lobe.ior,
                                  distribution=lobe.distribution.lower(), shadowing=settings.shadowing.lower())
    except ValueError as exc:
        raise SetupError(str(exc)) from None


# ---------------------------------------------------------------------------------------------
# Views


class View:
    """Perspective (eye position) or orthographic (one direction towards the viewer)."""

    __slots__ = ("perspective", "eye", "direction")

    def __init__(self, perspective, eye=None, direction=None):
        self.perspective = perspective
        self.eye = None if eye is None else tuple(float(x) for x in eye)
        self.direction = None if direction is None else np.asarray(direction, np.float32)

    @classmethod
    def from_view_matrix(cls, view_matrix, perspective):
        """From a world -> view matrix (RegionView3D.view_matrix convention, camera looks along -Z)."""
        inv = np.linalg.inv(np.asarray(view_matrix, np.float64).reshape(4, 4))
        return cls.from_camera_matrix(inv, perspective)

    @classmethod
    def from_camera_matrix(cls, camera_to_world, perspective):
        m = np.asarray(camera_to_world, np.float64).reshape(4, 4)
        if perspective:
            return cls(True, eye=m[:3, 3])
        z = m[:3, 2]
        norm = np.linalg.norm(z)
        if not norm > 0:
            raise SetupError("The view matrix is degenerate")
        return cls(False, direction=z / norm)

    @property
    def signature(self):
        return (self.perspective, self.eye, None if self.direction is None else tuple(self.direction.tolist()))


def camera_view(scene):
    cam = scene.camera
    if cam is None:
        raise SetupError("The scene has no camera")
    perspective = getattr(cam.data, "type", "PERSP") != "ORTHO"
    return View.from_camera_matrix(np.array(cam.matrix_world), perspective)


def region_view(region_3d, scene):
    """The view of a 3D viewport.  Built from its rotation, pivot and distance rather than
    view_matrix, which Blender refreshes only when the viewport redraws."""
    if region_3d.view_perspective == "CAMERA":
        return camera_view(scene)
    rot = np.array(region_3d.view_rotation.to_matrix(), np.float64)  # view -> world
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = np.array(region_3d.view_location, np.float64) + rot[:, 2] * region_3d.view_distance
    return View.from_camera_matrix(m, region_3d.view_perspective == "PERSP")


def find_region_3d(context):
    """The active 3D viewport's RegionView3D, or the first one in the window."""
    rv3d = getattr(context, "region_data", None)
    if rv3d is not None and hasattr(rv3d, "view_matrix"):
        return rv3d
    space = getattr(context, "space_data", None)  # the sidebar's region has no region_data
    if space is not None and space.type == "VIEW_3D" and space.region_3d is not None:
        return space.region_3d
    screens = [context.screen] if getattr(context, "screen", None) else []
    screens += [w.screen for w in context.window_manager.windows]
    for screen in screens:
        for area in screen.areas:
            if area.type == "VIEW_3D":
                return area.spaces.active.region_3d
    return None


# ---------------------------------------------------------------------------------------------
# Meshes


class MeshData:
    """World-space positions and normals of one object's evaluated mesh, per point or per corner,
    with the material slot of each element."""

    __slots__ = ("domain", "positions", "normals", "slots", "count", "note")

    def __init__(self, domain, positions, normals, slots, note=None):
        self.domain = domain
        self.positions = positions
        self.normals = normals
        self.slots = slots
        self.count = len(positions)
        self.note = note


def _read(collection, attr, count, width, dtype=np.float32):
    buf = np.empty(count * width, dtype)
    collection.foreach_get(attr, buf)
    return buf.reshape(count, width) if width > 1 else buf


def read_mesh(obj, depsgraph):
    """MeshData of an object's evaluated mesh (modifiers applied).  When modifiers change the
    topology, the attribute could not be written back to the original mesh element by element, so
    the base mesh is shaded instead and `note` says so."""
    ob_eval = obj.evaluated_get(depsgraph)
    mesh = ob_eval.data
    base = obj.data
    note = None
    if (len(mesh.vertices), len(mesh.loops), len(mesh.polygons)) != (len(base.vertices), len(base.loops),
                                                                       len(base.polygons)):
        mesh = base
        note = f"'{obj.name}': modifiers change the topology; shaded the base mesh (its colours are interpolated)"
    nv, nl, npoly = len(mesh.vertices), len(mesh.loops), len(mesh.polygons)
    if nv == 0:
        return MeshData("POINT", np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32),
                        np.zeros(0, np.int32), note)
    # Generic attributes copy in one memcpy-like pass; the older per-element collections
    # (mesh.loops, mesh.polygons) go through RNA item by item, 10-500x slower on large meshes.
    pos = _read(mesh.attributes["position"].data, "vector", nv, 3)
    mat_attr = mesh.attributes.get("material_index")
    if mat_attr is not None and mat_attr.domain == "FACE" and npoly:
        slots_face = _read(mat_attr.data, "value", npoly, 1, np.int32)
    else:
        slots_face = np.zeros(npoly, np.int32)
    multi = npoly > 0 and len(obj.material_slots) > 1 and slots_face.min() != slots_face.max()
    if mesh.normals_domain == "POINT" and not multi:
        nrm = _read(mesh.vertex_normals, "vector", nv, 3)
        domain = "POINT"
        slots = np.full(nv, slots_face[0] if npoly else 0, np.int32)
    else:
        # Flat or split normals (or several materials): one value per face corner.
        corner_attr = mesh.attributes.get(".corner_vert")
        if corner_attr is not None:
            corner_vert = _read(corner_attr.data, "value", nl, 1, np.int32)
        else:
            corner_vert = _read(mesh.loops, "vertex_index", nl, 1, np.int32)
        nrm = _read(mesh.corner_normals, "vector", nl, 3)
        pos = pos[corner_vert]
        if multi:
            starts = _read(mesh.polygons, "loop_start", npoly, 1, np.int32)
            slots = np.repeat(slots_face, np.diff(starts, append=nl))
        else:
            slots = np.full(nl, slots_face[0] if npoly else 0, np.int32)
        domain = "CORNER"
    mw = ob_eval.matrix_world
    m = np.array(mw, np.float32)
    world_pos = np.matmul(pos, m[:3, :3].T)
    world_pos += m[:3, 3]
    # Normals by the inverse transpose; the core normalises them, so no unit length is needed here.
    # It does refuse zero ones, which degenerate faces have: any direction will do for those.
    # (mathutils inverts in place; numpy.linalg would wake BLAS threads that compete with OpenMP's.)
    world_nrm = np.matmul(nrm, np.array(mw.to_3x3().inverted_safe(), np.float32))
    zero = np.einsum("ij,ij->i", world_nrm, world_nrm) < 1e-30
    if zero.any():
        world_nrm[zero] = (0.0, 0.0, 1.0)
    return MeshData(domain, world_pos, world_nrm, slots, note)


def write_colors(mesh, domain, rgb):
    """Writes (n, 3) colours into the add-on's FLOAT_COLOR attribute (recreated if its domain or
    type differ) and makes it the active colour attribute."""
    attr = mesh.color_attributes.get(ATTRIBUTE)
    if attr is not None and (attr.domain != domain or attr.data_type != "FLOAT_COLOR"):
        mesh.color_attributes.remove(attr)
        attr = None
    if attr is None:
        attr = mesh.color_attributes.new(ATTRIBUTE, "FLOAT_COLOR", domain)
    rgba = np.ones((len(rgb), 4), np.float32)
    rgba[:, :3] = rgb
    attr.data.foreach_set("color", rgba.ravel())
    mesh.color_attributes.active_color = attr
    mesh.update_tag()  # redraw; unlike update(), keeps the cached normals
    return attr


def remove_colors(mesh):
    attr = mesh.color_attributes.get(ATTRIBUTE)
    if attr is not None:
        mesh.color_attributes.remove(attr)
        return True
    return False


def tone_map(rgb, l_max):
    """The thesis's global logarithmic operator: Ld = log10(1 + Lw) / log10(1 + Lmax), applied to
    the luminance, colour kept."""
    lw = rgb @ LUMINANCE
    ld = np.log10(1 + np.maximum(lw, 0)) / np.log10(1 + l_max)
    scale = np.where(lw > 0, ld / np.maximum(lw, 1e-12), 0).astype(np.float32)
    return np.clip(rgb * scale[:, None], 0, 1).astype(np.float32)


def show_attribute_colors(window_manager):
    """Every 3D viewport in solid mode, flat lighting, colours from the active colour attribute."""
    for window in window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                shading = area.spaces.active.shading
                shading.type = "SOLID"
                shading.light = "FLAT"
                shading.color_type = "VERTEX"


# ---------------------------------------------------------------------------------------------
# Shaders: one per quality, kept for the session (the rotation matrices are the expensive part)


def quality_value(name):
    return name.lower()


AUTO = "auto"  # quality_value("AUTO"): one slicing shader per World and material, nothing to precompute
AUTO_CACHE_SIZE = 16


class ShaderCache:
    """Module-level store of wenv.Shader objects keyed by quality.  Tracks which environment and
    material each shader holds so unchanged ones are not set again."""

    def __init__(self):
        self._shaders = {}
        self._env_sig = {}
        self._env_base = {}  # image key -> untransformed wenv.Environment (pixels read once)
        # the last transformed Environment, kept so Auto's analysis of it (made on its first Auto
        # shader) serves later passes and materials under the same World
        self._env_current = (None, None)
        self._mat_key = {}
        self._auto = {}  # (World signature, material key, target, budget) -> wenv.Shader
        self.lock = threading.Lock()
        self.cache_dir = None  # None: wenv's default ($WENV_CACHE_DIR or ~/.cache/wenv)

    def clear(self):
        self._auto.clear()
        self._shaders.clear()
        self._env_sig.clear()
        self._env_base.clear()
        self._env_current = (None, None)
        self._mat_key.clear()

    def forget_data(self):
        """Drops everything derived from Blender data (environments, materials), keeps matrices."""
        self._env_sig = dict.fromkeys(self._env_sig)
        self._mat_key = dict.fromkeys(self._mat_key)
        self._env_base.clear()
        self._env_current = (None, None)
        self._auto.clear()

    def has(self, quality):
        """Whether shading at `quality` is ready without precomputation (always for Auto)."""
        return quality == AUTO or quality in self._shaders

    def add(self, quality, shader, spec=None, mat_key=None):
        self._shaders[quality] = shader
        self._env_sig[quality] = spec.signature if spec is not None else None
        self._mat_key[quality] = mat_key

    def build(self, quality, progress=None):
        """Builds (or loads from the matrix cache) the shader for `quality`; `progress(fraction)`
        may return True to cancel (wenv.CancelledError)."""
        placeholder = wenv.Environment(np.ones((4, 8, 4), np.float32))
        return wenv.Shader(placeholder, wenv.Lambert(DEFAULT_GREY), quality=quality, progress=progress,
                           cache_dir=self.cache_dir)

    def get(self, quality, progress=None):
        if quality not in self._shaders:
            self.add(quality, self.build(quality, progress))
        return self._shaders[quality]

    def environment(self, spec, images):
        if spec.kind == "color":
            return environment_from_spec(spec, images)
        base = self._env_base.get(spec.key)
        if base is None:
            if len(self._env_base) > 4:
                self._env_base.clear()
            base = environment_from_spec(WorldSpec("image", spec.image_name, spec.projection, 0.0, 1.0, key=spec.key),
                                         images)
            self._env_base[spec.key] = base
        if self._env_current[0] != spec.signature:
            self._env_current = (spec.signature, base.with_transform(rotation=spec.rotation, strength=spec.strength))
        return self._env_current[1]

    def use_environment(self, quality, signature, env):
        shader = self._shaders[quality]
        if self._env_sig.get(quality) != signature:
            shader.set_environment(env)
            self._env_sig[quality] = signature
        return shader

    def auto(self, signature, env, key, target_error, memory_budget_mb, normals):
        """The Auto shader for this World and material: wenv picks its setting from the lobes, the
        environment and the mesh's normals (those of the first mesh shaded with them)."""
        cache_key = (signature, key, target_error, memory_budget_mb)
        shader = self._auto.get(cache_key)
        if shader is None:
            if len(self._auto) >= AUTO_CACHE_SIZE:
                self._auto.clear()
            shader = wenv.Shader(env, material_from_key(key), quality="auto", target_error=target_error,
                                 memory_budget_mb=memory_budget_mb, normals=normals)
            self._auto[cache_key] = shader
        return shader

    def use_material(self, quality, key):
        shader = self._shaders[quality]
        if self._mat_key.get(quality) != key:
            shader.set_material(material_from_key(key))
            self._mat_key[quality] = key
        return shader


shaders = ShaderCache()


def shade_arrays(shader, data, view):
    if view.perspective:
        return shader.shade_mesh(data.positions, data.normals, view.eye)
    return shader.shade(data.normals, view.direction)


def slot_material_keys(obj):
    keys = []
    for slot in obj.material_slots:
        mat = slot.material
        ensure_material_settings(mat)
        keys.append(material_key(mat.wenv if mat is not None else None))
    return keys or [("default",)]


class ShadingPlan:
    """One shading pass.  `plan_shading` fills it from Blender data on the main thread (World
    pixels, meshes as world-space arrays, material values); `compute` touches no Blender data, so
    it may run on a worker thread (the live mode does, the core releases the GIL); `apply` writes
    the colours back on the main thread, by object name."""

    def __init__(self, quality, world, environment, view, tone, l_max, target_error=0.01, memory_budget_mb=1024):
        self.quality = quality
        self.target_error = target_error
        self.memory_budget_mb = memory_budget_mb
        self.world = world
        self.environment = environment
        self.view = view
        self.tone = tone
        self.l_max = l_max
        self.items = []  # (object name, MeshData, material keys per slot)
        self.notes = []
        self.results = None
        self.auto_choices = {}  # (object name, material key) -> stats["auto"] of the shader used

    def compute(self):
        results = []
        with shaders.lock:
            if self.quality != AUTO:
                shaders.use_environment(self.quality, self.world.signature, self.environment)
            for name, data, keys in self.items:
                rgb = np.empty((data.count, 3), np.float32)
                slots = np.clip(data.slots, 0, len(keys) - 1)
                for s in np.unique(slots):
                    sel = slots == s
                    if self.quality == AUTO:
                        shader = shaders.auto(self.world.signature, self.environment, keys[s], self.target_error,
                                              self.memory_budget_mb, data.normals[sel])
                        self.auto_choices[(name, keys[s])] = shader.stats["auto"]
                    else:
                        shader = shaders.use_material(self.quality, keys[s])
                    if sel.all():
                        rgb[:] = shade_arrays(shader, data, self.view)
                    else:
                        part = MeshData(data.domain, np.ascontiguousarray(data.positions[sel]),
                                        np.ascontiguousarray(data.normals[sel]), None)
                        rgb[sel] = shade_arrays(shader, part, self.view)
                if self.tone == "LOG":
                    rgb = tone_map(rgb, self.l_max)
                results.append((name, data.domain, rgb))
        self.results = results

    def apply(self, objects):
        """Writes the results into the meshes of `objects` (bpy.data.objects); an object deleted or
        edited since plan_shading is skipped.  Returns the names written."""
        done = []
        for name, domain, rgb in self.results:
            obj = objects.get(name)
            if obj is None or obj.type != "MESH":
                continue
            size = len(obj.data.vertices) if domain == "POINT" else len(obj.data.loops)
            if size == len(rgb):
                write_colors(obj.data, domain, rgb)
                done.append(name)
        return done


def plan_shading(scene, depsgraph, objects, view, images, progress=None):
    """Reads everything a pass over `objects` needs (main thread); builds the scene quality's
    shader first if it is missing.  Raises SetupError for a set-up that cannot be shaded."""
    st = scene.wenv
    spec = world_spec(scene.world)
    quality = quality_value(st.quality)
    notes = []
    editing = [o.name for o in objects if o.type == "MESH" and o.mode == "EDIT"]
    if editing:
        notes.append("skipped meshes in Edit Mode (leave it to shade them): " + ", ".join(editing))
    meshes = [o for o in objects if o.type == "MESH" and o.mode != "EDIT"]
    skipped = [o.name for o in objects if o.type != "MESH"]
    if skipped:
        notes.append("skipped objects that are not meshes: " + ", ".join(skipped))
    if not meshes:
        raise SetupError("Leave Edit Mode to shade" if editing else
                         "No mesh objects to shade: select at least one mesh")
    plan = ShadingPlan(quality, spec, shaders.environment(spec, images), view, st.tone_mapping, st.max_luminance,
                       st.target_error / 100.0, st.memory_budget)
    plan.notes = notes
    for obj in meshes:
        data = read_mesh(obj, depsgraph)
        if data.note:
            notes.append(data.note)
        if data.count == 0:
            notes.append(f"'{obj.name}' has no vertices")
            continue
        plan.items.append((obj.name, data, slot_material_keys(obj)))
    if quality != AUTO:
        shaders.get(quality, progress)
    return plan


def shade_objects(scene, depsgraph, objects, view, blend_data, progress=None):
    """Shades every mesh in `objects` for `view` with the scene's wenv settings, synchronously.
    Returns (shaded names, notes)."""
    plan = plan_shading(scene, depsgraph, objects, view, blend_data.images, progress)
    plan.compute()
    for (name, _key), choice in plan.auto_choices.items():
        if choice["method"] == "sh":  # a material without lobes: SH irradiance
            chose = f"spherical harmonics of order {choice['sh_order']}"
        else:
            q = wenv.AUTO_LADDER[choice["level"]]
            chose = ("the High preset" if q == wenv.QUALITY_PRESETS["high"]
                     else f"{q['global']}/{q['local']}/{q['normals']}, views {q['views']}")
        plan.notes.append(f"'{name}': Auto chose {chose} "
                          f"(predicted error {100 * choice['predicted_error']:.2g} %"
                          + ("" if choice["met"] else f", above the {100 * choice['target_error']:.2g} % target") + ")")
    return plan.apply(blend_data.objects), plan.notes


def shaded_objects(scene):
    """Mesh objects in the scene that carry the add-on's attribute."""
    return [o for o in scene.objects if o.type == "MESH" and ATTRIBUTE in o.data.color_attributes]
