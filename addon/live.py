"""Background precomputation and the live mode's change detection (no operators here: operators.py
drives these from modal timers, tests drive them directly)."""
import threading

import bpy

from . import bake, engine, lamps, materials, shading, views, world


class _WorkerJob:
    """Work on a worker thread (the core releases the GIL) that reports a fraction and stops when
    `cancel()` is called; the main thread polls `done`.  Subclasses define `_work`, which records
    its outcome; an exception is kept in `error`, reported on the main thread."""

    def __init__(self, name):
        self.fraction = 0.0
        self.error = None
        self._cancel = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self):
        self._thread.start()
        return self

    def _run(self):
        try:
            self._work()
        except Exception as exc:  # reported on the main thread
            self.error = exc

    def cancel(self):
        self._cancel.set()

    @property
    def done(self):
        return not self._thread.is_alive()

    def wait(self, timeout=None):
        self._thread.join(timeout)
        return self.done


class PrecomputeJob(_WorkerJob):
    """Builds a wenv.Shader; the main thread takes `result`."""

    def __init__(self, quality):
        super().__init__(f"wenv-precompute-{quality}")
        self.quality = quality
        self.result = None
        self.cancelled = False

    def _progress(self, fraction):
        self.fraction = fraction
        return self._cancel.is_set()

    def _work(self):
        try:
            self.result = engine.shaders.build(self.quality, self._progress)
        except engine.CancelledError:
            self.cancelled = True

    def install(self):
        """Main thread: puts the finished shader into the cache.  True if there was one."""
        if self.result is not None and not engine.shaders.has(self.quality):
            engine.shaders.add(self.quality, self.result)
        return self.result is not None


class RefineJob(_WorkerJob):
    """Shades a pass already written again at `quality` (the scene's own after a preview, then
    engine.REFINE_QUALITY), while the view rests, in steps of STEP_SECONDS, so that `cancel()` takes
    effect within a step; `results` is None if cancelled."""

    STEP_SECONDS = 0.05

    def __init__(self, plan, quality):
        super().__init__(f"wenv-refine-{quality}")
        self.plan = plan
        self.quality = quality
        self.results = None

    def _report(self, fraction):
        self.fraction = fraction

    def _work(self):
        self.results = self.plan.refine(self.quality, self.STEP_SECONDS, self._report, self._cancel)

    def apply(self, objects, scene):
        """Main thread: writes the refined colours (see ShadingPlan.apply)."""
        self.plan.results = self.results
        return self.plan.apply(objects, scene)


def _matrix_tuple(m):
    return tuple(round(v, 7) for row in m for v in row)


