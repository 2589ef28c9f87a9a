"""Faces of more than four corners against Cycles: the rolling grid of tests/test_attributes.py with
faces joined into faces of 6 and 8 corners, which Blender and Cycles shade as their loop triangles.
Blender computes UV tangents (MikkTSpace) for triangles and quads only: wenv reads them over the
triangles, as Cycles does."""
import numpy as np
import pytest

import bpy  # noqa: E402  (installed by scripts/setup.sh; missing, the tests fail rather than skip)

from test_attributes import rolling_grid  # noqa: E402


@pytest.fixture(scope="module")
def grid():
    return rolling_grid(ngons=True)


def test_the_grid_has_faces_of_six_and_eight_corners(grid):
    sizes = sorted({len(p.vertices) for p in bpy.data.objects["Crate.004 – ÿ"].data.polygons})
    assert sizes == [4, 6, 8]


@pytest.mark.parametrize("output", ["Position", "Normal", "True Normal", "Parametric"])
def test_geometry_on_faces_of_many_corners(grid, output):
    """The point, its normals and its place within each face's triangles, as Cycles reads them."""
    cycles, ours, _ = grid("ShaderNodeNewGeometry", output, lambda node: None)
    if output in ("True Normal", "Parametric"):  # (a pixel centre on a triangle's edge may take either triangle)
        inside = grid.sites.weights.min(axis=1) > 1e-4
        ours, cycles = ours[inside], cycles[inside]
    np.testing.assert_allclose(ours, cycles, atol=1e-5)


def test_uv_tangents_on_faces_of_many_corners(grid):
    """The Tangent node's UV map tangent where faces have 6 and 8 corners: within 1e-4 of Cycles."""
    def configure(node):
        node.direction_type = "UV_MAP"
    cycles, ours, notes = grid("ShaderNodeTangent", "Tangent", configure)
    assert notes == [] and np.ptp(ours, axis=0).max() > 0.5
    np.testing.assert_allclose(ours, cycles, atol=1e-4)
