"""Refining a view that rests (Shader.shade_mesh(first=, budget=)): an accurate Shader shades in steps
over a fast one's result.  The steps together give exactly what the accurate setting gives in one
call; each step touches only its own rows, starts where the last stopped and keeps to its budget
give or take one block."""

import numpy as np
import pytest

import wenv
from conftest import WAVELET_BASE, random_pairs
from test_culling import look_at, sphere


@pytest.fixture(scope="module")
def scene():
    env = wenv.Environment(np.float32(np.random.default_rng(4).uniform(0.1, 3.0, (32, 64, 3))))
    mat = wenv.CookTorrance(diffuse=0.2, lobes=[{"alpha": 0.1, "ior": 1.5}])
    return env, mat


def refine(accurate, pos, nrm, eye, out, budget, **kw):
    """Steps until every vertex to shade is done; the steps' (first, next) ranges."""
    steps, first = [], 0
    while True:
        before = out.copy()
        accurate.shade_mesh(pos, nrm, eye, out=out, first=first, budget=budget, **kw)
        nxt = accurate.stats["next_vertex"]
        steps.append((first, nxt, before, out.copy()))
        if nxt == first:
            raise AssertionError("a step made no progress")
        first = nxt
        total = accurate.stats.get("visible_vertices", len(pos))
        if first >= total:
            return steps


@pytest.mark.parametrize("cull", [False, True])
def test_steps_end_at_the_accurate_result(scene, cull):
    env, mat = scene
    pos, nrm = sphere(20000, seed=5)
    eye = (0.5, -6.0, 1.0)
    vp = look_at(eye, (1.0, 0.0, 0.6), fov_degrees=25.0) if cull else None
    kw = {"cull": True, "view_projection": vp} if cull else {}
    fast = wenv.Shader(env, mat, quality="draft")
    accurate = wenv.Shader(env, mat, quality={**WAVELET_BASE, "global": 64, "local": 32, "normals": 32,
                                              "views": 16, "coefficients": 256, "grazing": 4}, method="slicing")
    out = fast.shade_mesh(pos, nrm, eye, **kw)
    start = out.copy()
    steps = refine(accurate, pos, nrm, eye, out, 0.0, **kw)  # a zero budget: one block a step
    assert len(steps) > 3
    # the same setting in one call, on a Shader of its own
    whole = wenv.Shader(env, mat, quality=accurate.quality, method="slicing").shade_mesh(pos, nrm, eye, **kw)
    assert np.array_equal(out, whole)
    assert not np.array_equal(start, whole)  # the fast and accurate settings differ
    # each step wrote only the rows from its first to its next vertex (in shading order)
    order = np.flatnonzero(wenv.visible_vertices(pos, nrm, eye, vp)) if cull else np.arange(len(pos))
    for first, nxt, before, after in steps:
        others = np.setdiff1d(np.arange(len(pos)), order[first:nxt])
        assert np.array_equal(after[others], before[others])
        assert np.array_equal(after[order[first:nxt]], whole[order[first:nxt]])
        assert np.array_equal(after[order[nxt:]], start[order[nxt:]])  # not reached yet: the fast result
    assert steps[0][0] == 0 and all(a[1] == b[0] for a, b in zip(steps, steps[1:]))


def test_a_budget_is_kept_within_a_block(scene):
    env, mat = scene
    pos, nrm = sphere(200000, seed=6)
    eye = (0.3, -5.0, 0.4)
    shader = wenv.Shader(env, mat, quality="draft")
    shader.shade_mesh(pos, nrm, eye)  # every table row made: steps cost their vertices only
    out = np.zeros((len(pos), 3), np.float32)
    shader.shade_mesh(pos, nrm, eye, out=out, budget=0.0)
    nxt = shader.stats["next_vertex"]
    assert 0 < nxt < len(pos) // 4  # a zero budget shades one small block
    assert not out[nxt:].any() and out[:nxt].any()
    # without a budget every vertex is shaded in one call, and next_vertex says so
    shader.shade_mesh(pos, nrm, eye, out=out, first=nxt)
    assert shader.stats["next_vertex"] == len(pos)
    assert np.array_equal(out, shader.shade_mesh(pos, nrm, eye))


