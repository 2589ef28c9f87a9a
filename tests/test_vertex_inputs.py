"""The Principled inputs other than Roughness and Metallic per vertex (Shader.shade(...,
specular_ior_level=, specular_tint=, coat_weight=, coat_roughness=, sheen_weight=, sheen_roughness=,
sheen_tint=, alpha=)): a few values shaded exactly (emission through each vertex's own layers
included), a smooth input within its stated bound of each vertex's own material, Alpha an exact
scale of all a vertex reflects and emits, the reference taking each, and what cannot be shaded
named."""
import numpy as np
import pytest

import wenv
from tests.conftest import hdri_path
from tests.helpers.measure import relative_rmse
from tests.helpers.meshes import uv_sphere

# a paint that emits a little, so that the emission through each vertex's own coat and sheen is seen
BASE = dict(base_color=(0.6, 0.15, 0.08), roughness=0.4, emission_color=(0.2, 0.5, 1.0), emission_strength=0.3)


@pytest.fixture(scope="module")
def sphere():
    v, _ = uv_sphere(30, 60)
    eye = np.float32([0.4, -4.2, 0.6])
    views = ((eye - v) / np.linalg.norm(eye - v, axis=1)[:, None]).astype(np.float32)
    return v.astype(np.float32), views


def smooth(v, lo, hi, step, phase=1.0):
    t = 0.5 + 0.25 * np.sin(3.0 * v[:, 0] + phase) + 0.25 * np.cos(4.0 * phase * v[:, 2])
    return (np.round((lo + (hi - lo) * t) / step) * step).astype(np.float32)


def each_own(env, base, inputs, v, views, quality="default"):
    """Every vertex as a shader of a plain Principled at its own values shades it."""
    names = list(inputs)
    columns = np.column_stack([inputs[k].reshape(len(v), -1) for k in names])
    out = np.zeros((len(v), 3), np.float32)
    shader = None
    for row in np.unique(columns, axis=0):
        kw, j = dict(base), 0
        for k in names:
            width = inputs[k].reshape(len(v), -1).shape[1]
            kw[k] = float(row[j]) if width == 1 else tuple(float(x) for x in row[j:j + width])
            j += width
        with pytest.warns(UserWarning) if kw.get("alpha", 1.0) < 1.0 else _nothing():
            mat = wenv.Principled(**kw)
        if shader is None:
            shader = wenv.Shader(env, mat, quality=quality, method="slicing")
        shader.set_material(mat)
        rows = np.all(columns == row, axis=1)
        out[rows] = shader.shade(v[rows], views[rows])
    return out


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


TWO_VALUES = {
    "specular_ior_level": (0.2, 0.9),
    "specular_tint": ((1.0, 0.5, 0.3), (0.4, 1.0, 1.0)),
    "coat_weight": (0.0, 1.0),
    "coat_roughness": (0.05, 0.4),
    "sheen_weight": (0.0, 0.8),
    "sheen_roughness": (0.2, 0.7),
    "sheen_tint": ((1.0, 0.6, 0.2), (0.3, 0.3, 1.0)),
    "alpha": (0.3, 1.0),
}
# what an input needs to show: a coat or sheen of some weight
UNDER = {"coat_roughness": dict(coat_weight=1.0), "sheen_roughness": dict(sheen_weight=1.0),
         "sheen_tint": dict(sheen_weight=1.0)}


@pytest.mark.parametrize("name", list(TWO_VALUES))
def test_each_input_in_a_few_values_is_shaded_exactly(sphere, name):
    """An input of two values (a mask texture): every vertex as a plain material at its own value
    shades it, to float rounding, its emission through its own coat and sheen included."""
    v, views = sphere
    env = wenv.load_environment(hdri_path("sunset"))
    base = {**BASE, **UNDER.get(name, {})}
    a, b = (np.float32(x) for x in TWO_VALUES[name])
    mask = np.sin(9.0 * v[:, 0]) > 0.0
    values = np.where(mask[:, None] if a.ndim else mask, a, b).astype(np.float32)
    shader = wenv.Shader(env, wenv.Principled(**base), quality="default", method="slicing")
    got = shader.shade(v, views, **{name: values})
    want = each_own(env, base, {name: values}, v, views)
    np.testing.assert_allclose(got, want, rtol=3e-5, atol=2e-6)


@pytest.mark.parametrize("name, lo, hi, bound", [
    ("specular_ior_level", 0.0, 1.0, 0.005),  # 0.14-0.18 % measured
    ("coat_roughness", 0.02, 0.5, 0.006),  # 0.05-0.34 %
    ("sheen_roughness", 0.1, 0.9, 0.005),  # 0.04-0.05 %
    ("coat_weight", 0.0, 1.0, 1e-4),  # linear: exact
    ("sheen_weight", 0.0, 1.0, 5e-4),  # linear (to the LTC table's rounding)
])
def test_a_smooth_input_is_within_its_bound_of_each_vertex_own(sphere, name, lo, hi, bound):
    """An input varying smoothly over the sphere (16 values), under forest (a sun): against every vertex
    shaded with a plain material at its own value, within the bound docs/python.md states."""
    v, views = sphere
    env = wenv.load_environment(hdri_path("forest"))
    base = {**BASE, **UNDER.get(name, {})}
    inputs = {name: smooth(v, lo, hi, (hi - lo) / 15)}
    got = wenv.Shader(env, wenv.Principled(**base), quality="default", method="slicing").shade(v, views, **inputs)
    assert relative_rmse(got, each_own(env, base, inputs, v, views)) < bound


