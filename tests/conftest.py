"""Shared fixtures: Blender's bundled studio HDRIs, found without importing bpy."""
import glob
import importlib.util
import os

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


HDRI_NAMES = ["city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset"]


def hdri_path(name):
    return os.path.join(bundled_hdri_dir(), name + ".exr")


@pytest.fixture(scope="session")
def hdri_dir():
    return bundled_hdri_dir()
