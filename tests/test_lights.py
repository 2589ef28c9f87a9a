"""Exact lights (csrc/methods/wavelet/lights.h): the brightest pixels leave the wavelet lighting and come back per
vertex, clustered as coarsely as each lobe allows.  With every lit pixel taken out, the shader's
result is the lights' alone, and must match the reference, which sums the same pixels."""
import os
import sys

import numpy as np
import pytest

import wenv
from conftest import WAVELET_BASE, random_pairs

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.helpers import merl_files  # noqa: E402

QUALITY = {**WAVELET_BASE, "global": 32, "local": 16, "normals": 16, "views": 8, "coefficients": 0,
           "lights": 4096, "light_threshold": 1.0}


def softbox_and_sun():
    """Black but for a softbox of 600 pixels and a 2 x 2 sun, both far above the mean radiance."""
    img = np.zeros((256, 512, 3), np.float32)
    img[60:80, 300:330] = (100, 90, 80)
    img[100:102, 100:102] = (1e5, 9e4, 8e4)
    return wenv.Environment(img)


def pairs():
    """Random pairs, and pairs at views from 80 to 89.9 degrees, where lobes are thinnest and read
    the finest clusters."""
    nrm, v = random_pairs(800, seed=5)
    rng = np.random.default_rng(6)
    n2 = rng.normal(size=(400, 3))
    n2 /= np.linalg.norm(n2, axis=1, keepdims=True)
    t = np.cross(n2, rng.normal(size=(400, 3)))
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    th = np.radians(rng.uniform(80.0, 89.9, 400))[:, None]
    v2 = np.cos(th) * n2 + np.sin(th) * t
    return np.float32(np.r_[nrm, n2]), np.float32(np.r_[v, v2])


@pytest.mark.parametrize("roughness", [None, 0.002, 0.005, 0.05, 0.1, 0.2, 0.5])
def test_lights_alone_match_the_reference(roughness):
    """Lobes of every width, 0.002 and 0.005 narrower than the pixels (0.012 rad): there each pixel
    is integrated over its area, as the reference integrates such lobes, where its centre alone
    would light a lobe only when it happens to fall in it."""
    env = softbox_and_sun()
    nrm, v = pairs()
    if roughness is None:
        mat = wenv.Lambert(0.8)
    else:
        mat = wenv.CookTorrance(diffuse=0.0, lobes=[{"specular": 1, "alpha": roughness, "ior": 1.5}])
    shader = wenv.Shader(env, mat, quality=QUALITY, method="slicing")
    out, ref = shader.shade(nrm, v), wenv.reference(env, mat, nrm, v)
    assert shader.stats["direct_lights"] == 604
    err = float(np.sqrt(np.mean((out - ref) ** 2) / np.mean(ref ** 2)))
    # measured 0.008 - 0.05 %; narrower than a pixel 0.4 - 0.9 % (the pixels' areas on grids of
    # points against the lobe's own rule), 11 - 98 % at the pixels' centres alone
    assert err < (0.002 if roughness is None or roughness > 0.01 else 0.015), err
    assert np.abs(out - ref).max() < 0.01 * ref.max()


def test_fewer_lights_leave_the_rest_to_the_wavelets():
    """A budget below the lit pixels takes the brightest (the sun's 4 first), and the softbox's
    remainder stays in the wavelet lighting: still close, far closer than no lights at all."""
    env = softbox_and_sun()
    nrm, v = random_pairs(800, seed=7)
    mat = wenv.CookTorrance(diffuse=0.2, lobes=[{"specular": 1, "alpha": 0.2, "ior": 1.5}])
    ref = wenv.reference(env, mat, nrm, v)
    err = {}
    for lights in (0, 4, 604):
        sh = wenv.Shader(env, mat, quality=dict(QUALITY, lights=lights), method="slicing")
        assert sh.stats["direct_lights"] == lights
        out = sh.shade(nrm, v)
        assert np.all(np.isfinite(out))
        err[lights] = float(np.sqrt(np.mean((out - ref) ** 2) / np.mean(ref ** 2)))
    assert err[604] < err[4] < err[0], err


@pytest.mark.parametrize("spec", [{"brdf": "cook_torrance", "roughness": 0.05}, {"brdf": "cook_torrance", "roughness": 0.5},
                                  {"brdf": "retro", "width": 0.5}, {"brdf": "tinted", "roughness": 0.2}],
                         ids=["t0.05", "t0.5", "retro", "tinted"])
def test_a_tables_lights_alone_match_the_reference(spec):
    """A table's lobe has no shape to bound a cluster's error; its own envelope (the largest f cos at
    each distance from the mirror direction) lets clusters far out in its tail be read whole, and
    the result stays the pixels' sum: within what the tolerance allows (0.3 % of what a vertex
    reflects) of the reference, as reading every pixel was."""
    env = softbox_and_sun()
    nrm, v = pairs()
    mat = wenv.Tabulated(merl_files.table_of(spec))
    shader = wenv.Shader(env, mat, quality=QUALITY, method="slicing")
    out, ref = shader.shade(nrm, v), wenv.reference(env, mat, nrm, v)
    assert shader.stats["direct_lights"] == 604
    err = float(np.sqrt(np.mean((out - ref) ** 2) / np.mean(ref ** 2)))
    # measured 0.036 % (t0.05), 0.006-0.04 % for the rest
    assert err < 0.002, err
    assert np.abs(out - ref).max() < 0.01 * ref.max()
