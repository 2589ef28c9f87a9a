"""Shading passes: Blender data read into a plan, shaded by the engine, colours written back."""
import math

import numpy as np

from . import engine, lamps, materials, meshes, textures, world
from .engine import SetupError

LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)
# Scene.wenv.shaded_frame before any colours were written.  Every pass notes its frame there, in
# the data undo restores, so after an undo or redo it is known which frame the colours are of.
NO_FRAME = -2 ** 31


def tone_map(rgb, l_max):
    """The thesis's global logarithmic operator: Ld = log10(1 + Lw) / log10(1 + Lmax), applied to
    the luminance, colour kept."""
    lw = rgb @ LUMINANCE
    ld = np.log10(1 + np.maximum(lw, 0)) / np.log10(1 + l_max)
    scale = np.where(lw > 0, ld / np.maximum(lw, 1e-12), 0).astype(np.float32)
    return np.clip(rgb * scale[:, None], 0, 1).astype(np.float32)


def _with_inputs(part, inputs):
    """part (meshes.MeshData) with its own inputs per vertex in place of part's."""
    copy = meshes.MeshData(part.domain, part.positions, part.normals, None,
                           inputs={k: np.ascontiguousarray(a) for k, a in inputs.items()})
    copy.shading_normals = part.shading_normals
    copy.bump_map_correction = part.bump_map_correction
    return copy


