"""App handlers: shade from the scene camera on frame changes; forget per-file state on load."""
import bpy
from bpy.app.handlers import persistent

from . import engine, meshes, shading, views
from .live import LiveState

_last_error = {"message": None}


@persistent
def frame_change_post(scene, depsgraph=None):
    if not scene.wenv.shade_on_frame_change:
        return
    objects = meshes.shaded_objects(scene)
    if not objects:
        return
    try:
        view = views.camera_view(scene)
        shading.shade_objects(scene, depsgraph or bpy.context.evaluated_depsgraph_get(), objects, view, bpy.data)
        _last_error["message"] = None
    except engine.SetupError as exc:
        # Printed once per distinct problem: a frame handler has no operator to report through.
        if _last_error["message"] != str(exc):
            print(f"wenv: frame {scene.frame_current}: {exc}")
        _last_error["message"] = str(exc)


@persistent
def load_post(*_args):
    # Data of the previous file is gone: stop the live session, drop cached environments (images
    # of the new file may reuse names).  The shaders' rotation matrices stay (they are data-free).
    LiveState.reset()
    engine.shaders.forget_data()


def last_error():
    return _last_error["message"]


HANDLERS = ((bpy.app.handlers.frame_change_post, frame_change_post), (bpy.app.handlers.load_post, load_post))


def register():
    for handlers, fn in HANDLERS:
        if fn not in handlers:
            handlers.append(fn)


def unregister():
    for handlers, fn in HANDLERS:
        while fn in handlers:
            handlers.remove(fn)
