"""Maps of directions and the nonstandard Haar transform (docs/ARCHITECTURE.md §3.2, §3.3)."""
import math

import numpy as np
import pytest

import wenv


def random_dirs(n, seed=0, upper=False):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if upper:
        d[:, 2] = np.abs(d[:, 2])
    return d


def edge_dirs():
    """Seams and poles: axes, octant diagonals, the equator, points just off them."""
    pts = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1),
           (1, 1, 0), (1, -1, 0), (-1, 1, 0), (-1, -1, 0), (1, 1, 1), (1, 1, -1), (-1, -1, -1),
           (1e-9, 0, -1), (0, 1e-9, -1), (1e-7, 1e-7, -1)]
    d = np.array(pts, dtype=np.float64)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("kind", ["oct", "hemi"])
def test_round_trip_directions(kind):
    hemi = kind == "hemi"
    d = np.vstack([random_dirs(20000, 1, upper=hemi), edge_dirs() if not hemi else np.abs(edge_dirs())])
    enc = getattr(wenv, f"_{kind}_encode")
    dec = getattr(wenv, f"_{kind}_decode")
    uv = enc(d).astype(np.float64)
    assert np.all(np.abs(uv) <= 1.0 + 1e-6)
    back = dec(uv).astype(np.float64)
    assert np.all(np.isfinite(back))
    assert np.max(np.linalg.norm(back - d, axis=1)) < 1e-6


@pytest.mark.parametrize("n", [2, 4, 16, 64, 256])
def test_texel_solid_angles_sum(n):
    oct_ = np.array(wenv._texel_solid_angles(n, False))
    hemi = np.array(wenv._texel_solid_angles(n, True))
    assert np.all(oct_ > 0) and np.all(hemi > 0)
    assert abs(oct_.sum() - 4 * math.pi) < 1e-9 * 4 * math.pi
    assert abs(hemi.sum() - 2 * math.pi) < 1e-9 * 2 * math.pi
    if n >= 16:  # not equal-area: the spread docs/ARCHITECTURE.md §3.2 speaks of
        assert 3.0 < oct_.max() / oct_.min() < 8.0


@pytest.mark.parametrize("n", [2, 6, 16, 64])
def test_all_texel_solid_angles_at_once_equal_each_texel_s(n):
    """The pyramid of the grazing path reads every base texel's solid angle per image: computed
    once per orbit of the square's symmetries, they must be each texel's own."""
    each = np.array(wenv._texel_solid_angles(n, False))
    at_once = np.array(wenv._oct_texel_solid_angles_all(n))
    assert np.allclose(at_once, each, rtol=1e-12, atol=0)


def test_texel_solid_angle_matches_monte_carlo():
    n = 8
    exact = np.array(wenv._texel_solid_angles(n, False)).reshape(n, n)
    d = random_dirs(400000, 5)
    uv = wenv._oct_encode(d).astype(np.float64)
    ij = np.clip(((uv + 1) * 0.5 * n).astype(int), 0, n - 1)
    counts = np.zeros((n, n))
    np.add.at(counts, (ij[:, 1], ij[:, 0]), 1)
    mc = counts / len(d) * 4 * math.pi
    assert np.max(np.abs(mc - exact) / exact) < 0.05


@pytest.mark.parametrize("n,ch", [(2, 1), (8, 3), (32, 3), (64, 5)])
def test_haar_round_trip_and_parseval(n, ch):
    rng = np.random.default_rng(n)
    a = rng.normal(size=(n, n, ch)).astype(np.float32)
    b = rng.normal(size=(n, n, ch)).astype(np.float32)
    ha, hb = wenv._haar2d(a), wenv._haar2d(b)
    assert np.allclose(wenv._haar2d(ha, inverse=True), a, atol=1e-5)
    # orthonormal: energy and dot products are preserved per channel
    assert np.allclose((ha * hb).sum(axis=(0, 1)), (a * b).sum(axis=(0, 1)), rtol=1e-4, atol=1e-3)
    assert np.allclose((ha ** 2).sum(), (a ** 2).sum(), rtol=1e-5)


def test_haar_constant_has_one_coefficient():
    n = 16
    h = wenv._haar2d(np.full((n, n, 1), 2.0, np.float32))
    assert math.isclose(h[0, 0, 0], 2.0 * n, rel_tol=1e-6)
    h[0, 0, 0] = 0
    assert np.abs(h).max() < 1e-5


def test_haar_is_nonstandard():
    """One level of rows then one of columns: a single-pixel impulse has 3 log2 n + 1 coefficients."""
    n = 16
    img = np.zeros((n, n, 1), np.float32)
    img[5, 11, 0] = 1.0
    h = wenv._haar2d(img)
    assert np.count_nonzero(np.abs(h) > 1e-7) == 3 * 4 + 1


