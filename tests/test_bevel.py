"""wenv.Occluders.bevel, the Bevel node's normal, against the integral it stands for summed apart
in numpy: the smooth normals of the surface within the radius, weighted by (radius - r)^3 over
its area, summed over a dense grid of points on each triangle."""
import numpy as np
import pytest

import wenv
from tests.helpers.meshes import box, uv_sphere


def dense_bevel(positions, triangles, corner_normals, points, radius, m=80):
    """The integral as a sum over m^2 points a triangle (the centres of its m^2 pieces), the normal
    interpolated and made unit at each."""
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    up = [((i + 1 / 3) / m, (j + 1 / 3) / m), ((i + 2 / 3) / m, (j + 2 / 3) / m)]  # both pieces of each cell
    b = []
    for u, v in up:
        keep = u + v < 1.0
        b.append(np.column_stack([1.0 - u[keep] - v[keep], u[keep], v[keep]]))
    b = np.vstack(b)
    out = np.zeros((len(points), 3))
    for t, tri in enumerate(triangles):
        corners = positions[tri].astype(np.float64)
        x = b @ corners
        n = b @ corner_normals[3 * t:3 * t + 3].astype(np.float64)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        area = 0.5 * np.linalg.norm(np.cross(corners[1] - corners[0], corners[2] - corners[0])) / len(b)
        r = np.linalg.norm(x[None, :, :] - points[:, None, :], axis=2)
        w = np.clip(radius - r, 0.0, None) ** 3 * area
        out += w @ n
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def degrees_apart(a, b):
    return np.degrees(np.arccos(np.clip((a * b).sum(axis=1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1),
                                        -1.0, 1.0)))


def test_a_cube_bevels_its_edges_and_corners():
    """Flat faces (each triangle's normal its own): a face's middle keeps its normal, an edge's
    middle takes the mean of its two faces', a corner its three's, and points between as the dense
    sum has them (within 0.05 degrees)."""
    positions, triangles = box((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))
    face = np.cross(positions[triangles[:, 1]] - positions[triangles[:, 0]],
                    positions[triangles[:, 2]] - positions[triangles[:, 0]])
    corner_normals = np.repeat(face / np.linalg.norm(face, axis=1, keepdims=True), 3, axis=0).astype(np.float32)
    occ = wenv.Occluders(positions, triangles)
    points = np.float32([[0.0, 0.0, 1.0], [0.0, 1.0, 1.0], [1.0, 1.0, 1.0], [0.0, 0.9, 1.0], [0.95, 0.9, 1.0],
                         [0.0, 0.65, 1.0], [-0.8, 0.93, -1.0]])
    got = occ.bevel(points, corner_normals, 0.3)
    np.testing.assert_allclose(got[:3], [[0.0, 0.0, 1.0], [0.0, 2 ** -0.5, 2 ** -0.5], [3 ** -0.5] * 3], atol=1e-6)
    np.testing.assert_allclose(got[5], [0.0, 0.0, 1.0], atol=1e-7)  # (the edge beyond the radius)
    assert degrees_apart(got, dense_bevel(positions, triangles, corner_normals, points, 0.3)).max() < 0.05
    assert degrees_apart(got[3:4], points[:1] * 0 + [[0.0, 0.0, 1.0]])[0] > 10.0  # (it bevels)


def test_a_coarse_smooth_surface_bevels_as_its_normals_turn():
    """A coarse ellipsoid, smooth (its corners' normals turn by up to 40 degrees over a triangle),
    at radii smaller and larger than its triangles: within 0.15 degrees of the dense sum (0.04 and
    0.07 here)."""
    positions, triangles = uv_sphere(6, 10)
    positions = (np.asarray(positions, np.float32) * np.float32([1.0, 0.7, 1.3]))
    triangles = np.asarray(triangles)
    face = np.cross(positions[triangles[:, 1]] - positions[triangles[:, 0]],
                    positions[triangles[:, 2]] - positions[triangles[:, 0]])
    vertex = np.zeros_like(positions)
    np.add.at(vertex, triangles.ravel(), np.repeat(face, 3, axis=0))
    vertex /= np.linalg.norm(vertex, axis=1, keepdims=True)
    corner_normals = np.ascontiguousarray(vertex[triangles].reshape(-1, 3), np.float32)
    occ = wenv.Occluders(positions, triangles)
    rng = np.random.default_rng(3)
    at = rng.integers(0, len(triangles), 40)
    weights = rng.dirichlet((1, 1, 1), 40)[:, :, None]
    points = (weights * positions[triangles[at]]).sum(axis=1).astype(np.float32)
    own = (weights * vertex[triangles[at]]).sum(axis=1)  # each point's own (interpolated) normal
    for radius in (0.1, 0.4):
        got = occ.bevel(points, corner_normals, radius)
        apart = degrees_apart(got, dense_bevel(positions, triangles, corner_normals, points.astype(np.float64),
                                               radius))
        assert apart.max() < 0.15, (radius, apart.max())
        # and not merely each point's own normal (0.35 and 3.3 degrees from it at most here)
        assert degrees_apart(got, own).max() > (0.2 if radius == 0.1 else 2.0)