def test_two_smooth_inputs_share_the_members(sphere):
    """Roughness and Specular IOR Level both smooth: the members the shader keeps are shared between
    the two axes (Roughness 1/16 apart, the level in 2 steps of its root), within 1.5 % of each
    vertex's own (1.09-1.14 % measured); a second view makes nothing again."""
    v, views = sphere
    env = wenv.load_environment(hdri_path("forest"))
    inputs = dict(roughness=smooth(v, 0.1, 0.7, 0.6 / 8), specular_ior_level=smooth(v, 0.0, 1.0, 1 / 8, 1.9))
    shader = wenv.Shader(env, wenv.Principled(**BASE), quality="default", method="slicing")
    got = shader.shade(v, views, **inputs)
    assert relative_rmse(got, each_own(env, BASE, inputs, v, views)) < 0.015
    before = shader.stats["materials_reused"]
    np.testing.assert_array_equal(shader.shade(v, views, **inputs), got)
    assert shader.stats["materials_reused"] - before == shader.stats["materials_kept"]


def test_alpha_scales_all_a_vertex_reflects_and_emits(sphere):
    """Cycles weighs every closure of the Principled BSDF by Alpha: with lamps, shadows' own bounce
    aside, a vertex's Alpha scales its reflection, its lamps' light and its emission exactly, and the
    material's own Alpha multiplies it."""
    v, views = sphere
    env = wenv.load_environment(hdri_path("city"))
    lamp = wenv.Lamp("POINT", np.array([[1, 0, 0, 0], [0, 1, 0, -3], [0, 0, 1, 1], [0, 0, 0, 1]], np.float32),
                     energy=300.0, radius=0.2)
    alpha = np.clip(0.5 + v[:, 0], 0.0, 1.0).astype(np.float32)
    shader = wenv.Shader(env, wenv.Principled(**BASE), quality="default", method="slicing")
    kw = dict(positions=v, lamps=[lamp])
    opaque = shader.shade(v, views, **kw)
    np.testing.assert_allclose(shader.shade(v, views, alpha=alpha, **kw), alpha[:, None] * opaque, rtol=2e-5,
                               atol=1e-6)
    with pytest.warns(UserWarning, match="alpha"):
        half = wenv.Principled(**BASE, alpha=0.5)
    shader.set_material(half)
    np.testing.assert_allclose(shader.shade(v, views, alpha=alpha, **kw), alpha[:, None] * opaque, rtol=2e-5,
                               atol=1e-6)  # the vertex's own Alpha in place of the material's
    np.testing.assert_allclose(shader.shade(v, views, roughness=np.full(len(v), 0.4, np.float32), **kw),
                               0.5 * opaque, rtol=2e-5, atol=1e-6)  # the material's own, with a family


def test_the_reference_takes_each_input(sphere):
    """wenv.reference shades each distinct set of values with its own material, exactly."""
    v, views = sphere
    env = wenv.load_environment(hdri_path("city"))
    rows = np.arange(0, len(v), 53)
    v, views = v[rows], views[rows]
    odd = (np.arange(len(rows)) % 2).astype(bool)
    inputs = dict(coat_weight=np.where(odd, 1.0, 0.0).astype(np.float32),
                  specular_tint=np.where(odd[:, None], (1.0, 0.5, 0.2), (1.0, 1.0, 1.0)).astype(np.float32),
                  alpha=np.where(odd, 0.5, 1.0).astype(np.float32))
    got = wenv.reference(env, wenv.Principled(**BASE), v, views, **inputs)
    with pytest.warns(UserWarning):
        coated = wenv.Principled(**BASE, coat_weight=1.0, specular_tint=(1.0, 0.5, 0.2), alpha=0.5)
    # (to the rounding of a sum over another count of vertices)
    np.testing.assert_allclose(got[odd], wenv.reference(env, coated, v[odd], views[odd]), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(got[~odd], wenv.reference(env, wenv.Principled(**BASE), v[~odd], views[~odd]),
                               rtol=1e-6, atol=1e-9)


def test_what_cannot_be_shaded_is_named(sphere):
    v, views = sphere
    env = wenv.load_environment(hdri_path("city"))
    shader = wenv.Shader(env, wenv.Principled(**BASE), quality="draft", method="slicing")
    n = len(v)
    bad = np.full(n, 0.5, np.float32)
    bad[3] = np.inf
    with pytest.raises(ValueError, match=r"coat_weight\[3\] is inf"):
        shader.shade(v, views, coat_weight=bad)
    with pytest.raises(ValueError, match=r"sheen_tint has 1 rows|sheen_tint must"):
        shader.shade(v, views, sheen_tint=np.float32([0.5, 0.5, 0.5]))
    with pytest.raises(TypeError, match="alpha must have dtype float32"):
        shader.shade(v, views, alpha=np.ones(n))
    # five channels varying smoothly: more than a vertex's cell may mix
    tint = np.column_stack([smooth(v, 0.2, 1.0, 0.01, p) for p in (1.0, 1.3, 1.7)])
    with pytest.raises(ValueError, match=r"too many inputs vary smoothly per vertex \(roughness, specular_tint, "
                                         r"coat_weight: 5 values a vertex, at most 4"):
        shader.shade(v, views, roughness=smooth(v, 0.1, 0.7, 0.01), specular_tint=tint,
                     coat_weight=smooth(v, 0.0, 1.0, 0.01, 2.3))
    assert wenv.Principled.PER_VERTEX == {"exact_materials": 8, "smooth_channels": 4}
    # ... while as many of a few distinct materials are each shaded exactly
    few = dict(roughness=np.where(v[:, 0] > 0, 0.2, 0.6).astype(np.float32),
               specular_tint=np.where(v[:, 0:1] > 0, (1.0, 0.5, 0.5), (0.5, 1.0, 1.0)).astype(np.float32),
               coat_weight=np.where(v[:, 0] > 0, 0.0, 1.0).astype(np.float32))
    assert np.isfinite(shader.shade(v, views, **few)).all()
