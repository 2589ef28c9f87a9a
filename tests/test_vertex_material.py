"""Roughness and Metallic per vertex (Shader.shade(..., roughness=, metallic=)): a few values shaded
exactly, Metallic exactly linear, a smooth Roughness within its stated interpolation bound of each
vertex's own material and within the method's own error of the reference, with shadows, colours,
culled and budgeted steps, and bad input named."""
import numpy as np
import pytest

import wenv
from tests.conftest import hdri_path
from tests.helpers.measure import relative_rmse
from tests.helpers.meshes import uv_sphere
from tests.test_shadows import sphere_on_plane

PAINT = dict(base_color=(0.6, 0.15, 0.08))
METAL = dict(base_color=(0.9, 0.62, 0.35), metallic=1.0)


@pytest.fixture(scope="module")
def sphere():
    v, _ = uv_sphere(40, 80)
    eye = np.float32([0.4, -4.2, 0.6])
    views = ((eye - v) / np.linalg.norm(eye - v, axis=1)[:, None]).astype(np.float32)
    return v.astype(np.float32), views, eye


def smooth(v, lo, hi, step):
    t = 0.5 + 0.25 * np.sin(3.0 * v[:, 0] + 1.0) + 0.25 * np.cos(4.0 * v[:, 2])
    return (np.round((lo + (hi - lo) * t) / step) * step).astype(np.float32)


def each_own(env, inputs, v, views, roughness, metallic, method="slicing", **shade):
    """Every vertex as a shader of a plain Principled at its own (roughness, metallic) shades it."""
    out = np.zeros((len(v), 3), np.float32)
    shader = None
    for r, m in np.unique(np.stack([roughness, metallic], 1), axis=0):
        mat = wenv.Principled(**{**inputs, "roughness": float(r), "metallic": float(m)})
        if shader is None:
            shader = wenv.Shader(env, mat, quality="default", method=method)
        shader.set_material(mat)
        rows = (roughness == r) & (metallic == m)
        out[rows] = shader.shade(v, views, **shade)[rows]
    return out


@pytest.mark.parametrize("method", ["slicing", "rotation"])
def test_a_few_values_are_each_shaded_exactly(sphere, method):
    """A roughness of two values (a striped texture) and a metallic of two: every vertex as a plain
    material at its own values shades it, to float rounding -- no interpolation."""
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("sunset"))
    roughness = np.where(np.sin(9.0 * v[:, 0]) > 0.0, 0.15, 0.6).astype(np.float32)
    metallic = np.where(v[:, 2] > 0.2, 1.0, 0.0).astype(np.float32)
    quality = "draft" if method == "rotation" else "default"
    shader = wenv.Shader(env, wenv.Principled(**PAINT, roughness=0.4), quality=quality, method=method)
    got = shader.shade(v, views, roughness=roughness, metallic=metallic)
    want = np.zeros_like(got)
    for r in np.float32([0.15, 0.6]):  # the values as the vertices hold them
        for m in (0.0, 1.0):
            rows = (roughness == r) & (metallic == m)
            plain = wenv.Shader(env, wenv.Principled(**PAINT, roughness=float(r), metallic=m), quality=quality,
                                method=method)
            want[rows] = plain.shade(v[rows], views[rows])
    np.testing.assert_allclose(got, want, rtol=3e-5, atol=1e-6)
    # and the shader's own material is as it was
    np.testing.assert_array_equal(shader.shade(v, views), wenv.Shader(
        env, wenv.Principled(**PAINT, roughness=0.4), quality=quality, method=method).shade(v, views))


