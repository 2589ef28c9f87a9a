"""Meshes: evaluated meshes as world-space arrays; shaded colours in their colour attribute."""
import numpy as np

from . import engine

ATTRIBUTE = "wenv_radiance"


class MeshData:
    """World-space positions and normals of one object's evaluated mesh, per point or per corner,
    with the material slot of each element; `unplaced` (bool, or None) marks the elements whose
    position is not finite, which are left black."""

    __slots__ = ("domain", "positions", "normals", "slots", "count", "notes", "unplaced", "triangles", "inputs",
                 "textured", "shading_normals", "bump_map_correction", "term_weights", "term_inputs", "sites",
                 "mask_blocks", "view", "reads_camera", "reads_placement")

    def __init__(self, domain, positions, normals, slots, notes=(), unplaced=None, triangles=None, inputs=None):
        self.domain = domain
        self.positions = positions
        self.normals = normals
        self.slots = slots
        self.count = len(positions)
        self.notes = list(notes)
        self.unplaced = unplaced
        self.triangles = triangles  # (m, 3) int32 indices into positions (what casts shadows), or None
        # Principled inputs read from textures (textures.py), by the core's keyword: colours (n, 3)
        # linear, values (n,), float32, for the material slots in textured[keyword]
        self.inputs = dict(inputs or {})
        self.textured = {}
        # (n, 3) float32 world normals a normal map bends the shading to (textures.py), or None: the
        # mesh's, which the shadows' rays keep; and how Cycles' Bump Map Correction (the
        # materials') masks the bent Lambertian part's grazing light (the core's bump_map_correction:
        # False, or the Blender's term, compat.BUMP_MAP_CORRECTION)
        self.shading_normals = None
        self.bump_map_correction = True
        # per material slot of a mixture of shader nodes: each term's weight, (3,) or (n, 3)
        # (textures.read_term_weights), and each term's inputs read from textures, {keyword: (n,) or
        # (n, 3)}
        self.term_weights = {}
        self.term_inputs = {}
        # for a bake's texels (domain "TEXEL"), where each lies on the mesh (bake.TexelSites); None for
        # vertices and corners
        self.sites = None
        # (n,) int64: elements of one block (>= 0) share one occlusion mask, -1 its own (a bake's 2 x 2
        # texels: bake.mask_blocks); None: each its own
        self.mask_blocks = None
        # the views.View the rows are shaded for (what Layer Weight and Fresnel read), or None; and
        # whether an input read the view's camera space or frame (a Texture Coordinate's Camera or
        # Window), which a turn of the camera then changes
        self.view = None
        self.reads_camera = False
        # whether an input read depends on where the rows lie rather than on the mesh alone (world
        # positions, the view, the object's transform or Object Info: nodes.Evaluator.placed)
        self.reads_placement = False


def _read(collection, attr, count, width, dtype=np.float32):
    buf = np.empty(count * width, dtype)
    collection.foreach_get(attr, buf)
    return buf.reshape(count, width) if width > 1 else buf


def shaded_mesh(obj, depsgraph):
    """The mesh read_mesh shades: the evaluated one (modifiers applied), or the base mesh when
    modifiers change the topology (the attribute could not be written back to the original mesh
    element by element), with a note saying so."""
    mesh, base = obj.evaluated_get(depsgraph).data, obj.data
    if (len(mesh.vertices), len(mesh.loops), len(mesh.polygons)) != (len(base.vertices), len(base.loops),
                                                                       len(base.polygons)):
        return base, [f"'{obj.name}': modifiers change the topology; shaded the base mesh (its colours are "
                      "interpolated)"]
    return mesh, []


def corner_vertices(mesh):
    """The vertex of each face corner (int32, one per loop)."""
    nl = len(mesh.loops)
    corner_attr = mesh.attributes.get(".corner_vert")
    if corner_attr is not None:
        return _read(corner_attr.data, "value", nl, 1, np.int32)
    return _read(mesh.loops, "vertex_index", nl, 1, np.int32)


def read_mesh(obj, depsgraph):
    """MeshData of an object's mesh as shaded_mesh picks it."""
    mesh, notes = shaded_mesh(obj, depsgraph)
    return mesh_data(obj.name, mesh, obj.evaluated_get(depsgraph).matrix_world, len(obj.material_slots), notes)


