"""The only add-on module that touches the compiled `wenv` core: its limits, calls and shaders.

Every other module reaches the core through this one (as Cycles' add-on does through engine.py),
so what the core accepts is read here once, never repeated.  It imports no other add-on module,
so any of them may import it without a cycle.
"""
import hashlib
import os
import threading
import warnings

import numpy as np
import wenv

# ---------------------------------------------------------------------------------------------
# What the core accepts, read from it so properties and clamps follow a rebuilt core

QUALITY_PRESETS = wenv.QUALITY_PRESETS
QUALITIES = tuple(QUALITY_PRESETS)  # preset names, cheapest first
AUTO = "auto"  # quality_value("AUTO"): one slicing shader per World and material, nothing to precompute
AUTO_CACHE_SIZE = 16
ALPHA_RANGE = wenv.ALPHA_RANGE  # (min, max) of a lobe's alpha, both ends accepted
IOR_RANGE = wenv.IOR_RANGE  # (min, max): an index must be > min and <= max
IOR_MIN = IOR_RANGE[0] + 1e-4  # the lowest index offered, since the core refuses IOR_RANGE[0] itself

DEFAULT_GREY = (0.8, 0.8, 0.8)  # Blender's default material: what a mesh without one is shaded with

CancelledError = wenv.CancelledError  # raised when a progress callback asks to stop


# Rec. 709 luminance, as the glossmeter weighs a colour
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


class SetupError(Exception):
    """A scene set-up the add-on cannot shade; the message is shown to the user as it is.  Defined
    here, at the bottom of the add-on's imports, so every module can raise it."""


def quality_value(name):
    """The core's quality name for a Scene.wenv.quality enum identifier."""
    return name.lower()


def alpha_from_roughness(roughness):
    """A lobe's alpha for Blender's roughness r: the core's one conversion (r^2, as Cycles, floored)."""
    return wenv.alpha_from_roughness(float(roughness))


def roughness_from_alpha(alpha):
    """Blender's roughness r whose alpha (alpha_from_roughness) is `alpha`, above the conversion's floor."""
    return float(alpha) ** 0.5


# The Principled BSDF's inputs as the core defines them, once (wenv.Principled.INPUTS): name, socket,
# size, default, whether wenv shades it ("yes", "partly", "no") and the note a user reads when it
# is set to something wenv does not shade.
PRINCIPLED_INPUTS = wenv.Principled.INPUTS


def clamp_ior(ior):
    """`ior` moved into the range the core accepts (IOR_MIN..IOR_RANGE[1])."""
    return min(max(float(ior), IOR_MIN), IOR_RANGE[1])


# View angles at which lobes' summed albedo is taken: those the core checks (0 to 75 degrees; closer to
# grazing lobes added rather than layered commonly pass 1, which the core leaves as the model gives it).
_ENERGY_VIEW_DEGREES = (0.0, 36.9, 53.1, 66.4, 74.9)


def lobes_peak_albedo(lobes):
    """The most the Cook-Torrance lobes (dicts as wenv.CookTorrance takes) reflect together of
    what they receive, over the views the core checks and the three channels."""
    t = np.radians(_ENERGY_VIEW_DEGREES)
    views = np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], axis=1).astype(np.float32)
    total = np.zeros((len(t), 3))
    for lobe in lobes:
        white = wenv.CookTorrance(lobes=[{"specular": 1.0, "alpha": lobe["alpha"], "ior": lobe["ior"],
                                          "distribution": lobe["distribution"].lower()}])
        total += white.albedo(views) * np.asarray(lobe["specular"], np.float64)
    return float(total.max()) if lobes else 0.0


# ---------------------------------------------------------------------------------------------
# Core objects from plain values


def environment(pixels, projection="equirect", rotation=0.0, strength=1.0):
    """wenv.Environment of RGBA float32 pixels (H, W, 4), row 0 the top; ValueError if refused."""
    return wenv.Environment(pixels, projection=projection, rotation=rotation, strength=strength)


# Measured BRDFs read from files, keyed by (absolute path, size, modification time): each file is read
# once per version and its table shared by every shader and reading (a 90 x 90 x 180 MERL table is
# 17.5 MB), not copied per material.
_MEASURED_CACHE_SIZE = 8
_measured = {}
_measured_lock = threading.Lock()


