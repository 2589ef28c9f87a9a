"""What differs between the Blender versions the manifest names (4.2 LTS, 4.5 LTS and 5.0), in one
place: the rest of the add-on asks here rather than testing versions or attributes itself.

- Node trees: a new material's or World's node tree must be switched on before 5.0 (always on from
  5.0, where `use_nodes` is deprecated).
- Lights: Cycles' own `cast_shadow` (4.2) became `use_shadow`; colour temperature, exposure and
  normalize came with 4.5 (their absence is a light of its colour, exposure 0, normalized).
- The Principled BSDF's sockets a version lacks (Diffuse Roughness before 4.3) read as the node's
  default in the versions that have it (materials.principled_inputs).
- The Voronoi Texture hashes its 2D to 4D cells by PCG from 5.0, by lookup3 before: each version's
  pattern is its own (`VORONOI_CELL_HASH`).
- A Diffuse BSDF's Roughness is the classic Oren-Nayar model in Cycles before 4.3, the
  energy-preserving one since (`DIFFUSE_OREN_NAYAR_CLASSIC`; the core shades both).
- Bump Map Correction masks a bent diffuse closure's grazing light by a microfacet shadowing term
  from 4.5, by Chiang et al.'s before (`BUMP_MAP_CORRECTION`).
- Custom normals: from 5.0 a mesh keeps them as a corner attribute of vectors, `custom_normal`,
  set directly; before, encoded in each corner's normal space by `normals_split_custom_set`.
- Blender as a Python module (bpy from PyPI) 4.2 and 4.5 crash or hang when the interpreter exits
  with a class still registered (5.0 does not): a script that registered the add-on there has it
  unregistered at exit.
"""
import atexit

import bpy

NODES_ALWAYS_ON = bpy.app.version >= (5, 0, 0)
VORONOI_CELL_HASH = "PCG" if bpy.app.version >= (5, 0, 0) else "LOOKUP3"
# a Diffuse BSDF's Roughness: the classic Oren-Nayar in Cycles before 4.3 (wenv.Principled's
# oren_nayar="classic"), the energy-preserving one since
DIFFUSE_OREN_NAYAR_CLASSIC = bpy.app.version < (4, 3, 0)
# the bump terminator of a material's Bump Map Correction: Cycles' microfacet shadowing from 4.5,
# Chiang et al.'s term before
BUMP_MAP_CORRECTION = "MICROFACET" if bpy.app.version >= (4, 5, 0) else "CHIANG"


def new_node_material(name):
    """A new material with its node tree (a Principled BSDF into the output)."""
    mat = bpy.data.materials.new(name)
    if not NODES_ALWAYS_ON:
        mat.use_nodes = True
    return mat


def world_node_tree(world):
    """The World's node tree, switched on if it was off (before 5.0)."""
    if not NODES_ALWAYS_ON and not world.use_nodes:
        world.use_nodes = True
    return world.node_tree


def light_cast_shadow(light):
    cycles = getattr(light, "cycles", None)
    if cycles is not None and hasattr(cycles, "cast_shadow"):  # Blender 4.2 keeps Cycles' own
        return bool(cycles.cast_shadow)
    return bool(light.use_shadow)


def light_colour(light):
    """The light's colour, times its temperature's colour where it uses one (4.5+)."""
    colour = [float(c) for c in light.color]
    if getattr(light, "use_temperature", False):
        colour = [c * float(t) for c, t in zip(colour, light.temperature_color)]
    return colour


def light_exposure(light):
    return float(getattr(light, "exposure", 0.0))


def light_normalize(light):
    return bool(getattr(light, "normalize", True))


def light_soft_falloff(light):
    return bool(getattr(light, "use_soft_falloff", True))


def set_corner_normals(mesh, normals, vertex_normals=None):
    """Makes a new `mesh`'s corner normals `normals` ((corners, 3)), or each vertex's
    `vertex_normals` ((vertices, 3)) where given (a mesh smooth throughout, quicker before 5.0)."""
    if bpy.app.version >= (5, 0, 0):
        mesh.attributes.new("custom_normal", "FLOAT_VECTOR", "CORNER").data.foreach_set("vector", normals.ravel())
    elif vertex_normals is not None:
        mesh.normals_split_custom_set_from_vertices(vertex_normals)
    else:
        mesh.normals_split_custom_set(normals)


UNREGISTER_AT_EXIT = bpy.app.binary_path == "" and bpy.app.version < (5, 0, 0)


def unregister_at_exit(unregister):
    """Calls unregister() when the interpreter exits, where bpy as a module needs it (once)."""
    if UNREGISTER_AT_EXIT:
        atexit.unregister(unregister)
        atexit.register(unregister)