def test_metallic_is_exactly_linear(sphere):
    """Cycles weighs the metal by Metallic and what lies under it by 1 - Metallic: a metallic per
    vertex is each vertex's mix of the material at 0 and at 1, to float rounding."""
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("city"))
    metallic = np.clip(0.5 + v[:, 0], 0.0, 1.0).astype(np.float32)
    shader = wenv.Shader(env, wenv.Principled(**PAINT, roughness=0.3), quality="default", method="slicing")
    got = shader.shade(v, views, metallic=metallic)
    dielectric = wenv.Shader(env, wenv.Principled(**PAINT, roughness=0.3), quality="default",
                             method="slicing").shade(v, views)
    metal = wenv.Shader(env, wenv.Principled(**PAINT, roughness=0.3, metallic=1.0), quality="default",
                        method="slicing").shade(v, views)
    want = (1.0 - metallic)[:, None] * dielectric + metallic[:, None] * metal
    np.testing.assert_allclose(got, want, rtol=3e-5, atol=1e-6)


def test_levels_read_exactly_through_the_lights_apart(sphere):
    """More values than are shaded exactly, each on a roughness level: each vertex reads one member,
    and its lights through a material at its own roughness, which is that member's -- so shading the
    lights apart adds up to shading them with the member, to 0.1 %."""
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("sunset"))
    levels = np.arange(3, 14) / 24.0  # 11 values on the levels, past the 8 shaded exactly
    roughness = levels[np.random.default_rng(3).integers(0, len(levels), len(v))].astype(np.float32)
    shader = wenv.Shader(env, wenv.Principled(**METAL, roughness=0.3), quality="default", method="slicing")
    got = shader.shade(v, views, roughness=roughness)
    want = each_own(env, METAL, v, views, roughness, np.ones(len(v), np.float32))
    # to 1e-3: the lights read at the roughness to 1/8192, the members at the levels in double
    np.testing.assert_allclose(got, want, rtol=1e-3, atol=1e-5)


@pytest.mark.parametrize("inputs, hdri", [(PAINT, "sunset"), (METAL, "sunset"), (METAL, "forest"), (METAL, "studio")],
                         ids=["paint-sunset", "metal-sunset", "metal-forest", "metal-studio"])
def test_a_smooth_roughness_is_within_its_bound_of_each_vertex_own(sphere, hdri, inputs):
    """Roughness from 0.1 to 0.7 over the sphere in steps of 1/20 (13 values, most between the levels
    1/16 apart): against every vertex shaded with a plain material at its own roughness by the same
    shader, within 1 % relative RMSE (the stated bound; 0.16-0.72 % here, and 0.05-0.88 % over the
    eight HDRIs in steps of 1/40 in benchmarks/bench_vertex_material.py) -- the sun's highlight is not
    blurred, its lights being read at each vertex's own roughness.  The metal, whose lobe is the
    narrower, under three skies; the paint under the sun."""
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path(hdri))
    roughness = smooth(v, 0.1, 0.7, 1 / 20)
    metallic = np.full(len(v), inputs.get("metallic", 0.0), np.float32)
    shader = wenv.Shader(env, wenv.Principled(**inputs, roughness=0.4), quality="default", method="slicing")
    got = shader.shade(v, views, roughness=roughness)
    want = each_own(env, inputs, v, views, roughness, metallic)
    assert relative_rmse(got, want) < 0.01
    # interpolating the lights as well would be far off under the sun: the bound is not loose
    assert relative_rmse(got, shader.shade(v, views)) > 0.02


def test_against_the_reference_a_texture_costs_little_beyond_the_method(sphere):
    """Roughness 0.1-0.7 and a metallic band (0, 1/2, 1), against wenv.reference given the same values (each
    value's own material, exactly): within 1 % of the error the same shader has when each vertex is
    shaded with its own material (the method's own error, larger at the narrow lobes)."""
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("sunset"))
    front = np.flatnonzero(np.einsum("ij,ij->i", v, views) > 0.0)[::4]
    v, views = v[front], views[front]
    roughness = smooth(v, 0.1, 0.7, 1 / 20)
    metallic = np.round(np.clip((v[:, 2] + 0.3) / 0.6, 0.0, 1.0) * 2).astype(np.float32) / 2
    base = wenv.Principled(**PAINT, roughness=0.4, metallic=0.5)
    shader = wenv.Shader(env, base, quality="default", method="slicing")
    got = shader.shade(v, views, roughness=roughness, metallic=metallic)
    truth = wenv.reference(env, base, v, views, roughness=roughness, metallic=metallic)
    own = each_own(env, PAINT, v, views, roughness, metallic)
    assert relative_rmse(got, truth) < relative_rmse(own, truth) + 0.01


