"""What stands between a vertex and its sky: wenv.Occluders (an Embree scene), the per-vertex
occlusion masks it makes, and the reference that casts every pixel's ray.  Truth here is outside the
code under test: a ray-triangle intersection written in numpy, and closed-form view factors."""
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import wenv
from tests.helpers.meshes import box, merged, square, uv_sphere


def numpy_blocked(positions, triangles, origin, dirs, eps=1e-9):
    """Möller-Trumbore in float64 for every ray against every triangle: True where any hit lies ahead."""
    p = positions.astype(np.float64)
    a, b, c = p[triangles[:, 0]], p[triangles[:, 1]], p[triangles[:, 2]]
    e1, e2 = b - a, c - a
    hit = np.zeros(len(dirs), bool)
    for k, d in enumerate(dirs.astype(np.float64)):
        h = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, h)
        ok = np.abs(det) > eps
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = origin - a
        u = inv * np.einsum("ij,ij->i", s, h)
        q = np.cross(s, e1)
        v = inv * (q @ d)
        t = inv * np.einsum("ij,ij->i", e2, q)
        hit[k] = np.any(ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0))
    return hit


def frame(n):
    """wenv's one tangent frame (docs/ARCHITECTURE.md §3.1): rows tangent, bitangent, normal."""
    a = 1.0 / (1.0 + n[2])
    b = -n[0] * n[1] * a
    return np.array([[1 - n[0] * n[0] * a, b, -n[0]], [b, 1 - n[1] * n[1] * a, -n[1]], n])


@pytest.fixture(scope="module")
def yard():
    """A ground square with a box standing on it and a roof floating over one corner."""
    return merged(square(3.0, 0.0), box((-0.5, -0.5, 0.0), (0.5, 0.5, 1.2)), square(0.6, 1.5, 1.5, 1.5))


def non_manifold(scene):
    """`scene` (yard) with two fins hung from an edge of its roof, one below and one above: that edge
    is then shared by three triangles (besides the open squares' boundary edges)."""
    p, t = scene
    roof, n = len(p) - 4, len(p)
    a, b = p[roof], p[roof + 1]
    fins = np.float32([a - [0, 0, 0.6], b - [0, 0, 0.6], a + [0, 0, 0.6], b + [0, 0, 0.6]])
    tris = [(roof, roof + 1, n + 1), (roof, n + 1, n), (roof, roof + 1, n + 3), (roof, n + 3, n + 2)]
    return np.vstack([p, fins]), np.vstack([t, tris])


@pytest.mark.parametrize("shape", ["yard", "non-manifold"])
def test_masks_match_a_ray_cast_written_apart(yard, shape):
    """Each texel of each point's mask is what a ray cast written here in numpy finds; a mesh that is
    open, in pieces or non-manifold (an edge of three triangles) is cast as the triangles it is."""
    positions, triangles = yard if shape == "yard" else non_manifold(yard)
    if shape == "non-manifold":
        edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
        assert np.unique(edges, axis=0, return_counts=True)[1].max() == 3
    occ = wenv.Occluders(positions, triangles)
    rng = np.random.default_rng(4)
    pts = np.column_stack([rng.uniform(-2.5, 2.5, 40), rng.uniform(-2.5, 2.5, 40), np.zeros(40)]).astype(np.float32)
    pts = pts[np.maximum(np.abs(pts[:, 0]), np.abs(pts[:, 1])) > 0.55]  # not inside the box
    normals = np.tile(np.float32([0, 0, 1]), (len(pts), 1))
    o = occ.occlusion(pts, normals, resolution=8)
    local = o.directions.reshape(-1, 3)
    lift = occ.offset
    assert 1e-4 * occ.size <= lift < 2e-4 * occ.size
    world = local @ frame(np.array([0.0, 0.0, 1.0]))  # every vertex here faces +z: one frame
    mismatches = 0
    for i, p in enumerate(pts):
        want = ~numpy_blocked(positions, triangles, p + lift * np.array([0, 0, 1.0]), world)
        got = o.visible[i].reshape(-1)
        mismatches += int(np.sum(got != want))
    assert mismatches == 0
    assert 0 < o.blocked_vertices <= len(pts)
    assert np.all(o.open_fraction <= 1.0) and np.any(o.open_fraction < 0.9)