def plain_nonstandard_haar(img):
    """The nonstandard Haar transform written out in numpy (float64): each level the rows of the
    top-left block (averages left, details right), then its columns (averages on top)."""
    h = img.astype(np.float64).copy()
    s = h.shape[0]
    while s > 1:
        blk = h[:s, :s]
        blk = np.concatenate([blk[:, 0::2] + blk[:, 1::2], blk[:, 0::2] - blk[:, 1::2]], axis=1) / math.sqrt(2)
        h[:s, :s] = np.concatenate([blk[0::2] + blk[1::2], blk[0::2] - blk[1::2]], axis=0) / math.sqrt(2)
        s //= 2
    return h


@pytest.mark.parametrize("n,ch", [(1, 3), (2, 1), (4, 2), (16, 3), (64, 3), (32, 4)])
def test_haar_equals_the_transform_written_out(n, ch):
    rng = np.random.default_rng(100 + n)
    img = rng.normal(size=(n, n, ch)).astype(np.float32)
    h = wenv._haar2d(img)
    expected = plain_nonstandard_haar(img)
    assert np.allclose(h, expected, rtol=1e-5, atol=1e-5 * math.log2(2 * n))
    assert np.allclose(wenv._haar2d(h, inverse=True), img, atol=1e-5)


def noise_environment(height, width, seed):
    rng = np.random.default_rng(seed)
    return wenv.Environment(rng.uniform(0.0, 4.0, size=(height, width, 3)).astype(np.float32))


@pytest.mark.parametrize("height,sides", [(256, [128, 32]), (512, [512, 128]), (32, [16, 64, 8])])
def test_maps_made_in_one_pass_equal_each_made_alone(height, sides):
    """A new lighting makes the global map and the grazing path's pyramid base in one pass over the
    image; each map must be what a pass of its own makes (sides too fine for the image are looked
    up, the others splatted)."""
    env = noise_environment(height, 2 * height, height)
    together = wenv._oct_maps(env, sides)
    for side, m in zip(sides, together):
        assert m.shape == (side, side, 3)
        alone = wenv._oct_maps(env, [side])[0]
        assert np.array_equal(m, alone)
        assert np.all(np.isfinite(m)) and m.min() >= 0.0 and 0.5 < m.mean() < 3.5


def test_a_constant_environment_gives_constant_maps():
    env = wenv.Environment(np.full((512, 1024, 3), 1.75, np.float32))
    for m in wenv._oct_maps(env, [512, 128, 16]):
        assert np.allclose(m, 1.75, rtol=1e-6, atol=0)


def test_oct_maps_reject_bad_input():
    env = noise_environment(16, 32, 1)
    with pytest.raises(ValueError, match="sides"):
        wenv._oct_maps(env, [3])
    with pytest.raises(ValueError, match="sides"):
        wenv._oct_maps(env, [])
    with pytest.raises(TypeError, match="env"):
        wenv._oct_maps(np.zeros((4, 8, 3), np.float32), [8])


def test_maps_do_not_depend_on_the_number_of_threads():
    """Each thread sums its rows' pixels apart; the sums stay in double so that the maps, rounded
    to float, come out the same however the rows were split."""
    env = noise_environment(512, 1024, 5)
    before = wenv._work_threads()
    try:
        maps = {}
        for threads in (1, 2, 3, 5):
            wenv.set_num_threads(threads)
            maps[threads] = wenv._oct_maps(env, [512, 128])
    finally:
        wenv.set_num_threads(before)
    for threads in (2, 3, 5):
        for a, b in zip(maps[1], maps[threads]):
            assert np.array_equal(a, b)


def test_sparse_rows_dot_is_each_rows_terms_against_the_lighting():
    """wenv._sparse_rows_dot, the per-vertex sparse dot product of kept Haar terms against the
    lighting's coefficients (the gather limit benchmarks/measure.py times views against): numpy's
    sum of weight x lighting row per term; an index past the lighting or mismatched shapes are a
    named ValueError, never a read out of bounds."""
    rng = np.random.default_rng(4)
    index = rng.integers(0, 300, size=(1000, 17)).astype(np.uint16)
    weight = rng.standard_normal((1000, 17)).astype(np.float32)
    rgb = rng.random((300, 3), dtype=np.float32)
    want = np.einsum("vk,vkc->vc", weight.astype(np.float64), rgb[index].astype(np.float64))
    got = wenv._sparse_rows_dot(index, weight, rgb)
    assert got.shape == (1000, 3) and got.dtype == np.float32
    assert np.allclose(got, want, rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="index holds 300, past rgb's 300 rows"):
        wenv._sparse_rows_dot(np.full((2, 3), 300, np.uint16), np.ones((2, 3), np.float32), rgb)
    with pytest.raises(ValueError, match="same shape"):
        wenv._sparse_rows_dot(index, weight[:, :5], rgb)
    with pytest.raises(ValueError, match=r"\(m, 3\)"):
        wenv._sparse_rows_dot(index, weight, rgb[:, :2])
    with pytest.raises(TypeError, match="index must be an array convertible to uint16"):
        wenv._sparse_rows_dot("nope", weight, rgb)

