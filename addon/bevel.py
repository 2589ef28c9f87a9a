"""The Bevel node, as Cycles' svm_bevel converges: the mean of the smooth normals of the object's own
surface within the node's Radius of the point, weighted over the surface's area by Cycles' cubic
falloff (Radius - r)^3.  Cycles estimates that integral with Samples rays a shading point, across
a disk about three axes; wenv integrates it over the triangles near the point (wenv.Occluders.bevel:
found by Embree, each in closed form but an angular quadrature), so a bake shows no noise and no
Samples to raise.  An object's triangles, with their corners' smooth normals, are kept while its
mesh and place are the same."""
import numpy as np

from . import engine, meshes, nodes

_surfaces = {}  # object name -> (what its surface was made of, (wenv.Occluders, corner normals))


def surface(obj, depsgraph):
    """(wenv.Occluders of obj's own triangles in the world, their corners' smooth normals (3 m, 3)
    float32 in the same order, what these were made from, the mesh's world positions (float32) and
    the vertex of each face corner), or None for a mesh without a face; kept per mesh state."""
    from . import textures  # (which reads this module's normals)
    mesh, _ = meshes.shaded_mesh(obj, depsgraph)
    positions = textures.world_points(mesh, obj.matrix_world)
    corners = textures.triangle_corners(mesh)
    corner_vert = meshes.corner_vertices(mesh)
    normals = np.empty(len(mesh.loops) * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    # into the world by the inverse transpose, as read_mesh turns the normals
    to_world = np.array(obj.matrix_world.to_3x3().inverted_safe(), np.float64)
    normals = normals.reshape(-1, 3).astype(np.float64) @ to_world
    # a flat face's triangles each their own normal, as Cycles reads a hit's (its corners' are the
    # face's mean, which a quad folded along its diagonal does not lie in)
    face = np.empty(len(corners), np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", face)
    smooth = np.empty(len(mesh.polygons), bool)
    mesh.polygons.foreach_get("use_smooth", smooth)
    flat = ~smooth[face]
    normals = normals[corners]
    if flat.any():
        normals[flat] = textures.triangle_normals(obj, positions, corner_vert[corners[flat]])[:, None, :]
    made_of = engine.fingerprint(positions, corners, normals)
    held = _surfaces.get(obj.name)
    if held is not None and held[0] == made_of:
        return held[1]
    points = np.ascontiguousarray(positions, np.float32)
    triangles = corner_vert[corners].astype(np.int64)
    keep = engine.with_area(points, triangles)  # (a face of no area holds no surface)
    if not keep.any():
        return None
    try:
        occ = engine.merged_occluders([(points, triangles[keep])])[0]
    except ValueError as exc:  # (a position not finite, or over the budget)
        raise engine.SetupError(f"'{obj.name}': its Bevel node cannot read its surface: {exc}") from None
    corner_normals = np.ascontiguousarray(normals[keep].reshape(-1, 3), np.float32)
    if len(_surfaces) > 8:
        _surfaces.clear()
    made = (occ, corner_normals, made_of, points, corner_vert)
    _surfaces[obj.name] = (made_of, made)
    return made


# A bake's texel reads the normal interpolated from its triangle's corners where that is within
# LINEAR_DEGREES of the integral at the triangle's centre (and the triangle at most LINEAR_SHARE of
# the Radius across), the others their own: so a dense mesh's million texels cost about its
# vertices' and triangles' integrals, and a fold's or a coarse mesh's texels their own.
LINEAR_SHARE = 0.25
LINEAR_DEGREES = 0.25

_normals = {}  # object name -> (what its rows' normals were made of, the normals)


def normals(obj, depsgraph, positions, row_normals, radius, progress=None, sites=None):
    """The Bevel node's normal (world, unit, (n, 3) float32) at each of `positions` on obj, with
    `radius` (one, or each row's from a linked Radius): a point with no surface within it (or a
    Radius of 0 or less, as Cycles) keeps its own normal of `row_normals`.  With `sites` (a bake's
    bake.TexelSites, one a row) and one radius, a texel on a triangle over which the normal turns
    linearly reads its corners' (LINEAR_DEGREES).  Kept per object while the surface, the rows and
    the radius are the same.  progress(fraction) may cancel (return True: engine.CancelledError)."""
    own = np.ascontiguousarray(row_normals, np.float32)
    radius = np.asarray(radius, np.float32)
    if radius.ndim and len(radius) and np.ptp(radius) == 0.0:
        radius = radius[0]  # (one for all: a bake's texels may then share their corners')
    if not (radius > 0.0).any() or len(positions) == 0:
        return own
    held = surface(obj, depsgraph)
    if held is None:
        return own
    occ, corner_normals, made_of, points, corner_vert = held
    positions = np.ascontiguousarray(positions, np.float32)
    key = (made_of, engine.fingerprint(positions, radius), sites is not None)
    kept = _normals.get(obj.name)
    if kept is not None and kept[0] == key:
        got = kept[1].copy()
    else:
        got = (occ.bevel(positions, corner_normals, radius, progress) if radius.ndim else
               _bevelled(occ, corner_normals, positions, float(radius), progress, sites, points, corner_vert))
        if len(_normals) > 8:
            _normals.clear()
        _normals[obj.name] = (key, got.copy())
    none = ~got.any(axis=1)
    got[none] = own[none]
    return got


def _bevelled(occ, corner_normals, positions, radius, progress, sites, points, corner_vert):
    if sites is None:
        return occ.bevel(positions, corner_normals, radius, progress)
    v = corner_vert[sites.tri_corners]
    centre = points[v].mean(axis=1)
    reach = np.linalg.norm(points[v] - centre[:, None, :], axis=2).max(axis=1)
    # the triangles tried: small enough, and holding texels
    tried = np.zeros(len(v), bool)
    tried[np.unique(sites.triangle)] = True
    tried &= reach <= LINEAR_SHARE * radius
    linear = np.zeros(len(v), bool)
    at_vertex = np.zeros((len(points), 3), np.float32)
    if tried.any():
        needed = np.unique(v[tried])
        at_vertex[needed] = occ.bevel(points[needed], corner_normals, radius, progress)
        guess = nodes.unit_rows(at_vertex[v[tried]].sum(axis=1))
        truth = occ.bevel(np.ascontiguousarray(centre[tried], np.float32), corner_normals, radius, progress)
        linear[np.flatnonzero(tried)] = (guess * truth).sum(axis=1) >= np.cos(np.radians(LINEAR_DEGREES))
    small = linear[sites.triangle]
    got = np.zeros((len(positions), 3), np.float32)
    if (~small).any():
        got[~small] = occ.bevel(positions[~small], corner_normals, radius, progress)
    if small.any():
        inner = engine.corner_values_at(at_vertex[corner_vert], sites.corners[small], sites.weights[small])
        got[small] = nodes.unit_rows(inner)
    return got