def file_signature(path):
    """(absolute path, size, mtime in ns) of a BRDF file, or (path, None, None) when it cannot be
    read: what a material's key holds so a changed or replaced file is read again."""
    try:
        st = os.stat(path)
    except OSError:
        return (path, None, None)
    return (path, st.st_size, st.st_mtime_ns)


def measured_brdf(signature, shown_path):
    """The wenv.Tabulated of a MERL file, `signature` from file_signature; SetupError naming
    `shown_path` (as the user wrote it) when it is missing or not a MERL table."""
    path, size, _ = signature
    if size is None:
        raise SetupError(f"Measured BRDF file '{shown_path}' not found"
                         + (f" (looked at {path})" if shown_path != path else ""))
    with _measured_lock:
        table = _measured.get(signature)
        if table is None:
            try:
                table = wenv.load_brdf(path)
            except OSError as exc:
                raise SetupError(f"Measured BRDF file '{shown_path}' could not be read: {exc}") from None
            if len(_measured) >= _MEASURED_CACHE_SIZE:
                _measured.clear()
            _measured[signature] = table
    return table


def term_keys(key):
    """The keys of the core materials a material_key is shaded with: its own, or a mixture's terms'."""
    return [k for k, _ in key[1]] if key[0] == "MIXTURE" else [key]


def material_from_key(key):
    """wenv material for a materials.material_key(); a missing material is Blender's default
    grey, Lambertian.  SetupError for a measured BRDF whose file is missing or unreadable; a mixture
    of shader nodes is shaded term by term (term_keys)."""
    if key[0] == "MIXTURE":
        raise SetupError("a mixture of shader nodes is shaded term by term")
    if key[0] == "default":
        return wenv.Lambert(DEFAULT_GREY)
    if key[0] == "MEASURED":
        _, shown_path, signature = key
        return measured_brdf(signature, shown_path)
    if key[0] == "PRINCIPLED":
        return principled(dict(key[1]))
    model, diffuse, shadowing, lobes = key
    if model == "LAMBERT":
        return wenv.Lambert(diffuse)
    return wenv.CookTorrance(
        diffuse=diffuse,
        lobes=[{"specular": s, "alpha": a, "ior": n, "distribution": d.lower()} for s, a, n, d in lobes],
        shadowing=shadowing.lower())


