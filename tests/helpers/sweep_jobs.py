"""Job functions the sweep tests run in worker processes (importable there, as sweep.run needs)."""
import os
import signal


def square(x):
    return x * x


def first_attempt_fails(x, marker):
    """Raises the first time it runs for `marker` (a file it then leaves), succeeds after."""
    if not os.path.exists(marker):
        open(marker, "w").close()
        raise RuntimeError("the first attempt fails")
    return x + 1


def always_fails(x):
    raise ValueError(f"no result for {x}")


def counted(x, folder):
    """x * 10, leaving a file per call in folder (to count what ran)."""
    open(os.path.join(folder, f"{x}-{os.getpid()}-{len(os.listdir(folder))}"), "w").close()
    return x * 10


def dies_once(x, marker):
    """Kills its own worker process the first time it runs for `marker`, as a crash or an out of
    memory kill would."""
    if not os.path.exists(marker):
        open(marker, "w").close()
        os.kill(os.getpid(), signal.SIGKILL)
    return -x


def blender_gloss(roughness):
    """In the worker: a Principled material made in Blender, read by the add-on's glossmeter (bpy
    work, in the worker's own Blender)."""
    import bpy  # noqa: F401 -- the worker's Blender

    import addon
    from addon import compat, gloss, materials
    if not hasattr(bpy.types.Material, "wenv"):
        addon.register()
    mat = compat.new_node_material(f"paint {roughness}")
    mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = roughness
    return gloss.gloss_readings(materials.material_key(mat.wenv))[60]