def test_the_reference_shades_each_value_with_its_own_material(sphere):
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("city"))
    rows = np.arange(0, len(v), 37)
    roughness = np.where(np.arange(len(rows)) % 2, 0.2, 0.5).astype(np.float32)
    got = wenv.reference(env, wenv.Principled(**PAINT), v[rows], views[rows], roughness=roughness)
    for r in np.float32([0.2, 0.5]):
        sel = roughness == r
        np.testing.assert_array_equal(got[sel], wenv.reference(env, wenv.Principled(**PAINT, roughness=float(r)),
                                                               v[rows][sel], views[rows][sel]))


def test_colours_with_a_roughness_per_vertex(sphere):
    """Base Color and Roughness per vertex together (a painted, worn surface): as each vertex's own
    material with its colour, where both are of a few values."""
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("forest"))
    roughness = np.where(v[:, 0] > 0.0, 0.2, 0.5).astype(np.float32)
    colour = np.where((v[:, 2] > 0.0)[:, None], [0.8, 0.1, 0.1], [0.1, 0.5, 0.8]).astype(np.float32)
    shader = wenv.Shader(env, wenv.Principled(**PAINT, roughness=0.3), quality="default", method="slicing")
    got = shader.shade(v, views, roughness=roughness, base_color=colour)
    want = np.zeros_like(got)
    for r in np.float32([0.2, 0.5]):
        for c in np.unique(colour, axis=0):
            rows = (roughness == r) & np.all(colour == c, axis=1)
            plain = wenv.Shader(env, wenv.Principled(base_color=tuple(c), roughness=float(r)), quality="default",
                                method="slicing")
            want[rows] = plain.shade(v[rows], views[rows])
    np.testing.assert_allclose(got, want, rtol=3e-5, atol=1e-6)


METALS = np.float32([[1.0, 0.78, 0.34], [0.95, 0.64, 0.54], [0.56, 0.57, 0.58]])  # gold, copper, steel


@pytest.mark.parametrize("roughness", [0.2, 0.7])
def test_a_metal_takes_a_colour_per_vertex(sphere, roughness):
    """A metal's Base Color is its Fresnel colour: gold, copper and steel scattered over one metal shade
    as each metal's own material, within 0.2 % relative RMSE (the metal in black and in white, mixed per
    channel and view, exactly; each member's slices truncated and its lights read to their own
    tolerance); a Metallic map between them mixes each with the paint under it exactly; a coat
    over a metal of varying colour is refused with the reason."""
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("sunset"))
    which = np.random.default_rng(5).integers(0, len(METALS), len(v))
    colour = METALS[which]
    shader = wenv.Shader(env, wenv.Principled(base_color=(0.5, 0.5, 0.5), metallic=1.0, roughness=roughness),
                         quality="default", method="slicing")
    got = shader.shade(v, views, base_color=colour)
    own = [wenv.Shader(env, wenv.Principled(base_color=tuple(c), roughness=roughness, metallic=m),
                       quality="default", method="slicing").shade(v, views) for c in METALS for m in (0.0, 1.0)]
    want = np.zeros_like(got)
    for k in range(len(METALS)):
        want[which == k] = own[2 * k + 1][which == k]
    assert relative_rmse(got, want) < 0.002
    metallic = np.clip(v[:, 0] + 0.5, 0.0, 1.0).astype(np.float32)
    got = shader.shade(v, views, base_color=colour, metallic=metallic)
    for k in range(len(METALS)):
        mix = (1.0 - metallic)[:, None] * own[2 * k] + metallic[:, None] * own[2 * k + 1]
        want[which == k] = mix[which == k]
    assert relative_rmse(got, want) < 0.002
    coated = wenv.Shader(env, wenv.Principled(base_color=(0.5, 0.5, 0.5), metallic=1.0, coat_weight=1.0),
                         quality="draft", method="slicing")
    with pytest.raises(ValueError, match="a coat or sheen over a metal"):
        coated.shade(v, views, base_color=colour)