class LiveSession:
    """Re-shades a fixed set of objects (by name) whenever the view, their transforms, the World or
    their materials change.  `tick()` is cheap when nothing changed (it compares a signature);
    when something did, it reads the meshes and hands the shading to a worker thread, and a later
    tick writes the colours back, so the UI keeps running while the core shades."""

    def __init__(self, object_names):
        self.object_names = list(object_names)
        self.last_signature = None
        self.last_error = None
        self.shades = 0
        self._plan = None
        self._reads_camera = False  # the last pass read the camera's space or frame (signature)
        # changes to the scene's other objects (moved, edited, added, an instance placed), counted
        # by the depsgraph handler (note_updates): what the session's shadows and rays may meet
        self.others_changed = 0
        self._worker = None
        self._error = None
        self._discard = False  # the worker's plan was read from data an undo has since replaced
        self._refine = None  # RefineJob of the last pass written, while the view rests
        self.shown = None  # the quality of the colours shown (of the last pass or refinement written)
        self.refined = False  # the colours shown are engine.REFINE_QUALITY's refinement

    def stop(self):
        """Drops the refinement and waits for the workers (they hold the shaders)."""
        job = self._refine
        self._drop_refinement()
        if job is not None:
            job.wait()
        self.wait()

    def objects(self, scene):
        return [scene.objects[n] for n in self.object_names if n in scene.objects]

    def note_updates(self, scene, updates):
        """After a depsgraph update: counts a change to what the session's meshes do not hold --
        another object (not a lamp or camera: the signature reads those), a mesh or curve none of
        them uses, a collection (instances) -- but not the colours the session writes to its own."""
        own = set(self.object_names)
        own_data = {scene.objects[n].data for n in own if n in scene.objects}
        for update in updates:
            data = getattr(update.id, "original", update.id)
            if isinstance(data, bpy.types.Object):
                other = data.name not in own and data.type not in ("LIGHT", "CAMERA")
            else:
                other = (isinstance(data, (bpy.types.Mesh, bpy.types.Curve)) and data not in own_data
                         or isinstance(data, bpy.types.Collection))
            if other:
                self.others_changed += 1
                return

    def view(self, context):
        scene = context.scene
        if scene.wenv.view_source == "CAMERA":
            return views.camera_view(scene)
        rv3d = views.find_region_3d(context)
        if rv3d is None:
            raise engine.SetupError("No 3D viewport to take the view from")
        return views.region_view(rv3d, scene)

    def signature(self, context, view):
        scene = context.scene
        st = scene.wenv
        try:
            world_sig = world.world_spec(scene.world).signature
        except engine.SetupError as exc:
            world_sig = ("error", str(exc))
        objs = []
        for obj in self.objects(scene):
            mats = tuple(materials.material_key(s.material.wenv if s.material else None) for s in obj.material_slots)
            objs.append((obj.name, _matrix_tuple(obj.matrix_world), len(obj.data.vertices), mats))
        # a camera's turn or lens changes only what reads the camera's space or frame
        view_sig = (view.signature, view.camera_signature) if self._reads_camera else view.signature
        # the other objects, where the shadows or an Ambient Occlusion node's rays meet them
        if any(bake.reads_other_meshes(obj, st) for obj in self.objects(scene)):
            objs.append(("others", self.others_changed))
        return (view_sig, world_sig, tuple(objs), lamps.signature(scene), st.quality, st.tone_mapping, st.max_luminance, st.target_error,
                st.memory_budget, st.shade_only_seen, st.refine_at_rest, st.preview_changes, st.shadows, st.bounce_light,
                st.glossy_bounce)

    @property
    def busy(self):
        return (self._worker is not None and self._worker.is_alive()) or (self._refine is not None and
                                                                           not self._refine.done)

    def wait(self, timeout=None):
        """Waits for the pass being shaded and the refinement being made (a step of it once
        cancelled)."""
        if self._worker is not None:
            self._worker.join(timeout)
        if self._refine is not None:
            self._refine.wait(timeout)
        return not self.busy

    @property
    def refine_status(self):
        """What the panel shows of the refinement: None (the scene's quality is shown, nothing to
        refine), ("REFINING", fraction, quality shown, quality being made) or ("REFINED",)."""
        if self.refined:
            return ("REFINED",)
        if self._refine is not None:
            return ("REFINING", self._refine.fraction, self.shown, self._refine.quality)
        return None

    def _drop_refinement(self):
        if self._refine is not None:
            self._refine.cancel()
        self._refine = None
        self.refined = False

    def _wrote(self, scene, plan, quality):
        """Colours at `quality` of `plan` are shown: starts what comes next while the view rests --
        the scene's own quality after a preview, then (Refine at Rest) engine.REFINE_QUALITY."""
        self.shown = quality
        self.refined = quality == engine.REFINE_QUALITY and quality != plan.quality
        steps = [plan.quality, plan.chosen]
        if scene.wenv.refine_at_rest and plan.chosen in engine.REFINABLE:
            steps.append(engine.REFINE_QUALITY)
        later = [q for q in steps[steps.index(quality) + 1:] if q != quality]
        if later:
            self._refine = RefineJob(plan, later[0]).start()

    def _refinement_tick(self, context):
        """The view rests: writes the refinement once it is made.  Returns True when it wrote."""
        job = self._refine
        if job is None or not job.done:
            return False
        self._refine = None
        if job.error is not None:
            self.last_error = f"Refinement failed: {job.error}"
            return False
        if job.results is None:
            return False
        written = job.apply(context.blend_data.objects, context.scene)
        if written:
            self._wrote(context.scene, job.plan, job.quality)
        return bool(written)

    def data_replaced(self):
        """Undo or redo replaced Blender's data: the colours are the restored step's, whatever the
        last signature says, so shade again; a result still being computed was read from the data
        before and is dropped."""
        self.last_signature = None
        self._discard = self._worker is not None
        self._drop_refinement()

    def _compute(self):
        try:
            self._plan.compute()
        except Exception as exc:  # reported on the main thread by the next tick
            self._error = exc

    def tick(self, context):
        """Main thread, every timer event.  Returns True when it wrote new colours.  Set-up errors
        are kept in `last_error` (shown in the panel) rather than raised, so the session keeps
        running and picks up again once the set-up is fixed."""
        if self._worker is not None:
            if self._worker.is_alive():
                return False
            plan, error, discard = self._plan, self._error, self._discard
            self._plan = self._worker = self._error = None
            self._discard = False
            if discard:
                return False
            if error is not None:
                self.last_error = str(error)
                return False
            written = plan.apply(context.blend_data.objects, context.scene)
            self.last_error = None
            self.shades += bool(written)
            if written:
                self._wrote(context.scene, plan, plan.quality)
            return bool(written)
        depsgraph = context.evaluated_depsgraph_get()  # brings matrix_world etc. up to date
        try:
            view = self.view(context)
        except engine.SetupError as exc:
            self.last_error = str(exc)
            return False
        sig = self.signature(context, view)
        if sig == self.last_signature:
            return self._refinement_tick(context)
        self._drop_refinement()  # anything changed: the fast setting shows it at once
        self.last_signature = sig
        scene = context.scene
        try:
            self._plan = shading.plan_shading(scene, depsgraph, self.objects(scene), view, context.blend_data.images,
                                              preview=True)
        except engine.SetupError as exc:
            self.last_error = str(exc)
            return False
        self._reads_camera = any(data.reads_camera for _, data, _ in self._plan.items)
        self._worker = threading.Thread(target=self._compute, name="wenv-live", daemon=True)
        self._worker.start()
        return False


class LiveState:
    """The one live session of this Blender process (module-level: never stored in the .blend)."""

    session = None
    job = None
    preview_job = None  # builds engine.PREVIEW_QUALITY's shader without holding up the session
    stop_requested = False

    @classmethod
    def running(cls):
        return cls.session is not None

    @classmethod
    def start_jobs(cls, quality, preview_changes):
        """What the live operator starts with: the shader for `quality` if missing (the session
        waits for it: `job`, True returned) and, for Draft While Remaking, PREVIEW_QUALITY's if
        missing (`preview_job`, which the session does not wait for)."""
        if not engine.shaders.has(quality):
            cls.job = PrecomputeJob(quality).start()
        if preview_changes and quality != engine.PREVIEW_QUALITY and not engine.shaders.has(engine.PREVIEW_QUALITY):
            cls.preview_job = PrecomputeJob(engine.PREVIEW_QUALITY).start()
        return cls.job is not None

    @classmethod
    def reset(cls):
        for job in (cls.job, cls.preview_job):
            if job is not None:
                job.cancel()
        if cls.session is not None:
            cls.session.stop()
        cls.session = None
        cls.job = None
        cls.preview_job = None
        cls.stop_requested = False

