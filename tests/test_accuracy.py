"""Accuracy of the shading engine against the brute-force reference, per quality preset, on all of
Blender's bundled HDRIs: Lambert and specular-only Cook-Torrance (Beckmann, IOR 1.5) at
m = 0.05, 0.1, 0.2, 0.5, over a fixed set of 2000 random (normal, view) pairs with views uniform on
the hemisphere (grazing views included).

The reference values (wenv.reference over every pixel) are stored in data/accuracy_reference.npz
by benchmarks/accuracy.py --make-reference; test_stored_reference_is_current recomputes a sample of
them so the stored values cannot drift from what wenv.reference computes.  `high` runs with
method="slicing", which is the rotation method without the matrices (equal to it up to the
matrices' truncation, tested in test_shade.py): the matrices at that size take far longer to build
than a test may run."""
import json
import os

import numpy as np
import pytest

import wenv
from conftest import hdri_path

DATA = os.path.join(os.path.dirname(__file__), "data", "accuracy_reference.npz")
# 6000 further pairs (another seed) that benchmarks/auto_quality.py judges auto on.
EXTRA_DATA = os.path.join(os.path.dirname(__file__), "data", "accuracy_reference_extra.npz")

# Worst relative RMSE over the eight HDRIs, per preset and material: the measured worst case
# (benchmarks/accuracy.py prints the full table) with 10% headroom.  Suns and lamps are shaded as
# exact lights; what remains in draft's glossy figures is mostly bright extended features (studio's
# softboxes, courtyard's sunlit walls, forest's sky through leaves) and views past 80 degrees, which
# `high` takes per vertex (every pixel above 8x the mean radiance as a light, narrow lobes at grazing
# integrated per vertex); `default` takes the grazing views per vertex and resolves the features with
# high's local maps (1.48 % at m = 0.2, 2.21 % at m = 0.5, courtyard; 2.67 % at m = 0.1, forest;
# 29 / 9.8 / 44 % when it was the 64/32/32 rotation setting).  docs/performance.md, "Accuracy".  high's
# m = 0.1 went from 0.61 to 0.77 % (courtyard) when the grazing path's 1024 polar nodes became 96
# slope cells (aliasing of the lighting between nodes: 128 or 192 cells give 0.68 and 0.75 %).
BOUNDS = {
    "draft": {"lambert": 0.0432, "m0.05": 0.893, "m0.1": 0.815, "m0.2": 0.677, "m0.5": 0.279},
    "default": {"lambert": 0.0052, "m0.05": 0.053, "m0.1": 0.0294, "m0.2": 0.0163, "m0.5": 0.0243},
    "high": {"lambert": 0.00176, "m0.05": 0.0120, "m0.1": 0.0085, "m0.2": 0.0095, "m0.5": 0.0102},
}
METHOD = {"draft": "rotation", "default": "slicing", "high": "slicing", "auto level 5": "slicing"}
# Settings named here by what they are: auto's ladder level between `default` and `high`.
SETTINGS = {"auto level 5": wenv.AUTO_LADDER[5]}


@pytest.fixture(scope="module")
def data():
    return np.load(DATA)


def material(spec):
    if not spec["lobes"]:
        return wenv.Lambert(tuple(spec["diffuse"]))
    return wenv.CookTorrance(diffuse=tuple(spec["diffuse"]), lobes=spec["lobes"])


def relative_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


_errors = {}


def shade_errors(preset, data, materials):
    """{(hdri, material name): relative RMSE} of `preset` over data's pairs against its stored
    reference, for {name: wenv material}.  HDRIs in the outer loop: a new environment remakes only
    the lighting slices the pairs read."""
    nrm, v = data["normals"], data["views"]
    shader, out = None, {}
    for h in json.loads(str(data["hdris"])):
        env = wenv.load_environment(hdri_path(h))
        if shader is None:
            shader = wenv.Shader(env, wenv.Lambert((0.5, 0.5, 0.5)), quality=SETTINGS.get(preset, preset),
                                 method=METHOD[preset])
        else:
            shader.set_environment(env)
        for name, mat in materials.items():
            shader.set_material(mat)
            result = shader.shade(nrm, v)
            assert np.all(np.isfinite(result)) and np.all(result >= 0)
            out[(h, name)] = relative_rmse(result, data[f"{h}/{name}"])
    return out


def assert_stored_reference_current(data, materials, cases, pick):
    """wenv.reference recomputed live on the pairs `pick` of the stored ones equals what is stored,
    for each (hdri, material name) of `cases`; materials: {name: wenv material}."""
    for h, name in cases:
        env = wenv.load_environment(hdri_path(h))
        fresh = wenv.reference(env, materials[name], data["normals"][pick], data["views"][pick])
        assert np.allclose(fresh, data[f"{h}/{name}"][pick], rtol=1e-5, atol=1e-7), (h, name)


