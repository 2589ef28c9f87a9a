"""Writes csrc/scene/sheen_table.c: the table Cycles' Principled sheen reads, measured from Cycles itself
through bpy (the Blender module the project installs), so that wenv.Principled's sheen is Cycles'.

    .venv/bin/python scripts/measure_sheen_table.py      # about 5 minutes

Cycles' sheen (Zeltner, Burley and Chiang 2022, "Practical Multiple-Scattering Sheen Using Linearly
Transformed Cosines") is R(mu, r) times a linearly transformed cosine: in the frame whose x axis is
the view's tangential direction,

    f cos = R / pi * o_z * (A / ((A o_x + B o_z)^2 + (A o_y)^2 + o_z^2))^2,

with (A, B, R) read bilinearly from a 32 x 32 table over mu = n.v (node i at i / 31) and the Sheen
Roughness r (node j at j / 31; r clamped to [1e-3, 1]).  The table is a fit to a volumetric model
that takes hours to simulate, so it is measured here instead: a sphere with a sheen-only Principled
BSDF (black base, Specular IOR Level 0, Sheen Weight 1) lit by a sun of strength 1 and nothing else
is rendered by Cycles from an orthographic camera, each pixel's normal read from Cycles, for several
sun directions and every roughness node.  A delta light and a deterministic BSDF make every sample of
a pixel the same: the pixels are exact values of f cos, and a least-squares fit of the 96 node values
of one roughness (their linear interpolation in mu, as Cycles reads them) reproduces them to float
precision (relative RMSE 2e-6 .. 1e-4 from roughness 0.1 up; 0.2-4 % of a nearly vanishing sheen
below, where it reflects at grazing views only).  tests/test_principled.py checks the table against
renders of other sun directions and of environments.
"""
import math
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.append(ROOT)  # after PYTHONPATH: the tests' helpers, tests.helpers
OUT = os.path.join(ROOT, "csrc", "scene", "sheen_table.c")
N = 32
SUNS = [(-0.3, -1.0, 0.4), (0.9, -0.6, 0.2), (-0.9, 0.3, 0.5), (0.0, 0.8, 0.6), (0.2, 1.0, -0.3),
        (0.7, 0.2, -0.7), (-0.1, -0.2, 1.0), (0.95, 0.3, 0.05)]


def ltc(o, a, b):
    len2 = (a * o[:, 0] + b * o[:, 2]) ** 2 + (a * o[:, 1]) ** 2 + o[:, 2] ** 2
    return o[:, 2] * (a / len2) ** 2 / math.pi


def taps(mu):
    x = np.clip(mu, 0, 1) * (N - 1)
    i = np.minimum(x.astype(int), N - 1)
    j = np.minimum(i + 1, N - 1)
    return i, j, x - i


def model(params, mu, o):
    """f cos for node values params (3, N): A, B, R linear in mu between nodes."""
    i, j, f = taps(mu)
    a, b, r = ((1 - f) * p[i] + f * p[j] for p in params)
    return r * ltc(o, a, b)


def band_start(mu, o, value):
    """Per node, (A, B, R) of the best grid point over the pixels within half a node of it (R in
    closed form for each (A, B)): where the joint fit starts."""
    start = np.stack([np.ones(N), np.zeros(N), np.full(N, 1e-3)])
    found = np.zeros(N, bool)
    grid_a = np.exp(np.linspace(math.log(0.02), math.log(4.0), 60))
    grid_b = np.linspace(-3.0, 3.0, 61)
    for i in range(N):
        near = np.abs(mu - i / (N - 1)) < 0.5 / (N - 1)
        if near.sum() < 20:
            continue
        oo, vv, best = o[near], value[near], None
        for a in grid_a:
            for b in grid_b:
                d = ltc(oo, a, b)
                r = float(d @ vv) / max(float(d @ d), 1e-300)
                e = float(np.sum((r * d - vv) ** 2))
                if best is None or e < best[0]:
                    best = (e, a, b, r)
        start[:, i] = best[1:]
        found[i] = True
    have = np.flatnonzero(found)
    for c in range(3):  # nodes without pixels (grazing mu) take their neighbours'
        start[c] = np.interp(np.arange(N), have, start[c, have])
    return start