def test_auto_resolution_is_the_finest_within_the_ray_budget():
    """Occluders.auto_resolution(n): the side 'auto' casts n vertices at, the finest r (4 to 16) whose
    n r^2 rays stay within 2^23; what occlusion(resolution='auto') casts."""
    for n, r in ((1, 16), (32768, 16), (32769, 15), (126290, 8), (524288, 4), (10 ** 7, 4), (65536, 11)):
        assert wenv.Occluders.auto_resolution(n) == r
    occ = wenv.Occluders(*square(1.0, 1.0))
    p = np.zeros((40000, 3), np.float32)
    up = np.tile(np.float32([0, 0, 1]), (40000, 1))
    assert occ.occlusion(p, up, resolution="auto").resolution == wenv.Occluders.auto_resolution(40000) == 14
    with pytest.raises(ValueError, match="count"):
        wenv.Occluders.auto_resolution(-1)


def test_a_convex_mesh_blocks_nothing():
    """A convex mesh alone: every vertex sees its whole hemisphere and holds no mask: one index a
    vertex beside the positions and unit normals the masks are for (what the lights' rays start from)."""
    v, f = uv_sphere()
    occ = wenv.Occluders(v, f)
    o = occ.occlusion(v, v, resolution=16)
    assert o.blocked_vertices == 0 and o.nbytes == (4 + 24) * len(v)
    assert np.all(o.visible) and np.all(o.open_fraction == pytest.approx(1.0, abs=1e-12))


def test_open_fraction_is_the_view_factor_under_a_roof():
    """A point under the centre of a square roof sees the sky but for the roof's solid angle."""
    roof = wenv.Occluders(*square(1.0, 1.0))
    o = roof.occlusion(np.float32([[0, 0, 0]]), np.float32([[0, 0, 1]]), resolution=16)
    # a rectangle of half-sides a, b at distance d, seen from below its centre: 4 asin(ab / sqrt((a^2+d^2)(b^2+d^2)))
    solid = 4 * math.asin(1.0 / 2.0)
    assert o.open_fraction[0] == pytest.approx(1 - solid / (2 * math.pi), abs=0.03)
    assert not o.visible[0][7:9, 7:9].any() and o.visible[0][0, 0]  # the zenith blocked, the horizon open


