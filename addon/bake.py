"""Bakes: every texel of an image shaded as a vertex would be, through a mesh's UV map.

Each texel whose centre lies in a UV triangle is shaded at the point of the mesh under that centre:
its position and normal interpolated from the triangle's corners (bent by a normal map or Bump node
read at the texel), its material's inputs read from textures at the texel, lit by the World and the
lamps, seen from the view.  The texels are shaded by the same core call as vertices: a bake is a
mesh of a million vertices that costs no ray and no table row a mesh of that many vertices would
not.  With shadows, each texel casts its own rays against the scene (the object's own mesh and every
other blocker): point rays, every exact light cast along its own ray and a narrow lobe along nine
about its mirror direction, so a shadow's edge is as sharp as the texels; and a mask at the core's
Auto side (4 x 4 from 524k texels), one per 2 x 2 block of texels side by side on one face
(mask_blocks); what the rays meet sends the light of its vertices (their diffuse
light, or with Glossy Bounce their light towards the texel); what the texels' coarse masks miss of
the sky's soft occlusion is added back from the vertices (_mask_correction).  The result goes into a
Blender image (the margin extended about the islands, the texels outside them untouched); undo
restores the image as it was (its pixels are no part of Blender's undo, so the add-on keeps each
bake's and puts them back, restore_after_undo)."""
import copy
import json
import threading

import numpy as np

from . import engine, lamps, materials, meshes, shading, textures, views, world
from .engine import SetupError

DEFAULT_MARGIN = 16  # texels, as Cycles' bake
BAKE_NODE = "wenv bake"  # the Image Texture node showing a bake (the active node: Solid mode's Texture colour)
EMISSION_NODE = "wenv bake emission"  # its light, emitted into
OUTPUT_NODE = "wenv bake output"  # a Material Output for EEVEE only: Material Preview and EEVEE show the bake
# Byte images are stored in their colour space: those wenv writes, and how (float images hold scene
# linear values whatever their colour space says)
SRGB_SPACES = ("sRGB",)
DATA_SPACES = ("Non-Color", "Raw", "Linear Rec.709", "Linear")
# texels' bytes during a bake: the triangle and weights (wenv.uv_texels), the RGBA buffer read and
# written, and the texels' positions, normals and shading
BYTES_PER_TEXEL = 12 + 16


class TexelSites:
    """Where each baked texel's centre lies on a mesh: texel (flat index into the image, row 0 at
    v = 0), the loop triangle holding it, its three corners and their barycentric weights (outside
    the triangle for the ring about the islands, `inside` False).  `uv` are the bake UV map's corner
    coordinates; `shift` the offset in texels of these sites from the texels' centres (shifted())."""

    __slots__ = ("width", "height", "texels", "triangle", "corners", "weights", "tri_corners", "uv", "area", "count",
                 "shift", "inside")

    def __init__(self, width, height, texels, triangle, weights, tri_corners, uv, shift=(0.0, 0.0)):
        self.width, self.height = width, height
        self.texels = texels
        self.triangle = triangle
        self.tri_corners = tri_corners
        self.corners = tri_corners[triangle].astype(np.int64, copy=False)
        self.weights = weights
        self.uv = uv
        self.area = _uv_areas(uv, tri_corners)  # each triangle's area in the bake map
        self.count = len(texels)
        self.shift = shift
        self.inside = np.ones(self.count, bool)  # False: a texel of the ring just outside the islands

    def at(self, values):
        """Values given per face corner ((nl,) or (nl, k)) at each texel, linear over its triangle
        (float32)."""
        out = engine.corner_values_at(values.reshape(len(values), -1), self.corners, self.weights)
        return out.reshape(-1) if values.ndim == 1 else out

    def footprint_in(self, uv):
        """Each texel's side in the units of another UV map (corner coordinates `uv`): the bake's texel
        scaled by how much larger that map's triangle is."""
        ratio = _uv_areas(uv, self.tri_corners)[self.triangle] / self.area[self.triangle]
        return (np.sqrt(ratio / (self.width * self.height))).astype(np.float32)

    def shifted(self, du, dv):
        """The sites `du`, `dv` texels along the bake map's u and v, within each texel's own
        triangle's plane (past its edge where the texel is near one)."""
        a, b, c = (self.uv[self.tri_corners[:, k]].astype(np.float64) for k in range(3))
        e1, e2 = b - a, c - a
        det = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
        su, sv = du / self.width, dv / self.height
        dwb = ((e2[:, 1] * su - e2[:, 0] * sv) / det)[self.triangle]
        dwc = ((-e1[:, 1] * su + e1[:, 0] * sv) / det)[self.triangle]
        weights = self.weights.astype(np.float64)
        weights[:, 1] += dwb
        weights[:, 2] += dwc
        weights[:, 0] = 1.0 - weights[:, 1] - weights[:, 2]
        moved = TexelSites.__new__(TexelSites)
        for name in TexelSites.__slots__:
            setattr(moved, name, getattr(self, name))
        moved.weights = weights.astype(np.float32)
        moved.shift = (self.shift[0] + du, self.shift[1] + dv)
        return moved

    def uv_gradients(self, corner_points):
        """At each texel, the world gradients of the bake map's u and v over its triangle (corner
        positions per face corner, (nl, 3))."""
        t = self.tri_corners
        p0, p1, p2 = (corner_points[t[:, k]] for k in range(3))
        grad_u, _ = textures.triangle_gradients(p0, p1, p2, self.uv[t, 0].astype(np.float64))
        grad_v, _ = textures.triangle_gradients(p0, p1, p2, self.uv[t, 1].astype(np.float64))
        return grad_u[self.triangle], grad_v[self.triangle]


