"""Writes csrc/scene/principled_tables.c: the GGX tables Blender's Principled BSDF (Cycles,
"Principled v2") reads for its energy compensation and its layers' albedo, computed here from their
definitions by deterministic quadrature (Cycles estimates the same integrals by Monte Carlo).

    .venv/bin/python scripts/make_principled_tables.py [--points 256]   # about a minute

Every table samples rough = (alpha_x alpha_y)^(1/4) (Principled's Roughness) and mu = n.v on node
grids, node i at i / (n - 1) (clamped to [1e-4, 1]), with the view V = (sqrt(1 - mu^2), 0, mu) and
the normal +Z; lookups interpolate linearly between nodes.  Each is an expectation over the GGX
distribution of visible normals D_V(h) = G1(V) max(0, V.h) D(h) / mu (alpha = rough^2, Smith
height-correlated G2, lambda = (sqrt(1 + alpha^2 tan^2) - 1) / 2), L the mirror of V about h, and
"valid" L.z > 0:

* ggx_E[mu][rough] (32 x 32): E[G2(V, L) / G1(V) valid], the directional albedo of the lobe with
  F = 1 (its energy loss is 1 - E).
* ggx_Eavg[rough] (32): Int_0^1 2 mu E(mu) dmu, its cosine-weighted mean over views.
* ggx_gen_schlick_ior_s[z][mu][rough] (16^3): E[s(V.h) valid] with s(c) = (F(c, eta) - F0) / (1 - F0)
  clamped to [0, 1], F the exact dielectric Fresnel of eta = ior_from_F0(z^4), z = clamp(k/15, 1e-4,
  0.99): how far from F0 towards 1 the lobe's Fresnel lifts its albedo.
* ggx_gen_schlick_s[z][mu][rough] (16^3): E[(1 - V.h)^e valid] with e = 5 (1 - z) / z.

The visible normals are drawn by Heitz's 2018 mapping of the unit square, here a product midpoint
rule of points x points (the integrands are smooth but for the validity cut).  When alpha^2 is at or
below 2e-10 the lobe is a mirror (h = n): E = 1, s = s(mu).
"""
import argparse
import math
import os

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "csrc", "scene", "principled_tables.c")
SINGULAR = 2e-10


def smith_lambda(alpha, cos):
    cos = np.clip(cos, 1e-12, 1.0)
    tan2 = np.maximum(1.0 / (cos * cos) - 1.0, 0.0)
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def fresnel_dielectric(c, eta):
    t = eta * eta - (1.0 - c * c)
    ct = np.sqrt(np.maximum(t, 0.0)) / eta
    c = np.abs(c)
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return np.where(t <= 0, 1.0, 0.5 * (rs * rs + rp * rp))


def ior_from_f0(f):
    s = math.sqrt(min(max(f, 0.0), 0.99))
    return (1 + s) / (1 - s)


def visible_normals(alpha, mu, points):
    """Half vectors (N, 3) of the GGX visible-normal distribution for view (sqrt(1-mu^2), 0, mu),
    one per cell of a points x points midpoint grid on the unit square (Heitz 2018)."""
    u = (np.arange(points) + 0.5) / points
    u1, u2 = np.meshgrid(u, u, indexing="ij")
    u1, u2 = u1.ravel(), u2.ravel()
    v = np.array([math.sqrt(max(0.0, 1 - mu * mu)), 0.0, mu])
    vh = np.array([alpha * v[0], alpha * v[1], v[2]])
    vh /= np.linalg.norm(vh)
    lensq = vh[0] ** 2 + vh[1] ** 2
    t1 = np.array([-vh[1], vh[0], 0.0]) / math.sqrt(lensq) if lensq > 0 else np.array([1.0, 0.0, 0.0])
    t2 = np.cross(vh, t1)
    r, phi = np.sqrt(u1), 2 * math.pi * u2
    a, b = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1 + vh[2])
    b = (1 - s) * np.sqrt(np.maximum(0.0, 1 - a * a)) + s * b
    nh = a[:, None] * t1 + b[:, None] * t2 + np.sqrt(np.maximum(0.0, 1 - a * a - b * b))[:, None] * vh
    h = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(0.0, nh[:, 2])], 1)
    return h / np.linalg.norm(h, axis=1, keepdims=True), v


def node(i, n, lo=1e-4, hi=1.0):
    return min(max(i / (n - 1), lo), hi)


