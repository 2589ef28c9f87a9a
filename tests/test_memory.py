"""tests/helpers/memory.py measures a setting's peak memory in a fresh process: positive, growing with
the setting, and what the shader holds afterwards matches its own count of its arrays (shader.stats).
Rotation's matrices are built here without a cache and the mesh is a small sphere, so it runs in
about two seconds."""
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.helpers.memory import peak_memory, sphere_mesh  # noqa: E402
from conftest import WAVELET_BASE  # noqa: E402

SMALL = {**WAVELET_BASE, "global": 16, "local": 8, "normals": 8, "views": 4, "coefficients": 32}
LARGER = {**WAVELET_BASE, "global": 32, "local": 16, "normals": 16, "views": 8, "coefficients": 128}


@pytest.fixture(scope="module")
def sphere():
    return sphere_mesh(20000)


def close_to_model(m):
    """Held memory within 1 MB + 10 % of the shader's count (the rest: output, small buffers)."""
    return abs(m["held_mb"] - m["model_mb"]) < 1 + 0.1 * m["model_mb"]


def test_rotation_memory_grows_with_the_setting(sphere):
    small = peak_memory("rotation", SMALL, *sphere, cache_dir=False)
    larger = peak_memory("rotation", LARGER, *sphere, cache_dir=False)
    for m in (small, larger):
        assert m["exact"] and m["cache"] == "none" and m["vertices"] == 20000
        assert 0 < m["held_mb"] <= m["increment_mb"] <= m["peak_mb"] - m["baseline_mb"] + 0.5
        assert close_to_model(m), m
    assert larger["quality"]["normals"] == 16
    # 32/16/16 holds ~38 MB of matrices, 16/8/8 ~2 MB: the measured peaks must tell them apart.
    assert larger["increment_mb"] > small["increment_mb"] + 20


def test_split_sum_counts_its_source_pyramid(sphere):
    m = peak_memory("split_sum", {"prefilter": 32, "samples": 16, "lut": 16}, *sphere)
    assert m["cache"] == "none" and m["increment_mb"] > 0
    # The environment's mip pyramid, kept to prefilter again for a new material, is most of it.
    assert m["stats"]["source_bytes"] > m["stats"]["prefilter_bytes"] > 0
    assert close_to_model(m), m


# What a Shader without `method` runs, and the memory budget for rotation's matrices.
import numpy as np  # noqa: E402

import wenv  # noqa: E402

DRAFT_MB = 29  # `draft`'s matrices in memory (64 x 64 x 16 x 16 x 16 x 16 at epsilon 1e-3)


def flat_scene():
    return wenv.Environment(np.ones((16, 32, 3), np.float32)), wenv.Lambert(0.5)


def test_high_without_a_method_slices_instead_of_building_gigabytes(tmp_path):
    """`high`'s matrices would take ~9.5 GB: without a method it slices, and rotation asked for by
    name is a ValueError that says how much, before anything large is built."""
    env, mat = flat_scene()
    shader = wenv.Shader(env, mat, quality="high", cache_dir=str(tmp_path))
    assert shader.method == "slicing" and list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match=r"about 9[0-9]{3} MB, more than memory_budget_mb \(1024\).*slicing"):
        wenv.Shader(env, mat, quality="high", method="rotation", cache_dir=False)
    # default slices too (its matrices would take ~2.4 GB); draft's 29 MB are built and rotate
    assert wenv.Shader(env, mat, quality="default", cache_dir=str(tmp_path)).method == "slicing"
    assert wenv.Shader(env, mat, quality="draft", cache_dir=str(tmp_path)).method == "rotation"


def test_rotation_is_chosen_where_its_matrices_are_cached(tmp_path):
    """Over the budget and not cached: slicing; once the matrices are in the cache (built with a
    larger budget), the same call loads them and rotates."""
    env, mat = flat_scene()
    small = DRAFT_MB // 2
    assert wenv.Shader(env, mat, quality="draft", cache_dir=str(tmp_path), memory_budget_mb=small).method == "slicing"
    with pytest.raises(ValueError, match="memory_budget_mb"):
        wenv.Shader(env, mat, quality="draft", method="rotation", cache_dir=str(tmp_path), memory_budget_mb=small)
    built = wenv.Shader(env, mat, quality="draft", method="rotation", cache_dir=str(tmp_path))
    assert built.stats["cache"] == "built" and abs(built.stats["rotation_bytes"] / 2**20 - DRAFT_MB) < 3
    again = wenv.Shader(env, mat, quality="draft", cache_dir=str(tmp_path), memory_budget_mb=small)
    assert again.method == "rotation" and again.stats["cache"] == "loaded"


def test_matrix_epsilons_that_print_alike_keep_their_own_cache_files(tmp_path):
    env, mat = flat_scene()
    for eps in (1e-3, 1.0004e-3):
        wenv.Shader(env, mat, quality=dict(SMALL, matrix_epsilon=eps), method="rotation", cache_dir=str(tmp_path))
    assert len(list(tmp_path.iterdir())) == 2
