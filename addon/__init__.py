"""wenv for Blender: shade meshes under the World's HDR environment with view-dependent BRDFs
(wavelet rotation) and read a material's gloss as an ISO 2813 glossmeter would.

The numerical core is the `wenv` module (a wheel bundled with this extension).  Laid out by role,
as Cycles' add-on: properties, operators, ui and handlers are registered here; world, materials,
gloss, views, meshes and shading turn Blender data into plain values and colours back; live runs
them in the background; engine is the only module that imports `wenv`."""
import os

import bpy

from . import compat, engine, handlers, operators, properties, ui

_modules = (properties, operators, ui, handlers)


def _matrix_cache_dir():
    """Installed as an extension, precomputed matrices go to its user folder (Blender's rule for
    files an extension writes); $WENV_CACHE_DIR wins, and a development copy uses wenv's default."""
    if os.environ.get("WENV_CACHE_DIR"):
        return None
    try:
        return bpy.utils.extension_path_user(__package__, path="matrices", create=True)
    except ValueError:  # not loaded as an extension
        return None


_registered = False


def register():
    global _registered
    for module in _modules:
        module.register()
    engine.shaders.cache_dir = _matrix_cache_dir()
    _registered = True
    compat.unregister_at_exit(_unregister_at_exit)


def unregister():
    global _registered
    for module in reversed(_modules):
        module.unregister()
    engine.shaders.clear()
    engine.shadows.clear()
    _registered = False


def _unregister_at_exit():
    if _registered:
        unregister()
