"""The Ambient Occlusion node, as Cycles' svm_ao casts it: the share of a cosine-weighted hemisphere
about each point's normal (the opposite one for Inside) whose rays run the node's Distance without
meeting a mesh of the scene that casts shadows (only the object's own with Only Local).

Cycles casts the node's Samples rays at each of a pixel's samples, and the pixel converges to that
share.  wenv casts one stratified set at each point instead -- the node's Samples, but at least
VERTEX_RAYS at a vertex and TEXEL_RAYS at a bake's texel -- turned about the normal by a hash of the
point, so that neighbouring points' errors differ rather than band.  Rays go to Embree (wenv.Occluders) from each
point, each a little along itself (passing the point's own triangle, as Cycles' rays skip it).  The meshes' Embree scene and each object's
shares are kept while the meshes, the points and the node's settings are the same, so a new view
casts nothing."""
import math

import numpy as np

from . import engine, meshes

VERTEX_RAYS = 64  # at least, at each vertex (31,658 of Suzanne's: 2 M rays, about 0.3 s on 2 cores)
TEXEL_RAYS = 16  # at least, at each texel of a bake (a million: 16 M rays, about 3 s on 2 cores, 45 % of it Embree's)
CHUNK = 1 << 20  # rays cast between two calls of progress()

_scenes = {}  # which meshes -> their wenv.Occluders (the last two kept)
_shares = {}  # object name -> (what its shares were cast from, the shares)


def _pattern(k):
    """k unit directions about +z, cosine-weighted: a Fibonacci spiral over the unit disk (each
    point an equal area) lifted onto the hemisphere, as Cycles lifts its concentric disk samples."""
    i = np.arange(k, dtype=np.float64) + 0.5
    r = np.sqrt(i / k)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1.0 - r * r, 0.0))])


def _turns(n):
    """A turn in [0, 2 pi) per point from a hash of its index (the same at every call)."""
    h = np.arange(n, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
    h ^= h >> np.uint64(31)
    h *= np.uint64(0xBF58476D1CE4E5B9)
    h ^= h >> np.uint64(29)
    return (h >> np.uint64(11)).astype(np.float64) * (2.0 * math.pi / float(1 << 53))


def _frames(normals):
    """Two unit tangents per unit normal (Duff et al.'s branchless basis)."""
    x, y, z = normals[:, 0], normals[:, 1], normals[:, 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = np.column_stack([1.0 + sign * x * x * a, sign * b, -sign * x])
    s = np.column_stack([b, sign + y * y * a, -y])
    return t, s


def blockers(depsgraph, obj, only_local):
    """(name, world positions, triangles) of the meshes the node's rays may meet: obj's alone with
    Only Local, else every visible mesh object of the scene that casts shadows (Object > Visibility >
    Shadow, as Cycles' shadow rays see them; one in Edit Mode is skipped, as wenv skips it)."""
    scene = depsgraph.scene
    objs = [obj] if only_local else [
        o for o in scene.objects
        if o.type == "MESH" and o.mode != "EDIT" and o.visible_get() and getattr(o, "visible_shadow", True)]
    out = []
    for o in objs:
        data = meshes.read_mesh(o, depsgraph)
        if data.count:
            out.append((o.name, data.positions, engine.shadow_triangles(data.positions, data.triangles)[0]))
    return out


def _occluders(meshes_in):
    key = tuple((name, engine.fingerprint(p, t)) for name, p, t in meshes_in)
    held = _scenes.get(key)
    if held is None:
        if len(_scenes) > 1:
            _scenes.clear()
        try:
            made = engine.merged_occluders([(p, t) for _, p, t in meshes_in])[0]
        except ValueError as exc:  # (over the memory budget, a position not finite)
            raise engine.SetupError(f"The Ambient Occlusion node's meshes cannot be cast against: {exc}") from None
        held = _scenes[key] = (made, key)
    return held


def shares(name, positions, normals, distance, inside, meshes_in, rays=VERTEX_RAYS, progress=None):
    """Each point's unoccluded share ((n,) float32): of `rays` cosine-weighted rays about its unit
    normal (negated for `inside`) from its world position, those that run `distance` without
    meeting `meshes_in` ([(name, world positions, triangles)]).  Kept for `name` (an object) while
    all of these are the same.  progress(fraction) between chunks of rays may cancel (return True:
    engine.CancelledError)."""
    n = len(positions)
    if distance <= 0.0 or n == 0 or not any(len(t) for _, _, t in meshes_in):
        return np.ones(n, np.float32)  # (Cycles: no rays at all)
    occ, scene_key = _occluders([m for m in meshes_in if len(m[2])])
    made_of = (scene_key, engine.fingerprint(positions, normals), float(distance), bool(inside), rays)
    held = _shares.get(name)
    if held is not None and held[0] == made_of:
        return held[1]
    up = np.asarray(normals, np.float64)
    up = up / np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-30)
    if inside:
        up = -up
    origins = np.asarray(positions, np.float32)
    t, s = (v.astype(np.float32) for v in _frames(up))
    up = up.astype(np.float32)
    pattern = _pattern(rays).astype(np.float32)
    turn = _turns(n)
    cos, sin = np.cos(turn).astype(np.float32)[:, None], np.sin(turn).astype(np.float32)[:, None]
    step = np.float32(occ.offset)
    open_rays = np.zeros(n, np.int64)
    points = max(1, CHUNK // rays)
    for start in range(0, n, points):
        stop = min(n, start + points)
        c, si = cos[start:stop], sin[start:stop]
        # each point's pattern turned by its own angle, then set in its frame
        px = c * pattern[None, :, 0] - si * pattern[None, :, 1]
        py = si * pattern[None, :, 0] + c * pattern[None, :, 1]
        d = (px[..., None] * t[start:stop, None, :] + py[..., None] * s[start:stop, None, :]
             + pattern[None, :, 2, None] * up[start:stop, None, :])
        d = d.reshape(-1, 3)
        # each ray starts a little along itself, as Cycles' skips the point's own triangle: one below
        # that triangle's plane (about a smooth normal) passes it
        o = (origins[start:stop, None, :] + step * d.reshape(stop - start, rays, 3)).reshape(-1, 3)
        hit = occ.occluded(o, d, float(distance) - occ.offset)
        open_rays[start:stop] = rays - hit.reshape(-1, rays).sum(axis=1)
        if progress is not None and progress(stop / n):
            raise engine.CancelledError("cancelled")
    got = (open_rays / float(rays)).astype(np.float32)
    if len(_shares) > 16:
        _shares.clear()
    _shares[name] = (made_of, got)
    return got
