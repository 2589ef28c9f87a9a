"""Shading only what is seen (Shader.shade_mesh(cull=True), wenv.visible_vertices): the vertices
skipped are exactly those whose normal faces away from the eye or that lie outside the view
frustum, computed here independently in numpy; the others get exactly what shading all gives, and
shading all is unchanged."""
import numpy as np
import pytest

import wenv


def sphere(n=4000, seed=3):
    rng = np.random.default_rng(seed)
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return np.float32(nrm * 1.5 + [0.2, 0.0, 0.1]), np.float32(nrm)


def look_at(eye, target, fov_degrees=30.0, aspect=1.5, near=0.1, far=50.0):
    """World -> clip (OpenGL), camera at eye looking at target, +Z up."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    view = np.eye(4)
    view[:3, :3] = np.stack([right, up, -fwd])
    view[:3, 3] = -view[:3, :3] @ eye
    f = 1 / np.tan(np.radians(fov_degrees) / 2)
    proj = np.array([[f / aspect, 0, 0, 0], [0, f, 0, 0],
                     [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)], [0, 0, -1, 0]])
    return proj @ view


def expected_visible(pos, nrm, eye, vp=None):
    p, n = pos.astype(np.float64), nrm.astype(np.float64)
    d = np.asarray(eye, float) - p
    seen = n[:, 0] * d[:, 0] + n[:, 1] * d[:, 1] + n[:, 2] * d[:, 2] > 0
    if vp is not None:
        clip = np.c_[p, np.ones(len(p))] @ vp.T
        w = clip[:, 3:]
        seen &= (w[:, 0] > 0) & np.all((clip[:, :3] >= -w) & (clip[:, :3] <= w), axis=1)
    return seen


@pytest.fixture(scope="module")
def shader():
    env = wenv.Environment(np.float32(np.random.default_rng(1).uniform(0.1, 2.0, (32, 64, 3))))
    mat = wenv.CookTorrance(diffuse=0.3, lobes=[{"alpha": 0.2}])
    return wenv.Shader(env, mat, quality="draft")


@pytest.mark.parametrize("frustum", [False, True])
def test_culled_vertices_are_exactly_the_back_facing_and_off_screen(shader, frustum):
    pos, nrm = sphere()
    eye = (0.5, -6.0, 1.0)
    # a narrow lens aimed off the centre: part of the facing half is off screen
    vp = look_at(eye, (1.0, 0.0, 0.6), fov_degrees=18.0) if frustum else None
    want = expected_visible(pos, nrm, eye, vp)
    assert 0.1 < want.mean() < (0.45 if frustum else 0.55)
    got = wenv.visible_vertices(pos, nrm, eye, vp)
    assert got.dtype == bool and np.array_equal(got, want)

    everything = shader.shade_mesh(pos, nrm, eye)
    out = np.full_like(everything, 7.0)
    back = shader.shade_mesh(pos, nrm, eye, cull=True, view_projection=vp, out=out)
    assert back is out and shader.stats["visible_vertices"] == want.sum()
    assert np.array_equal(out[want], everything[want]) and np.all(out[~want] == 7.0)
    fresh = shader.shade_mesh(pos, nrm, eye, cull=True, view_projection=vp)
    assert np.array_equal(fresh[want], everything[want]) and np.all(fresh[~want] == 0.0)


def test_shading_all_is_unchanged(shader):
    """Without cull, shade_mesh is shade with the views towards the eye, every row."""
    pos, nrm = sphere(500)
    eye = np.array([0.3, -5.0, 2.0])
    assert np.array_equal(shader.shade_mesh(pos, nrm, tuple(eye)), shader.shade(nrm, np.float32(eye - pos)))
    assert "visible_vertices" not in shader.stats


def test_culling_arguments_are_checked(shader):
    pos, nrm = sphere(50)
    eye = (0, -5, 0)
    with pytest.raises(ValueError, match="view_projection is only read with cull=True"):
        shader.shade_mesh(pos, nrm, eye, view_projection=np.eye(4))
    with pytest.raises(TypeError, match="view_projection must be a 4 x 4 matrix"):
        shader.shade_mesh(pos, nrm, eye, cull=True, view_projection=[[1, 0], [0, 1]])
    with pytest.raises(ValueError, match="view_projection must be finite"):
        shader.shade_mesh(pos, nrm, eye, cull=True, view_projection=np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match=r"out must be a float32 array of shape \(50, 3\)"):
        shader.shade_mesh(pos, nrm, eye, cull=True, out=np.zeros((49, 3), np.float32))
    with pytest.raises(TypeError, match="out must be a writable"):
        shader.shade_mesh(pos, nrm, eye, cull=True, out=np.zeros((50, 3), np.float32).tobytes())
    # a camera behind which everything lies sees nothing, and shading nothing is fine
    none_seen = shader.shade_mesh(pos, nrm, eye, cull=True, view_projection=look_at(eye, (0, -10, 0)))
    assert shader.stats["visible_vertices"] == 0 and not none_seen.any()
