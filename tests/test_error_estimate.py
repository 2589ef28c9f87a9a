"""tests/helpers/measure.py's mirror_weighted_pairs and estimated_error, which
benchmarks/auto_quality.py judges auto with and benchmarks/speed_vs_accuracy.py charts the methods
with: the weighted pairs give the means of random_pairs' law (normals uniform on the sphere, views
uniform on their hemisphere), and far steadier ones where a narrow lobe reflects a small bright source; the control-variate estimate
is the relative RMSE itself where nothing is sampled apart."""
import os
import sys

import numpy as np
import pytest

import wenv

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.helpers.measure import estimated_error, mirror_weighted_pairs, random_pairs, relative_rmse  # noqa: E402

SUN = np.array([0.3, 0.4, 0.5]) / np.linalg.norm([0.3, 0.4, 0.5])


@pytest.fixture(scope="module")
def sun_sky():
    """A dim sky with one 4x4-pixel sun about 1000x brighter, on a 128x256 equirectangular image."""
    env = wenv.Environment(np.full((128, 256, 3), 0.2, np.float32))
    dirs, _ = env.samples()
    nearest = np.argsort(dirs @ SUN)[-16:]
    px = np.full((128 * 256, 3), 0.2, np.float32)
    px[nearest] = 200.0
    return wenv.Environment(px.reshape(128, 256, 3))


def mirror(nrm, v):
    return 2 * np.sum(nrm * v, axis=1, keepdims=True) * nrm - v


def test_pairs_are_valid_and_weights_reproduce_uniform_means(sun_sky):
    nrm, v, w = mirror_weighted_pairs(sun_sky, 0.05, 200000, seed=1)
    assert nrm.shape == v.shape == (200000, 3) and w.shape == (200000,)
    assert np.allclose(np.linalg.norm(nrm, axis=1), 1, atol=1e-5) and np.allclose(np.linalg.norm(v, axis=1), 1, atol=1e-5)
    assert np.all(np.sum(nrm * v, axis=1) >= -1e-6) and np.all(w > 0)
    # about half the pairs reflect toward the sun, yet the weighted means are the uniform law's
    assert np.mean(mirror(nrm, v) @ SUN > np.cos(0.3)) > 0.4
    un, uv = random_pairs(200000, seed=2)
    for f in (lambda n, v: np.ones(len(n)), lambda n, v: np.sum(n * v, axis=1), lambda n, v: n[:, 2] ** 2,
              lambda n, v: v[:, 0] * n[:, 0]):
        assert abs(np.mean(w * f(nrm, v)) - np.mean(f(un, uv))) < 0.01


def test_sun_hit_mean_square_is_steadier_than_uniform(sun_sky):
    """The mean square of a sun's reflection in a lobe of m = 0.05: uniform pairs catch it a few
    dozen times in 20000 and scatter; weighted pairs agree with each other and with the uniform law."""
    def glint_squared(nrm, v):  # a glint, squared: the mirror direction within about m of the sun
        return np.exp((mirror(nrm, v) @ SUN - 1) / 0.05 ** 2)

    weighted = [np.mean(w * glint_squared(n, v)) for n, v, w in (mirror_weighted_pairs(sun_sky, 0.05, 20000, s) for s in range(8))]
    uniform = [np.mean(glint_squared(*random_pairs(20000, 100 + s))) for s in range(8)]
    k = 1 / 0.05 ** 2
    exact = -np.expm1(-2 * k) / (2 * k)  # the mean of exp(k (cos - 1)) over r uniform on the sphere
    assert np.std(weighted) / np.mean(weighted) < 0.3 * np.std(uniform) / np.mean(uniform)
    assert abs(np.mean(weighted) / exact - 1) < 0.05


def test_estimate_is_the_error_when_read_on_the_same_pairs():
    """With the many pairs the stored ones, unweighted, the control's terms cancel: the estimate is
    the plain relative RMSE whatever the control; with the reference as control, it is the error
    read on the weighted pairs alone."""
    rng = np.random.default_rng(5)
    ref = rng.random((500, 3)) + 0.1
    out = ref * (1 + 0.2 * rng.standard_normal((500, 3)))
    for control in (ref + 0.05 * rng.standard_normal((500, 3)), np.zeros_like(ref), out):
        assert estimated_error(out, ref, control, out, control, np.ones(500)) == pytest.approx(relative_rmse(out, ref), rel=1e-9)
    w = rng.random(500) + 0.5
    many_ref = rng.random((500, 3)) + 0.1
    many_out = many_ref * 1.1
    want = np.sqrt(np.mean(w * np.mean((many_out - many_ref) ** 2, axis=1)) / np.mean(w * np.mean(many_ref ** 2, axis=1)))
    assert estimated_error(out, ref, ref, many_out, many_ref, w) == pytest.approx(want, rel=1e-9)