def mesh_data(name, mesh, matrix_world, slot_count, notes=()):
    """MeshData of `mesh` placed by `matrix_world` (a mathutils.Matrix), whose object has
    `slot_count` material slots; `name` is the object's, for the notes."""
    notes = list(notes)
    nv, nl, npoly = len(mesh.vertices), len(mesh.loops), len(mesh.polygons)
    if nv == 0:
        return MeshData("POINT", np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32),
                        np.zeros(0, np.int32), notes)
    # Generic attributes copy in one memcpy-like pass; the older per-element collections
    # (mesh.loops, mesh.polygons) go through RNA item by item, 10-500x slower on large meshes.
    pos = _read(mesh.attributes["position"].data, "vector", nv, 3)
    mat_attr = mesh.attributes.get("material_index")
    if mat_attr is not None and mat_attr.domain == "FACE" and npoly:
        slots_face = _read(mat_attr.data, "value", npoly, 1, np.int32)
    else:
        slots_face = np.zeros(npoly, np.int32)
    multi = npoly > 0 and slot_count > 1 and slots_face.min() != slots_face.max()
    if mesh.normals_domain == "POINT" and not multi:
        nrm = _read(mesh.vertex_normals, "vector", nv, 3)
        domain = "POINT"
        slots = np.full(nv, slots_face[0] if npoly else 0, np.int32)
    else:
        # Flat or split normals (or several materials): one value per face corner.
        corner_vert = corner_vertices(mesh)
        nrm = _read(mesh.corner_normals, "vector", nl, 3)
        pos = pos[corner_vert]
        if multi:
            starts = _read(mesh.polygons, "loop_start", npoly, 1, np.int32)
            slots = np.repeat(slots_face, np.diff(starts, append=nl))
        else:
            slots = np.full(nl, slots_face[0] if npoly else 0, np.int32)
        domain = "CORNER"
    mw = matrix_world
    m = np.array(mw, np.float32)
    with np.errstate(invalid="ignore", over="ignore"):  # positions not finite: found below
        world_pos = np.matmul(pos, m[:3, :3].T)
        world_pos += m[:3, 3]
        # Normals by the inverse transpose; the core normalises them, so no unit length is needed
        # here.  It does refuse zero ones, which degenerate faces have: any direction will do for
        # those.  (mathutils inverts in place; numpy.linalg would wake BLAS threads that compete
        # with OpenMP's.)
        world_nrm = np.matmul(nrm, np.array(mw.to_3x3().inverted_safe(), np.float32))
        zero = np.einsum("ij,ij->i", world_nrm, world_nrm) < 1e-30
    if zero.any():
        world_nrm[zero] = (0.0, 0.0, 1.0)
    # A vertex at NaN or infinity (a broken import, a scale past float's range) is lit from nowhere:
    # it is left black and the rest shaded, with a note (the core refuses such positions).
    unplaced = None
    if not (np.isfinite(world_pos).all() and np.isfinite(world_nrm).all()):  # ~30x cheaper than by rows
        unplaced = ~(np.isfinite(world_pos).all(axis=1) & np.isfinite(world_nrm).all(axis=1))
        world_pos[unplaced] = 0.0
        world_nrm[unplaced] = (0.0, 0.0, 1.0)
        what = "vertices" if domain == "POINT" else "face corners"
        notes.append(f"'{name}': {int(unplaced.sum())} {what} at no finite position (NaN or infinite) "
                     "left black")
    # the triangles, indexing the points or the corners shaded: what the mesh blocks its sky with
    tris = mesh.loop_triangles
    triangles = _read(tris, "vertices" if domain == "POINT" else "loops", len(tris), 3, np.int32)
    return MeshData(domain, world_pos, world_nrm, slots, notes, unplaced, triangles.reshape(-1, 3))


def joined(parts):
    """One MeshData of several of the same domain (each part's triangles moved past the rows before
    it): what many instances of one object send back, shaded as one part."""
    if len(parts) == 1:
        return parts[0]
    starts = np.cumsum([0] + [d.count for d in parts[:-1]])
    unplaced = (None if all(d.unplaced is None for d in parts) else
                np.concatenate([np.zeros(d.count, bool) if d.unplaced is None else d.unplaced for d in parts]))
    return MeshData(parts[0].domain, np.concatenate([d.positions for d in parts]),
                    np.concatenate([d.normals for d in parts]), np.concatenate([d.slots for d in parts]),
                    [n for d in parts for n in d.notes], unplaced,
                    np.concatenate([d.triangles + np.int32(k) for d, k in zip(parts, starts)]))