def constant_environment(value=1.0, width=512):
    return wenv.Environment(np.full((width // 2, width, 3), value, np.float32))


def test_shadowed_reference_is_the_view_factor():
    """Lambertian white under a white sky: radiance albedo (1 - F), F the view factor of a square roof
    of half-side a at height h over the point, (4/pi) A/sqrt(1+A^2) atan(A/sqrt(1+A^2)), A = a/h."""
    env = constant_environment()
    mat = wenv.Lambert(0.8)
    roof = wenv.Occluders(*square(1.0, 1.0))
    n = np.float32([[0, 0, 1]])
    v = np.float32([[0.3, 0, 1]])
    got = wenv.reference(env, mat, n, v, positions=np.float32([[0, 0, 0]]), occluders=roof)[0]
    a = 1.0
    s = a / math.sqrt(1 + a * a)
    F = 4 / math.pi * s * math.atan(s)
    np.testing.assert_allclose(got, 0.8 * (1 - F), rtol=0.01)


def test_shadowed_reference_is_unchanged_where_nothing_blocks():
    """Occluders that block none of the pixels leave the reference as it was, to the bit; a glossy
    lobe under a real HDRI, a narrow one included."""
    from conftest import hdri_path
    env = wenv.load_environment(hdri_path("sunset"))
    mat = wenv.CookTorrance(diffuse=0.2, lobes=[{"alpha": 0.2}, {"alpha": 0.002, "specular": 0.5}])
    far = wenv.Occluders(*square(0.5, -50.0))  # far below every vertex
    rng = np.random.default_rng(3)
    n = rng.normal(size=(6, 3)).astype(np.float32)
    n[:, 2] = np.abs(n[:, 2]) + 0.5
    v = rng.normal(size=(6, 3)).astype(np.float32)
    v[:, 2] = np.abs(v[:, 2]) + 0.3
    p = rng.uniform(-1, 1, (6, 3)).astype(np.float32)
    plain = wenv.reference(env, mat, n, v)
    shadowed = wenv.reference(env, mat, n, v, positions=p, occluders=far)
    np.testing.assert_array_equal(plain, shadowed)


def test_shadowed_reference_darkens_what_is_covered(yard):
    """Nothing is brighter for what blocks it; under the roof (a sixth of the sky's cosine-weighted
    view) the light falls clearly, in the open hardly."""
    from conftest import hdri_path
    env = wenv.load_environment(hdri_path("forest"))
    occ = wenv.Occluders(*yard)
    mat = wenv.Lambert(0.5)
    p = np.float32([[1.5, 1.5, 0.0], [-2.5, -2.5, 0.0]])  # under the roof, in the open
    n = np.float32([[0, 0, 1]] * 2)
    v = np.float32([[0, 0.5, 1]] * 2)
    shadowed = wenv.reference(env, mat, n, v, positions=p, occluders=occ)
    plain = wenv.reference(env, mat, n, v)
    assert np.all(shadowed <= plain + 1e-6)
    assert np.all(shadowed[0] < 0.95 * plain[0])
    assert np.all(shadowed[1] > 0.85 * plain[1])


BAD = [
    (lambda: wenv.Occluders(np.float32([[0, 0, 0], [1, 0, 0], [0, math.nan, 0]]), [[0, 1, 2]]), ValueError,
     "positions[2]"),
    (lambda: wenv.Occluders(np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), [[0, 1, 3]]), ValueError, "triangles[0]"),
    (lambda: wenv.Occluders(np.float32([[0, 0, 0], [1, 0, 0], [2, 0, 0]]), [[0, 1, 2]]), ValueError, "degenerate"),
    (lambda: wenv.Occluders(np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), [[0, 1, -1]]), ValueError, "triangles"),
    (lambda: wenv.Occluders(np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), [[0.0, 1.0, 2.0]]), TypeError,
     "integer"),
    (lambda: wenv.Occluders(np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.zeros((0, 3), int)), ValueError,
     "at least one triangle"),
    (lambda: wenv.Occluders(np.zeros((10_000_000, 3), np.float32), np.zeros((20_000_000, 3), np.uint32)),
     ValueError, "memory budget"),
]


@pytest.mark.parametrize("i", range(len(BAD)))
def test_bad_scenes_are_named(i):
    fn, exc, text = BAD[i]
    with pytest.raises(exc) as info:
        fn()
    assert text in str(info.value)


def test_bad_occlusion_arguments_are_named():
    occ = wenv.Occluders(*square(1.0, 1.0))
    p, n = np.float32([[0, 0, 0]]), np.float32([[0, 0, 1]])
    with pytest.raises(ValueError, match="resolution"):
        occ.occlusion(p, n, resolution=2)
    with pytest.raises(ValueError, match="normals"):
        occ.occlusion(p, np.float32([[0, 0, 0]]))
    with pytest.raises(ValueError, match="positions"):
        occ.occlusion(np.float32([[math.inf, 0, 0]]), n)
    with pytest.raises(ValueError, match="rows"):
        occ.occlusion(np.float32([[0, 0, 0], [1, 1, 1]]), n)
    with pytest.raises(ValueError, match="occluders need positions"):
        wenv.reference(constant_environment(1.0, 64), wenv.Lambert(0.5), n, n, occluders=occ)
    with pytest.raises(TypeError, match="occluders"):
        wenv.reference(constant_environment(1.0, 64), wenv.Lambert(0.5), n, n, positions=p, occluders="roof")
    with pytest.raises(wenv.CancelledError):
        occ.occlusion(np.zeros((5000, 3), np.float32), np.tile(n, (5000, 1)), progress=lambda f: True)