def test_a_metal_of_a_colour_per_vertex_against_the_reference(sphere):
    """Colour, Metallic and Roughness per vertex together against the reference (each vertex's own
    material, its colour the metal's Fresnel colour): within the method's own error plus 1 %."""
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("city"))
    front = np.flatnonzero(np.einsum("ij,ij->i", v, views) > 0.0)[::6]
    v, views = v[front], views[front]
    which = np.random.default_rng(6).integers(0, len(METALS), len(v))
    colour = METALS[which]
    metallic = np.where(v[:, 2] > 0.0, 1.0, 0.0).astype(np.float32)
    roughness = np.where(v[:, 0] > 0.0, 0.25, 0.5).astype(np.float32)
    base = wenv.Principled(base_color=(0.5, 0.5, 0.5), roughness=0.4)
    shader = wenv.Shader(env, base, quality="default", method="slicing")
    got = shader.shade(v, views, base_color=colour, metallic=metallic, roughness=roughness)
    truth = wenv.reference(env, base, v, views, base_color=colour, metallic=metallic, roughness=roughness)
    own = np.zeros_like(got)
    for k, c in enumerate(METALS):
        for m in (0.0, 1.0):
            for r in np.float32([0.25, 0.5]):
                rows = (which == k) & (metallic == m) & (roughness == r)
                mat = wenv.Principled(base_color=tuple(c), metallic=m, roughness=float(r))
                own[rows] = wenv.Shader(env, mat, quality="default", method="slicing").shade(v[rows], views[rows])
    assert relative_rmse(got, truth) < relative_rmse(own, truth) + 0.01


def test_shadows_and_the_own_bounce_with_a_material_per_vertex():
    """A sphere on a plane, a roughness of two values: with a given bounce, each vertex as its own
    material's shader with the same occlusion shades it; with its own bounce (bounce='self'), a
    uniform roughness shades as the plain material does."""
    positions, triangles, normals = sphere_on_plane()
    occlusion = wenv.Occluders(positions, triangles).occlusion(positions, normals, resolution=8)
    eye = np.float32([0.5, -6.0, 4.0])
    views = ((eye - positions) / np.linalg.norm(eye - positions, axis=1)[:, None]).astype(np.float32)
    env = wenv.load_environment(hdri_path("sunset"))
    glow = np.full((len(positions), 3), 0.05, np.float32)
    roughness = np.where(positions[:, 2] > 0.05, 0.15, 0.6).astype(np.float32)
    shader = wenv.Shader(env, wenv.Principled(**PAINT, roughness=0.3), quality="default", method="slicing")
    got = shader.shade(normals, views, occlusion=occlusion, bounce=glow, roughness=roughness)
    want = each_own(env, PAINT, normals, views, roughness, np.zeros(len(roughness), np.float32),
                    occlusion=occlusion, bounce=glow)
    np.testing.assert_allclose(got, want, rtol=3e-5, atol=1e-6)
    uniform = np.full(len(positions), 0.3, np.float32)
    np.testing.assert_allclose(shader.shade(normals, views, occlusion=occlusion, roughness=uniform),
                               shader.shade(normals, views, occlusion=occlusion), rtol=3e-5, atol=1e-6)


