"""Helpers for the measured-BRDF tests: MERL's half/difference-angle layout, a writer of its
``.binary`` format, a numpy model of how a table is read (unmeasured samples filled) and
interpolated, and analytic BRDFs (numpy) to tabulate.

Conventions (MERL's, Matusik et al. 2003, and the specification of wenv.Tabulated):

* index coordinates (sqrt(theta_h / 90deg) n_th, theta_d / 90deg n_td, phi_d / 180deg n_pd), phi_d
  folded into [0, 180) by reciprocity; sample (i, j, k) stands for the bin [i, i + 1) x [j, j + 1) x
  [k, k + 1) (MERL's reader looks a sample up by the floor of the index coordinate) and sits at its
  centre, (i, j, k) + 1/2 (samples_at="centres", MERL files), or at its start, (i, j, k)
  (samples_at="starts"): theta_h sample i at ((i + o) / n_th)^2 * 90 degrees, theta_d sample j at
  (j + o) / n_td * 90 degrees, phi_d sample k at (k + o) / n_pd * 180 degrees, o = 1/2 or 0;
* trilinear interpolation between the samples' positions, phi_d periodic (period n_pd), theta_h and
  theta_d held at their first and last sample outside them;
* file: three little-endian int32 (n_th, n_td, n_pd), then 3 n float64, channel after channel, each in
  the order k + n_pd (j + n_td i); the file stores value / scale with scales 1/1500, 1.15/1500, 1.66/1500.

Every BRDF here is a function f(wi, wo) of float64 arrays (N, 3), (N, 3) of unit local-frame
directions (z = normal) returning (N, 3) RGB in 1/sr (f itself, no cosine), 0 where either direction
is at or below the horizon.
"""
import math
import struct

import numpy as np

SCALES = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
HALF_PI = 0.5 * math.pi

_erf = np.frompyfunc(math.erf, 1, 1)


def erf(x):
    x = np.asarray(x, np.float64)
    return _erf(x).astype(np.float64) if x.size else np.zeros_like(x)


# ------------------------------------------------------------------ Rusinkiewicz's coordinates

# Where sample 0 sits on each axis of the index coordinates (wenv.Tabulated's samples_at).
OFFSETS = {"centres": 0.5, "starts": 0.0}


def offset(samples_at):
    if samples_at not in OFFSETS:
        raise ValueError(f"samples_at must be 'centres' or 'starts', got {samples_at!r}")
    return OFFSETS[samples_at]


def rusinkiewicz_samples(n_th, n_td, n_pd, samples_at="centres"):
    """theta_h, theta_d, phi_d (radians) of the samples, each of shape (n_th, n_td, n_pd), at the
    centres of their bins (a MERL file's) or at their starts."""
    o = offset(samples_at)
    th = ((np.arange(n_th) + o) / n_th) ** 2 * HALF_PI
    td = (np.arange(n_td) + o) / n_td * HALF_PI
    pd = (np.arange(n_pd) + o) / n_pd * math.pi
    return np.meshgrid(th, td, pd, indexing="ij")


def directions(theta_h, theta_d, phi_d):
    """(wi, wo), unit vectors (..., 3) in the local frame, for half/difference angles (phi_h = 0).

    The half vector h is at (theta_h, 0); the difference vector d at (theta_d, phi_d) in h's frame is
    turned by theta_h about y (then by phi_h = 0 about z): wi = R_y(theta_h) d, wo = 2 (wi.h) h - wi.
    """
    th, td, pd = np.broadcast_arrays(*(np.asarray(a, np.float64) for a in (theta_h, theta_d, phi_d)))
    d = np.stack([np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], -1)
    ct, st = np.cos(th), np.sin(th)
    wi = np.stack([ct * d[..., 0] + st * d[..., 2], d[..., 1], -st * d[..., 0] + ct * d[..., 2]], -1)
    h = np.stack([st, np.zeros_like(st), ct], -1)
    wo = 2 * np.sum(wi * h, -1, keepdims=True) * h - wi
    return wi, wo