def assert_within_bounds(preset, errors, bounds, data, n_materials):
    """Every HDRI and material of data measured, none above its bound."""
    assert len(errors) == len(json.loads(str(data["hdris"]))) * n_materials
    over = {k: round(100 * e, 2) for k, e in errors.items() if e > bounds[preset][k[1]]}
    assert not over, f"{preset}: relative RMSE (%) above the bounds: {over}"


def preset_errors(preset, data):
    """shade_errors of the stored Cook-Torrance and Lambert materials, computed once per session."""
    if preset not in _errors:
        specs = json.loads(str(data["materials"]))
        _errors[preset] = shade_errors(preset, data, {name: material(spec) for name, spec in specs.items()})
    return _errors[preset]


def test_stored_reference_is_current(data):
    made = {name: material(spec) for name, spec in json.loads(str(data["materials"])).items()}
    assert_stored_reference_current(data, made, [("sunset", "m0.2"), ("studio", "lambert"), ("forest", "m0.05")],
                                    np.arange(0, 2000, 125))


def test_extra_reference_is_current_and_new_pairs(data):
    extra = np.load(EXTRA_DATA)
    specs = json.loads(str(extra["materials"]))
    assert extra["normals"].shape == (6000, 3) and specs == json.loads(str(data["materials"]))
    assert not np.isin(extra["normals"][:, 0], data["normals"][:, 0]).any()  # drawn afresh
    pick = np.arange(7, 6000, 397)
    for h, name in [("sunrise", "m0.1"), ("interior", "m0.5")]:
        env = wenv.load_environment(hdri_path(h))
        fresh = wenv.reference(env, material(specs[name]), extra["normals"][pick], extra["views"][pick])
        assert np.allclose(fresh, extra[f"{h}/{name}"][pick], rtol=1e-5, atol=1e-7)


def test_pairs_cover_grazing_views(data):
    cos = np.sum(data["normals"] * data["views"], axis=1)
    assert data["normals"].shape == (2000, 3) and np.all(cos >= 0)
    assert np.sum(cos < np.cos(np.radians(85))) > 50


@pytest.mark.parametrize("preset", ["draft", "default", "high"])
def test_relative_rmse_within_preset_bounds(preset, data):
    assert_within_bounds(preset, preset_errors(preset, data), BOUNDS, data, len(BOUNDS[preset]))


def test_high_within_one_percent_from_m_0_1(data):
    """The engine's accuracy goal: `high` within 1 % of the reference for m >= 0.1 (and Lambert)
    under every bundled HDRI."""
    errors = preset_errors("high", data)
    over = {k: round(100 * e, 2) for k, e in errors.items() if k[1] != "m0.05" and e >= 0.01}
    assert len(errors) == 40 and not over, f"high: relative RMSE (%) at or above 1 %: {over}"


def test_auto_level_5_within_one_percent_from_m_0_1(data):
    """Auto's level 5 -- `default`'s grazing path with `high`'s tables and the bright extended
    features (above 16x the mean) as exact lights read to 5 % -- is within 1 % of the reference for
    m >= 0.1 and Lambert under every bundled HDRI (measured worst: 0.16 % Lambert, 0.85 / 0.95 /
    0.97 % at m = 0.1 / 0.2 / 0.5, courtyard), as `high` is, at a third of high's time per view:
    what auto takes at a 1 % target for these lobes where `default` is not enough."""
    errors = preset_errors("auto level 5", data)
    over = {k: round(100 * e, 2) for k, e in errors.items() if k[1] != "m0.05" and e >= 0.01}
    assert len(errors) == 40 and not over, f"auto level 5: relative RMSE (%) at or above 1 %: {over}"
    default, high = preset_errors("default", data), preset_errors("high", data)
    for name in ("m0.1", "m0.2", "m0.5"):  # between default and high, nearer high
        worst = [max(e[k] for k in e if k[1] == name) for e in (default, errors, high)]
        assert worst[1] < worst[0] and worst[1] < 1.2 * worst[2], (name, worst)


def test_default_within_three_percent_from_m_0_2(data):
    """The interactive preset's accuracy goal (a view change within 30 ms at 126k vertices,
    benchmarks/bench_interactive.py): within 3 % of the reference for m >= 0.2 under every bundled
    HDRI."""
    errors = preset_errors("default", data)
    over = {k: round(100 * e, 2) for k, e in errors.items() if k[1] in ("m0.2", "m0.5") and e >= 0.03}
    assert len(errors) == 40 and not over, f"default: relative RMSE (%) at or above 3 %: {over}"


def test_higher_presets_are_more_accurate(data):
    draft, default, high = (preset_errors(p, data) for p in ("draft", "default", "high"))
    for name in BOUNDS["draft"]:
        median = [np.median([e[k] for k in e if k[1] == name]) for e in (draft, default, high)]
        assert median[0] > median[1] > median[2], (name, median)