def test_culled_and_budgeted_steps_and_the_diffuse_light(sphere):
    """shade_mesh (every vertex, or culled in budgeted steps) gives what shade gives; diffuse_light
    takes the materials too."""
    v, views, eye = sphere
    env = wenv.load_environment(hdri_path("courtyard"))
    roughness = smooth(v, 0.1, 0.7, 1 / 100)
    metallic = np.clip(v[:, 1] + 0.5, 0.0, 1.0).astype(np.float32)
    kw = dict(roughness=roughness, metallic=metallic)
    shader = wenv.Shader(env, wenv.Principled(**PAINT, roughness=0.3), quality="default", method="slicing")
    whole = shader.shade(v, views, **kw)
    np.testing.assert_allclose(shader.shade_mesh(v, v, eye, **kw), whole, rtol=1e-5, atol=1e-7)
    out = np.zeros_like(whole)
    k = 0
    while True:
        shader.shade_mesh(v, v, eye, cull=True, out=out, first=k, budget=0.001, **kw)
        k = shader.stats["next_vertex"]
        if k >= shader.stats["visible_vertices"]:
            break
    seen = wenv.visible_vertices(v, v, eye)
    np.testing.assert_allclose(out[seen], whole[seen], rtol=1e-5, atol=1e-7)
    two = np.where(v[:, 0] > 0.0, 0.2, 0.6).astype(np.float32)
    got = shader.diffuse_light(v, roughness=two)
    for r in np.float32([0.2, 0.6]):
        plain = wenv.Shader(env, wenv.Principled(**PAINT, roughness=float(r)), quality="default", method="slicing")
        np.testing.assert_allclose(got[two == r], plain.diffuse_light(v)[two == r], rtol=3e-5, atol=1e-6)


@pytest.mark.parametrize("quality", ["default", "high"])
def test_a_family_fits_what_the_shader_keeps(sphere, quality):
    """A roughness over most of [0, 1] with a Metallic map and a colour (three sides), at `default` and at
    `high` (7x larger tables): the family's levels are spaced so that its members fit among the
    materials the shader keeps, so a second view makes none again (every member set is found kept)."""
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("forest"))
    shader = wenv.Shader(env, wenv.Principled(**PAINT, roughness=0.3), quality=quality, method="slicing")
    kw = dict(roughness=((v[:, 2] + 1.0) / 2.0).astype(np.float32),
              metallic=np.clip(v[:, 0] + 0.5, 0.0, 1.0).astype(np.float32),
              base_color=np.full((len(v), 3), 0.5, np.float32))
    first = shader.shade(v, views, **kw)
    before = shader.stats["materials_reused"]
    np.testing.assert_array_equal(shader.shade(v, views, **kw), first)
    assert shader.stats["materials_reused"] - before == shader.stats["materials_kept"] > 3


def test_bad_input_is_named(sphere):
    v, views, _ = sphere
    env = wenv.load_environment(hdri_path("city"))
    shader = wenv.Shader(env, wenv.Principled(**PAINT), quality="draft", method="slicing")
    r = np.full(len(v), 0.3, np.float32)
    bad = r.copy()
    bad[7] = np.nan
    with pytest.raises(ValueError, match=r"roughness\[7\] is nan"):
        shader.shade(v, views, roughness=bad)
    with pytest.raises(ValueError, match=r"metallic\[7\] is nan"):
        shader.shade(v, views, metallic=bad)
    with pytest.raises(ValueError, match=r"roughness must have shape"):
        shader.shade(v, views, roughness=r[:-1])
    with pytest.raises(TypeError, match="roughness must have dtype float32"):
        shader.shade(v, views, roughness=r.astype(np.float64))
    with pytest.raises(ValueError, match=r"roughness\[7\] is nan"):
        wenv.reference(env, wenv.Principled(**PAINT), v, views, roughness=bad)
    lambert = wenv.Shader(env, wenv.Lambert(0.5), quality="draft", method="slicing")
    with pytest.raises(ValueError, match="need a Principled material"):
        lambert.shade(v, views, roughness=r)
    peer = wenv.Shader(env, wenv.Principled(**PAINT), quality="default", method="split_sum")
    with pytest.raises(ValueError, match="use a wavelet method"):
        peer.shade(v, views, roughness=r)
    # nothing is left half-done: the shader still shades its own material
    np.testing.assert_array_equal(shader.shade(v, views), wenv.Shader(
        env, wenv.Principled(**PAINT), quality="draft", method="slicing").shade(v, views))