def normalised(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def half_diff(wi, wo):
    """Rusinkiewicz's (theta_h, theta_d, phi_d in [0, pi)) of unit vectors (N, 3), as MERL computes
    them (d = R_y(-theta_h) R_z(-phi_h) wi), the angles by arctan2 as wenv does."""
    wi, wo = np.asarray(wi, np.float64), np.asarray(wo, np.float64)
    h = normalised(wi + wo)
    theta_h = np.arctan2(np.hypot(h[:, 0], h[:, 1]), h[:, 2])  # well conditioned near 0, unlike arccos
    phi_h = np.arctan2(h[:, 1], h[:, 0])
    cp, sp, ct, st = np.cos(phi_h), np.sin(phi_h), np.cos(theta_h), np.sin(theta_h)
    x = cp * wi[:, 0] + sp * wi[:, 1]
    y = -sp * wi[:, 0] + cp * wi[:, 1]
    z = wi[:, 2]
    dx, dz = ct * x - st * z, st * x + ct * z
    theta_d = np.arctan2(np.hypot(dx, y), dz)
    p = np.arctan2(y, dx)
    phi_d = np.where(p < 0, p + math.pi, p)
    return theta_h, theta_d, phi_d


def _taps(x, n, periodic):
    fl = np.floor(x)
    f = x - fl
    if periodic:
        a = np.mod(fl.astype(np.int64), n)
        return a, (a + 1) % n, f
    a = fl.astype(np.int64)
    low = ~(fl >= 0)
    high = fl >= n - 1
    a = np.where(low, 0, np.where(high, n - 1, a))
    b = np.where(low | high, a, a + 1)
    f = np.where(low | high, 0.0, f)
    return a, b, f


def above_horizon(n_th, n_td, n_pd, samples_at="centres"):
    """Which samples have both their directions above the horizon (with phi_h = 0:
    wi.z = cos th cos td - sin th sin td cos pd, wo.z = 2 cos td cos th - wi.z)."""
    th, td, pd = rusinkiewicz_samples(n_th, n_td, n_pd, samples_at)
    zi = np.cos(th) * np.cos(td) - np.sin(th) * np.sin(td) * np.cos(pd)
    return (zi > 0) & (2 * np.cos(td) * np.cos(th) - zi > 0)


def interpolate(table, wi, wo, samples_at="centres"):
    """The specification's f(wi, wo) of a table (n_th, n_td, n_pd, 3) whose samples sit at
    `samples_at`, at local-frame directions (N, 3) (normalised here, in float64): trilinear between
    the samples' positions over the neighbours whose own directions lie above the horizon, their
    weights renormalised (plain trilinear when none does), 0 at or below the horizon.  Returns
    float64 (N, 3)."""
    table = np.asarray(table, np.float64)
    n_th, n_td, n_pd = table.shape[:3]
    o = offset(samples_at)
    above = above_horizon(n_th, n_td, n_pd, samples_at)
    wi, wo = normalised(np.atleast_2d(wi)), normalised(np.atleast_2d(wo))
    wi, wo = np.broadcast_arrays(wi, wo)
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    out = np.zeros(wi.shape[:1] + (3,))
    if not np.any(up):
        return out
    th, td, pd = half_diff(wi[up], wo[up])
    i0, i1, fi = _taps(np.sqrt(th / HALF_PI) * n_th - o, n_th, False)
    j0, j1, fj = _taps(td / HALF_PI * n_td - o, n_td, False)
    k0, k1, fk = _taps(pd / math.pi * n_pd - o, n_pd, True)
    kept_acc, plain_acc = np.zeros((len(th), 3)), np.zeros((len(th), 3))
    total, kept = np.zeros(len(th)), np.zeros(len(th))
    for i, wi_ in ((i0, 1 - fi), (i1, fi)):
        for j, wj in ((j0, 1 - fj), (j1, fj)):
            for k, wk in ((k0, 1 - fk), (k1, fk)):
                w = wi_ * wj * wk
                ok = above[i, j, k]
                total += w
                kept += np.where(ok, w, 0.0)
                kept_acc += np.where(ok, w, 0.0)[:, None] * table[i, j, k]
                plain_acc += w[:, None] * table[i, j, k]
    safe = np.where(kept > 0, kept, 1.0)
    out[up] = np.where((kept > 0)[:, None], kept_acc * (total / safe)[:, None], plain_acc)
    return out


def tabulate(f, n_th, n_td, n_pd, samples_at="centres"):
    """float64 table (n_th, n_td, n_pd, 3) of f at the sample positions (the bins' centres, as in a
    MERL file, or their starts; 0 where a direction of the sample is at or below the horizon)."""
    wi, wo = directions(*rusinkiewicz_samples(n_th, n_td, n_pd, samples_at))
    wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
    v = np.zeros((len(wi), 3))
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    v[up] = f(wi[up], wo[up])
    return v.reshape(n_th, n_td, n_pd, 3)


# ------------------------------------------------------------------ the MERL .binary format

def merl_bytes(table, unmeasured=None, dims=None):
    """The file's bytes for a table (n_th, n_td, n_pd, 3) of f; `unmeasured` (n_th, n_td, n_pd) bool
    entries are written as -1 in every channel; `dims` overrides the header (for broken files)."""
    table = np.asarray(table, np.float64)
    if table.ndim != 4 or table.shape[3] != 3:
        raise ValueError("table must be (n_th, n_td, n_pd, 3)")
    n_th, n_td, n_pd = table.shape[:3]
    stored = np.moveaxis(table / SCALES, 3, 0).copy()  # (3, n_th, n_td, n_pd): C order is k + n_pd (j + n_td i)
    if unmeasured is not None:
        mask = np.asarray(unmeasured, bool)
        if mask.shape != table.shape[:3]:
            raise ValueError("unmeasured must be (n_th, n_td, n_pd)")
        stored[:, mask] = -1.0
    header = struct.pack("<3i", *(dims if dims is not None else (n_th, n_td, n_pd)))
    return header + stored.astype("<f8").tobytes()


def write_merl(path, table, unmeasured=None, dims=None):
    """Writes `table` (RGB f in 1/sr) as a MERL .binary file; see merl_bytes."""
    data = merl_bytes(table, unmeasured, dims)
    with open(path, "wb") as fp:
        fp.write(data)
    return path


def read_merl(path):
    """numpy reader (for checking the writer): (table (n_th, n_td, n_pd, 3) scaled, unmeasured mask)."""
    with open(path, "rb") as fp:
        data = fp.read()
    dims = struct.unpack("<3i", data[:12])
    n = dims[0] * dims[1] * dims[2]
    raw = np.frombuffer(data, "<f8", count=3 * n, offset=12).reshape(3, *dims)
    if len(data) != 12 + 24 * n:
        raise OSError(f"{path}: size does not match the dimensions")
    mask = np.any(raw < 0, axis=0)
    table = np.moveaxis(raw, 0, 3) * SCALES
    return table, mask


def fill_unmeasured(table, unmeasured):
    """The specification's filling of unmeasured samples: along theta_d at each (theta_h, phi_d),
    each unmeasured sample takes the last measured one at smaller theta_d (forward), leading ones the
    first measured; a column with nothing measured takes the (filled) column of the nearest theta_h
    at the same phi_d that has a measured sample.  (Tests avoid ties between two nearest columns.)"""
    t = np.array(table, np.float64)
    mask = np.asarray(unmeasured, bool)
    n_th, n_td, n_pd = mask.shape
    has = ~np.all(mask, axis=1)  # (n_th, n_pd)
    for i in range(n_th):
        for k in range(n_pd):
            if not has[i, k]:
                continue
            measured = np.flatnonzero(~mask[i, :, k])
            first = measured[0]
            t[i, :first, k] = t[i, first, k]
            for j in range(first + 1, n_td):
                if mask[i, j, k]:
                    t[i, j, k] = t[i, j - 1, k]
    for i in range(n_th):
        for k in range(n_pd):
            if has[i, k]:
                continue
            cands = [s for s in range(n_th) if has[s, k]]
            if not cands:
                t[i, :, k] = 0.0
                continue
            src = min(cands, key=lambda s: abs(s - i))
            t[i, :, k] = t[src, :, k]
    return t


# ------------------------------------------------------------------ analytic BRDFs (numpy)

def fresnel(cos_i, ior):
    """Exact unpolarised Fresnel reflectance of a dielectric (from Snell's law and the s/p amplitudes)."""
    c = np.clip(np.asarray(cos_i, np.float64), 0.0, 1.0)
    sin_t = np.sqrt(1 - c * c) / ior
    cos_t = np.sqrt(np.maximum(0.0, 1 - sin_t * sin_t))
    rs = (c - ior * cos_t) / (c + ior * cos_t)
    rp = (ior * c - cos_t) / (ior * c + cos_t)
    return 0.5 * (rs * rs + rp * rp)


def beckmann_d(m, cos_h):
    c2 = cos_h * cos_h
    tan2 = (1 - c2) / c2
    return np.exp(-tan2 / (m * m)) / (math.pi * m * m * c2 * c2)


def beckmann_lambda(m, cos):
    cos = np.minimum(np.asarray(cos, np.float64), 1.0)
    sin = np.sqrt(np.maximum(0.0, 1 - cos * cos))
    out = np.zeros_like(cos)
    ok = sin > 0
    a = cos[ok] / (m * sin[ok])
    out[ok] = (erf(a) - 1) / 2 + np.exp(-a * a) / (2 * a * math.sqrt(math.pi))
    return out


def _lobe(m, wi, wo):
    """D G2 / (4 cos_i cos_o) (Beckmann, height-correlated Smith) and cos_d = wi.h, for unit rows above
    the horizon."""
    h = normalised(wi + wo)
    ci, co = wi[:, 2], wo[:, 2]
    cos_d = np.sum(wi * h, axis=1)
    g2 = 1 / (1 + beckmann_lambda(m, ci) + beckmann_lambda(m, co))
    return beckmann_d(m, h[:, 2]) * g2 / (4 * ci * co), cos_d


def _upper(wi, wo):
    wi, wo = normalised(wi), normalised(wo)
    return wi, wo, (wi[:, 2] > 0) & (wo[:, 2] > 0)


def cook_torrance(m, ior=1.5, colour=(1.0, 1.0, 1.0)):
    """wenv.CookTorrance(diffuse=0, lobes=[{"alpha": m, "ior": ior, "specular": colour}]) with the
    default Beckmann distribution and Smith shadowing, as f(wi, wo) (no cosine)."""
    colour = np.broadcast_to(np.asarray(colour, np.float64), (3,))

    def f(wi, wo):
        wi, wo, up = _upper(wi, wo)
        out = np.zeros((len(wi), 3))
        if np.any(up):
            v, cos_d = _lobe(m, wi[up], wo[up])
            out[up] = (fresnel(cos_d, ior) * v)[:, None] * colour
        return out

    return f


def retro_norm(width):
    """Integral of exp(-gamma^2 / width^2) over the whole sphere of directions (gamma: angle to a fixed
    direction): 2 pi Int_0^pi exp(-g^2/w^2) sin g dg, by Gauss-Legendre."""
    z, w = np.polynomial.legendre.leggauss(2000)
    g = (z + 1) * math.pi / 2
    return 2 * math.pi * float(np.sum(w * np.exp(-g * g / width**2) * np.sin(g))) * math.pi / 2


def retro(width, colour=(0.8, 0.6, 0.4)):
    """A retro-reflective lobe, f = colour exp(-gamma^2 / width^2) / norm with gamma the angle between
    wi and wo (= 2 theta_d: it peaks when light returns towards the viewer, which no Cook-Torrance
    lobe, centred on the mirror direction, can represent).  norm = 1.1 x the lobe's integral over the
    whole sphere, so Int f cos_i d wi < colour / 1.1 < 1 at every view."""
    colour = np.broadcast_to(np.asarray(colour, np.float64), (3,))
    norm = 1.1 * retro_norm(width)

    def f(wi, wo):
        wi, wo, up = _upper(wi, wo)
        out = np.zeros((len(wi), 3))
        g = np.arccos(np.clip(np.sum(wi[up] * wo[up], axis=1), -1.0, 1.0))
        out[up] = np.exp(-g * g / width**2)[:, None] * colour / norm
        return out

    return f


def tint(cos_d):
    """RGB that shifts with theta_d: red at normal incidence (cos_d = 1), blue at grazing."""
    s2 = 1 - np.asarray(cos_d, np.float64) ** 2
    return np.stack([0.05 + 0.85 * (1 - s2), 0.3 + 0 * s2, 0.05 + 0.85 * s2], -1)


def tinted(m):
    """A Cook-Torrance-like Beckmann lobe (Smith shadowing, no Fresnel) whose colour moves from red at
    theta_d = 0 to blue at theta_d = 90 degrees: D G2 / (4 cos_i cos_o) tint(cos_d).  Its albedo stays
    below 0.9 (D G2 / (4 ci co) integrates to at most 1)."""

    def f(wi, wo):
        wi, wo, up = _upper(wi, wo)
        out = np.zeros((len(wi), 3))
        if np.any(up):
            v, cos_d = _lobe(m, wi[up], wo[up])
            out[up] = v[:, None] * tint(cos_d)
        return out

    return f


def table_of(spec, shape=(90, 90, 180), samples_at="centres"):
    """The table (shape + (3,), float64) of a BRDF named by a JSON-able spec: {"brdf": "cook_torrance",
    "roughness": m} (white, index 1.5), {"brdf": "retro", "width": w} or {"brdf": "tinted",
    "roughness": m}, with an optional "diffuse": [r, g, b] albedo added above the horizon as a
    Lambertian floor, sampled at `samples_at`.  What benchmarks/accuracy.py's TABLES and the tests
    that read their stored references are made from."""
    if spec["brdf"] == "cook_torrance":
        f = cook_torrance(spec["roughness"])
    elif spec["brdf"] == "retro":
        f = retro(spec["width"])
    elif spec["brdf"] == "tinted":
        f = tinted(spec["roughness"])
    else:
        raise ValueError(f"unknown brdf {spec['brdf']!r}")
    table = tabulate(f, *shape, samples_at)
    if "diffuse" in spec:
        table += np.asarray(spec["diffuse"], np.float64) / math.pi * above_horizon(*shape, samples_at)[..., None]
    return table


# ------------------------------------------------------------------ integrals and sampling

def albedo(f, wo, n_mu=400, n_phi=800):
    """Directional albedo Int f(wi, wo) cos_i d wi (RGB) for one view wo (3,), by Gauss-Legendre in
    cos_i times the midpoint rule in phi."""
    z, w = np.polynomial.legendre.leggauss(n_mu)
    mu = (z + 1) / 2
    phi = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
    M, P = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - M * M)
    wi = np.stack([s * np.cos(P), s * np.sin(P), M], -1).reshape(-1, 3)
    weights = np.outer(w / 2 * mu, np.full(n_phi, 2 * math.pi / n_phi)).reshape(-1)
    wo = np.broadcast_to(normalised(wo), wi.shape)
    return np.sum(f(wi, wo) * weights[:, None], axis=0)


def random_upper(rng, n):
    """n random unit vectors of the upper hemisphere (uniform in solid angle), float64."""
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return normalised(v)
