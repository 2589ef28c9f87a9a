"""Operators: shade, precompute, live mode, material settings and the glossmeter's inverse."""
import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty

from . import bake, engine, gloss, materials, meshes, shading, views
from .live import LiveSession, LiveState, PrecomputeJob

IDENTITY = ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def _quality(context):
    return engine.quality_value(context.scene.wenv.quality)


class _Precomputing:
    """Mixin: in invoke, build a missing shader on a worker thread while a modal timer shows the
    progress in Blender's progress indicator; Esc cancels."""

    _job = None
    _timer = None

    def start_precompute(self, context):
        wm = context.window_manager
        self._job = PrecomputeJob(_quality(context)).start()
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.progress_begin(0.0, 1.0)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def finish_precompute(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        job, self._job = self._job, None
        if job.error is not None:
            self.report({"ERROR"}, f"Precomputation failed: {job.error}")
            return False
        if job.cancelled or not job.install():
            self.report({"WARNING"}, "Precomputation cancelled")
            return False
        return True

    def modal(self, context, event):
        if event.type == "ESC":
            self._job.cancel()
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}  # the rest of Blender stays usable meanwhile
        context.window_manager.progress_update(self._job.fraction)
        if not self._job.done:
            return {"RUNNING_MODAL"}
        if not self.finish_precompute(context):
            return {"CANCELLED"}
        return self.execute(context)


def _progress_reporter(wm, what="precomputing"):
    """Progress into Blender's progress indicator (begun at the first report), and, in background
    runs and scripts, printed every 10 % (there is no indicator to see)."""
    state = {"begun": False, "printed": -1}

    def report(fraction):
        if not state["begun"]:
            wm.progress_begin(0.0, 1.0)
            state["begun"] = True
        wm.progress_update(fraction)
        step = int(fraction * 10)
        if bpy.app.background and step > state["printed"]:
            state["printed"] = step
            print(f"wenv: {what}: {100 * fraction:.0f} %", flush=True)
        return False
    return report


class WENV_OT_precompute(_Precomputing, bpy.types.Operator):
    """Precompute the rotation matrices of the scene's quality (loaded from the cache if built before)"""
    bl_idname = "wenv.precompute"
    bl_label = "Precompute"

    def execute(self, context):
        quality = _quality(context)
        if not engine.shaders.has(quality):
            wm = context.window_manager
            try:
                engine.shaders.get(quality, _progress_reporter(wm, engine.preparing(quality)))
            finally:
                wm.progress_end()
        return {"FINISHED"}

    def invoke(self, context, event):
        if engine.shaders.has(_quality(context)):
            return {"FINISHED"}
        return self.start_precompute(context)


def resolve_view(context, source, view_matrix, perspective):
    if source == "SCENE":
        source = context.scene.wenv.view_source
    if source == "CAMERA":
        return views.camera_view(context.scene)
    if source == "MATRIX":
        return views.View.from_view_matrix([list(r) for r in view_matrix], perspective)
    rv3d = views.find_region_3d(context)
    if rv3d is None:
        raise engine.SetupError("No 3D viewport to take the view from: use the scene camera")
    return views.region_view(rv3d, context.scene)


def _view_choice(scene_setting):
    """The `view` option of an operator that takes the scene's `scene_setting` by default (with
    _ViewMatrix's options for MATRIX)."""
    return EnumProperty(name="View", default="SCENE", items=[
        ("SCENE", "Scene Setting", f"As the scene's wenv {scene_setting} setting"),
        ("VIEWPORT", "Viewport", "The active 3D viewport"),
        ("CAMERA", "Camera", "The scene camera"),
        ("MATRIX", "Matrix", "The View Matrix and Perspective given here")])


class _ViewMatrix:
    """Mixin: the view an operator's `view` option MATRIX names."""

    view_matrix: FloatVectorProperty(name="View Matrix", size=(4, 4), subtype="MATRIX", default=IDENTITY,
                                     description="World to view matrix (as RegionView3D.view_matrix)")
    perspective: BoolProperty(name="Perspective", default=True)


