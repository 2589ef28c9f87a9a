"""What differs between the Blender versions the manifest names (4.2 LTS, 4.5 LTS, 5.0) for the
tests, in one place (the add-on's own differences are addon/compat.py's)."""


def node_material(bpy, name):
    """A new material with its node tree (a Principled BSDF into the output): nodes are always on
    from 5.0, and switched on here before."""
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    return mat


def use_world_nodes(bpy, world):
    """A World's node tree, switched on before 5.0 (always on from 5.0)."""
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True


def has_light_temperature(bpy):
    """Whether lights have a colour temperature (Blender 4.5+)."""
    return bpy.app.version >= (4, 5, 0)


def has_diffuse_roughness(bpy):
    """Whether the Principled BSDF has Diffuse Roughness (Blender 4.3+)."""
    return bpy.app.version >= (4, 3, 0)


def exits_cleanly(version):
    """Whether Blender as a Python module of this (major, minor) exits with status 0 once a script
    registered an add-on: bpy 4.2 segfaults at interpreter exit when a property with a Python getter
    was ever registered, even unregistered again (its own bug: eight lines of bpy show it, without
    wenv); 4.5 hung unless the classes are unregistered, which the add-on does at exit
    (addon/compat.py)."""
    return tuple(version) != (4, 2)