class ShadingPlan:
    """One shading pass.  `plan_shading` fills it from Blender data on the main thread (World
    pixels, meshes as world-space arrays, material values); `compute` touches no Blender data, so
    it may run on a worker thread (the live mode does, the core releases the GIL); `apply` writes
    the colours back on the main thread, by object name."""

    def __init__(self, quality, spec, environment, view, tone, l_max, target_error=0.01, memory_budget_mb=1024,
                 cull=False, shadows=False, bounce=True, glossy_bounce=True):
        self.quality = quality  # what compute() shades at
        self.chosen = quality  # the scene's setting: quality is PREVIEW_QUALITY while this one is made
        self.cull = cull  # shade only the vertices a viewport sees (engine.shade_arrays)
        self.target_error = target_error
        self.memory_budget_mb = memory_budget_mb
        self.world = spec  # world.WorldSpec
        self.environment = environment
        self.view = view
        self.tone = tone
        self.l_max = l_max
        self.items = []  # (object name, MeshData, material keys per slot)
        self.shadows = shadows  # shade with the scene in the way (engine.shadows)
        self.bounce = bounce  # with shadows, what blocks sends back its diffuse light (else black)
        self.glossy_bounce = glossy_bounce  # and its glossy light, towards each vertex it blocks
        self.casts = []  # per item: whether it blocks light (the object's Casts Shadows)
        # the items only receive light, standing in no scene of their own: a bake's texels, whose mesh
        # is among the blockers (and senders)
        self.receive_only = False
        # with receive_only, the side of the items' occlusion masks: None, the kept occlusion at the
        # core's Auto; a number, cast at it for this pass alone (a bake's texels: millions of them);
        # with point rays if `point_rays` (wenv.Occluders.occlusion; the kept one made so for the pass)
        self.resolution = None
        self.point_rays = False
        self.blockers = []  # (object name, positions, triangles) of the other meshes that block light
        # with bounce light, per blocker (in the same order): (object name, MeshData, material keys),
        # whose diffuse light it sends back into what it shadows
        self.senders = []
        self.lamps = []  # the scene's lamps (wenv.Lamp: no Blender data)
        self.lamp_settings = []  # and what they were made of (lamps.read_lamps': their light linking)
        self.lamps_key = ()  # what tells this pass's lamps from another's (the bounce made with them)
        self.notes = []
        self.results = None
        self.auto_choices = {}  # (object name, material key) -> stats["auto"] of the shader used

    def _parts(self, items):
        """Per object of `items`: (name, data, keys, parts), parts being (slot, selection, MeshData of
        the vertices of that material slot) -- the mesh itself when one slot holds them all."""
        for name, data, keys in items:
            slots = np.clip(data.slots, 0, len(keys) - 1)
            parts = []
            for s in np.unique(slots):
                sel = slots == s
                mine = {k: a for k, a in data.inputs.items() if s in data.textured[k]}
                if sel.all() and len(mine) == len(data.inputs):
                    part = data
                else:
                    part = meshes.MeshData(data.domain, np.ascontiguousarray(data.positions[sel]),
                                           np.ascontiguousarray(data.normals[sel]), None,
                                           inputs={k: np.ascontiguousarray(a[sel]) for k, a in mine.items()})
                    if data.shading_normals is not None:
                        part.shading_normals = np.ascontiguousarray(data.shading_normals[sel])
                        part.bump_map_correction = data.bump_map_correction
                    if data.mask_blocks is not None:
                        part.mask_blocks = data.mask_blocks[sel]
                parts.append((s, sel, part))
            yield name, data, keys, parts

    def _result(self, name, data, rgb, seen):
        if data.unplaced is not None:
            rgb[data.unplaced] = 0.0
            if seen is not None:
                seen[data.unplaced] = True  # written black, not left as they were
        return name, data.domain, tone_map(rgb, self.l_max) if self.tone == "LOG" else rgb, seen

    def material_keys(self):
        return {t for _, data, keys in self.items + self.senders for s in np.unique(np.clip(data.slots, 0, len(keys) - 1))
                for t in engine.term_keys(keys[s])}

    def preview_if_slow(self):
        """Shade at engine.PREVIEW_QUALITY instead when the setting chosen would first remake its
        lighting or BRDF slices (engine.ShaderCache.ready) and the preview's shader is built."""
        if (self.chosen != engine.PREVIEW_QUALITY and engine.shaders.has(engine.PREVIEW_QUALITY)
                and not engine.shaders.ready(self.chosen, self.world, self.material_keys(), self.target_error,
                                             self.memory_budget_mb)):
            self.quality = engine.PREVIEW_QUALITY

    def _shader(self, quality, name, key, normals, cancelled=None):
        """The shader for one material at `quality`, holding this pass's lighting (under the
        shader cache's lock)."""
        if quality == engine.AUTO:
            shader = engine.shaders.auto(self.world.signature, self.environment, key, self.target_error,
                                         self.memory_budget_mb, normals, cancelled)
            self.auto_choices[(name, key)] = shader.stats["auto"]
            return shader
        engine.shaders.get(quality)
        engine.shaders.use_environment(quality, self.world.signature, self.environment)
        return engine.shaders.use_material(quality, key, cancelled)

    def _takes(self, shader, name, part):
        """part, or a copy without its per-vertex Roughness and Metallic when the shader's method does
        not shade them (Auto's choice of a peer), which is then noted: the material's own values are
        used."""
        dropped = [k for k in engine.VERTEX_MATERIAL_INPUTS if k in part.inputs]
        if not dropped or engine.takes_vertex_materials(shader):
            return part
        note = (f"'{name}': textured {' and '.join(k.title() for k in dropped)} shaded at the unlinked value by "
                f"{shader.method} (Auto's choice; the wavelet qualities read the texture)")
        if note not in self.notes:
            self.notes.append(note)
        return _with_inputs(part, {k: a for k, a in part.inputs.items() if k not in dropped})

    def _ordered_parts(self, quality, items=None):
        """(object index, name, material key, selection, part, weight) of every part of the pass (of
        `items` when given, else of the meshes shaded), those
        of one material together, the materials the shader at `quality` keeps first (the current one
        first of all): a shader holds one material at a time and keeps the last few, so each
        material's BRDF slices are made at most once per pass (~0.3-0.7 s at `default`) and a kept
        one's not at all.  A mixture of shader nodes is a work item per term (closures.py), weighted
        by its weight over the part's rows ((3,) or (rows, 3)); weight None: 1."""
        kept = engine.shaders.kept_materials(quality)
        work, order = [], {}
        for i, (name, data, keys, parts) in enumerate(self._parts(self.items if items is None else items)):
            for s, sel, part in parts:
                if keys[s][0] != "MIXTURE":
                    order.setdefault(keys[s], len(order))
                    work.append((i, name, keys[s], sel, part, None))
                    continue
                term_inputs = data.term_inputs.get(s, ())
                for t, ((term_key, _mean), weight) in enumerate(zip(keys[s][1], data.term_weights.get(s, ()))):
                    order.setdefault(term_key, len(order))
                    own = term_inputs[t] if t < len(term_inputs) else {}
                    term_part = part if not own else _with_inputs(part, {k: a[sel] for k, a in own.items()})
                    work.append((i, name, term_key, sel, term_part, weight if weight.ndim == 1 else weight[sel]))
        # stable: meshes in order within a material
        work.sort(key=lambda w: (kept.index(w[2]) if w[2] in kept else len(kept), order[w[2]]))
        return work

    def _buffers(self):
        return ([np.zeros((data.count, 3), np.float32) for _, data, _ in self.items],
                [np.ones(data.count, bool) if self.cull else None for _, data, _ in self.items])

    def _results(self, rgbs, seens):
        return [self._result(name, data, rgb, seen) for (name, data, _), rgb, seen in zip(self.items, rgbs, seens)]

    def _scenes(self, quality, work, cancelled=None, report=None):
        """Per part of `work`, the keywords of shading it with the scene in the way: its occlusion
        against every blocking mesh, and with bounce light the light every occluder vertex sends back
        (the diffuse light of the parts shaded and of the other blockers, each with its own shadows
        and materials).  None without shadows.  report(fraction) as the occlusions are cast;
        `cancelled` (a threading.Event) stops them."""
        if not self.shadows:
            return [self._lit(w[1]) for w in work]
        named = [] if self.receive_only else [
            (name, data.positions, data.triangles if cast else np.zeros((0, 3), np.int32))
            for (name, data, _), cast in zip(self.items, self.casts)]
        first_blocker = len(named)  # where the blockers' (and the senders') rows start
        named += self.blockers
        meshes_in = [(p, t) for _, p, t in named]
        if not any(len(t) for _, t in meshes_in):
            return [self._lit(w[1]) for w in work]
        # the blockers not shaded send their light too: their own shadows, then their diffuse light
        senders = self._ordered_parts(quality, self.senders) if self.bounce else []
        everything = work + senders
        with engine.shadows.lock:
            occluders, offsets = engine.shadows.occluders(meshes_in, self.memory_budget_mb)
            shadowing = self._shadowing_lamps(named)
            # the receivers' occlusions made for this pass alone (nothing made of them is kept)
            transient = self.receive_only and (self.resolution is not None or self.point_rays)

            def occlusion_of(k, part):
                progress = _ray_progress(k, len(everything), report, cancelled)
                receiver = self.receive_only and k < len(work)
                if receiver and self.resolution is not None:
                    return engine.shadows.cast(occluders, part.positions, part.normals, self.resolution,
                                               self.point_rays, progress, part.mask_blocks)
                kept = engine.shadows.occlusion(occluders, part.positions, part.normals, progress)
                return kept.with_point_rays() if receiver and self.point_rays else kept
            occlusions = [occlusion_of(k, part) for k, (_, _, _, _, part, _) in enumerate(everything)]
        bounce = np.zeros((offsets[-1], 3), np.float32)
        # with glossy bounce, what each occluder vertex sends towards each direction, and its normal
        sent = (np.zeros((offsets[-1], engine.SENDING_SIDE ** 2, 3), np.float32) if self.bounce and self.glossy_bounce
                else None)  # made below, pass by pass
        sent_normals = np.tile(np.float32([0.0, 0.0, 1.0]), (offsets[-1], 1)) if sent is not None else None
        scenes, made, sending = [], [], []
        for k, ((i, name, key, sel, part, weight), occlusion) in enumerate(zip(everything, occlusions)):
            sender = k >= len(work)
            shader = self._shader(quality, name, key, part.normals, cancelled)
            if not engine.models_shadows(shader):  # Auto's choice for this part: it sends back no light
                note = (f"'{name}': {'sends no bounce light' if sender else 'shaded without shadows'} by "
                        f"{shader.method} (Auto's choice; the wavelet qualities shade shadows)")
                if note not in self.notes:
                    self.notes.append(note)
                if not sender:
                    scenes.append(None)
                continue
            if not sender:
                scenes.append(occlusion)
            if not self.bounce or (self.receive_only and not sender):
                continue
            made_by = (quality, self.world.signature, key, self.target_error, self.memory_budget_mb,
                       engine.fingerprint(*(part.inputs[k] for k in sorted(part.inputs))) if part.inputs else None,
                       tuple(sorted(part.inputs)), self.lamps_key,
                       None if part.shading_normals is None else engine.fingerprint(part.shading_normals))
            made.append((id(occlusion), made_by))  # what each sender's light was made of, and from
            taken = self._takes(shader, name, part)
            with engine.shadows.lock:
                light = engine.shadows.light(occlusion, ("diffuse", key), made_by,
                                             lambda: engine.diffuse_light(shader, taken, occlusion,
                                                                          self._lamps_of(name, shadowing)))
            rows = offsets[first_blocker + i if sender else i] + np.flatnonzero(sel)  # blockers follow the shaded
            bounce[rows] += light if weight is None else weight * light
            if sent is None:
                continue
            sent_normals[rows] = part.normals
            sending.append((name, key, part, occlusion, rows, weight))
        lits = [self._lit(w[1], shadowing) for w in work]
        if sent is None:
            return [dict(occlusion=o, bounce=bounce if self.bounce else None, **(lit or {})) if o is not None else lit
                    for o, lit in zip(scenes, lits)]
        made = tuple(made)
        passing = {id(o) for o in occlusions[:len(work)]} if transient else set()

        def at_hits(occlusion, bounces):
            if id(occlusion) in passing:
                return occlusion.read_sent(sent_normals, sent)  # cast for this pass alone: nothing kept
            with engine.shadows.lock:
                return engine.shadows.light(occlusion, ("hits", bounces), made,
                                            lambda: occlusion.read_sent(sent_normals, sent))
        # each pass sends what the last one received: the light that has bounced once more; the
        # maps are shaded at engine.SENDING_QUALITY, a bounce being a share of what is seen, with
        # lobes no narrower than the maps hold (engine.sending_key)
        for bounces in range(GLOSSY_BOUNCES):
            again = np.zeros_like(sent)
            for name, key, part, occlusion, rows, weight in sending:
                received = at_hits(occlusion, bounces) if bounces else None
                shader = self._shader(engine.SENDING_QUALITY, name, engine.sending_key(key), part.normals, cancelled)
                taken = self._takes(shader, name, part)
                taken = _with_inputs(taken, engine.sending_inputs(taken.inputs)) if taken.inputs else taken
                with engine.shadows.lock:
                    toward = engine.shadows.light(occlusion, ("sent", key, bounces), made, lambda: engine.sent_light(
                        shader, taken, occlusion, self._lamps_of(name, shadowing), bounce_hits=received))
                again[rows] += toward if weight is None else _per_direction(weight) * toward
            sent = again
        return [dict(occlusion=o, bounce_hits=at_hits(o, GLOSSY_BOUNCES), **(lit or {})) if o is not None else lit
                for o, lit in zip(scenes, lits)]

    def _lamps_of(self, name, made=None):
        """Of the lamps `made` from self.lamp_settings (None: self.lamps), those that light object
        `name` (their Lights' light linking)."""
        return [lamp for lamp, s in zip(self.lamps if made is None else made, self.lamp_settings)
                if lamps.lights(s, name)]

    def _lit(self, name, made=None):
        """The keywords of object `name`'s lamps (_lamps_of), or None without any."""
        mine = self._lamps_of(name, made)
        return {"lamps": mine} if mine else None

    def _shadowing_lamps(self, named):
        """self.lamps, with each whose Light links its shadows blocked only by the meshes of `named`
        ((object name, positions, triangles), the scene's blockers) that its blocker collection lets
        block it (new wenv.Lamps, then; by nothing when it lets none)."""
        own = {}
        blocking = [(name, p, t) for name, p, t in named if len(t)]
        for j, s in enumerate(self.lamp_settings):
            if s["blockers"] is None or not s["cast_shadow"]:
                continue
            some = [(p, t) for name, p, t in blocking if lamps.blocked_by(s, name)]
            if len(some) < len(blocking):  # all of them: the scene's own occluders
                own[j] = engine.shadows.occluders_of(some, self.memory_budget_mb) if some else False
        return engine.make_lamps(self.lamp_settings, own) if own else self.lamps

    def compute(self, rays=None):
        """Shades every part; rays(fraction), if given, while their occlusions are cast."""
        rgbs, seens = self._buffers()
        with engine.shaders.lock:
            work = self._ordered_parts(self.quality)
            for (i, name, key, sel, part, weight), scene in zip(work, self._scenes(self.quality, work, report=rays)):
                shader = self._shader(self.quality, name, key, part.normals)
                rgb, part_seen = engine.shade_arrays(shader, self._takes(shader, name, part), self.view, self.cull,
                                                     scene)
                rgbs[i][sel] += rgb if weight is None else weight * rgb
                if seens[i] is not None and part_seen is not None:
                    seens[i][sel] = part_seen
        self.results = self._results(rgbs, seens)

    def refine(self, quality, step_seconds, report, cancelled, rays=None):
        """compute() again at `quality`, in steps of about `step_seconds` that each hold the
        shader cache's lock only for themselves, so a new pass waits at most a step (a new
        material's BRDF slices, made in the first step, stop when cancelled).  Returns the results
        as compute() makes them, or None once `cancelled` (a threading.Event) is set;
        `report(fraction)` after each step, `rays(fraction)` while occlusions are cast."""
        rgbs, seens = self._buffers()
        total = sum(data.count for _, data, _ in self.items)
        done = 0
        work = self._ordered_parts(quality)
        with engine.shaders.lock:
            try:
                scenes = self._scenes(quality, work, cancelled, rays)
            except engine.CancelledError:
                return None
        for (i, name, key, sel, part, weight), scene in zip(work, scenes):
            out = np.zeros((part.count, 3), np.float32)
            first, count = 0, None
            while count is None or first < count:
                if cancelled.is_set():
                    return None
                with engine.shaders.lock:
                    try:
                        shader = self._shader(quality, name, key, part.normals, cancelled)
                    except engine.CancelledError:
                        return None
                    first, count = engine.shade_step(shader, self._takes(shader, name, part), self.view, self.cull,
                                                     out, first, step_seconds, scene)
                report((done + part.count * (first / count if count else 1.0)) / total)
            rgbs[i][sel] += out if weight is None else weight * out
            done += part.count
            if seens[i] is not None and self.view.perspective and self.view.view_projection is not None:
                seens[i][sel] = engine.visible_vertices(part, self.view)
        return self._results(rgbs, seens)

    def apply(self, objects, scene):
        """Writes the results into the meshes of `objects` (bpy.data.objects); an object deleted or
        edited since plan_shading is skipped.  Notes the frame in `scene` (see NO_FRAME).  Returns
        the names written."""
        done = []
        for name, domain, rgb, seen in self.results:
            obj = objects.get(name)
            if obj is None or obj.type != "MESH":
                continue
            size = len(obj.data.vertices) if domain == "POINT" else len(obj.data.loops)
            if size == len(rgb):
                meshes.write_colors(obj.data, domain, rgb, seen)
                done.append(name)
        if done and scene.wenv.shaded_frame != scene.frame_current:
            scene.wenv.shaded_frame = scene.frame_current
        return done