@pytest.mark.parametrize("method", ["slicing", "rotation", "split_sum", "sh"])
def test_emission_is_added_as_it_is_emitted(sphere, method):
    """A Principled BSDF's Emission (Color x Strength) is added to what it reflects, in every method and
    the reference: under a black World every vertex seen shows exactly Color x Strength (no coat or
    sheen over it), and a World's strength scales the reflection alone."""
    v, views, _ = sphere
    front = np.einsum("ij,ij->i", v, views) > 0.0
    black = wenv.Environment(np.zeros((32, 64, 3), np.float32))
    mat = wenv.Principled(**PAINT, emission_color=(1.0, 0.5, 0.25), emission_strength=3.0)
    assert mat.unhonoured == ()
    quality = "draft" if method == "rotation" else "default"
    glow = np.float32([3.0, 1.5, 0.75])
    np.testing.assert_array_equal(wenv.Shader(black, mat, quality=quality, method=method).shade(v, views)[front],
                                  np.tile(glow, (front.sum(), 1)))
    some = np.flatnonzero(front)[::9]
    np.testing.assert_array_equal(wenv.reference(black, mat, v[some], views[some]), np.tile(glow, (len(some), 1)))
    env = wenv.load_environment(hdri_path("sunset"))
    lit = wenv.Shader(env, mat, quality=quality, method=method)
    reflected = wenv.Shader(env, wenv.Principled(**PAINT), quality=quality, method=method).shade(v, views)
    np.testing.assert_allclose(lit.shade(v, views)[front], reflected[front] + glow, rtol=1e-5, atol=1e-5)
    lit.set_environment(env.with_transform(strength=2.0))
    np.testing.assert_allclose(lit.shade(v, views)[front], 2.0 * reflected[front] + glow, rtol=1e-5, atol=1e-5)


def test_emission_shines_through_a_coat_and_lights_what_it_faces():
    """Under a coat, the emission is dimmed as Cycles dims it (by the coat's albedo, more towards
    grazing), as the reference has it; with shadows, an emitting mesh's own bounce carries its light."""
    env = wenv.Environment(np.zeros((32, 64, 3), np.float32))
    coated = wenv.Principled(**PAINT, coat_weight=1.0, emission_color=(1.0, 1.0, 1.0), emission_strength=1.0)
    shader = wenv.Shader(env, coated, quality="default", method="slicing")
    angles = np.radians(np.linspace(0.0, 85.0, 18))
    normals = np.tile(np.float32([0.0, 0.0, 1.0]), (len(angles), 1))
    views = np.stack([np.sin(angles), np.zeros_like(angles), np.cos(angles)], 1).astype(np.float32)
    got = shader.shade(normals, views)
    np.testing.assert_allclose(got, wenv.reference(env, coated, normals, views), rtol=1e-3)  # a 257-cosine table
    assert 0.9 < got[0, 0] < 1.0 and got[-1, 0] < got[0, 0] - 0.1  # the coat reflects more towards grazing
    positions, triangles, nrm = sphere_on_plane()
    occlusion = wenv.Occluders(positions, triangles).occlusion(positions, nrm, resolution=8)
    eye = np.float32([0.5, -6.0, 4.0])
    vd = ((eye - positions) / np.linalg.norm(eye - positions, axis=1)[:, None]).astype(np.float32)
    glowing = wenv.Shader(env, wenv.Principled(**PAINT, emission_strength=2.0), quality="default", method="slicing")
    own = glowing.shade(nrm, vd, occlusion=occlusion)
    none = glowing.shade(nrm, vd, occlusion=occlusion, bounce=None)
    plane = positions[:, 2] == 0.0
    assert np.all(own[plane] >= none[plane] - 1e-6) and (own[plane] - none[plane]).max() > 0.01