def test_a_new_lighting_remakes_at_once_every_row_the_last_whole_call_read(scene):
    """Without a budget a mesh is shaded in one call, so what a new lighting remakes at once (what
    the latest call read) is all the mesh read, not its last block's share: shading the same view
    again then makes nothing."""
    env, mat = scene
    pos, nrm = sphere(20000, seed=7)
    eye = (0.4, -5.0, 0.8)
    shader = wenv.Shader(env, mat, quality={**WAVELET_BASE, "global": 32, "local": 16, "normals": 32,
                                            "views": 8, "coefficients": 64}, method="slicing")
    first = shader.shade_mesh(pos, nrm, eye)
    read = shader.stats["pairs_ready"]
    other = wenv.Environment(np.float32(np.random.default_rng(9).uniform(0.1, 3.0, (32, 64, 3))))
    shader.set_environment(other)
    assert shader.stats["pairs_ready"] == read > 0
    again = shader.shade_mesh(pos, nrm, eye)
    assert shader.stats["pairs_ready"] == read and not np.array_equal(first, again)
    assert np.array_equal(again, wenv.Shader(other, mat, quality=shader.quality, method="slicing")
                          .shade_mesh(pos, nrm, eye))


def test_scattered_pairs_read_their_entries_alone_to_the_bit(scene):
    """300 scattered pairs, whose table rows are all missing, read their 16 entries made for them
    alone rather than hundreds of whole rows (csrc/methods/wavelet/vertex_shading.c): the same
    values to the bit as a shader that made the rows, since an entry sums a row's terms in the row's
    order.  Asked for again, the rows are made."""
    env, mat = scene
    nrm, v = random_pairs(300, seed=5)
    shader = wenv.Shader(env, mat, quality="default", method="slicing")
    alone = shader.shade(nrm, v)
    assert shader.stats["pairs_ready"] == 0
    rows = wenv.Shader(env, mat, quality="default", method="slicing")
    whole = rows.shade(np.tile(nrm, (100, 1)), np.tile(v, (100, 1)))[:300]  # 30,000 vertices: rows
    assert rows.stats["pairs_ready"] > 0 and np.any(alone > 0)
    assert np.array_equal(alone, whole)
    again = shader.shade(nrm, v)
    assert shader.stats["pairs_ready"] > 0 and np.array_equal(again, alone)
    # a mesh's vertices share their normal samples: even a small one makes rows, which its next views read
    pos, sphere_nrm = sphere(2000, seed=5)
    small = wenv.Shader(env, mat, quality="default", method="slicing")
    small.shade_mesh(pos, sphere_nrm, (0.4, -5.0, 0.8))
    assert small.stats["pairs_ready"] > 0


def test_step_arguments_are_checked(scene):
    env, mat = scene
    shader = wenv.Shader(env, mat, quality="draft")
    pos, nrm = sphere(100)
    eye = (0, -5, 0)
    with pytest.raises(ValueError, match="first must not be negative, got -1"):
        shader.shade_mesh(pos, nrm, eye, first=-1)
    with pytest.raises(ValueError, match="first is out of range"):
        shader.shade_mesh(pos, nrm, eye, first=2**70)
    with pytest.raises(TypeError, match="first must be an int, got float"):
        shader.shade_mesh(pos, nrm, eye, first=0.5)
    with pytest.raises(ValueError, match=r"first \(101\) is past the 100 vertices to shade"):
        shader.shade_mesh(pos, nrm, eye, first=101)
    with pytest.raises(ValueError, match="budget must be >= 0 seconds"):
        shader.shade_mesh(pos, nrm, eye, budget=-0.5)
    with pytest.raises(ValueError, match="budget must be >= 0 seconds"):
        shader.shade_mesh(pos, nrm, eye, budget=float("nan"))
    with pytest.raises(TypeError, match="budget must be a number of seconds or None"):
        shader.shade_mesh(pos, nrm, eye, budget="1")
    out = shader.shade_mesh(pos, nrm, eye, first=100)  # nothing left to shade is fine
    assert shader.stats["next_vertex"] == 100 and not out.any()