def _uv_areas(uv, tri_corners):
    a, b, c = (uv[tri_corners[:, k]].astype(np.float64) for k in range(3))
    return 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))


def texel_sites(uv, tri_corners, width, height, memory_budget_mb, progress=None, border=False):
    """(TexelSites of the texels whose centres lie in the UV triangles -- with `border`, and the ring
    just outside the islands, each texel of it on its inside neighbour's triangle continued
    (sites.inside False) --, texels two islands both cover)."""
    triangle, weights, _covered, overlapped = engine.uv_texels(uv, tri_corners, width, height, memory_budget_mb,
                                                               progress, border)
    flat = triangle.reshape(-1)
    texels = np.flatnonzero(flat != -1)
    w = weights.reshape(-1, 2)[texels]
    full = np.empty((len(texels), 3), np.float32)
    full[:, 1:] = w
    full[:, 0] = 1.0 - w[:, 0] - w[:, 1]
    held = flat[texels]
    sites = TexelSites(width, height, texels, np.where(held >= 0, held, -2 - held), full, tri_corners, uv)
    sites.inside = held >= 0
    return sites, overlapped


def texel_data(obj, depsgraph, mesh, sites, shadows=False):
    """meshes.MeshData of the texels (domain "TEXEL"): world positions and normals interpolated over
    each texel's triangle (smooth or flat as the mesh's corner normals are), the material slot of its
    face; texels at no finite position are `unplaced` (left black).  With `shadows`, the blocks of
    texels that share an occlusion mask (mask_blocks)."""
    ob_eval = obj.evaluated_get(depsgraph)
    nl = len(mesh.loops)
    nrm = np.empty(nl * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", nrm)
    with np.errstate(invalid="ignore", over="ignore"):
        corner_points = textures.world_points(mesh, ob_eval.matrix_world)[meshes.corner_vertices(mesh)]
        points = sites.at(corner_points)
        normals = sites.at(nrm.reshape(nl, 3)) @ np.array(ob_eval.matrix_world.to_3x3().inverted_safe(), np.float32)
        length = np.linalg.norm(normals, axis=1)
    zero = ~(length > 1e-20)
    normals = np.where(zero[:, None], np.float32([0.0, 0.0, 1.0]), normals / np.where(zero, 1.0, length)[:, None])
    tris = mesh.loop_triangles
    slot_of_triangle = np.empty(len(tris), np.int32)
    tris.foreach_get("material_index", slot_of_triangle)
    notes, unplaced = [], None
    if not (np.isfinite(points).all() and np.isfinite(normals).all()):
        unplaced = ~(np.isfinite(points).all(axis=1) & np.isfinite(normals).all(axis=1))
        points[unplaced] = 0.0
        normals[unplaced] = (0.0, 0.0, 1.0)
        notes.append(f"'{obj.name}': {int(unplaced.sum())} texels at no finite position (NaN or infinite) left black")
    data = meshes.MeshData("TEXEL", np.ascontiguousarray(points, np.float32), np.ascontiguousarray(normals, np.float32),
                           slot_of_triangle[sites.triangle], notes, unplaced)
    data.sites = sites
    if shadows:
        with np.errstate(invalid="ignore", over="ignore"):
            data.mask_blocks = mask_blocks(sites, points, normals, texel_sizes(sites, corner_points))
    return data


def texel_sizes(sites, corner_points):
    """Each texel's side on the mesh (world units): the square root of its share of its triangle's
    area (corner positions per face corner, (nl, 3))."""
    p0, p1, p2 = (corner_points[sites.tri_corners[:, k]].astype(np.float64) for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1)
    return np.sqrt(area / np.maximum(sites.area, 1e-30) / (sites.width * sites.height))[sites.triangle]


# Neighbouring texels that share a mask: within this many texels' sides of their block's first, their
# normals within this angle of its.  A mask's texel is 22 degrees across at the bake's 4 x 4.
SHARED_MASK_REACH = 2.5
SHARED_MASK_COS = np.cos(np.radians(10.0))


def mask_blocks(sites, points, normals, sizes):
    """The texels' blocks of 2 x 2 of the image that share one occlusion mask (meshes.MeshData's
    mask_blocks): each texel joins its block's first (in texel order) where it lies next to it on
    the mesh, facing about the same way (not across a seam to another island, or a crease); else -1.
    Each keeps its own point rays, so a shadow's edge stays as sharp as the texels; what is shared is
    the sky's soft occlusion and the blockers' light, at half the image's resolution."""
    x, y = sites.texels % sites.width, sites.texels // sites.width
    block = (y // 2) * ((sites.width + 1) // 2) + x // 2
    owner = engine.masks_from(block)
    reach = SHARED_MASK_REACH * np.maximum(sizes, sizes[owner])
    near = np.linalg.norm(points - points[owner], axis=1) <= reach
    facing = np.einsum("ij,ij->i", normals, normals[owner]) >= SHARED_MASK_COS
    return np.where(near & facing, block, -1).astype(np.int64)


class _Stages:
    """Progress over a bake's stages, each a share of the whole; progress(fraction) returning True
    cancels (CancelledError at the next report)."""

    SHARES = {"sites": 0.05, "reading": 0.15, "shadows": 0.25, "shading": 0.4, "vertices": 0.1, "writing": 0.05}

    def __init__(self, progress, shadows):
        self.progress = progress
        self.cancelled = threading.Event()
        shares = {k: v for k, v in self.SHARES.items() if shadows or k not in ("shadows", "vertices")}
        total = sum(shares.values())
        self.start, at = {}, 0.0
        for k, v in shares.items():
            self.start[k] = (at / total, v / total)
            at += v

    def report(self, stage, fraction=0.0):
        if self.progress is None:
            return False
        first, share = self.start[stage]
        if self.progress(first + share * min(max(fraction, 0.0), 1.0)):
            self.cancelled.set()
        if self.cancelled.is_set():
            raise engine.CancelledError("the bake was cancelled")
        return False

    def reporter(self, stage):
        return lambda fraction: self.report(stage, fraction)


def _refined(plan, report, cancelled, rays=None):
    """plan's radiance per row of its one item (tone mapping left for later), shaded in steps that
    call report(fraction) (rays(fraction) while shadow rays are cast) and stop once `cancelled` (a
    threading.Event) is set."""
    plan.tone = "NONE"
    plan.cull = False
    results = plan.refine(plan.quality, 0.25, report, cancelled, rays)
    if results is None:
        raise engine.CancelledError("the bake was cancelled")
    return results[0][2]


def _stand_around(plan, around):
    """Puts the scene of `around` (the add-on's vertex plan of the baked object) into `plan` as what
    its items receive light from: the object's own mesh (when it casts shadows) and every other
    blocker, each sending the light its vertices are shaded with (their rays and light kept across
    passes, as the vertex shading keeps them)."""
    plan.shadows = True
    plan.receive_only = True
    if around.items and around.casts[0]:
        name, data, _ = around.items[0]
        plan.blockers.append((name, data.positions, data.triangles))
        if plan.bounce:
            plan.senders.append(around.items[0])
    plan.blockers += around.blockers
    plan.senders += around.senders


def _vertex_shading(plan, item, resolution, report, cancelled):
    """The radiance of `item` (the baked object's vertices) in `plan`'s scene, its masks at
    `resolution` (None: the vertex shading's own, kept) with point rays, as the texels'."""
    at = copy.copy(plan)
    at.items, at.casts, at.resolution = [item], [False], resolution
    return _refined(at, report, cancelled)


def _mask_correction(plan, around, mesh, sites, stages):
    """What the texels' masks miss against the vertices' finer ones, at each texel: the vertices'
    shading with masks of their own side less their shading with masks of the texels' side,
    interpolated over the triangle (None when the sides are the same).  A million texels cast 4 x 4
    rays each, where the vertices of a 31k mesh cast 16 x 16: the sky's soft occlusion is then the
    vertices', and what is sharp (a lamp's or a sun's shadow, a highlight its own geometry hides)
    the texels'.  Both of the vertices' shadings cast point rays, as the texels do: an exact light's
    or a narrow lobe's answer is the same rays in both, and cancels."""
    if not around.items:
        return None
    item = around.items[0]
    side = engine.shadows.occlusion_resolution(item[1].count)
    if side == plan.resolution:
        return None
    fine = _vertex_shading(plan, item, None, lambda f: stages.report("vertices", 0.5 * f), stages.cancelled)
    coarse = _vertex_shading(plan, item, plan.resolution, lambda f: stages.report("vertices", 0.5 + 0.5 * f),
                             stages.cancelled)
    rows = meshes.corner_vertices(mesh) if item[1].domain == "POINT" else np.arange(len(mesh.loops))
    return sites.at((fine - coarse)[rows])


def encode(rgb, image):
    """Linear radiance as `image` stores it: scene linear in a float image; in a byte image, the sRGB
    curve or the values themselves (Non-Color, linear), clipped to [0, 1].  Returns (values, how many
    were clipped).  SetupError for a byte image in another colour space."""
    if image.is_float:
        return rgb, 0
    space = image.colorspace_settings.name
    if space not in SRGB_SPACES + DATA_SPACES:
        raise SetupError(f"Image '{image.name}' stores bytes in colour space '{space}', which wenv does not write: "
                         "use a float image, or sRGB, Non-Color or Linear Rec.709")
    clipped = int(np.count_nonzero((rgb > 1.0).any(axis=1)))
    rgb = np.clip(rgb, 0.0, 1.0)
    if space in SRGB_SPACES:
        rgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(rgb, 1 / 2.4) - 0.055)
    return rgb.astype(np.float32), clipped


def check_image(image, memory_budget_mb):
    """SetupError for an image a bake cannot write: no pixels, tiled, over the memory budget."""
    width, height = image.size
    if image.source == "TILED":
        raise SetupError(f"Image '{image.name}' is a UDIM image: wenv bakes into single images")
    if width == 0 or height == 0:
        raise SetupError(f"Image '{image.name}' has no pixels ({width} x {height}): its file may be missing")
    check_size(width, height, memory_budget_mb)


def check_size(width, height, memory_budget_mb):
    need = width * height * BYTES_PER_TEXEL / 2 ** 20
    if need > memory_budget_mb:
        raise SetupError(f"A {width} x {height} bake needs {need:.0f} MB, over the memory budget of "
                         f"{memory_budget_mb} MB (the scene's wenv Memory Budget)")


def bake(scene, depsgraph, obj, image, view, blend_data, uv_map=None, margin=DEFAULT_MARGIN, progress=None,
         view_source="MATRIX"):
    """Shades every texel of `image` (bpy.types.Image) that lies in a UV island of `obj`'s mesh
    through its UV map `uv_map` (None: the active render one), seen from `view` (views.View), with the
    scene's wenv settings, and writes them into the image; the islands' colours are carried `margin`
    texels outwards, the other texels are left as they were.  progress(fraction) may return True to
    cancel (CancelledError, the image untouched).  The image's wenv settings record the bake, so a
    change of what it was made of marks it stale (staleness); `view_source` ("CAMERA", "VIEWPORT" or
    "MATRIX") says which view to compare with.  Returns (texels baked, notes).  SetupError for what
    cannot be baked: not a mesh, no UV map, an image with no pixels or over the memory budget."""
    if obj is None or obj.type != "MESH":
        raise SetupError(f"'{obj.name}' is not a mesh: only meshes bake" if obj is not None else
                         "No object to bake: select a mesh")
    if obj.mode == "EDIT":
        raise SetupError(f"'{obj.name}' is in Edit Mode: leave it to bake")
    st = scene.wenv
    check_image(image, st.memory_budget)
    if margin < 0:
        raise SetupError(f"The bake's margin must be 0 or more texels, got {margin}")
    stages = _Stages(progress, st.shadows)
    stages.report("sites")
    mesh, notes = meshes.shaded_mesh(obj, depsgraph)
    layer = textures.uv_layer(mesh, uv_map)
    if layer is None:
        raise SetupError(f"'{obj.name}' has no UV map {repr(uv_map) if uv_map else 'to render with'} to bake "
                         "through: add one (UV > Unwrap)")
    width, height = image.size
    tri_corners = textures.triangle_corners(mesh)
    # the margin's first ring is shaded as the surface continued past the islands' edges: filtering
    # across a seam then reads the shading there, not a mean of the island's texels
    sites, overlapped = texel_sites(textures.corner_uvs(mesh, layer), tri_corners, width, height, st.memory_budget,
                                    stages.reporter("sites"), border=margin > 0)
    inside = int(sites.inside.sum())
    if overlapped:
        notes.append(f"UV map '{layer.name}' of '{obj.name}': islands overlap on {overlapped} texels, which show the "
                     "first face's shading (unwrap without overlaps for a bake)")
    if inside == 0:
        raise SetupError(f"No texel of '{image.name}' lies in a face of UV map '{layer.name}' of '{obj.name}'")
    stages.report("reading")
    data = texel_data(obj, depsgraph, mesh, sites, st.shadows)
    data.view = view
    notes.extend(data.notes)
    for read in (textures.read_inputs, textures.read_term_weights, textures.read_shading_normals):
        notes.extend(read(obj, depsgraph, data, progress=stages.reporter("reading")))  # (procedural textures)
    plan = shading.new_plan(scene, view, blend_data.images, cull=False, shadows=False)
    notes += [n for n in plan.notes if n not in notes]
    notes += [n for n in materials.slot_notes(obj) if n not in notes and not n.endswith(textures.AT_VERTICES)]
    plan.items.append((obj.name, data, materials.slot_material_keys(obj)))
    plan.casts.append(False)
    around = None
    if st.shadows:
        around = shading.plan_shading(scene, depsgraph, [obj], view, blend_data.images)
        notes += [n for n in around.notes if n not in notes]
        _stand_around(plan, around)
        plan.resolution, plan.point_rays = engine.shadows.occlusion_resolution(data.count), True
    stages.report("reading", 1.0)
    rgb = _refined(plan, stages.reporter("shading"), stages.cancelled,
                   stages.reporter("shadows") if st.shadows else None)
    if around is not None:
        correction = _mask_correction(plan, around, mesh, sites, stages)
        if correction is not None:
            rgb = np.maximum(rgb + correction, 0.0)
    if data.unplaced is not None:
        rgb[data.unplaced] = 0.0
    if st.tone_mapping == "LOG":
        rgb = shading.tone_map(rgb, st.max_luminance)
    stages.report("writing")
    state = state_of(scene, depsgraph, obj, [p for p in CHANGES if p not in AROUND or reads_other_meshes(obj, st)])
    clipped = write(image, sites, rgb, margin)
    record = image.wenv
    record.baked_object, record.uv_map, record.margin, record.view = obj.name, layer.name, margin, view_source
    record.reads_camera = data.reads_camera
    record.view_key, record.state_key = view_key(view, data.reads_camera), json.dumps(state)
    record.frame, record.texels, record.stale = scene.frame_current, inside, ""
    if clipped:
        notes.append(f"Image '{image.name}' holds bytes: {clipped} texels brighter than 1 were clipped (a float image "
                     "keeps them)")
    stages.report("writing", 1.0)
    return inside, notes


# ---------------------------------------------------------------------------------------------
# What a bake was made of, and whether it still shows it

# What changed, in the panel's words, per part of state_of
CHANGES = {"mesh": "the object moved or its mesh changed", "materials": "a material changed",
           "surroundings": "another mesh that shadows or lights it changed",
           "casters": "another mesh that shadows or lights it changed",
           "world": "the World changed", "lamps": "a lamp changed", "settings": "the scene's wenv settings changed",
           "frames": "an image sequence or movie shows another frame"}
# read from a few datablocks' settings: the panel compares them at each redraw (a frame change need
# not update the depsgraph)
CHEAP = ("world", "lamps", "settings", "frames", "casters")
# recorded only by a bake that read meshes besides its own
AROUND = ("surroundings", "casters")


def _key(value):
    """A short text naming `value` (anything with a repr), floats rounded so that a value read
    twice names the same."""
    return engine.fingerprint(np.frombuffer(repr(value).encode(), np.uint8)).hex()


def view_key(view, reads_camera=False):
    """A key of `view` (of its camera's space and frame too with `reads_camera`)."""
    signature = tuple(np.round(np.asarray(x, np.float64), 5).tolist() if isinstance(x, (tuple, np.ndarray)) else x
                      for x in view.signature)
    return _key((signature, view.camera_signature) if reads_camera else signature)


def reads_other_meshes(obj, settings):
    """Whether a bake of `obj` reads meshes besides its own: the shadows and light of the others
    (the scene's wenv Shadows), or the rays of an Ambient Occlusion node not set to Only Local in
    one of its materials (any node tree the material's reaches)."""
    if settings.shadows:
        return True
    trees = [slot.material.node_tree for slot in obj.material_slots
             if slot.material is not None and slot.material.node_tree is not None]
    seen = set()
    while trees:
        tree = trees.pop()
        if tree.name in seen:
            continue
        seen.add(tree.name)
        for node in tree.nodes:
            if node.bl_idname == "ShaderNodeAmbientOcclusion" and not node.only_local:
                return True
            if getattr(node, "node_tree", None) is not None:
                trees.append(node.node_tree)
    return False


def _mesh_key(obj, depsgraph):
    mesh, _ = meshes.shaded_mesh(obj, depsgraph)
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    return engine.fingerprint(co, np.array(obj.matrix_world, np.float32)).hex()


def _surroundings_key(scene, depsgraph, obj):
    """What the other meshes that may shadow or light `obj` are: each visible one's place and shape,
    whether it casts shadows, and with Bounce Light its materials (their light)."""
    st, others = scene.wenv, []
    bounce = st.shadows and st.bounce_light
    for other in scene.objects:
        if other.type != "MESH" or other.name == obj.name or other.mode == "EDIT" or not other.visible_get():
            continue
        looks = _looks([slot.material for slot in other.material_slots]) if bounce else None
        others.append((other.name, _mesh_key(other, depsgraph), other.wenv.casts_shadows,
                       getattr(other, "visible_shadow", True), looks))
    if depsgraph is not None:  # instances, curves and text: where they are, and with Bounce Light their materials
        for name, p, t, sender in meshes.other_geometry(depsgraph, skip={obj.name}, senders=bounce)[0]:
            others.append((name, engine.fingerprint(p, t).hex(), _looks(sender[1]) if sender is not None else None))
    return _key(others)


def _looks(mats):
    """What the light of a blocker with these materials' slots is made of (or why it cannot be)."""
    try:
        return _key(materials.material_keys(mats))
    except SetupError as exc:
        return _key(str(exc))


def state_of(scene, depsgraph, obj, parts=tuple(CHANGES)):
    """Keys of what a bake of `obj` is made of besides the view (`parts` of CHANGES): its mesh and
    place, its materials, the other meshes about it, the World, the lamps and the scene's wenv
    settings."""
    out = {}
    if "mesh" in parts:
        out["mesh"] = _mesh_key(obj, depsgraph)
    if "materials" in parts:
        out["materials"] = _key(materials.slot_material_keys(obj))
    if "surroundings" in parts:
        out["surroundings"] = _surroundings_key(scene, depsgraph, obj)
    if "casters" in parts:
        # which meshes cast shadows (an add-on's setting updates no depsgraph) and are seen
        out["casters"] = _key(sorted(o.name for o in scene.objects
                                     if o.type == "MESH" and o.name != obj.name and o.wenv.casts_shadows
                                     and getattr(o, "visible_shadow", True) and o.visible_get()))
    if "world" in parts:
        try:
            out["world"] = _key(world.world_spec(scene.world).signature)
        except SetupError as exc:
            out["world"] = _key(str(exc))
    if "lamps" in parts:
        out["lamps"] = _key(lamps.signature(scene))
    if "settings" in parts:
        st = scene.wenv
        out["settings"] = _key((st.quality, st.shadows, st.bounce_light, st.glossy_bounce, st.tone_mapping,
                                round(st.max_luminance, 6), round(st.target_error, 6)))
    if "frames" in parts:
        out["frames"] = _key(textures.frames_shown(obj))
    return out


def note_changes(scene, depsgraph, images, parts, objects_changed, shared_changed=False):
    """After a change to the scene: marks stale (wenv.stale, the words of CHANGES) each baked image of
    `images` whose object is in `scene` and not stale yet, when a part of what it was made of that
    the change could touch (`parts`, of CHANGES; "mesh" only for the objects named in
    `objects_changed`, "surroundings" for the others, or whatever the objects changed with
    `shared_changed`: a collection, material, node tree or image) is no longer what it was.  A bake
    compares only the parts it recorded: "surroundings" where it read other meshes."""
    for image in images:
        record = image.wenv
        if not record.baked_object or record.stale:
            continue
        obj = scene.objects.get(record.baked_object)
        if obj is None or obj.type != "MESH":
            continue
        mine = [p for p in parts if (p != "mesh" or obj.name in objects_changed)
                and (p != "surroundings" or shared_changed or set(objects_changed) - {obj.name})]
        changed = _first_changed(record, scene, depsgraph, obj, mine)
        if changed is not None:
            record.stale = CHANGES[changed]


def _first_changed(record, scene, depsgraph, obj, parts):
    """The first of `parts` (of CHANGES) whose key now differs from the one the bake recorded, or None."""
    if not parts:
        return None
    try:
        before = json.loads(record.state_key)
    except ValueError:
        return parts[0]  # nothing readable was recorded: the bake cannot be called current
    # a part a bake did not record (made before the part was) is not compared
    parts = [p for p in parts if p in before]
    now = state_of(scene, depsgraph, obj, parts)
    return next((p for p in parts if now[p] != before[p]), None)


def staleness(image, scene, context=None):
    """Why `image`'s bake no longer shows what it would now (what changed since, or the view moved),
    or None when it is current or was never baked."""
    record = image.wenv
    if not record.baked_object:
        return None
    if record.stale:
        return record.stale
    # the parts cheap to read are compared here too: a change to an add-on's setting updates no
    # depsgraph, so note_changes never hears of it
    obj = scene.objects.get(record.baked_object)
    changed = _first_changed(record, scene, None, obj, CHEAP) if obj is not None else None
    if changed is not None:
        return CHANGES[changed]
    try:
        if record.view == "CAMERA":
            now = views.camera_view(scene)
        elif record.view == "VIEWPORT" and context is not None:
            rv3d = views.find_region_3d(context)
            now = views.region_view(rv3d, scene) if rv3d is not None else None
        else:
            now = None
    except SetupError:
        return "the view is gone"
    if now is not None and view_key(now, record.reads_camera) != record.view_key:
        return "the camera moved" if record.view == "CAMERA" else "the view changed"
    return None


# ---------------------------------------------------------------------------------------------
# Showing a bake: an Image Texture node in each of the object's materials, the active node (Solid
# mode's Texture colour shows it), and emitted into a Material Output for EEVEE alone (Material
# Preview and EEVEE renders show it; Cycles keeps the material's own output)


def show_in_materials(obj, image):
    """Adds (or points at `image`) the bake's nodes in every material of `obj`; returns the names of
    the materials shown in (materials linked from a library are left alone)."""
    shown = []
    for slot in obj.material_slots:
        mat = slot.material
        if mat is None or mat.library is not None or mat.node_tree is None or mat.name in shown:
            continue
        tree = mat.node_tree
        nodes = tree.nodes
        tex = nodes.get(BAKE_NODE) or nodes.new("ShaderNodeTexImage")
        emit = nodes.get(EMISSION_NODE) or nodes.new("ShaderNodeEmission")
        out = nodes.get(OUTPUT_NODE) or nodes.new("ShaderNodeOutputMaterial")
        for node, name, dx in ((tex, BAKE_NODE, -600.0), (emit, EMISSION_NODE, -300.0), (out, OUTPUT_NODE, 0.0)):
            node.name = node.label = name
            node.location = (dx, -600.0)
        tex.image = image
        tex.interpolation = "Linear"
        emit.inputs["Strength"].default_value = 1.0
        out.target = "EEVEE"
        tree.links.new(tex.outputs["Color"], emit.inputs["Color"])
        tree.links.new(emit.outputs["Emission"], out.inputs["Surface"])
        nodes.active = tex
        shown.append(mat.name)
    return shown


def hide_in_materials(materials_):
    """Removes the bake's nodes from each material of `materials_`; returns how many had them."""
    count = 0
    for mat in materials_:
        if mat is None or mat.library is not None or mat.node_tree is None:
            continue
        nodes = mat.node_tree.nodes
        mine = [n for n in nodes if n.name in (BAKE_NODE, EMISSION_NODE, OUTPUT_NODE)]
        for node in mine:
            nodes.remove(node)
        count += bool(mine)
    return count


# ---------------------------------------------------------------------------------------------
# Writing, and undo

# Each baked image's pixels per step of the undo history: image name -> {"steps": {step: RGBA (h, w, 4)},
# "shown": the step its pixels are}.  Blender's undo does not hold image pixels; the image's
# wenv.bake_step does go back and forth with the steps, and restore_after_undo puts the pixels of the
# step it names back.  Holds no Blender data.
_steps = {}
KEPT_STEPS = 8  # per image: undoing further back than that many bakes leaves the image as it is


def _pixels(image):
    width, height = image.size
    px = np.empty(width * height * 4, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(height, width, 4)


def _put(image, px):
    image.pixels.foreach_set(px.reshape(-1))
    image.update()


def write(image, sites, rgb, margin):
    """Writes the texels' colours (linear) into `image` as it stores them (encode), alpha 1, and the
    margin about them: the sites' ring about the islands, then the rest extended; the pixels before
    are kept for undo.  Returns how many were clipped."""
    values, clipped = encode(rgb, image)
    before = _pixels(image)
    px = before.copy()
    flat = px.reshape(-1, 4)
    flat[sites.texels, :3] = values
    flat[sites.texels, 3] = 1.0
    filled = np.zeros(len(flat), bool)
    filled[sites.texels] = True
    engine.extend_margin(px, filled.reshape(px.shape[:2]), max(margin - int(not sites.inside.all()), 0))
    held = _steps.get(image.name_full)
    if held is None or held["shown"] != image.wenv.bake_step:
        held = {"steps": {image.wenv.bake_step: before}, "shown": image.wenv.bake_step}
        _steps[image.name_full] = held
    step = max(held["steps"]) + 1
    held["steps"][step] = px
    for old in sorted(held["steps"])[:-KEPT_STEPS]:
        del held["steps"][old]
    _put(image, px)
    image.wenv.bake_step = step
    held["shown"] = step
    return clipped


def restore_after_undo(images):
    """After an undo or redo: each baked image of `images` (bpy.data.images) whose wenv.bake_step
    names another bake than its pixels show gets that bake's pixels back (or the pixels from before
    its first bake).  An image with edits of its own since (painted, say) keeps them.  Returns the
    names of the images restored."""
    restored = []
    for image in images:
        held = _steps.get(image.name_full)
        if held is None:
            continue
        step = image.wenv.bake_step
        px = held["steps"].get(step)
        if px is None or tuple(image.size) != (px.shape[1], px.shape[0]):
            continue
        shown = held["steps"].get(held["shown"])
        # an image made again by the undo system (a new image, redone) holds no pixels of a bake
        # yet; one that still holds the bake it showed is put back; one edited since is left alone
        if step == held["shown"] and image.is_dirty:
            continue
        if image.is_dirty and shown is not None and not np.array_equal(_pixels(image), shown):
            continue
        _put(image, px)
        held["shown"] = step
        restored.append(image.name)
    return restored


def forget():
    """Drops every kept bake (a new file was loaded)."""
    _steps.clear()
