"""A colour per vertex (Shader.shade(..., base_color=)): each vertex shaded as a material of its own
colour would be, in every method, the reference, with shadows and in culled or budgeted steps, and
refused with the reason where a material's colour cannot vary alone."""
import numpy as np
import pytest

import wenv
from tests.conftest import hdri_path
from tests.helpers.meshes import uv_sphere
from tests.test_shadows import MATERIALS as SHADOW_MATERIALS
from tests.test_shadows import relative_rmse, sky

PALETTE = np.float32([[0.8, 0.1, 0.1], [0.1, 0.6, 0.2], [0.9, 0.9, 0.2]])

# each made with a colour: Principled paint (a clear coat over it), Lambert, Cook-Torrance
MAKERS = {
    "principled": lambda c: wenv.Principled(base_color=tuple(c), roughness=0.3, coat_weight=0.5),
    "lambert": lambda c: wenv.Lambert(tuple(c)),
    "cook_torrance": lambda c: wenv.CookTorrance(tuple(c), [dict(alpha=0.2, specular=1.0, ior=1.5)]),
}


@pytest.fixture(scope="module")
def sphere():
    v, _ = uv_sphere(16, 32)
    eye = np.float32([0.4, -3.5, 1.0])
    views = ((eye - v) / np.linalg.norm(eye - v, axis=1)[:, None]).astype(np.float32)
    groups = np.random.default_rng(1).integers(0, len(PALETTE), len(v))
    return v, views, groups


def by_group(make_shaded, groups):
    """What each vertex gets from a material of its group's colour."""
    out = None
    for g, colour in enumerate(PALETTE):
        rows = groups == g
        shaded = make_shaded(colour, rows)
        out = np.zeros((len(groups), 3), np.float32) if out is None else out
        out[rows] = shaded
    return out


@pytest.mark.parametrize("method", ["rotation", "slicing", "split_sum", "sh"])
@pytest.mark.parametrize("kind", list(MAKERS))
def test_each_vertex_is_shaded_as_a_material_of_its_colour(sphere, kind, method):
    """Three colours scattered over a sphere: every vertex as a shader of a material of its colour
    shades it, to float rounding (the colour multiplies the Lambertian part alone), where the
    material's own colour is another."""
    v, views, groups = sphere
    env = wenv.load_environment(hdri_path("sunset"))
    quality = "draft" if method == "rotation" else "default"
    shader = wenv.Shader(env, MAKERS[kind]((0.5, 0.5, 0.5)), quality=quality, method=method)
    got = shader.shade(v, views, base_color=PALETTE[groups])
    want = by_group(lambda c, rows: wenv.Shader(env, MAKERS[kind](c), quality=quality, method=method).shade(
        v[rows], views[rows]), groups)
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-7)
    assert relative_rmse(shader.shade(v, views), want) > 0.1


def test_the_reference_takes_a_colour_per_vertex(sphere):
    v, views, groups = sphere
    env = wenv.load_environment(hdri_path("city"))
    rows = np.arange(0, len(v), 7)
    got = wenv.reference(env, MAKERS["principled"]((0.5, 0.5, 0.5)), v[rows], views[rows],
                         base_color=PALETTE[groups[rows]])
    want = by_group(lambda c, sel: wenv.reference(env, MAKERS["principled"](c), v[rows][sel], views[rows][sel]),
                    groups[rows])
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)


def test_colours_with_shadows_and_the_bounce_they_send(sphere):
    """A sphere resting on a plane, a colour per vertex: bounce='self' is the mesh's light with its
    own colours (as diffuse_light(base_color=) gives it), and the shading matches the ray-cast
    reference given the same colours and bounce within the shadows' 4 %."""
    from tests.test_shadows import sphere_on_plane
    positions, triangles, normals = sphere_on_plane()
    occluders = wenv.Occluders(positions, triangles)
    occlusion = occluders.occlusion(positions, normals)
    eye = np.array([0.5, -6.0, 4.0], np.float32)
    views = ((eye - positions) / np.linalg.norm(eye - positions, axis=1)[:, None]).astype(np.float32)
    colours = PALETTE[np.random.default_rng(4).integers(0, len(PALETTE), len(positions))]
    env = sky()
    shader = wenv.Shader(env, SHADOW_MATERIALS["lambert"], quality="default")
    light = shader.diffuse_light(normals, occlusion=occlusion, base_color=colours)
    own = shader.shade(normals, views, occlusion=occlusion, base_color=colours)
    np.testing.assert_allclose(own, shader.shade(normals, views, occlusion=occlusion, bounce=light,
                                                 base_color=colours), rtol=1e-5, atol=1e-7)
    front = np.flatnonzero(np.einsum("ij,ij->i", normals, views) > 0.05)[::3]
    truth = wenv.reference(env, SHADOW_MATERIALS["lambert"], normals[front], views[front],
                           positions=positions[front], occluders=occluders, bounce=light, base_color=colours[front])
    assert relative_rmse(own[front], truth) < 0.04


