"""Helpers shared by the example scripts: bundled HDRIs, test geometry, tone mapping."""
import glob
import importlib.util
import os

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "out")


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


def sphere_image(size):
    """Normals of a unit sphere seen orthographically from -Y (looking along +Y), one per pixel
    inside the disk; returns (mask, normals, view) with the view pointing back at the camera."""
    t = (np.arange(size) + 0.5) / size * 2 - 1
    x, z = np.meshgrid(t, -t)
    r2 = x * x + z * z
    mask = r2 < 1
    n = np.stack([x[mask], -np.sqrt(1 - r2[mask]), z[mask]], axis=1).astype(np.float32)
    view = np.array([0.0, -1.0, 0.0], np.float32)
    return mask, n, view


def tone_map(rgb, l_max):
    """The thesis's global logarithmic operator: Ld = log10(1 + Lw) / log10(1 + Lmax)."""
    lw = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    ld = np.log10(1 + lw) / np.log10(1 + l_max)
    scale = np.where(lw > 0, ld / np.maximum(lw, 1e-12), 0)
    return np.clip(rgb * scale[..., None], 0, 1)


def relative_rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


def random_pairs(n, seed):
    """n (normal, view) pairs: normals uniform on the sphere, views uniform on the hemisphere
    around each normal (grazing views included), float32."""
    rng = np.random.default_rng(seed)
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[np.sum(nrm * v, axis=1) < 0] *= -1
    return nrm.astype(np.float32), v.astype(np.float32)
