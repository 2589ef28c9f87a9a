"""The Ambient Occlusion node, as Cycles' svm_ao casts it: the share of a cosine-weighted hemisphere
about each point's normal (the opposite one for Inside) whose rays run the node's Distance without
meeting a mesh of the scene that casts shadows (only the object's own with Only Local).

Cycles casts the node's Samples rays at each of a pixel's samples, and the pixel converges to that
share.  wenv casts one stratified set at each point instead (wenv.Occluders.ambient, in the core:
its pattern turned about the normal by a hash of the point, so that neighbouring points' errors
differ rather than band) -- the node's Samples, but at least VERTEX_RAYS at a vertex and
TEXEL_RAYS at a bake's texel.  The meshes' Embree scene and each object's shares are kept while the
meshes, the points and the node's settings are the same, so a new view casts nothing."""
import numpy as np

from . import engine, meshes

VERTEX_RAYS = 64  # at least, at each vertex (31,658 of Suzanne's: 2 M rays, about 0.1 s on 2 cores)
TEXEL_RAYS = 16  # at least, at each texel of a bake (a million: 16 M rays, about 0.6 s on 2 cores)

_scenes = {}  # which meshes -> their wenv.Occluders (the last two kept)
_shares = {}  # object name -> (what its shares were cast from, the shares)


def blockers(depsgraph, obj, only_local):
    """(name, world positions, triangles) of the meshes the node's rays may meet: obj's alone with
    Only Local, else every visible mesh object of the scene that casts shadows (Object > Visibility >
    Shadow, as Cycles' shadow rays see them; one in Edit Mode is skipped, as wenv skips it) and the
    instances, curves and text that do (meshes.other_geometry)."""
    scene = depsgraph.scene
    objs = [obj] if only_local else [
        o for o in scene.objects
        if o.type == "MESH" and o.mode != "EDIT" and o.visible_get() and getattr(o, "visible_shadow", True)]
    out = []
    for o in objs:
        data = meshes.read_mesh(o, depsgraph)
        if data.count:
            out.append((o.name, data.positions, engine.shadow_triangles(data.positions, data.triangles)[0]))
    if not only_local:  # what else Cycles' rays meet: instances, curves, text
        out += [(name, p, engine.shadow_triangles(p, t)[0])
                for name, p, t, _ in meshes.other_geometry(depsgraph, skip={o.name for o in objs})[0]]
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
    got = occ.ambient(np.ascontiguousarray(positions, np.float32), np.ascontiguousarray(normals, np.float32),
                      float(distance), int(rays), inside=bool(inside), progress=progress)
    if len(_shares) > 16:
        _shares.clear()
    _shares[name] = (made_of, got)
    return got