def principled(inputs):
    """wenv.Principled of the node's inputs (wenv's names).  What it does not shade the add-on lists
    itself (materials.principled_notes), so the core's warning about it is not repeated."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return wenv.Principled(**inputs)


def principled_unhonoured(inputs):
    """The names of the inputs wenv does not shade (wenv.Principled.unhonoured)."""
    return principled(inputs).unhonoured


def fit_principled_roughness(inputs, target, geometry):
    """The Principled Roughness (Blender's) reading `target` GU, the other inputs kept."""
    return wenv.fit_roughness(target, geometry, material=principled(inputs))


def gloss(key, geometries):
    """Glossmeter readings (GU) of a material_key at each geometry, then its haze (HU, ASTM E430 with
    the 20 degree instrument); ValueError or RuntimeError if the core cannot read it, SetupError if
    its BRDF file cannot be read.  A mixture of shader nodes reads as the sum of its terms' readings,
    each by its weight's luminance (the instrument's flux is linear in the BRDF)."""
    if key[0] == "MIXTURE":
        total = np.zeros(len(geometries) + 1)
        for term_key, weight in key[1]:
            total += float(np.float32(weight) @ LUMINANCE) * np.array(gloss(term_key, geometries))
        return tuple(float(x) for x in total)
    mat = material_from_key(key)
    return tuple(wenv.gloss(mat, geometries)) + (wenv.haze(mat),)


def fit_alpha(target, **options):
    """wenv.fit_alpha: a Cook-Torrance lobe's alpha reading `target` GU (ValueError if none can)."""
    return wenv.fit_alpha(target, **options)


_method_memo = {}


def needs_matrices(quality):
    """Whether shading at `quality` starts by precomputing rotation matrices (built once, then read
    from the cache); slicing, which `default`, `high` and Auto use unless matrices are cached,
    precomputes nothing.  The core's choice, asked once per quality and cache folder (panels ask at
    every redraw)."""
    if quality == AUTO:
        return False
    key = (quality, shaders.cache_dir)
    if key not in _method_memo:
        _method_memo[key] = wenv.method_for(quality, cache_dir=shaders.cache_dir) == "rotation"
    return _method_memo[key]


def preparing(quality):
    """What building the shader for `quality` does, in a user's words (for progress messages)."""
    return f"precomputing the {quality} matrices" if needs_matrices(quality) else f"preparing {quality} shading"


def describe_auto_choice(choice):
    """Words for what an Auto shader chose (its stats["auto"]), for the notes shown to the user."""
    if choice["method"] == "sh":  # a material without lobes: SH irradiance
        return f"spherical harmonics of order {choice['sh_order']}"
    q = wenv.AUTO_LADDER[choice["level"]]
    preset = next((name for name, p in QUALITY_PRESETS.items() if p == q), None)
    return (f"the {preset.title()} preset" if preset is not None
            else f"{q['global']}/{q['local']}/{q['normals']}, views {q['views']}")


# ---------------------------------------------------------------------------------------------
# Shadows: the scene's meshes as occluders, and each shaded part's occlusion, kept per mesh state

def fingerprint(*arrays):
    """What tells arrays apart by content (a cache key)."""
    h = hashlib.blake2b(digest_size=16)
    for a in arrays:
        h.update(np.ascontiguousarray(a).view(np.uint8).ravel())
        h.update(str(a.shape).encode())
    return h.digest()


def with_area(positions, triangles):
    """Which triangles have an area: not zero, between finite positions (the core refuses the others)."""
    a, b, c = (positions[triangles[:, k]].astype(np.float64) for k in range(3))
    with np.errstate(invalid="ignore", over="ignore"):
        area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    return np.isfinite(area) & (area > 0.0)


def shadow_triangles(positions, triangles):
    """The triangles of a mesh that can block light: those with_area (a degenerate face blocks
    nothing).  Returns (kept, dropped)."""
    if len(triangles) == 0:
        return triangles.reshape(0, 3), 0
    keep = with_area(positions, triangles)
    return np.ascontiguousarray(triangles[keep]), int((~keep).sum())


def occluder_bytes(positions, triangles):
    """About the bytes occluders of `positions` and `triangles` (arrays, or None) take: what the memory
    budget holds them to."""
    return wenv.Occluders.bytes_needed(0 if positions is None else len(positions),
                                       0 if triangles is None else len(triangles))


def merged_occluders(meshes, memory_budget_mb=1024):
    """(wenv.Occluders of `meshes` ([(world positions, triangles)]) as one, where each one's vertices
    start among its positions)."""
    positions = np.ascontiguousarray(np.vstack([p for p, _ in meshes]), np.float32)
    offsets = np.cumsum([0] + [len(p) for p, _ in meshes])
    triangles = np.vstack([t + o for (_, t), o in zip(meshes, offsets)]).astype(np.int64)
    return wenv.Occluders(positions, triangles, memory_budget_mb=memory_budget_mb), offsets


class ShadowCache:
    """The scene's occluders (an Embree scene of every blocking mesh, world space) and each shaded
    part's occlusion, kept while the meshes' positions and triangles are unchanged (by content: a
    new view, World or material casts no ray).  When meshes change (moved, deformed, edited, added
    or removed), a part that did not change is made from its occlusion before, casting again only
    the vertices whose rays met the changed meshes or meet them now.  Holds no Blender data."""

    def __init__(self):
        self.lock = threading.Lock()
        self.clear()

    def clear(self):
        self._mesh_keys = None  # fingerprint of each mesh of the occluders, in order
        self._triangle_counts = None
        self._occluders = None
        self._occlusions = {}  # fingerprint of a part's positions and normals -> wenv.Occlusion
        self._before = {}  # the same, cast against the occluders before the last change
        self._changed = None  # (first, count): the triangles of those occluders that changed
        self._lights = {}  # (id of an occlusion kept above, what it is of which material) -> (key, light)
        self._some = {}  # fingerprints of some of the meshes -> their wenv.Occluders (a lamp's shadow linking)

    def occluders(self, meshes, memory_budget_mb=1024):
        """wenv.Occluders of `meshes` ((positions, triangles) each, in order) and where each one's
        vertices start among its positions; the same object while the meshes are unchanged."""
        keys = [fingerprint(p, t) for p, t in meshes]
        if keys != self._mesh_keys:
            occluders, offsets = merged_occluders(meshes, memory_budget_mb)
            self._changed = None if self._mesh_keys is None else _changed_triangles(
                self._mesh_keys, keys, self._triangle_counts, [len(t) for _, t in meshes])
            self._before = self._occlusions if self._changed is not None else {}
            self._occluders = (occluders, offsets)
            self._mesh_keys, self._triangle_counts = keys, [len(t) for _, t in meshes]
            self._occlusions = {}
            self._lights = {}
            self._some = {}
        return self._occluders

    def occluders_of(self, meshes, memory_budget_mb=1024):
        """wenv.Occluders of some of the meshes occluders() was last given ((positions, triangles)
        each): what blocks a lamp whose Light links its shadows.  Kept while those meshes are."""
        key = tuple(fingerprint(p, t) for p, t in meshes)
        if key not in self._some:
            self._some[key] = merged_occluders(meshes, memory_budget_mb)[0]
        return self._some[key]

    def occlusion(self, occluders, positions, normals, progress=None):
        """The occlusion of one part (its world positions and normals) against `occluders`: kept,
        made from the one before the last change when the part itself did not change, or cast."""
        key = fingerprint(positions, normals)
        if key not in self._occlusions:
            if progress is not None:  # rays are cast from here: the start, whenever the core's first report comes
                progress(0.0)
            before = self._before.get(key)  # kept until made: a cancelled pass may come back for it
            if before is not None:
                made = occluders.occlusion(positions, normals, progress=progress, previous=before,
                                           changed=self._changed)
                del self._before[key]
            else:
                # the core's Auto: 16 x 16 texels up to 32k vertices, 8 x 8 at 126k (casting ~1.7 s)
                made = occluders.occlusion(positions, normals, resolution=self.occlusion_resolution(len(positions)),
                                           progress=progress)
            self._occlusions[key] = made
        return self._occlusions[key]

    @staticmethod
    def occlusion_resolution(count):
        """The side of the masks occlusion() casts `count` vertices at (the core's Auto)."""
        return wenv.Occluders.auto_resolution(count)

    @staticmethod
    def cast(occluders, positions, normals, resolution, point_rays=False, progress=None, mask_blocks=None):
        """An occlusion cast at `resolution` for one pass and kept nowhere (a bake's texels: millions
        of them, each bake of other texels); the elements of one of `mask_blocks` (meshes.MeshData's)
        share the mask of its first."""
        if progress is not None:
            progress(0.0)
        return occluders.occlusion(positions, normals, resolution=resolution, progress=progress,
                                   point_rays=point_rays, masks_from=masks_from(mask_blocks))

    def drop_light(self):
        """Forgets every light made (as a new World would make it anew), keeping the rays."""
        self._lights = {}

    def light(self, occlusion, holder, key, make):
        """The light a part sends back (make() when not kept): it depends on its occlusion and on
        `key`, what lights it and what it is made of (World, material, quality), not on the view.
        One is kept per occlusion and `holder` (what it is, of which material), the last made: a
        World turning in live mode makes a new one each time."""
        slot = (id(occlusion), holder)
        kept = self._lights.get(slot)
        if kept is None or kept[0] != key:
            kept = self._lights[slot] = (key, make())
        return kept[1]


def masks_from(blocks):
    """The element whose mask each reads (wenv's masks_from): the first of its block (blocks >= 0), or
    itself (-1); None for None."""
    if blocks is None:
        return None
    out = np.arange(len(blocks))
    rows = np.flatnonzero(blocks >= 0)
    ids = blocks[rows]
    first = np.empty(int(ids.max()) + 1 if len(ids) else 0, np.int64)
    first[ids[::-1]] = rows[::-1]  # of repeated indices the last assignment stays: each block's first row
    out[rows] = first[ids]
    return out


def _changed_triangles(keys_before, keys, counts_before, counts):
    """(first, count) of the triangles before that changed between two lists of meshes (their
    fingerprints): those between the meshes both lists start and end with."""
    head = 0
    while head < min(len(keys), len(keys_before)) and keys[head] == keys_before[head]:
        head += 1
    tail = 0
    while (tail < min(len(keys), len(keys_before)) - head and
           keys[len(keys) - 1 - tail] == keys_before[len(keys_before) - 1 - tail]):
        tail += 1
    first = sum(counts_before[:head])
    return first, sum(counts_before[head:len(keys_before) - tail])


shadows = ShadowCache()


# The methods that shade with shadows (the wavelet ones); Auto may choose another, which says so.
SHADOW_METHODS = ("rotation", "slicing")


def models_shadows(shader):
    return shader.method in SHADOW_METHODS


# The inputs the core shades per vertex through a family of materials (the wavelet methods only): all
# it takes per vertex but the colours every method takes
VERTEX_MATERIAL_INPUTS = tuple(row["name"] for row in PRINCIPLED_INPUTS
                               if row["per_vertex"] and row["name"] not in ("base_color", "emission_color"))
# how much may vary per vertex at once (the core's limits)
PER_VERTEX_LIMITS = wenv.Principled.PER_VERTEX


def takes_vertex_materials(shader):
    return shader.method in SHADOW_METHODS


def diffuse_light(shader, data, occlusion, lamps=None):
    """The light each vertex of `data` sends back to what it blocks: its Lambertian part's, head-on,
    with its shadows (and its own inputs, read from textures: data.inputs), the lamps' included."""
    kw = dict(lamps=lamps, positions=data.positions) if lamps else {}
    return shader.diffuse_light(_shading_normals(data), occlusion=occlusion, **kw, **_bent(data), **data.inputs)


# What a blocker sends towards what it shadows, its glossy light included (a metal's mirror image
# of its surroundings): each sending vertex's radiance at SENDING_SIDE x SENDING_SIDE directions of
# its hemisphere (the core's sending maps: Occlusion.sending_directions, read_sent).
SENDING_SIDE = 8
# what the maps are shaded at: Draft, whose few per cent on a lobe are a few per cent of a bounce
SENDING_QUALITY = "draft"
# The roughness the maps' lobes are widened to at least (Blender's; GGX alpha 0.16): a lobe narrower
# than the maps' spacing (about 22 degrees) would be read where a texel centre happens to fall, and
# a sun's highlight caught on one would spread over its neighbours many times over.  Widening keeps
# the light a lobe reflects and spreads it as the maps can hold it.
SENDING_ROUGHNESS = 0.6
ROUGHNESS_INPUTS = ("roughness", "coat_roughness")


def sending_key(key):
    """The material key the sending maps are shaded with: `key`'s lobes widened to SENDING_ROUGHNESS
    at least (a measured BRDF as it is)."""
    if key[0] == "PRINCIPLED":
        inputs = dict(key[1])
        for name in ROUGHNESS_INPUTS:
            if name in inputs:
                inputs[name] = max(inputs[name], SENDING_ROUGHNESS)
        return ("PRINCIPLED", tuple(sorted(inputs.items())))
    if key[0] in ("MIXTURE", "default", "MEASURED") or key[0] == "LAMBERT":
        return key
    model, diffuse, shadowing, lobes = key
    least = alpha_from_roughness(SENDING_ROUGHNESS)
    return (model, diffuse, shadowing, tuple((s, max(a, least), n, d) for s, a, n, d in lobes))


def sending_inputs(inputs):
    """Per-vertex inputs with their roughness widened as sending_key widens the material's."""
    return {k: np.maximum(v, np.float32(SENDING_ROUGHNESS)) if k in ROUGHNESS_INPUTS else v
            for k, v in inputs.items()}


def sent_light(shader, data, occlusion, lamps=None, bounce_hits=None):
    """The radiance each vertex of `data` sends towards each direction of its sending map (those of
    occlusion.sending_directions), with its shadows and lamps, and what reaches its blocked
    directions (bounce_hits; None: black): (n, SENDING_SIDE^2, 3)."""
    kw = dict(lamps=lamps, positions=data.positions) if lamps else {}
    kw.update(bounce=None) if bounce_hits is None else kw.update(bounce_hits=bounce_hits)
    directions = occlusion.sending_directions(SENDING_SIDE)
    out = np.empty((data.count, len(directions), 3), np.float32)
    for j, views in enumerate(directions):
        out[:, j] = shader.shade(_shading_normals(data), views, occlusion=occlusion, **kw, **_bent(data),
                                 **data.inputs)
    return out


def make_lamps(settings, blockers=None):
    """wenv.Lamp for each of lamps.read_lamps' settings, lamp j blocked by blockers[j] where given (a
    wenv.Occluders; False: by nothing) rather than by the scene; SetupError naming the light whose
    setting the core refuses (a negative or infinite power a script set, say)."""
    made = []
    for j, s in enumerate(settings):
        kw = {k: v for k, v in s.items() if k not in ("type", "matrix", "name", "receivers", "blockers")}
        own = (blockers or {}).get(j)
        if own is False:
            kw["cast_shadow"] = False
        elif own is not None:
            kw["blockers"] = own
        try:
            made.append(wenv.Lamp(s["type"], s["matrix"], **kw))
        except ValueError as exc:
            raise SetupError(f"Light '{s['name']}': {exc}") from None
    return made


def _shading_normals(data):
    """The normals shading reads: a normal map's where there is one, else the mesh's."""
    return data.normals if data.shading_normals is None else data.shading_normals


def _bent(data):
    """The keywords telling the core which normals a normal map or Bump node bent, so that their
    Lambertian part receives its light as Cycles' bump terminator lets it through."""
    if data.shading_normals is None:
        return {}
    return {"smooth_normals": data.normals, "bump_map_correction": data.bump_map_correction}


# ---------------------------------------------------------------------------------------------
# Bakes: which texel lies in which UV triangle, and the margin about the islands


def uv_texels(uv, triangles, width, height, memory_budget_mb, progress=None, border=False):
    """wenv.uv_texels: (triangle per texel or -1 (height, width), -2 - t for the border ring's with
    `border`, barycentric weights of the second and third corners (height, width, 2), texels covered,
    texels overlapped); SetupError when the image has no texels or its bake would pass the memory
    budget."""
    try:
        return wenv.uv_texels(uv, triangles, width, height, memory_budget_mb=memory_budget_mb, progress=progress,
                              border=border)
    except ValueError as exc:
        raise SetupError(f"Cannot bake: {exc}") from None


def noise_texture(points, **settings):
    """(fac, colour) of Blender's Noise Texture at `points` ((n, 3) float32), as Cycles evaluates it
    (wenv.noise_texture's settings)."""
    return wenv.noise_texture(np.ascontiguousarray(points, np.float32), **settings)


def voronoi_texture(points, **settings):
    """(distance, colour) of Blender's Voronoi Texture at `points` ((n, 3) float32), as Cycles evaluates it."""
    return wenv.voronoi_texture(np.ascontiguousarray(points, np.float32), **settings)


def wave_texture(points, **settings):
    """Blender's Wave Texture's Fac at `points` ((n, 3) float32), as Cycles evaluates it."""
    return wenv.wave_texture(np.ascontiguousarray(points, np.float32), **settings)


def white_noise_texture(points, w=0.0, **settings):
    """(value, colour) of Blender's White Noise Texture at `points` ((n, 3) float32) and W, as Cycles
    evaluates it."""
    return wenv.white_noise_texture(np.ascontiguousarray(points, np.float32), w, **settings)


def gabor_texture(points, **settings):
    """(value, phase, intensity) of Blender's Gabor Texture at `points` ((n, 3) float32), as Cycles
    evaluates it."""
    return wenv.gabor_texture(np.ascontiguousarray(points, np.float32), **settings)


def corner_values_at(values, corners, weights):
    """wenv.corner_values_at: values per face corner (m, k) at points of corners and weights (n, 3),
    (n, k) float32."""
    return wenv.corner_values_at(values, corners, weights)


def extend_margin(pixels, filled, margin):
    """wenv.extend_margin: the islands' colours carried `margin` texels outwards, in place."""
    return wenv.extend_margin(pixels, filled, margin)


# ---------------------------------------------------------------------------------------------
# Shaders: one per quality, kept for the session (the rotation matrices are the expensive part)


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
        # quality -> the material keys its shader keeps (the core keeps the last few it was given:
        # setting one again makes nothing), the current one first
        self._kept = {}
        self._relays = {}  # quality -> the ProgressRelay its shader reports to (set_material cancels)
        self._auto = {}  # (World signature, material key, target, budget) -> wenv.Shader
        self.lock = threading.Lock()
        self.cache_dir = None  # None: wenv's default ($WENV_CACHE_DIR or ~/.cache/wenv)

    def clear(self):
        self._auto.clear()
        self._shaders.clear()
        self._env_sig.clear()
        self._env_base.clear()
        self._env_current = (None, None)
        self._kept.clear()
        self._relays.clear()

    def forget_data(self):
        """Drops everything derived from Blender data (environments, materials), keeps matrices."""
        self._env_sig = dict.fromkeys(self._env_sig)
        self._kept.clear()  # the core still recognises them: setting one again costs nothing
        self._env_base.clear()
        self._env_current = (None, None)
        self._auto.clear()

    def has(self, quality):
        """Whether shading at `quality` is ready without precomputation (always for Auto)."""
        return quality == AUTO or quality in self._shaders

    def add(self, quality, built, spec=None, mat_key=None):
        """Keeps `built` (what build() returned) as the shader for `quality`."""
        self._shaders[quality], self._relays[quality] = built
        self._env_sig[quality] = spec.signature if spec is not None else None
        self._kept[quality] = [mat_key] if mat_key is not None else []

    def build(self, quality, progress=None):
        """Builds (or loads from the matrix cache) the shader for `quality`; `progress(fraction)`
        may return True to cancel (CancelledError).  Returns (shader, relay) for add().  The shader
        keeps its callback for later set_material calls, so it gets a relay that forwards to
        `progress` only while building: a callback that holds Blender data (a window manager) must
        not outlive its operator; use_material points it at a refinement's cancellation."""
        placeholder = wenv.Environment(np.ones((4, 8, 4), np.float32))
        relay = ProgressRelay(progress)
        try:
            return wenv.Shader(placeholder, wenv.Lambert(DEFAULT_GREY), quality=quality, progress=relay,
                               cache_dir=self.cache_dir), relay
        finally:
            relay.target = None

    def get(self, quality, progress=None):
        if quality not in self._shaders:
            self.add(quality, self.build(quality, progress))
        return self._shaders[quality]

    def ready(self, quality, spec, keys, target_error, memory_budget_mb):
        """Whether a pass at `quality` under the World `spec` with the material keys `keys` costs
        only its shading: the shader holds this image (a new rotation or strength remakes nothing)
        and keeps every one of the materials, or Auto has a shader for each.  Otherwise the pass
        remakes lighting slices or BRDF slices first (a new image ~0.25 s, a new material ~0.3-0.7 s
        at `default` for 126k vertices): what the live mode shows PREVIEW_QUALITY for meanwhile."""
        if quality == AUTO:
            return all((spec.signature, k, target_error, memory_budget_mb) in self._auto for k in keys)
        held = self._env_sig.get(quality)
        kept = self._kept.get(quality, ())
        return quality in self._shaders and held is not None and held[0] == spec.key and all(k in kept for k in keys)

    def environment(self, image_key, signature, rotation, strength, load_base):
        """The image `image_key`'s Environment turned and scaled as the World asks.  The
        untransformed one is kept per image, so `load_base()` (which reads the pixels out of
        Blender: world.py) runs once per image; `signature` names the transformed one."""
        base = self._env_base.get(image_key)
        if base is None:
            if len(self._env_base) > 4:
                self._env_base.clear()
            base = load_base()
            self._env_base[image_key] = base
        if self._env_current[0] != signature:
            self._env_current = (signature, base.with_transform(rotation=rotation, strength=strength))
        return self._env_current[1]

    def use_environment(self, quality, signature, env):
        shader = self._shaders[quality]
        if self._env_sig.get(quality) != signature:
            shader.set_environment(env)
            self._env_sig[quality] = signature
        return shader

    def auto(self, signature, env, key, target_error, memory_budget_mb, normals, cancelled=None):
        """The Auto shader for this World and material: wenv picks its setting from the lobes, the
        environment and the mesh's normals (those of the first mesh shaded with them).  Its
        precomputation stops with CancelledError once `cancelled` (a threading.Event) is set."""
        cache_key = (signature, key, target_error, memory_budget_mb)
        shader = self._auto.get(cache_key)
        if shader is None:
            if len(self._auto) >= AUTO_CACHE_SIZE:
                self._auto.clear()
            # a relay, so that the cached shader keeps no tie to this refinement's event
            relay = ProgressRelay((lambda _fraction: cancelled.is_set()) if cancelled is not None else None)
            try:
                shader = wenv.Shader(env, material_from_key(key), quality=AUTO, target_error=target_error,
                                     memory_budget_mb=memory_budget_mb, normals=normals, progress=relay)
            finally:
                relay.target = None
            self._auto[cache_key] = shader
        return shader

    def kept_materials(self, quality):
        """The material keys the shader for `quality` keeps, the current one first (Auto: none)."""
        return tuple(self._kept.get(quality, ()))

    def use_material(self, quality, key, cancelled=None):
        """The shader for `quality` holding material `key`; a new material's BRDF slices stop with
        CancelledError once `cancelled` (a threading.Event) is set, the shader left as it was."""
        shader = self._shaders[quality]
        kept = self._kept.setdefault(quality, [])
        if not kept or kept[0] != key:
            relay = self._relays.get(quality)
            if relay is not None and cancelled is not None:
                relay.target = lambda _fraction: cancelled.is_set()
            try:
                shader.set_material(material_from_key(key))  # one the core keeps costs nothing
            finally:
                if relay is not None:
                    relay.target = None
            kept[:] = ([key] + [k for k in kept if k != key])[:shader.stats.get("materials_kept", 1)]
        return shader


class ProgressRelay:
    """A progress callback whose target can be dropped: reports to `target` while it is set."""

    __slots__ = ("target",)

    def __init__(self, target=None):
        self.target = target

    def __call__(self, fraction):
        target = self.target
        return bool(target(fraction)) if target is not None else False


shaders = ShaderCache()


# What the live mode refines to while the view rests, from which settings (Auto picks its own).
REFINE_QUALITY = "high"
REFINABLE = ("draft", "default")
# What the live mode shows at once while the quality set remakes its slices for a new image or
# material (ShaderCache.ready): ~20 ms for 126k vertices.
PREVIEW_QUALITY = "draft"


def _sparing_the_eye(call, data, eye):
    """call(positions) for data's positions; should the core refuse vertices exactly at the eye
    (wenv.EyeAtVertexError, which lists them), the call is made again with those moved off it along
    their normals.  Returns (result, which were moved, or None): the caller leaves them black."""
    try:
        return call(data.positions), None
    except wenv.EyeAtVertexError as exc:
        at_eye = np.zeros(len(data.positions), bool)
        at_eye[exc.vertices] = True
    positions = data.positions.copy()
    positions[at_eye] -= data.normals[at_eye]
    return call(positions), at_eye


def shade_step(shader, data, view, cull, out, first, budget, scene=None):
    """One step of shade_arrays into `out`: the vertices to shade from the first-th on, for about
    `budget` seconds (the core's shade_mesh(first=, budget=)).  Returns (next, total): where the
    next step starts and how many there are to shade.  An orthographic view is shaded whole."""
    if view.perspective:
        kw = {"cull": True, "view_projection": view.view_projection} if cull and view.view_projection is not None else {}
        kw.update(scene or {}, **_bent(data), **data.inputs)
        _, at_eye = _sparing_the_eye(lambda p: shader.shade_mesh(p, _shading_normals(data), view.eye, out=out,
                                                                 first=first, budget=budget, **kw), data, view.eye)
        if at_eye is not None:
            out[at_eye] = 0.0
        stats = shader.stats
        return stats["next_vertex"], stats.get("visible_vertices", data.count)
    out[:] = shader.shade(_shading_normals(data), view.direction, **_with_positions(scene, data), **_bent(data),
                          **data.inputs)
    return data.count, data.count


def _with_positions(scene, data):
    """The keywords of shading `data` orthographically: scene's, and the positions lamps need."""
    kw = dict(scene or {})
    if kw.get("lamps"):
        kw["positions"] = data.positions
    return kw


def visible_vertices(data, view):
    """Which vertices of `data` a perspective viewport's `view` sees (facing it, on screen)."""
    return wenv.visible_vertices(data.positions, data.normals, view.eye, view.view_projection)


def shade_arrays(shader, data, view, cull=False, scene=None):
    """Radiance (n, 3) for world-space `data` (meshes.MeshData) seen from `view` (views.View), and
    which vertices were shaded: with `cull` and a viewport's perspective view, only those facing
    the eye and on screen (the rest are black), else all (None).  A vertex at the eye is black.
    `scene`: the keywords of shading with shadows (occlusion, bounce) and lamps, or None."""
    if not view.perspective:
        return shader.shade(_shading_normals(data), view.direction, **_with_positions(scene, data), **_bent(data),
                            **data.inputs), None
    seen = None
    kw = dict(scene or {}, **_bent(data), **data.inputs)
    if cull and view.view_projection is not None:
        seen = visible_vertices(data, view)
        kw.update(cull=True, view_projection=view.view_projection)
    rgb, at_eye = _sparing_the_eye(lambda p: shader.shade_mesh(p, _shading_normals(data), view.eye, **kw), data,
                                   view.eye)
    if at_eye is not None:
        rgb[at_eye] = 0.0
        if seen is not None:
            seen[at_eye] = True  # written black
    return rgb, seen