class WENV_OT_shade(_Precomputing, _ViewMatrix, bpy.types.Operator):
    """Shade the selected meshes under the World for the current view into the 'wenv_radiance' colour attribute"""
    bl_idname = "wenv.shade"
    bl_label = "Shade"
    bl_options = {"REGISTER", "UNDO"}

    view: _view_choice("View")
    target: EnumProperty(name="Objects", default="SELECTED", items=[
        ("SELECTED", "Selected", "The selected objects"),
        ("SHADED", "Shaded", "Every mesh in the scene that was shaded before")])

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        scene = context.scene
        objects = list(context.selected_objects) if self.target == "SELECTED" else meshes.shaded_objects(scene)
        wm = context.window_manager
        quality = _quality(context)
        progress = (None if engine.shaders.has(quality)
                    else _progress_reporter(wm, engine.preparing(quality)))
        rays = _progress_reporter(wm, "casting shadow rays") if scene.wenv.shadows else None
        try:
            view = resolve_view(context, self.view, self.view_matrix, self.perspective)
            done, notes = shading.shade_objects(scene, context.evaluated_depsgraph_get(), objects, view,
                                                context.blend_data, progress, rays)
        except engine.SetupError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except engine.CancelledError:
            self.report({"WARNING"}, "Precomputation cancelled")
            return {"CANCELLED"}
        finally:
            if progress is not None or rays is not None:
                wm.progress_end()
        for note in notes:
            self.report({"WARNING"}, note)
        self.report({"INFO"}, f"Shaded {len(done)} object(s)")
        return {"FINISHED"}

    def invoke(self, context, event):
        if engine.shaders.has(_quality(context)):
            return self.execute(context)
        return self.start_precompute(context)


class WENV_OT_clear(bpy.types.Operator):
    """Remove the add-on's colour attribute from the selected meshes"""
    bl_idname = "wenv.clear"
    bl_label = "Clear Shading"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        n = sum(meshes.remove_colors(o.data) for o in context.selected_objects if o.type == "MESH")
        self.report({"INFO"}, f"Removed shading from {n} mesh(es)")
        return {"FINISHED"}


class WENV_OT_bake(_ViewMatrix, bpy.types.Operator):
    """Shade every texel of the scene's Bake Image (or a new one) through the active mesh's UV map, as its vertices would be shaded, and show it"""
    bl_idname = "wenv.bake"
    bl_label = "Bake"
    bl_options = {"REGISTER", "UNDO"}

    view: _view_choice("Bake View")

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        scene, st = context.scene, context.scene.wenv
        obj = context.active_object
        source = st.bake_view if self.view == "SCENE" else self.view
        made = None
        wm = context.window_manager
        try:
            if obj is None or obj.type != "MESH":
                raise engine.SetupError(f"'{obj.name}' is not a mesh: only meshes bake" if obj is not None else
                                        "No active object to bake: make a mesh active")
            view = resolve_view(context, source, self.view_matrix, self.perspective)
            image = st.bake_image
            if image is None:
                bake.check_size(st.bake_resolution, st.bake_resolution, st.memory_budget)
                image = made = bpy.data.images.new(f"{obj.name} wenv bake", st.bake_resolution, st.bake_resolution,
                                                   alpha=True, float_buffer=st.bake_float)
            count, notes = bake.bake(scene, context.evaluated_depsgraph_get(), obj, image, view, context.blend_data,
                                     uv_map=st.bake_uv_map or None, margin=st.bake_margin,
                                     progress=_progress_reporter(wm, "baking"), view_source=source)
        except (engine.SetupError, engine.CancelledError) as exc:
            if made is not None:
                bpy.data.images.remove(made)
            cancelled = isinstance(exc, engine.CancelledError)
            self.report({"WARNING" if cancelled else "ERROR"}, "Bake cancelled" if cancelled else str(exc))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        if made is not None:
            st.bake_image = made
        if st.bake_show:
            bake.show_in_materials(obj, image)
            views.show_attribute_colors(wm, "TEXTURE")
        for note in notes:
            self.report({"WARNING"}, note)
        self.report({"INFO"}, f"Baked {count} texels of '{obj.name}' into '{image.name}'")
        return {"FINISHED"}