def fit(mu, o, value, start):
    """Levenberg-Marquardt on the 3 N node values (finite-difference Jacobian, a light second-difference
    penalty along mu for nodes few pixels constrain)."""
    p, damping = start.copy(), 1e-3
    d2 = np.zeros((3 * (N - 2), 3 * N))
    for c in range(3):
        for i in range(N - 2):
            d2[c * (N - 2) + i, c * N + i:c * N + i + 3] = (1e-4, -2e-4, 1e-4)

    def cost(q):
        return float(np.sum((model(q, mu, o) - value) ** 2) + np.sum((d2 @ q.ravel()) ** 2))

    current = cost(p)
    for _ in range(200):
        base = model(p, mu, o)
        res = base - value
        jac = np.empty((len(value), 3 * N))
        for k in range(3 * N):
            q = p.copy()
            h = 1e-7 * max(1.0, abs(q.flat[k]))
            q.flat[k] += h
            jac[:, k] = (model(q, mu, o) - base) / h
        lhs = jac.T @ jac + d2.T @ d2
        rhs = -(jac.T @ res + d2.T @ (d2 @ p.ravel()))
        while True:
            step = np.linalg.solve(lhs + damping * np.diag(np.diag(lhs) + 1e-12), rhs)
            trial = p + step.reshape(3, N)
            c = cost(trial)
            if c < current:
                p, current, damping = trial, c, max(damping / 3, 1e-9)
                break
            damping *= 4
            if damping > 1e6:
                break
        if damping > 1e6 or np.max(np.abs(step)) < 1e-10:
            break
    return p, float(np.sqrt(np.mean((model(p, mu, o) - value) ** 2)) / np.sqrt(np.mean(value ** 2)))


def main():
    import bpy
    from tests.helpers.cycles_sphere import SphereScene
    scene = SphereScene("sunset", size=128, samples=2)
    sc = scene.scene
    sc.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    sun_data = bpy.data.lights.new("wenv-sun", "SUN")
    sun_data.energy = 1.0
    sun_data.angle = 0.0
    sun = bpy.data.objects.new("wenv-sun", sun_data)
    sc.collection.objects.link(sun)
    nrm = scene.normals.astype(np.float64)
    v = np.array([0.0, -1.0, 0.0])
    mu = nrm @ v
    t = v - mu[:, None] * nrm
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    b = np.cross(nrm, t)

    def sun_towards(d):
        d = np.asarray(d, np.float64) / np.linalg.norm(d)
        # the sun shines along its local -Z: turn +Z onto d
        z = np.array([0.0, 0.0, 1.0])
        axis = np.cross(z, d)
        s, c = np.linalg.norm(axis), float(z @ d)
        sun.rotation_mode = "AXIS_ANGLE"
        sun.rotation_axis_angle = (math.atan2(s, c), *(axis / s if s > 1e-9 else (1.0, 0.0, 0.0)))
        return d

    table = np.zeros((3, N, N))  # [A, B, R][roughness j][mu i]
    fits = []
    for j in range(N):
        r = max(j / (N - 1), 1e-3)
        scene.principled(base_color=(0.0, 0.0, 0.0), specular_ior_level=0.0, sheen_weight=1.0, sheen_roughness=r)
        mus, os_, vals = [], [], []
        for d in SUNS:
            d = sun_towards(d)
            img = scene.render(seed=0)[scene.mask][:, 1].astype(np.float64)
            o = np.stack([t @ d, b @ d, nrm @ d], 1)
            keep = (o[:, 2] > 0.02) & (mu > 0.01)
            mus.append(mu[keep])
            os_.append(o[keep])
            vals.append(img[keep])
        mu_all, o_all, v_all = np.concatenate(mus), np.concatenate(os_), np.concatenate(vals)
        params, rel = fit(mu_all, o_all, v_all, band_start(mu_all, o_all, v_all))
        table[:, j] = params
        fits.append(rel)
        print(f"roughness node {j:2d} (r = {r:.4f}): {len(v_all)} pixels, fit relative RMSE {rel:.2e}", flush=True)
    # node 0 was measured at r = 1e-3 (Cycles' clamp), 0.031 of the way to node 1: undo the blend
    w = 1e-3 * (N - 1)
    table[:, 0] = (table[:, 0] - w * table[:, 1]) / (1 - w)
    # where the sheen reflects nothing (low roughness, away from grazing) A and B are free and R fits
    # to +-1e-3 about 0: an albedo is not negative
    table[2] = np.maximum(table[2], 0.0)

    def c_array(name, values):
        flat = np.asarray(values, np.float64).ravel()
        rows = [", ".join(f"{x:.8g}f" if ("." in f"{x:.8g}" or "e" in f"{x:.8g}") else f"{x:.8g}.0f"
                          for x in flat[r:r + 8]) for r in range(0, len(flat), 8)]
        return f"const float {name}[{len(flat)}] = {{\n    " + ",\n    ".join(rows) + "\n};\n"

    text = ("/* Generated by scripts/measure_sheen_table.py (see its docstring): Cycles' Principled sheen table,\n"
            " * measured from Cycles through bpy; do not edit.  [A, B, R][sheen roughness 32][mu 32], nodes at\n"
            f" * i / 31.  Fit residuals (relative RMSE per roughness): {min(fits):.1e} .. {max(fits):.1e}. */\n"
            "#include \"scene/sheen_table.h\"\n\n" + c_array("wenv_sheen_ltc", table))
    with open(OUT, "w") as fp:
        fp.write(text)
    print("wrote", OUT)


if __name__ == "__main__":
    main()
