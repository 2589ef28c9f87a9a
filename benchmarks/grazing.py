"""Where the error at grazing views comes from: 150 views 78-89.9 degrees from the normal, specular
Cook-Torrance m = 0.1, `high` (slicing), under the bundled courtyard HDRI and a checkerboard of
8-degree squares, measured against wenv.reference

  - with generic normals and views,
  - with every normal exactly on a normal sample (no interpolation between normal samples),
  - with the views also exactly on view samples (no interpolation at all: the BRDF slice times the
    lighting slice alone), at local maps of 64, 128 and 256 texels a side.

    .venv/bin/python benchmarks/grazing.py      # ~1 min; prints the table, writes out/grazing.json
"""
import json
import os

import numpy as np

import wenv
from measure import OUT
from tests.helpers.measure import bundled_hdri, relative_rmse

HIGH = wenv.QUALITY_PRESETS["high"]
COUNT = 150


def checkerboard(h=512, w=1024, squares=(22, 45)):
    r, c = np.mgrid[0:h, 0:w]
    img = np.where(((r // (h // squares[0])) + (c // (w // squares[1]))) % 2 == 0, 1.0, 0.2).astype(np.float32)
    return wenv.Environment(np.ascontiguousarray(np.stack([img] * 3, axis=2)))


def frame(n):
    """The shading frames (tangent, bitangent) of unit normals (csrc/math/frame.c, wenv_frame)."""
    a = 1.0 / (1.0 + n[:, 2])
    b = -n[:, 0] * n[:, 1] * a
    t = np.stack([1 - n[:, 0] ** 2 * a, b, -n[:, 0]], 1)
    return t, np.stack([b, 1 - n[:, 1] ** 2 * a, -n[:, 1]], 1)


def grazing_views(nrm, rng):
    t, b = frame(nrm)
    th = np.radians(rng.uniform(78.0, 89.9, len(nrm)))
    ph = rng.uniform(0, 2 * np.pi, len(nrm))
    return np.cos(th)[:, None] * nrm + np.sin(th)[:, None] * (np.cos(ph)[:, None] * t + np.sin(ph)[:, None] * b)


def main():
    rng = np.random.default_rng(5)
    n_side, v_side = HIGH["normals"], HIGH["views"]
    generic = rng.normal(size=(COUNT, 3))
    generic /= np.linalg.norm(generic, axis=1, keepdims=True)
    generic = generic[generic[:, 2] > -0.99]
    cells = rng.integers(0, n_side, size=(COUNT, 2))
    on_normals = wenv._oct_decode((-1 + (cells + 0.5) * 2 / n_side).astype(np.float64))
    on_normals = on_normals[on_normals[:, 2] > -0.99]
    # views on the view samples of each normal's own frame, below 0.2 in cosine
    local = []
    while len(local) < len(on_normals):
        i, j = rng.integers(0, v_side + 1, 2)
        d = wenv._hemi_decode(np.array([[-1 + 2 * i / v_side, -1 + 2 * j / v_side]]))[0]
        if 0.01 < d[2] < 0.2:
            local.append(d)
    local = np.array(local)
    t, b = frame(on_normals)
    on_views = local[:, :1] * t + local[:, 1:2] * b + local[:, 2:3] * on_normals
    cases = {
        "generic normals and views": (generic, grazing_views(generic, rng)),
        "normals on normal samples": (on_normals, grazing_views(on_normals, rng)),
        "normals and views on samples": (on_normals, on_views),
    }
    mat = wenv.CookTorrance(diffuse=0.0, lobes=[{"specular": 1.0, "alpha": 0.1, "ior": 1.5}])
    settings = {"high": HIGH, "views 64": {**HIGH, "views": 64},
                "local 128, global 256": {**HIGH, "local": 128, "global": 256},
                "local 256, global 256": {**HIGH, "local": 256, "global": 256}}
    results = {}
    for env_name, env in (("courtyard", wenv.load_environment(bundled_hdri("courtyard"))),
                          ("checkerboard", checkerboard())):
        for case, (nrm, view) in cases.items():
            nrm32, view32 = nrm.astype(np.float32), view.astype(np.float32)
            ref = wenv.reference(env, mat, nrm32, view32)
            for label, q in settings.items():
                if label.startswith("local") and case != "normals and views on samples":
                    continue
                out = wenv.Shader(env, mat, quality=q, method="slicing").shade(nrm32, view32)
                err = relative_rmse(out, ref)
                results[f"{env_name}/{case}/{label}"] = err
                print(f"{env_name:12s} {case:30s} {label:22s} {100 * err:6.2f} %", flush=True)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "grazing.json"), "w") as fp:
        json.dump(results, fp, indent=1)
    print("wrote out/grazing.json")


if __name__ == "__main__":
    main()