# With glossy bounce, how many times light bounces between the meshes: twice, so that a metal
# sphere's underside, which mirrors the floor, shows the floor's light in the floor's mirror image.
GLOSSY_BOUNCES = 2


def _per_direction(weight):
    """A term's weight ((3,) or (rows, 3)) against sending maps (rows, directions, 3)."""
    return weight if weight.ndim == 1 else weight[:, None, :]


def _ray_progress(k, parts, report, cancelled):
    """The progress callback of part k's occlusion among `parts`: its share of report(fraction),
    and True to stop once `cancelled` is set (a refinement's rays stop when it is cancelled: the
    core raises CancelledError, which refine() catches).  None when neither is asked for."""
    if report is None and cancelled is None:
        return None

    def progress(fraction):
        if report is not None:
            report((k + fraction) / parts)
        return cancelled is not None and cancelled.is_set()
    return progress


def new_plan(scene, view, images, cull=None, shadows=None):
    """A ShadingPlan of the scene's World, lamps and wenv settings, with no meshes yet (main
    thread); `cull` and `shadows` in place of the scene's settings where given.  Raises SetupError
    for a set-up that cannot be shaded."""
    st = scene.wenv
    # Blender's limits on a float property let NaN through (a script may set it)
    for label, value in (("Max Luminance", st.max_luminance), ("Target Error", st.target_error)):
        if not math.isfinite(value):
            raise SetupError(f"The scene's wenv {label} is {value}: set a number")
    spec = world.world_spec(scene.world)
    plan = ShadingPlan(engine.quality_value(st.quality), spec, world.environment(spec, images), view, st.tone_mapping,
                       st.max_luminance, st.target_error / 100.0, st.memory_budget,
                       cull=st.shade_only_seen if cull is None else cull, shadows=st.shadows if shadows is None else shadows,
                       bounce=st.bounce_light, glossy_bounce=st.glossy_bounce)
    note = world.world_note(spec, images)
    if note:
        plan.notes.append(note)
    lamp_settings, lamp_notes = lamps.read_lamps(scene)
    plan.notes.extend(lamp_notes)
    plan.lamps = engine.make_lamps(lamp_settings)
    plan.lamp_settings = lamp_settings
    plan.lamps_key = lamps.key_of(lamp_settings)
    return plan