class WENV_OT_bake_hide(bpy.types.Operator):
    """Remove the bake's nodes from the active object's materials (Material Preview and EEVEE show the materials again) and set the viewports back"""
    bl_idname = "wenv.bake_hide"
    bl_label = "Hide Bake"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        obj = context.active_object
        mats = [slot.material for slot in obj.material_slots] if obj is not None else []
        n = bake.hide_in_materials(mats)
        views.restore_viewports(bpy.data.screens)
        self.report({"INFO"}, f"Bake nodes removed from {n} material(s)")
        return {"FINISHED"}


def _redraw_viewports(context):
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


LIVE_UNDO_STEP = "Live Shading"


class WENV_OT_live(bpy.types.Operator):
    """Re-shade the selected meshes whenever the view, their transforms, the World or the materials change (Esc or click again to stop)"""
    bl_idname = "wenv.live"
    bl_label = "Live"
    # No UNDO option: the colours written every tick make no step each (they would flood the undo
    # history); _stop pushes one step for the whole session, as Blender's own modal tools make one
    # when they finish.

    interval: FloatProperty(name="Interval", default=0.05, min=0.01, max=2.0,
                            description="Seconds between checks for changes")

    def invoke(self, context, event):
        if LiveState.running():
            LiveState.stop_requested = True  # the running modal sees it on its next tick
            return {"FINISHED"}
        names = [o.name for o in context.selected_objects if o.type == "MESH"]
        if not names:
            self.report({"ERROR"}, "Select at least one mesh for live shading")
            return {"CANCELLED"}
        LiveState.reset()
        LiveState.session = LiveSession(names)
        wm = context.window_manager
        if LiveState.start_jobs(_quality(context), context.scene.wenv.preview_changes):
            wm.progress_begin(0.0, 1.0)
        self._timer = wm.event_timer_add(self.interval, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        self.report({"ERROR"}, "Live mode is interactive: invoke it (bpy.ops.wenv.live('INVOKE_DEFAULT') in a "
                                "Blender session); scripts call wenv.shade")
        return {"CANCELLED"}

    def _stop(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        if LiveState.job is not None:
            wm.progress_end()
        wrote = LiveState.session is not None and LiveState.session.shades > 0
        LiveState.reset()
        if wrote:
            bpy.ops.ed.undo_push(message=LIVE_UNDO_STEP)
        _redraw_viewports(context)
        return {"FINISHED"}

    def cancel(self, context):
        # Blender ends the operator itself (a file is loaded, its window closes): the session's data
        # is gone or going, so no undo step.
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        if LiveState.job is not None:
            wm.progress_end()
        LiveState.reset()

    def modal(self, context, event):
        if event.type == "ESC" or LiveState.stop_requested or LiveState.session is None:
            return self._stop(context)
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        preview = LiveState.preview_job
        if preview is not None and preview.done:
            LiveState.preview_job = None
            preview.install()  # if it failed, changes simply show the scene's quality when made
        job = LiveState.job
        if job is not None:
            context.window_manager.progress_update(job.fraction)
            if not job.done:
                return {"PASS_THROUGH"}
            context.window_manager.progress_end()
            LiveState.job = None
            if not job.install():
                self.report({"WARNING"}, "Precomputation cancelled" if job.cancelled else f"Precomputation failed: {job.error}")
                return self._stop(context)
        if LiveState.session.tick(context):
            _redraw_viewports(context)
        return {"PASS_THROUGH"}


def _active_material(context):
    obj = context.object
    return obj.active_material if obj is not None else None


class _MaterialOperator:
    @classmethod
    def poll(cls, context):
        return _active_material(context) is not None


class WENV_OT_from_principled(_MaterialOperator, bpy.types.Operator):
    """Set the active material to Cook-Torrance lobes approximating its Principled BSDF (editable; the Principled model shades the node itself)"""
    bl_idname = "wenv.from_principled"
    bl_label = "Cook-Torrance from Principled BSDF"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        try:
            notes = materials.fill_from_principled(_active_material(context))
        except engine.SetupError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        for w in notes:
            self.report({"WARNING"}, w)
        return {"FINISHED"}


class WENV_OT_lobe_add(_MaterialOperator, bpy.types.Operator):
    """Add a Cook-Torrance lobe to the active material"""
    bl_idname = "wenv.lobe_add"
    bl_label = "Add Lobe"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        st = _active_material(context).wenv
        st.lobes.add()
        st.active_lobe = len(st.lobes) - 1
        st.initialized = True
        return {"FINISHED"}


class WENV_OT_lobe_remove(_MaterialOperator, bpy.types.Operator):
    """Remove the active lobe"""
    bl_idname = "wenv.lobe_remove"
    bl_label = "Remove Lobe"
    bl_options = {"REGISTER", "UNDO"}

    index: IntProperty(name="Index", default=-1, description="Lobe to remove (-1: the active one)")

    def execute(self, context):
        st = _active_material(context).wenv
        i = st.active_lobe if self.index < 0 else self.index
        if not 0 <= i < len(st.lobes):
            self.report({"ERROR"}, f"No lobe {i}")
            return {"CANCELLED"}
        st.lobes.remove(i)
        st.active_lobe = max(0, min(st.active_lobe, len(st.lobes) - 1))
        st.initialized = True
        return {"FINISHED"}


class WENV_OT_fit_roughness(_MaterialOperator, bpy.types.Operator):
    """Set the roughness so the material reads the target gloss (the Principled BSDF's Roughness, or a one-lobe Cook-Torrance's alpha)"""
    bl_idname = "wenv.fit_roughness"
    bl_label = "Set Roughness for Target Gloss"
    bl_options = {"REGISTER", "UNDO"}

    target: FloatProperty(name="Target", default=-1.0, description="Gloss in GU (-1: the material's Target Gloss)")
    geometry: EnumProperty(name="Geometry", default="MATERIAL", items=[
        ("MATERIAL", "Material Setting", "The material's target geometry"),
        ("20", "20°", ""), ("60", "60°", ""), ("85", "85°", "")])

    def execute(self, context):
        mat = _active_material(context)
        st = mat.wenv
        target = st.target_gloss if self.target < 0 else self.target
        geometry = int(st.target_geometry if self.geometry == "MATERIAL" else self.geometry)
        try:
            if st.model == "PRINCIPLED":
                r = gloss.fit_principled_roughness(mat, target, geometry)
                materials.principled_node(mat).inputs["Roughness"].default_value = r
                self.report({"INFO"}, f"Roughness {r:.4g} (the Principled BSDF's) reads {target:g} GU at "
                                      f"{geometry} degrees")
                return {"FINISHED"}
            alpha = gloss.fit_alpha(st, target, geometry)
        except engine.SetupError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        lobe = st.lobes[0]
        lobe.alpha = alpha
        st.initialized = True
        self.report({"INFO"}, f"Roughness {lobe.roughness:.4g} (alpha {alpha:.4g}) reads {target:g} GU at "
                              f"{geometry} degrees")
        return {"FINISHED"}


classes = (WENV_OT_precompute, WENV_OT_shade, WENV_OT_clear, WENV_OT_bake, WENV_OT_bake_hide, WENV_OT_live, WENV_OT_from_principled,
           WENV_OT_lobe_add, WENV_OT_lobe_remove, WENV_OT_fit_roughness)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    LiveState.reset()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
