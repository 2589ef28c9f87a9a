"""benchmarks/memory.py measures a setting's peak memory in a fresh process: positive, growing with
the setting, and what the shader holds afterwards matches its own count of its arrays (shader.stats).
Rotation's matrices are built here without a cache and the mesh is a small sphere, so it runs in
about two seconds."""
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from benchmarks.memory import peak_memory, sphere_mesh  # noqa: E402

SMALL = {"global": 16, "local": 8, "normals": 8, "views": 4, "coefficients": 32}
LARGER = {"global": 32, "local": 16, "normals": 16, "views": 8, "coefficients": 128}


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