def plan_shading(scene, depsgraph, objects, view, images, progress=None, preview=False):
    """Reads everything a pass over `objects` needs (main thread); builds the shader it shades
    with first if it is missing.  With `preview` (the live mode) and the scene's Draft While
    Remaking, a pass the scene's quality would first remake slices for is planned at
    engine.PREVIEW_QUALITY (plan.chosen keeps the scene's).  Raises SetupError for a set-up that
    cannot be shaded."""
    st = scene.wenv
    notes = []
    editing = [o.name for o in objects if o.type == "MESH" and o.mode == "EDIT"]
    if editing:
        notes.append("skipped meshes in Edit Mode (leave it to shade them): " + ", ".join(editing))
    mesh_objects = [o for o in objects if o.type == "MESH" and o.mode != "EDIT"]
    skipped = [o.name for o in objects if o.type != "MESH"]
    if skipped:
        notes.append("skipped objects that are not meshes: " + ", ".join(skipped))
    if not mesh_objects:
        raise SetupError("Leave Edit Mode to shade" if editing else
                         "No mesh objects to shade: select at least one mesh")
    plan = new_plan(scene, view, images)
    if st.shade_only_seen and view.view_projection is None and st.view_source == "VIEWPORT" and not view.perspective:
        notes.append("Shade Only What Is Seen applies to perspective viewports: this orthographic view shades "
                     "every vertex")
    notes.extend(plan.notes)
    plan.notes = notes
    for obj in mesh_objects:
        data = meshes.read_mesh(obj, depsgraph)
        data.view = view
        notes.extend(data.notes)
        if data.count == 0:
            notes.append(f"'{obj.name}' has no vertices")
            continue
        notes.extend(textures.read_inputs(obj, depsgraph, data))
        notes.extend(textures.read_term_weights(obj, depsgraph, data))
        notes.extend(textures.read_shading_normals(obj, depsgraph, data))
        plan.items.append((obj.name, data, materials.slot_material_keys(obj)))
        plan.casts.append(obj.wenv.casts_shadows)
        notes += [n for n in materials.slot_notes(obj) if n not in notes]
    if st.shadows:
        shaded = {o.name for o in mesh_objects}
        for obj in scene.objects:
            if (obj.type == "MESH" and obj.name not in shaded and obj.wenv.casts_shadows and obj.visible_get()
                    and obj.mode != "EDIT"):
                data = meshes.read_mesh(obj, depsgraph)
                data.view = view
                if not data.count:
                    continue
                plan.blockers.append((obj.name, data.positions,
                                      engine.shadow_triangles(data.positions, data.triangles)[0]))
                if st.bounce_light:  # its light, read as a shaded mesh's is
                    for read in (textures.read_inputs, textures.read_term_weights, textures.read_shading_normals):
                        notes += [n for n in read(obj, depsgraph, data) if n not in notes]
                    notes += [n for n in materials.slot_notes(obj) if n not in notes]
                    plan.senders.append((obj.name, data, materials.slot_material_keys(obj)))
        notes += _other_blockers(plan, depsgraph, shaded, st)
        dropped = 0
        for (_, data, _), cast in zip(plan.items, plan.casts):
            if cast:
                data.triangles, n = engine.shadow_triangles(data.positions, data.triangles)
                dropped += n
        if dropped:
            notes.append(f"{dropped} degenerate face(s) (no area) cast no shadow")
    if preview and st.preview_changes:
        plan.preview_if_slow()
    if plan.quality != engine.AUTO:
        engine.shaders.get(plan.quality, progress)
    return plan