@pytest.mark.parametrize("method", ["slicing", "split_sum"])
def test_an_emission_color_per_vertex(sphere, method):
    """emission_color: each vertex's Emission Color in place of the material's (a texture's), through
    its coat and sheen as its own material would emit it, in every method and the reference; the
    culled and budgeted steps and the mesh's own bounce carry it; bad colours are named."""
    v, views, eye = sphere
    rng = np.random.default_rng(11)
    colours = rng.uniform(0.0, 2.0, (len(v), 3)).astype(np.float32)
    inputs = dict(PAINT, roughness=0.4, coat_weight=0.6, sheen_weight=0.4, emission_strength=1.5)
    env = wenv.load_environment(hdri_path("sunset"))
    shader = wenv.Shader(env, wenv.Principled(**inputs), quality="default", method=method)
    got = shader.shade(v, views, emission_color=colours)
    reflected = wenv.Shader(env, wenv.Principled(**{**inputs, "emission_strength": 0.0}), quality="default",
                            method=method).shade(v, views)
    white = wenv.Shader(env, wenv.Principled(**inputs, emission_color=(1.0, 1.0, 1.0)), quality="default",
                        method=method).shade(v, views)
    assert (white - reflected).max() > 0.5  # it emits
    np.testing.assert_allclose(got, reflected + colours * (white - reflected), rtol=1e-4, atol=1e-4)
    some = np.arange(0, len(v), 97)
    for i in some[:6]:
        own = wenv.Principled(**inputs, emission_color=tuple(float(c) for c in colours[i]))
        np.testing.assert_allclose(wenv.reference(env, wenv.Principled(**inputs), v[i:i + 1], views[i:i + 1],
                                                  emission_color=colours[i:i + 1]),
                                   wenv.reference(env, own, v[i:i + 1], views[i:i + 1]), rtol=1e-6, atol=1e-7)
    whole = shader.shade_mesh(v, v, eye, emission_color=colours)
    culled = shader.shade_mesh(v, v, eye, cull=True, emission_color=colours)
    seen = wenv.visible_vertices(v, v, eye)
    np.testing.assert_allclose(culled[seen], whole[seen], rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match=r"emission_color\[2\]"):
        bad = colours.copy()
        bad[2, 1] = -1.0
        shader.shade(v, views, emission_color=bad)
    with pytest.raises(ValueError, match="emission_color has"):
        shader.shade(v, views, emission_color=colours[:5])


def test_an_emission_color_per_vertex_lights_what_it_faces():
    """With shadows, the mesh's own bounce carries each vertex's emission."""
    env = wenv.Environment(np.zeros((32, 64, 3), np.float32))
    positions, triangles, nrm = sphere_on_plane()
    occlusion = wenv.Occluders(positions, triangles).occlusion(positions, nrm, resolution=8)
    vd = (np.float32([0.5, -6.0, 4.0]) - positions).astype(np.float32)
    shader = wenv.Shader(env, wenv.Principled(**PAINT, emission_strength=2.0), quality="default", method="slicing")
    sphere_glows = np.where((positions[:, 2] > 0.0)[:, None], np.float32([1.0, 0.8, 0.2]), 0.0).astype(np.float32)
    own = shader.shade(nrm, vd, occlusion=occlusion, emission_color=sphere_glows)
    none = shader.shade(nrm, vd, occlusion=occlusion, bounce=None, emission_color=sphere_glows)
    plane = positions[:, 2] == 0.0
    assert np.all(own[plane] >= none[plane] - 1e-6) and (own[plane] - none[plane]).max() > 0.01
