"""App handlers: shade from the scene camera on frame changes; keep the colours and the live session
right after an undo or redo; forget per-file state on load."""
import bpy
from bpy.app.handlers import persistent

from . import bake, engine, meshes, properties, shading, views
from .live import LiveState

_last_error = {"message": None}
_render = {"active": False}

LOCK_NEEDED = ("frames are not re-shaded while rendering with the interface unlocked: the viewport would read "
               "the meshes while wenv writes them (Blender's note on altering data from handlers); turn on "
               "Render > Lock Interface to re-shade each rendered frame")


def interface_runs_beside_renders():
    """Whether a viewport may draw while a render runs (not in background mode)."""
    return not bpy.app.background


def _report_once(message):
    # Printed once per distinct problem: a frame handler has no operator to report through.
    if _last_error["message"] != message:
        print(message)
    _last_error["message"] = message


@persistent
def render_init(*_args):
    _render["active"] = True


@persistent
def render_done(*_args):
    _render["active"] = False


def rendering():
    return _render["active"]


@persistent
def frame_change_post(scene, depsgraph=None):
    if not scene.wenv.shade_on_frame_change:
        return
    if _render["active"] and not scene.render.use_lock_interface and interface_runs_beside_renders():
        _report_once(f"wenv: {LOCK_NEEDED}")
        return
    objects = meshes.shaded_objects(scene)
    images = [i for i in bpy.data.images if i.wenv.bake_on_frame_change and i.wenv.baked_object in scene.objects]
    if not objects and not images:
        return
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    try:
        view = views.camera_view(scene)
        if objects:
            shading.shade_objects(scene, depsgraph, objects, view, bpy.data)
        for image in images:
            record = image.wenv
            bake.bake(scene, depsgraph, scene.objects[record.baked_object], image, view, bpy.data,
                      uv_map=record.uv_map or None, margin=record.margin, view_source="CAMERA")
        _last_error["message"] = None
    except engine.SetupError as exc:
        _report_once(f"wenv: frame {scene.frame_current}: {exc}")


# What a change to a datablock of each type may change of a bake (bake.CHANGES); objects also their
# mesh and the other meshes about a bake, and a Light object or Light the lamps
_TOUCHES = ((bpy.types.World, ("world",)), (bpy.types.Material, ("materials", "surroundings")),
            (bpy.types.ShaderNodeTree, ("materials", "world", "surroundings")), (bpy.types.Light, ("lamps",)),
            (bpy.types.Image, ("materials", "world", "surroundings")), (bpy.types.Mesh, ("mesh", "surroundings")),
            (bpy.types.Collection, ("surroundings",)), (bpy.types.Scene, ("world", "lamps", "settings", "surroundings")))
# changes to data that objects share: the other meshes about a bake may change with them (an
# object hidden in the viewport updates the scene alone)
_SHARED = (bpy.types.Material, bpy.types.ShaderNodeTree, bpy.types.Image, bpy.types.Collection, bpy.types.Scene)


@persistent
def depsgraph_update_post(scene, depsgraph):
    """Tells the live session what changed about its meshes (LiveSession.note_updates); marks the
    bakes a change makes stale (bake.note_changes): only the parts of them the changed datablocks
    could touch are compared."""
    if LiveState.session is not None:
        LiveState.session.note_updates(scene, depsgraph.updates)
    if not any(i.wenv.baked_object and not i.wenv.stale for i in bpy.data.images):
        return
    parts, objects, shared = set(), set(), False
    for update in depsgraph.updates:
        data = getattr(update.id, "original", update.id)
        if isinstance(data, bpy.types.Object):
            objects.add(data.name)
            parts.update(("lamps",) if data.type == "LIGHT" else ("mesh", "surroundings"))
            continue
        if isinstance(data, bpy.types.Image) and data.wenv.baked_object:
            continue  # a bake's own image, written
        for kind, touched in _TOUCHES:
            if isinstance(data, kind):
                parts.update(touched)
        shared = shared or isinstance(data, _SHARED)
        if isinstance(data, bpy.types.Mesh):
            objects.update(o.name for o in scene.objects if o.data == data)
    if parts:
        bake.note_changes(scene, depsgraph, bpy.data.images, sorted(parts), objects, shared)


@persistent
def undo_post(scene, *_args):
    """After an undo or redo: Blender's data is now a step's.  (Handlers take the scene as an
    argument and keep nothing: the data they saw before is freed.)"""
    if LiveState.session is not None:
        LiveState.session.data_replaced()
    bake.restore_after_undo(bpy.data.images)
    # Frame changes make no undo step of their own (playback would make one per frame), and Blender
    # runs frame handlers after the operator that changed the frame has pushed its step, so a step
    # may hold the colours of the frame before.  Such colours are shaded for the frame restored,
    # as the frame handler would have; colours of their own frame are left as the step holds them.
    if scene is None:
        return
    st = scene.wenv
    if st.shade_on_frame_change and st.shaded_frame not in (shading.NO_FRAME, scene.frame_current):
        # evaluated first: a step holds the camera where it was when pushed, not where its
        # animation puts it at this frame
        frame_change_post(scene, bpy.context.evaluated_depsgraph_get())


@persistent
def load_post(*_args):
    # Data of the previous file is gone: stop the live session, drop cached environments (images
    # of the new file may reuse names).  The shaders' rotation matrices stay (they are data-free).
    LiveState.reset()
    engine.shaders.forget_data()
    engine.shadows.clear()
    bake.forget()
    properties.migrate(bpy.data)


def last_error():
    return _last_error["message"]


HANDLERS = ((bpy.app.handlers.frame_change_post, frame_change_post), (bpy.app.handlers.load_post, load_post),
            (bpy.app.handlers.render_init, render_init), (bpy.app.handlers.render_complete, render_done),
            (bpy.app.handlers.render_cancel, render_done), (bpy.app.handlers.undo_post, undo_post),
            (bpy.app.handlers.redo_post, undo_post), (bpy.app.handlers.depsgraph_update_post, depsgraph_update_post))


def register():
    for handlers, fn in HANDLERS:
        if fn not in handlers:
            handlers.append(fn)


def unregister():
    for handlers, fn in HANDLERS:
        while fn in handlers:
            handlers.remove(fn)
