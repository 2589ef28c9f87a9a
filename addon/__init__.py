"""wenv for Blender: shade meshes under the World's HDR environment with view-dependent BRDFs
(wavelet rotation) and read a material's gloss as an ISO 2813 glossmeter would.

The numerical core is the `wenv` module (a wheel bundled with this extension)."""
from . import handlers, operators, properties, ui

_modules = (properties, operators, ui, handlers)


def register():
    for module in _modules:
        module.register()


def unregister():
    for module in reversed(_modules):
        module.unregister()
    from . import core
    core.shaders.clear()
