"""Shared fixtures: Blender's bundled studio HDRIs, found without importing bpy."""
import glob
import importlib.util
import os
import pathlib

import numpy as np
import pytest


def bundled_hdri_dir():
    """Folder of the eight CC0 HDRIs that ship with every Blender (and the bpy wheel)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError("the bpy package is not installed: run scripts/setup.sh")
    for root in spec.submodule_search_locations:
        hits = sorted(glob.glob(os.path.join(root, "*", "datafiles", "studiolights", "world")))
        if hits:
            return hits[-1]
    raise RuntimeError("bpy is installed but its studiolights/world folder was not found")


# The wavelet settings besides the resolutions that `default` had while it was the 64/32/32 rotation
# setting: tests that sweep resolutions, lights or the grazing path keep the rest fixed with these (a
# partial quality dict takes its missing keys from `default`, which now slices at high's local
# resolution with the grazing path and lights read to 5 %).
WAVELET_BASE = {"light_coefficients": 1024, "matrix_epsilon": 1e-3, "lights": 128, "light_threshold": 256.0,
                "light_tolerance": 0.003, "grazing": 0.0, "grazing_slopes": 0}

HDRI_NAMES = ["city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset"]


def hdri_path(name):
    return os.path.join(bundled_hdri_dir(), name + ".exr")


@pytest.fixture(scope="session")
def hdri_dir():
    return bundled_hdri_dir()


@pytest.fixture
def one_thread():
    """wenv on one thread for the test: progress is reported by OpenMP's thread 0 as its items
    finish, so how many reports come before the last depends on the schedule (and the machine's
    load) unless thread 0 does every item."""
    import wenv
    old = wenv.get_num_threads()
    wenv.set_num_threads(1)
    yield
    wenv.set_num_threads(old)


def unit(a):
    a = np.asarray(a, dtype=np.float64)
    return (a / np.linalg.norm(a, axis=-1, keepdims=True)).astype(np.float32)


def random_pairs(n, seed=0):
    """n (normal, view) pairs, float32: normals uniform on the sphere, views on their hemisphere."""
    rng = np.random.default_rng(seed)
    nrm = unit(rng.normal(size=(n, 3)))
    v = unit(rng.normal(size=(n, 3)))
    v[np.sum(nrm * v, axis=1) < 0] *= -1
    return nrm, v


ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def markdown_files():
    """The documentation whose examples are tested: README.md, then every docs/*.md."""
    return [README, *sorted((ROOT / "docs").glob("*.md"))]


def fenced_blocks(path, languages=("python",)):
    """(language, text) of every fenced block of `path` in one of `languages`, in order."""
    blocks, block, language = [], None, None
    for line in path.read_text(encoding="utf-8").splitlines():
        fence = line.strip()
        if block is None and fence.startswith("```") and fence[3:] in languages:
            block, language = [], fence[3:]
        elif block is not None and fence == "```":
            blocks.append((language, "\n".join(block) + "\n"))
            block = None
        elif block is not None:
            block.append(line)
    return blocks


def python_blocks(path=None):
    """Every ```python block of README.md and docs/*.md (of `path` alone if given), in order, each
    as (path, text)."""
    return [(p, text) for p in ([path] if path else markdown_files()) for _, text in fenced_blocks(p)]


def readme_block(first_line):
    """The Python block of README.md or a docs/*.md whose first lines start with `first_line`:
    exactly one must, wherever the block lives."""
    hits = [text for _, text in python_blocks() if text.startswith(first_line)]
    assert len(hits) == 1, f"README.md and docs/*.md have {len(hits)} Python blocks starting with {first_line!r}"
    return hits[0]