def expectation(rough, mu, points, integrand):
    """E over visible normals of integrand(c = V.h, L) with invalid L counted as 0."""
    alpha = rough * rough
    if alpha * alpha <= SINGULAR:
        h = np.array([[0.0, 0.0, 1.0]])
        v = np.array([math.sqrt(max(0.0, 1 - mu * mu)), 0.0, mu])
    else:
        h, v = visible_normals(alpha, mu, points)
    c = h @ v
    light = 2 * c[:, None] * h - v
    valid = light[:, 2] > 0
    return float(np.mean(np.where(valid, integrand(alpha, c, light), 0.0)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=256, help="midpoint grid side over the unit square")
    args = ap.parse_args()
    p = args.points

    e = np.zeros((32, 32))
    for j in range(32):
        mu = node(j, 32)
        for i in range(32):
            rough = node(i, 32)
            alpha = rough * rough
            lam_v = smith_lambda(alpha, mu)

            def g2_over_g1(alpha, c, light, lam_v=lam_v):
                return (1 + lam_v) / (1 + lam_v + smith_lambda(alpha, light[:, 2]))
            e[j, i] = expectation(rough, mu, p, g2_over_g1)
    # Eavg: Int 2 mu E(mu) dmu by Gauss-Legendre in mu, E computed afresh at each node
    z, w = np.polynomial.legendre.leggauss(24)
    mus, ws = (z + 1) / 2, w / 2
    eavg = np.zeros(32)
    for i in range(32):
        rough = node(i, 32)
        alpha = rough * rough
        total = 0.0
        for mu, wt in zip(mus, ws):
            lam_v = smith_lambda(alpha, mu)

            def g2_over_g1(alpha, c, light, lam_v=lam_v):
                return (1 + lam_v) / (1 + lam_v + smith_lambda(alpha, light[:, 2]))
            total += wt * 2 * mu * expectation(rough, float(mu), p, g2_over_g1)
        eavg[i] = total

    ior_s = np.zeros((16, 16, 16))
    exp_s = np.zeros((16, 16, 16))
    q = max(64, p * 3 // 4)
    for k in range(16):
        zc = min(max(k / 15, 1e-4), 0.99)
        eta = ior_from_f0(zc ** 4)
        f0 = ((eta - 1) / (eta + 1)) ** 2
        expo = 5 * (1 - zc) / zc
        for j in range(16):
            mu = node(j, 16)
            for i in range(16):
                rough = node(i, 16)
                ior_s[k, j, i] = expectation(rough, mu, q, lambda a, c, l: np.clip(
                    (fresnel_dielectric(c, eta) - f0) / (1 - f0), 0.0, 1.0))
                exp_s[k, j, i] = expectation(rough, mu, q, lambda a, c, l: np.clip(1 - c, 0.0, 1.0) ** expo)
        print(f"s tables: slice {k + 1} of 16", flush=True)

    def c_array(name, values, shape_comment):
        flat = np.clip(np.asarray(values, np.float64).ravel(), 0.0, 1.0)
        flat[flat < 1e-30] = 0.0  # below float's normal range: 0 (C would truncate it with a warning)
        def literal(v):
            text = f"{v:.7g}"
            return text + ("f" if "." in text or "e" in text else ".0f")
        rows = [", ".join(literal(v) for v in flat[r:r + 8]) for r in range(0, len(flat), 8)]
        return (f"/* {shape_comment} */\nconst float {name}[{len(flat)}] = {{\n    " + ",\n    ".join(rows) + "\n};\n")

    text = ("/* Generated by scripts/make_principled_tables.py (see its docstring for the definitions); do not\n"
            f" * edit.  Quadrature: {p} x {p} visible normals per entry ({q} x {q} for the s tables). */\n"
            "#include \"scene/principled_tables.h\"\n\n"
            + c_array("wenv_ggx_E", e, "[mu 32][rough 32]") + "\n"
            + c_array("wenv_ggx_Eavg", eavg, "[rough 32]") + "\n"
            + c_array("wenv_ggx_gen_schlick_ior_s", ior_s, "[z 16][mu 16][rough 16]") + "\n"
            + c_array("wenv_ggx_gen_schlick_s", exp_s, "[z 16][mu 16][rough 16]"))
    with open(OUT, "w") as fp:
        fp.write(text)
    print("wrote", OUT, "E(1, 1) =", e[31, 31], "Eavg(1) =", eavg[31])


if __name__ == "__main__":
    main()