def test_a_cancelled_occlusion_keeps_nothing_of_its_block():
    """A cancel leaves the later vertices of the block being cast unwritten; what the block kept was
    read from them, a count of garbage hits copied (a crash when the heap held no zeros there).  In a
    process whose fresh allocations are filled with a non-zero byte (glibc's MALLOC_PERTURB_), the
    cancel is reported and nothing crashes."""
    script = ("import numpy as np, wenv\n"
              "v = np.float32([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])\n"
              "occ = wenv.Occluders(v, np.uint32([[0, 1, 2], [0, 2, 3]]))\n"
              "n = np.tile(np.float32([0, 0, 1]), (5000, 1))\n"
              "try:\n"
              "    occ.occlusion(np.zeros((5000, 3), np.float32), n, progress=lambda f: True)\n"
              "except wenv.CancelledError:\n"
              "    print('cancelled')\n")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    run = subprocess.run([sys.executable, "-c", script], env={**os.environ, "MALLOC_PERTURB_": "204", "PYTHONPATH": root},
                         capture_output=True, text=True, timeout=300, cwd=root)
    assert run.returncode == 0 and run.stdout.strip() == "cancelled", (run.returncode, run.stderr[-2000:])


def test_occluded_tests_single_rays():
    occ = wenv.Occluders(*square(1.0, 1.0))
    up, side = np.float32([0, 0, 1]), np.float32([1, 0, 0])
    assert occ.occluded(np.float32([0, 0, 0]), np.stack([up, side, -up])).tolist() == [True, False, False]
    assert occ.occluded(np.float32([[0, 0, 0], [5, 0, 0]]), np.stack([up, up])).tolist() == [True, False]
    assert occ.occluded(np.float32([0, 0, 0]), up[None], tfar=0.5).tolist() == [False]  # the roof is further


def test_ambient_shares_are_the_closed_form_under_a_wide_roof():
    """wenv.Occluders.ambient (the Ambient Occlusion node): under a roof at height h, wide enough to
    stand for a plane, a cosine-weighted ray runs the distance d > h where cos theta < h / d: the open
    share is (h / d)^2 (cos^2 theta is uniform over such rays).  Within half a ray of it at 1024
    rays a point; the rays below (Inside) meet nothing, nor any ray for a distance of 0."""
    occ = wenv.Occluders(*square(1000.0, 1.0))
    points = np.float32([[0.0, 0.0, 0.0], [3.0, -2.0, 0.0], [0.0, 0.0, 0.5]])
    up = np.tile(np.float32([0.0, 0.0, 1.0]), (3, 1))
    got = occ.ambient(points, up, 2.0, 1024)
    np.testing.assert_allclose(got, [0.25, 0.25, 0.0625], atol=0.5 / 1024)
    assert occ.ambient(points, up * 7.0, 2.0, 1024).tolist() == got.tolist()  # (normals made unit)
    np.testing.assert_array_equal(occ.ambient(points, up, 2.0, 64, inside=True), 1.0)
    np.testing.assert_array_equal(occ.ambient(points, up, 0.0, 64), 1.0)
    np.testing.assert_array_equal(occ.ambient(points[:2], up[:2], 0.9, 64), 1.0)  # (the roof beyond reach)
    # each point's pattern turned its own way (under half a roof: the turn shows): the same rays at
    # every call, not the same as a neighbour's
    half = wenv.Occluders(*square(500.0, 1.0, x=500.0))
    at, normal = np.tile(points[:1], (64, 1)), np.tile(up[:1], (64, 1))
    few = half.ambient(at, normal, 2.0, 8)
    assert len(set(few.tolist())) > 1 and half.ambient(at, normal, 2.0, 8).tolist() == few.tolist()


def test_bad_ambient_arguments_are_named():
    occ = wenv.Occluders(*square(1.0, 1.0))
    point, up = np.float32([[0.0, 0.0, 0.0]]), np.float32([[0.0, 0.0, 1.0]])
    for rays in (0, 1025):
        with pytest.raises(ValueError, match="rays must be from 1 to 1024"):
            occ.ambient(point, up, 1.0, rays)
    with pytest.raises(ValueError, match="distance must be finite"):
        occ.ambient(point, up, float("nan"), 16)
    with pytest.raises(ValueError, match="normals"):
        occ.ambient(point, np.float32([[0.0, np.nan, 1.0]]), 1.0, 16)
    with pytest.raises(ValueError, match="points"):
        occ.ambient(np.float32([[0.0, 0.0]]), up, 1.0, 16)
    with pytest.raises(TypeError, match="progress"):
        occ.ambient(point, up, 1.0, 16, progress=3)
    with pytest.raises(wenv.CancelledError):
        occ.ambient(np.tile(point, (100000, 1)), np.tile(up, (100000, 1)), 1.0, 16, progress=lambda f: True)
