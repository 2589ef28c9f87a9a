"""Stability of every shading method: finite output everywhere (poles, seams, grazing views, roughness
0.01 to 1, under a sun), error inside an envelope stated per method and per range of view angles,
error falling as quality rises, and no flicker (views 0.1 degrees apart give close colours).

Environments are Blender's bundled sunset and city HDRIs box-filtered (flux kept) to 64 x 32 so the
brute-force reference costs milliseconds: city keeps its sun in one pixel at ~400 times the mean
radiance, about a fifth of all the light.  Materials are specular-only Cook-Torrance (Beckmann,
index 1.5), so no diffuse term hides the glossy error.  The envelopes are the measured errors with a
margin of about a quarter; benchmarks/stability.py draws the same sweeps at full scale."""
import numpy as np
import pytest

import wenv
from conftest import WAVELET_BASE, hdri_path

METHODS = ["rotation", "slicing", "split_sum", "sh"]
# Rising quality per method: rotation builds its matrices here (no cache), so it stops at 32/16/16;
# slicing is the same method without matrices and goes one step higher.
LADDERS = {
    "rotation": [{**WAVELET_BASE, "global": 16, "local": 8, "normals": 8, "views": 4, "coefficients": 0},
                 {**WAVELET_BASE, "global": 32, "local": 16, "normals": 16, "views": 8, "coefficients": 0}],
    "slicing": [{**WAVELET_BASE, "global": 16, "local": 8, "normals": 8, "views": 4, "coefficients": 0},
                {**WAVELET_BASE, "global": 32, "local": 16, "normals": 16, "views": 8, "coefficients": 0},
                {**WAVELET_BASE, "global": 64, "local": 32, "normals": 32, "views": 16, "coefficients": 0}],
    "split_sum": [{"prefilter": 16, "samples": 16, "lut": 8}, {"prefilter": 32, "samples": 64, "lut": 16},
                  {"prefilter": 64, "samples": 128, "lut": 32}],
    "sh": [{"order": 2, "views": 8}, {"order": 4, "views": 8}, {"order": 8, "views": 16}],
}
# View-angle ranges of the envelope test, degrees from the normal.
BINS = [(0.0, 60.0), (60.0, 85.0), (85.0, 89.9)]
# Largest relative RMSE per range, over sunset and city at m = 0.2 and 0.5, at each method's top
# setting in LADDERS.  Measured (worst of the four cases):
#   rotation 32/16/16   43 / 29 / 25 %   (city's one-pixel sun against a 32 x 32 global map)
#   slicing 64/32/32   7.5 / 15 / 13 %
#   split_sum p64       16 / 55 / 51 %   (n = v = r fails away from normal incidence)
#   sh order 8         7.2 / 40 / 70 %   (city's sun rings at grazing views)
ENVELOPES = {
    "rotation": (0.55, 0.37, 0.32),
    "slicing": (0.10, 0.19, 0.17),
    "split_sum": (0.21, 0.70, 0.65),
    "sh": (0.10, 0.52, 0.88),
}


def unit(a):
    a = np.asarray(a, np.float64)
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def f32(a):
    return np.ascontiguousarray(a, dtype=np.float32)


def tilted(nrm, angle_deg, azimuth_deg, helper=(0.31, 0.52, 0.79)):
    """Views at angle_deg from each normal, at an azimuth from a tangent fixed by `helper`."""
    nrm = unit(nrm)
    t = unit(np.cross(nrm, helper))
    b = np.cross(nrm, t)
    a = np.radians(np.asarray(angle_deg, np.float64))[..., None]
    z = np.radians(np.asarray(azimuth_deg, np.float64))[..., None]
    return unit(np.cos(a) * nrm + np.sin(a) * (np.cos(z) * t + np.sin(z) * b))


def specular(*roughness):
    """Specular-only Cook-Torrance; several lobes share an albedo of at most 1."""
    k = 1.0 / len(roughness)
    return wenv.CookTorrance(diffuse=0.0, lobes=[dict(specular=(k, k, k), alpha=m, ior=1.5) for m in roughness])


def rel_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b ** 2)))


@pytest.fixture(scope="module")
def envs():
    out = {}
    for name in ("sunset", "city"):
        px = wenv.load_environment(hdri_path(name)).pixels[..., :3]
        f = px.shape[0] // 32
        out[name] = wenv.Environment(f32(px.reshape(32, f, 64, f, 3).mean(axis=(1, 3))))
    return out


@pytest.fixture(scope="module")
def pairs():
    """Random normals; a third of the views in each range of BINS, at random azimuths."""
    rng = np.random.default_rng(0)
    per = 50
    nrm = unit(rng.normal(size=(per * len(BINS), 3)))
    angles = np.concatenate([rng.uniform(lo, hi, per) for lo, hi in BINS])
    return f32(nrm), f32(tilted(nrm, angles, rng.uniform(0, 360, len(nrm)))), per


@pytest.fixture(scope="module")
def references(envs, pairs):
    nrm, v, _ = pairs
    return {(h, m): wenv.reference(env, specular(m), nrm, v) for h, env in envs.items() for m in (0.2, 0.5)}


def shader(env, mat, method, quality):
    return wenv.Shader(env, mat, quality=quality, method=method, cache_dir=False)


# Brightest colour over the brightest pixel allowed at the first two settings of each ladder.  Under
# m = 0.01 at views past 80 degrees, far narrower than an 8 x 8 local map resolves, wavelet
# truncation rang up to 4.9 times the brightest pixel until the mean radiance under each lobe was
# bounded by the lighting's brightest texel; measured now: 0.43 and 0.47 (the reference gives 0.1).
OVERSHOOT = {"rotation": 1.0, "slicing": 1.0, "split_sum": 1.0, "sh": 1.0}
OVERSHOOT_SECOND = OVERSHOOT