# Objects Cycles renders as meshes though they are not: their evaluated geometry
CONVERTED_TYPES = ("CURVE", "FONT", "SURFACE", "META")


def other_geometry(depsgraph, skip=(), room=None, senders=False):
    """[(name, world positions (float32), triangles, sender)] of what blocks light in Cycles besides
    the scene's mesh objects: every instance of a mesh or of such an object (a collection
    instance's, particles', a Geometry Nodes tree's), and the curves, text, surfaces and metaballs,
    which Cycles renders as meshes -- each where its object casts shadows (Object > Visibility >
    Shadow, and wenv's Casts Shadows) -- and how many were left out: past `room` (bytes,
    engine.occluder_bytes; None: no limit), the rest are counted, not read.  `name` is the original
    object's, which light linking names; objects named in `skip` are left out, but not their
    instances.  With `senders`, what sends light back: instances of one object with the same
    materials are one entry, whose sender is (MeshData, [its material slots' materials], the
    instanced mesh object or None (a curve, text...), the rows of each instance in turn) and whose
    positions and triangles are the MeshData's (else sender is None)."""
    out, left, groups = [], 0, {}
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type not in ("MESH",) + CONVERTED_TYPES or not (inst.is_instance or ob.type != "MESH"):
            continue
        original = ob.original
        # (an instance is never the object's own mesh: a scatter's instances shadow the mesh they lie on)
        if (not inst.is_instance and original.name in skip) or not getattr(ob, "visible_shadow", True):
            continue
        if not original.wenv.casts_shadows or (not inst.is_instance and not original.visible_get()):
            continue
        if left:  # (past the room: counted, not read)
            left += 1
            continue
        mesh = ob.data if ob.type == "MESH" else ob.to_mesh()
        try:
            if mesh is None or not len(mesh.polygons):
                continue
            if room is not None:
                room -= engine.occluder_bytes(mesh.vertices, mesh.loop_triangles)
                if room < 0:
                    left = 1
                    continue
            if senders:
                materials = [slot.material.original if slot.material is not None else None
                             for slot in ob.material_slots]
                data = mesh_data(original.name, mesh, inst.matrix_world, len(materials))
                group = (original.name, data.domain, tuple(m.name if m else None for m in materials))
                if group not in groups:
                    groups[group] = len(out)
                    out.append((original.name, None, None, ([], materials, original if inst.is_instance and
                                                            original.type == "MESH" else None)))
                out[groups[group]][3][0].append(data)
                continue
            co = _read(mesh.attributes["position"].data, "vector", len(mesh.vertices), 3)
            triangles = _read(mesh.loop_triangles, "vertices", len(mesh.loop_triangles), 3, np.int32)
        finally:
            if ob.type != "MESH":
                ob.to_mesh_clear()
        m = np.array(inst.matrix_world, np.float32)
        out.append((original.name, (co @ m[:3, :3].T + m[:3, 3]).astype(np.float32), triangles.reshape(-1, 3), None))
    for k, (name, _, _, sender) in enumerate(out):
        if sender is not None:
            parts, materials, original = sender
            data = joined(parts)
            out[k] = (name, data.positions, data.triangles, (data, materials, original, [d.count for d in parts]))
    return out, left


def write_colors(mesh, domain, rgb, seen=None):
    """Writes (n, 3) colours into the add-on's FLOAT_COLOR attribute (recreated if its domain or
    type differ) and makes it the active colour attribute.  With `seen` (bool, n), only those rows:
    the others keep the colours they had (black in a new attribute)."""
    attr = mesh.color_attributes.get(ATTRIBUTE)
    if attr is not None and (attr.domain != domain or attr.data_type != "FLOAT_COLOR"):
        mesh.color_attributes.remove(attr)
        attr = None
    rgba = np.ones((len(rgb), 4), np.float32)
    if attr is None:
        attr = mesh.color_attributes.new(ATTRIBUTE, "FLOAT_COLOR", domain)
    elif seen is not None and len(attr.data) == len(rgb):
        attr.data.foreach_get("color", rgba.ravel())
        rgb = np.where(seen[:, None], rgb, rgba[:, :3])
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


def shaded_objects(scene):
    """Mesh objects in the scene that carry the add-on's attribute."""
    return [o for o in scene.objects if o.type == "MESH" and ATTRIBUTE in o.data.color_attributes]