def test_each_point_may_have_its_own_radius():
    """A radius per point (a Bevel node's linked Radius): each point as a call at its own radius,
    to the bit, against the dense sum too; a radius of 0 or less reads nothing, as Cycles'."""
    positions, triangles = box((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))
    face = np.cross(positions[triangles[:, 1]] - positions[triangles[:, 0]],
                    positions[triangles[:, 2]] - positions[triangles[:, 0]])
    corner_normals = np.repeat(face / np.linalg.norm(face, axis=1, keepdims=True), 3, axis=0).astype(np.float32)
    occ = wenv.Occluders(positions, triangles)
    points = np.float32([[0.0, 0.9, 1.0], [0.95, 0.9, 1.0], [0.0, 0.65, 1.0], [0.5, 1.0, 0.7], [0.0, 0.95, 1.0],
                         [0.2, 0.97, 1.0]])
    radii = np.float32([0.3, 0.15, 0.45, 0.2, 0.0, -0.1])
    got = occ.bevel(points, corner_normals, radii)
    for k in range(4):
        np.testing.assert_array_equal(got[k], occ.bevel(points[k:k + 1], corner_normals, float(radii[k]))[0])
        assert degrees_apart(got[k:k + 1], dense_bevel(positions, triangles, corner_normals, points[k:k + 1],
                                                       float(radii[k])))[0] < 0.05
    np.testing.assert_array_equal(got[4:], 0.0)
    with pytest.raises(ValueError, match=r"radius\[1\] must be finite"):
        occ.bevel(points[:2], corner_normals, np.float32([0.1, np.nan]))
    with pytest.raises(ValueError, match="radius must have shape"):
        occ.bevel(points, corner_normals, radii[:3])


def test_no_surface_within_the_radius_gives_zeros():
    positions, triangles = box((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))
    occ = wenv.Occluders(positions, triangles)
    normals = np.zeros((36, 3), np.float32)
    normals[:, 2] = 1.0
    got = occ.bevel(np.float32([[0.0, 0.0, 3.0], [0.0, 0.0, 1.05]]), normals, 0.1)
    np.testing.assert_array_equal(got[0], 0.0)
    np.testing.assert_allclose(got[1], [0.0, 0.0, 1.0], atol=1e-7)


def test_bad_arguments_are_named():
    positions, triangles = box((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))
    occ = wenv.Occluders(positions, triangles)
    normals = np.tile(np.float32([0.0, 0.0, 1.0]), (36, 1))
    point = np.float32([[0.0, 0.0, 1.0]])
    for radius in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="radius"):
            occ.bevel(point, normals, radius)
    with pytest.raises(ValueError, match="corner_normals has 35 rows"):
        occ.bevel(point, normals[:35], 0.1)
    with pytest.raises(ValueError, match="points"):
        occ.bevel(np.float32([[0.0, np.nan, 1.0]]), normals, 0.1)
    with pytest.raises(ValueError, match="corner_normals"):
        occ.bevel(point, np.where(normals == 1.0, np.inf, normals).astype(np.float32), 0.1)
    with pytest.raises(TypeError, match="progress"):
        occ.bevel(point, normals, 0.1, progress=3)
    many = np.tile(point, (100000, 1))
    with pytest.raises(wenv.CancelledError):
        occ.bevel(many, normals, 0.1, progress=lambda fraction: True)