# The most rows (vertices or corners, each instance's own) that instances, curves and text send Bounce
# Light from: each costs its rays and its shading as a mesh's vertex does, and a scatter of
# instances multiplies them (a million take about as long as a 1M-vertex mesh's bounce)
SENDER_ROWS = 1_000_000


def _other_blockers(plan, depsgraph, shaded, st):
    """Adds to plan.blockers what else blocks light in Cycles (meshes.other_geometry: instances,
    curves, text), within the memory budget; returns notes."""
    used = sum(engine.occluder_bytes(data.positions, data.triangles) for _, data, _ in plan.items)
    used += sum(engine.occluder_bytes(p, t) for _, p, t in plan.blockers)
    # with Bounce Light they send their light back too, each kind (an object's instances with the same
    # materials) as one part, up to SENDER_ROWS rows in all; plan.senders stays in step with
    # plan.blockers, so those that send come first
    others, left = meshes.other_geometry(depsgraph, skip=shaded, room=st.memory_budget * 1048576.0 - used,
                                         senders=st.bounce_light)
    notes, sending, silent, rows_sent = [], [], [], 0
    for entry in others:
        sender = entry[3]
        if sender is not None and rows_sent + sender[0].count <= SENDER_ROWS:
            rows_sent += sender[0].count
            sending.append(entry)
        else:
            silent.append(entry)
    for name, p, t, (data, mats, instanced, rows) in sending:
        plan.blockers.append((name, p, engine.shadow_triangles(p, t)[0]))
        data.view = plan.view
        notes += [n for n in data.notes if n not in notes]
        plan.senders.append((name, data, materials.material_keys(mats)))
        read = [f"'{m.name}'" for m in mats if textures.reads_per_point(m)]
        if not read:
            textures.unlinked_term_weights(mats, data)
            continue
        got = textures.read_instanced(instanced, depsgraph, data, rows)
        if got is not None:  # each instance reads what its object reads at the same row
            notes += [n for n in got if n not in notes]
            continue
        textures.unlinked_term_weights(mats, data)
        note = (f"'{name}' (instanced, or a curve or text) sends back the light of its materials' unlinked values: "
                f"{', '.join(read)} read where each instance lies (the world, the view, the object) or bend its "
                "normals, which wenv reads on mesh objects only")
        if note not in notes:
            notes.append(note)
    for name, p, t, _ in silent:
        plan.blockers.append((name, p, engine.shadow_triangles(p, t)[0]))
    unsent = sum(entry[3] is not None for entry in silent)
    if unsent:
        notes.append(f"{unsent} instanced object(s), curve(s) or text(s) block light but send none back: past "
                     f"{SENDER_ROWS:,} vertices of such light in all (Bounce Light)")
    if left:
        notes.append(f"{left} instance(s) or curve object(s) cast no shadow: over the memory budget "
                     f"({st.memory_budget} MB) with the rest of the scene")
    return notes


def shade_objects(scene, depsgraph, objects, view, blend_data, progress=None, rays=None):
    """Shades every mesh in `objects` for `view` with the scene's wenv settings, synchronously;
    progress(fraction) while a shader is made, rays(fraction) while shadow rays are cast.  Returns
    (shaded names, notes)."""
    plan = plan_shading(scene, depsgraph, objects, view, blend_data.images, progress)
    plan.compute(rays)
    for (name, _key), choice in plan.auto_choices.items():
        plan.notes.append(f"'{name}': Auto chose {engine.describe_auto_choice(choice)} "
                          f"(predicted error {100 * choice['predicted_error']:.2g} %"
                          + ("" if choice["met"] else f", above the {100 * choice['target_error']:.2g} % target") + ")")
    return plan.apply(blend_data.objects, scene), plan.notes