def test_culled_and_stepped_shading_reads_each_vertexs_own_colour(sphere):
    v, views, groups = sphere
    colours = PALETTE[groups]
    shader = wenv.Shader(wenv.load_environment(hdri_path("forest")), MAKERS["principled"]((0.5, 0.5, 0.5)),
                         quality="draft")
    eye = (0.4, -3.5, 1.0)
    whole = shader.shade(v, views, base_color=colours)
    culled = shader.shade_mesh(v, v, eye, cull=True, base_color=colours)
    seen = wenv.visible_vertices(v, v, eye)
    assert 0 < seen.sum() < len(v)
    np.testing.assert_allclose(culled[seen], whole[seen], rtol=2e-5, atol=1e-7)
    assert not culled[~seen].any()
    stepped, first = np.zeros_like(whole), 0
    while first < len(v):
        shader.shade_mesh(v, v, eye, out=stepped, first=first, budget=0.0, base_color=colours)
        first = shader.stats["next_vertex"]
    np.testing.assert_allclose(stepped, whole, rtol=2e-5, atol=1e-7)


def test_colours_above_one_are_read_as_one(sphere):
    """As a material clamps its own Base Color (Cycles does too)."""
    v, views, _ = sphere
    shader = wenv.Shader(wenv.load_environment(hdri_path("city")), MAKERS["lambert"]((0.5, 0.5, 0.5)),
                         quality="draft")
    bright = np.tile(np.float32([2.0, 1.0, 0.5]), (len(v), 1))
    np.testing.assert_array_equal(shader.shade(v, views, base_color=bright),
                                  shader.shade(v, views, base_color=np.minimum(bright, 1.0)))


def test_colours_that_cannot_vary_alone_are_refused_with_the_reason(sphere):
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("city"))
    colours = np.full((len(v), 3), 0.5, np.float32)
    for mat, reason in ((wenv.Principled(metallic=1.0, coat_weight=1.0), "a coat or sheen over a metal"),
                        (wenv.Principled(diffuse_roughness=0.5), "rough diffuse lobe"),
                        (wenv.Tabulated(np.full((16, 16, 32, 3), 0.05)), "tabulated material has no colour")):
        shader = wenv.Shader(env, mat, quality="draft")
        with pytest.raises(ValueError, match=reason):
            shader.shade(v, views, base_color=colours)
        if not (isinstance(mat, wenv.Principled) and mat.inputs["metallic"] > 0.0):  # the reference: each colour its own metal
            with pytest.raises(ValueError, match=reason):
                wenv.reference(env, mat, v[:3], views[:3], base_color=colours[:3])
    # a metal's colour per vertex is shaded by the wavelet methods (tests/test_vertex_material.py)
    peer = wenv.Shader(env, wenv.Principled(metallic=1.0), quality="default", method="split_sum")
    with pytest.raises(ValueError, match="use a wavelet method"):
        peer.shade(v, views, base_color=colours)
    shader = wenv.Shader(env, MAKERS["lambert"]((0.5, 0.5, 0.5)), quality="draft")
    with pytest.raises(ValueError, match="base_color has 3 rows, one per vertex"):
        shader.shade(v, views, base_color=colours[:3])
    bad = colours.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"base_color\[5\] is not finite"):
        shader.shade(v, views, base_color=bad)
    bad[5, 1] = -0.1
    with pytest.raises(ValueError, match=r"base_color\[5\]"):
        shader.diffuse_light(v, base_color=bad)
    with pytest.raises(TypeError, match="base_color must be a C-contiguous float32 array of shape"):
        shader.shade_mesh(v, v, (0.0, -4.0, 0.0), base_color=colours[:, :2])
