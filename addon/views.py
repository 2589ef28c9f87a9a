"""3D views: the View a pass is shaded for (camera, viewport or matrix); viewports set to show the
shaded colours, and set back."""
import numpy as np

from .engine import SetupError


# Cycles' camera space looks along +Z, Blender's along -Z (blender_camera_matrix)
_CYCLES_CAMERA = np.diag([1.0, 1.0, -1.0, 1.0])


class View:
    """Perspective (eye position) or orthographic (one direction towards the viewer); a viewport's
    perspective view also has its world-to-clip matrix, which tells what is on screen.  `camera`
    (world to Cycles' camera space, the camera's scale cleared) and `window` (world to the clip space
    of the camera's or viewport's frame) are what a Texture Coordinate's Camera and Window read, where
    known; they are not part of `signature` (camera_signature: only a material reading them
    depends on a camera's turn or lens)."""

    __slots__ = ("perspective", "eye", "direction", "view_projection", "camera", "window")

    def __init__(self, perspective, eye=None, direction=None, view_projection=None):
        self.perspective = perspective
        self.eye = None if eye is None else tuple(float(x) for x in eye)
        self.direction = None if direction is None else np.asarray(direction, np.float32)
        self.view_projection = None if view_projection is None else np.asarray(view_projection, np.float64)
        self.camera = None
        self.window = None

    @classmethod
    def from_view_matrix(cls, view_matrix, perspective):
        """From a world -> view matrix (RegionView3D.view_matrix convention, camera looks along -Z)."""
        m = np.asarray(view_matrix, np.float64).reshape(4, 4)
        if not np.isfinite(m).all():
            raise SetupError("The view matrix holds values that are not finite")
        try:
            inv = np.linalg.inv(m)
        except np.linalg.LinAlgError:
            raise SetupError("The view matrix is singular: no view it could come from") from None
        return cls.from_camera_matrix(inv, perspective)

    @classmethod
    def from_camera_matrix(cls, camera_to_world, perspective):
        m = np.asarray(camera_to_world, np.float64).reshape(4, 4)
        if not np.isfinite(m).all():
            raise SetupError("The view (camera) matrix holds values that are not finite")
        if perspective:
            view = cls(True, eye=m[:3, 3])
        else:
            z = m[:3, 2]
            norm = np.linalg.norm(z)
            if not norm > 0:
                raise SetupError("The view matrix is degenerate")
            view = cls(False, direction=z / norm)
        unscaled = m.copy()
        lengths = np.linalg.norm(m[:3, :3], axis=0)
        if (lengths > 0).all():
            unscaled[:3, :3] /= lengths
            try:
                view.camera = _CYCLES_CAMERA @ np.linalg.inv(unscaled)
            except np.linalg.LinAlgError:
                pass  # (a flattened camera: Camera coordinates stay unknown)
        return view

    @property
    def camera_signature(self):
        return tuple(None if m is None else tuple(np.round(m, 6).ravel().tolist()) for m in (self.camera, self.window))

    @property
    def signature(self):
        return (self.perspective, self.eye, None if self.direction is None else tuple(self.direction.tolist()),
                None if self.view_projection is None else tuple(self.view_projection.ravel().tolist()))


def camera_view(scene):
    cam = scene.camera
    if cam is None:
        raise SetupError("The scene has no camera")
    perspective = getattr(cam.data, "type", "PERSP") != "ORTHO"
    view = View.from_camera_matrix(np.array(cam.matrix_world), perspective)
    if cam.type == "CAMERA" and cam.data.type != "PANO" and view.camera is not None:
        import bpy

        render = scene.render
        # the frame as Cycles renders it: the lens, sensor fit, shift and the image's aspect
        projection = cam.calc_matrix_camera(bpy.context.view_layer.depsgraph, x=render.resolution_x,
                                            y=render.resolution_y, scale_x=render.pixel_aspect_x,
                                            scale_y=render.pixel_aspect_y)
        view.window = np.array(projection, np.float64) @ np.linalg.inv(_CYCLES_CAMERA) @ view.camera
    return view


def region_view(region_3d, scene):
    """The view of a 3D viewport.  Built from its rotation, pivot and distance rather than
    view_matrix, which Blender refreshes only when the viewport redraws."""
    if region_3d.view_perspective == "CAMERA":
        return camera_view(scene)
    rot = np.array(region_3d.view_rotation.to_matrix(), np.float64)  # view -> world
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = np.array(region_3d.view_location, np.float64) + rot[:, 2] * region_3d.view_distance
    view = View.from_camera_matrix(m, region_3d.view_perspective == "PERSP")
    # the lens and the region's shape (window_matrix) after the view just built
    window = np.array(region_3d.window_matrix, np.float64) @ np.linalg.inv(m)
    view.window = window
    if view.perspective:
        view.view_projection = window
    return view


def find_region_3d(context):
    """The active 3D viewport's RegionView3D, or the first one in the window."""
    rv3d = getattr(context, "region_data", None)
    if rv3d is not None and hasattr(rv3d, "view_matrix"):
        return rv3d
    space = getattr(context, "space_data", None)  # the sidebar's region has no region_data
    if space is not None and space.type == "VIEW_3D" and space.region_3d is not None:
        return space.region_3d
    screens = [context.screen] if getattr(context, "screen", None) else []
    screens += [w.screen for w in context.window_manager.windows]
    for screen in screens:
        for area in screen.areas:
            if area.type == "VIEW_3D":
                return area.spaces.active.region_3d
    return None


def _open_viewports(window_manager):
    """The shading of every 3D viewport shown in a window."""
    for window in window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                yield area.spaces.active.shading


SHADING_KEYS = ("type", "light", "color_type")
SHOWN = {"type": "SOLID", "light": "FLAT", "color_type": "VERTEX"}


def showing_attribute_colors(window_manager):
    """Whether an open 3D viewport shows the colours or a bake (set by show_attribute_colors, not yet
    set back)."""
    return any(shading.wenv.showing for shading in _open_viewports(window_manager))


def show_attribute_colors(window_manager, color_type="VERTEX"):
    """Every open 3D viewport in solid mode, flat lighting, colours from the active colour attribute
    (the shaded radiance, shown as the scene's view transform maps it), or with color_type "TEXTURE"
    from the materials' active Image Texture node (a bake).  Each keeps what it had in its own
    shading settings (View3DShading.wenv) for restore_viewports; one already showing the colours
    keeps its first backup."""
    for shading in _open_viewports(window_manager):
        backup = shading.wenv
        if not backup.showing:
            for k in SHADING_KEYS:
                setattr(backup, k, getattr(shading, k))
            backup.showing = True
        for k, value in dict(SHOWN, color_type=color_type).items():
            setattr(shading, k, value)


def restore_viewports(screens):
    """Sets every 3D viewport of `screens` (bpy.data.screens: those of other workspaces and editors
    hidden in an area too) that show_attribute_colors changed back as it was."""
    for screen in screens:
        for area in screen.areas:
            for space in area.spaces:
                if space.type != "VIEW_3D" or not space.shading.wenv.showing:
                    continue
                shading, backup = space.shading, space.shading.wenv
                for k in SHADING_KEYS:
                    setattr(shading, k, getattr(backup, k))
                backup.showing = False
