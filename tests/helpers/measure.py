"""What the tests and the benchmarks measure with: Blender's bundled HDRIs, random (normal, view)
pairs, pairs weighted toward the lighting's bright reflections, and the relative RMSE against the
reference, plain or estimated with a control variate (tests/test_error_estimate.py)."""
import glob
import importlib.util
import math
import os

import numpy as np


def bundled_hdri(name):
    """Path of one of Blender's eight bundled studio HDRIs (forest, city, courtyard, interior, night,
    studio, sunrise, sunset), found in the installed bpy wheel."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("bpy is not installed: run scripts/setup.sh first")
    for root in spec.submodule_search_locations:
        hits = sorted(glob.glob(os.path.join(root, "*", "datafiles", "studiolights", "world", name + ".exr")))
        if hits:
            return hits[-1]
    raise SystemExit(f"bundled HDRI {name!r} not found")


def relative_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


def random_directions(rng, n):
    """n directions uniform on the sphere, float64 (n, 3)."""
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def random_pairs(n, seed):
    """n (normal, view) pairs: normals uniform on the sphere, views uniform on the hemisphere
    around each normal (grazing views included), float32."""
    rng = np.random.default_rng(seed)
    nrm = random_directions(rng, n)
    v = random_directions(rng, n)
    v[np.sum(nrm * v, axis=1) < 0] *= -1
    return nrm.astype(np.float32), v.astype(np.float32)


def mirror_weighted_pairs(env, roughness, n, seed, share=0.5, components=512):
    """n (normal, view) pairs for estimating means over random_pairs' distribution with far less
    variance where a narrow lobe reflects a small bright source (a sun hit is rare among uniform
    pairs yet dominates the mean square), and each pair's weight, the uniform density over the one
    drawn from: E[weight * f] is the uniform mean of f.

    Normals uniform on the sphere with views uniform on their hemisphere are the same pairs as the
    mirror direction r = 2(n.v)n - v uniform on the sphere with the normal uniform on r's hemisphere
    (the reflection maps one hemisphere onto itself).  So only r's density changes: with
    probability `share` r is drawn about one of the lighting's `components` brightest pixels
    (chosen by flux squared, as they weigh in a mean square; von Mises-Fisher spread about the
    reflected lobe's width 2 * roughness), uniformly otherwise.  share=0 gives random_pairs' law."""
    rng = np.random.default_rng(seed)
    dirs, flux = env.samples()
    f = flux.astype(np.float64).mean(axis=1)
    top = np.argsort(f)[-components:]
    mu = dirs[top].astype(np.float64)
    mu /= np.linalg.norm(mu, axis=1, keepdims=True)
    pick_weight = f[top] ** 2
    pick_weight /= pick_weight.sum()
    kappa = 1.0 / (2.0 * roughness) ** 2
    r = random_directions(rng, n)
    near = rng.random(n) < share
    k = int(near.sum())
    centre = mu[rng.choice(len(mu), size=k, p=pick_weight)]
    u = rng.random(k)
    cos_t = 1.0 + np.log(u + (1.0 - u) * np.exp(-2.0 * kappa)) / kappa  # vMF's cosine to its centre
    phi = 2.0 * np.pi * rng.random(k)
    helper = np.where(np.abs(centre[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(centre, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(centre, e1)
    sin_t = np.sqrt(np.clip(1.0 - cos_t * cos_t, 0.0, None))[:, None]
    r[near] = cos_t[:, None] * centre + sin_t * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    vmf_norm = kappa / (2.0 * np.pi * -np.expm1(-2.0 * kappa))
    density = np.empty(n)
    for i in range(0, n, 4096):  # the mixture's density at every r, in blocks to bound memory
        density[i:i + 4096] = (vmf_norm * np.exp(kappa * (r[i:i + 4096] @ mu.T - 1.0))) @ pick_weight
    weight = (1.0 / (4.0 * np.pi)) / ((1.0 - share) / (4.0 * np.pi) + share * density)
    nrm = random_directions(rng, n)
    nrm[np.sum(nrm * r, axis=1) < 0] *= -1
    v = 2.0 * np.sum(nrm * r, axis=1, keepdims=True) * nrm - r
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return nrm.astype(np.float32), v.astype(np.float32), weight


def estimated_error(out, ref, control, out_many, control_many, weight):
    """Relative RMSE against the reference, with the control's difference from `out` read off the
    many weighted pairs and the reference's own difference from the control off the stored ones:
    E[(o - r)^2] = E_w[(o - c)^2] + E[(o - r)^2 - (o - c)^2], and E[r^2] = E_w[c^2] + E[r^2 - c^2]."""
    def per_pair(x):
        return np.mean(np.square(x, dtype=np.float64), axis=1)
    mse = np.mean(weight * per_pair(out_many - control_many)) + np.mean(per_pair(out - ref) - per_pair(out - control))
    ms = np.mean(weight * per_pair(control_many)) + np.mean(per_pair(ref) - per_pair(control))
    return math.sqrt(max(mse, 0.0) / ms)