@pytest.mark.parametrize("method", METHODS)
def test_finite_and_bounded_everywhere(method, envs):
    """Normals at the poles, on the seams and fold of the octahedral map, at the frame's singular
    point (-Z) and on the equirect seam (-X), and along a great circle through all of them; views
    from the normal to 89.999 degrees; lobes of roughness 0.01, 0.2 and 1 together; under the sun.
    Every colour is finite, non-negative and, since the lobes' albedo is at most 1, no brighter than
    the brightest pixel."""
    special = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (1, 1, 0), (-1, -1, 0),
               (1, 1, 1), (1, -1, -1), (1e-7, 0, -1), (0, 1e-7, -1), (-1, 1e-7, 0), (-1, -1e-7, 0)]
    t = np.radians(np.arange(0.0, 360.0, 1.0))
    circle = np.stack([np.sin(t), 0 * t, np.cos(t)], axis=1)
    nrm = unit(np.vstack([special, circle, np.random.default_rng(1).normal(size=(100, 3))]))
    angles = np.array([0.0, 30.0, 80.0, 89.9, 89.999])
    azimuths = np.array([0.0, 90.0, 180.0, 270.0])
    nn = np.repeat(nrm, len(angles) * len(azimuths), axis=0)
    aa = np.tile(np.repeat(angles, len(azimuths)), len(nrm))
    zz = np.tile(azimuths, len(nrm) * len(angles))
    views = f32(tilted(nn, aa, zz))
    mat = specular(0.01, 0.2, 1.0)
    for env in envs.values():
        peak = env.pixels[..., :3].max(axis=(0, 1))
        for quality, allowed in ((LADDERS[method][0], OVERSHOOT[method]),
                                 (LADDERS[method][1], OVERSHOOT_SECOND[method])):
            out = shader(env, mat, method, quality).shade(f32(nn), views)
            assert np.all(np.isfinite(out)) and np.all(out >= 0)
            assert np.all(out <= peak * allowed), (quality, (out / peak).max())


@pytest.mark.parametrize("method", METHODS)
def test_error_inside_envelope(method, envs, pairs, references):
    nrm, v, per = pairs
    top = LADDERS[method][-1]
    worst = np.zeros(len(BINS))
    for (h, m), ref in references.items():
        out = shader(envs[h], specular(m), method, top).shade(nrm, v)
        for i in range(len(BINS)):
            rows = slice(i * per, (i + 1) * per)
            worst[i] = max(worst[i], rel_rmse(out[rows], ref[rows]))
    assert np.all(worst <= ENVELOPES[method]), (method, worst)


@pytest.mark.parametrize("method", METHODS)
def test_error_falls_as_quality_rises(method, envs, pairs):
    """Every step up the ladder lowers the error under both environments at m = 0.2.  Split-sum
    converges to its own n = v = r approximation, not to the reference, so it is measured where that
    holds (views along the normal); elsewhere its error stays whatever the quality.  Measured, sunset |
    city: rotation 39 -> 17 % | 60 -> 28 %; slicing 39 -> 17 -> 11 % | 60 -> 28 -> 12 %; split-sum
    19 -> 4.7 -> 2.0 % | 30 -> 8.4 -> 3.8 %; SH 52 -> 35 -> 18 % | 83 -> 72 -> 54 %."""
    nrm, v, _ = pairs
    if method == "split_sum":
        v = nrm
    mat = specular(0.2)
    for env in envs.values():
        ref = wenv.reference(env, mat, nrm, v)
        errors = [rel_rmse(shader(env, mat, method, q).shade(nrm, v), ref) for q in LADDERS[method]]
        assert all(b < a for a, b in zip(errors, errors[1:])) and errors[-1] < 0.7 * errors[0], (method, errors)


# Largest colour jump between views 0.1 degrees apart, over the ring's brightest colour (Euclidean
# RGB), at the top setting of each method, m = 0.2, under the city sun.  Measured: rotation 0.62 %,
# slicing 0.47 %, split-sum 0.38 %, SH 0.75 % (the reference itself jumps by up to 0.81 %: the sun is one
# pixel of this 64 x 32 map).
FLICKER_BOUND = {"rotation": 0.008, "slicing": 0.006, "split_sum": 0.005, "sh": 0.01}


@pytest.mark.parametrize("method", METHODS)
def test_no_flicker(method, envs):
    """Rings of 3600 views 0.1 degrees apart at 30 and 80 degrees from the normal, around a generic
    normal and around -Z (the singular point of the normal-sample frames)."""
    mat = specular(0.2)
    sh = shader(envs["city"], mat, method, LADDERS[method][-1])
    worst = 0.0
    for normal in ((0.3, -0.4, 0.87), (0.0, 0.0, -1.0)):
        for elevation in (30.0, 80.0):
            az = np.arange(0.0, 360.0, 0.1)
            nn = np.tile(unit(normal), (len(az), 1))
            out = sh.shade(f32(nn), f32(tilted(nn, np.full(len(az), elevation), az))).astype(np.float64)
            jump = np.linalg.norm(np.diff(np.vstack([out, out[:1]]), axis=0), axis=1)
            worst = max(worst, jump.max() / np.linalg.norm(out, axis=1).max())
    assert worst < FLICKER_BOUND[method], (method, worst)
