"""Random scenes and random use of the Blender add-on, in bpy: Worlds of every kind (none, a colour,
generated images with NaN, infinite, negative or huge pixels, missing and corrupt files, mirror
balls, turned and scaled Mappings, nodes the add-on does not read), meshes of every kind (empty,
degenerate, NaN vertices, loose edges, zero and negative scales, modifiers that change topology,
custom normals, several material slots, empty slots), materials of every model with odd values
(Principled inputs out of range or linked, no Principled node, Cook-Torrance with no or many lobes,
measured files missing, empty, corrupt or a folder), odd scene settings and cameras, then the
operators, the live session, the gloss readings, frame changes and a save and reload, in random
order.

What counts as found: an operator failing with a Python traceback (an error of the add-on's own,
not a report), an exception escaping a property's getter or update or a handler (Blender prints
them; here sys.excepthook records them), an exception from the live session's tick (it keeps
set-up errors in last_error) or a glossmeter reading, colours written that are not finite and
non-negative, a slow iteration, or a crash of the process (the test runs this in a subprocess).
Iteration i draws from its own generator seeded with (seed, i), so a finding is replayed alone
with --only i.

    .venv/bin/python tests/fuzz/addon_scenes.py --seed 0 --iterations 300 [--json out.json]
    .venv/bin/python tests/fuzz/addon_scenes.py --seed 0 --only 12          # replay one iteration, verbosely
"""
import collections
import glob
import math
import os
import sys
import tempfile
import time
import traceback

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.append(ROOT)  # after PYTHONPATH: scripts/sanitize_tests.sh puts its sanitized wenv there
import bpy  # noqa: E402

import addon  # noqa: E402
from addon import engine, live, meshes, ui, world  # noqa: E402
from tests.helpers import merl_files  # noqa: E402
from draws import Draws, arguments, report  # noqa: E402  (tests/fuzz, the script's folder)

HDRIS = sorted(glob.glob(os.path.join(bpy.utils.system_resource("DATAFILES", path="studiolights/world"), "*.exr")))
# Principled inputs a user sets, and values from ordinary to absurd (Blender clamps to the sockets' limits)
PRINCIPLED = ("Base Color", "Metallic", "Roughness", "IOR", "Alpha", "Specular IOR Level", "Specular Tint",
              "Anisotropic", "Coat Weight", "Coat Roughness", "Coat IOR", "Coat Tint", "Sheen Weight",
              "Sheen Roughness", "Sheen Tint", "Subsurface Weight", "Transmission Weight", "Emission Color",
              "Emission Strength", "Thin Film Thickness")
NUMBERS = (0.0, 1.0, -1.0, 0.5, 0.2, 0.05, 1e-6, 2.0, 1e6, 1e30, -1e30, math.nan, math.inf, -math.inf, 1e-30)


class Found(Exception):
    pass


class FakeLayout:
    """Stands in for Blender's UILayout, which only a drawn region has (none in background mode): every
    call and attribute is taken, so that a panel's own code runs as Blender would run it."""

    def __getattr__(self, name):
        return self._take

    def __setattr__(self, name, value):
        pass

    def _take(self, *args, **kwargs):
        return self


class FakePanel:
    layout = FakeLayout()


class AddonFuzzer(Draws):
    # ---- values ------------------------------------------------------------------------------

    def number(self, ordinary=0.5, p=0.3):
        return float(self.pick(NUMBERS)) if self.chance(p) else ordinary * float(self.r.uniform(0.0, 2.0))

    def colour(self, p=0.2):
        return tuple(self.number(0.5, p) for _ in range(3))

    def log(self, what):
        self.counts[what] += 1
        if self.verbose:
            print("  " + what, flush=True)

    def assign(self, owner, name, value):
        """A property set as a script would: Blender refuses some values (TypeError, ValueError,
        OverflowError) and clamps the rest; either is fine."""
        if self.verbose:
            print(f"  {getattr(owner, 'name', type(owner).__name__)}.{name} = {value!r}", flush=True)
        try:
            setattr(owner, name, value)
        except (TypeError, ValueError, OverflowError):
            self.log("property refused")

    # ---- the World ---------------------------------------------------------------------------
    def image(self, odd):
        """A World image: Blender's HDRIs or a small generated one, or (odd) odd pixels or files."""
        k = int(self.r.integers(2, 5)) if odd else int(self.r.integers(2))
        if k == 0:
            return bpy.data.images.load(self.pick(HDRIS), check_existing=True)
        if k <= 2:  # generated; odd pixels among ordinary ones
            w, h = int(self.pick([1, 2, 3, 8, 33, 64])), int(self.pick([1, 2, 4, 16, 32]))
            img = bpy.data.images.new("sky", w, h, alpha=True, float_buffer=self.chance(0.7))
            if self.chance(0.2):  # before the pixels: a generated image is made again when it changes
                spaces = img.colorspace_settings.bl_rna.properties["name"].enum_items
                self.assign(img.colorspace_settings, "name", self.pick([i.identifier for i in spaces]))
            px = self.r.lognormal(-1.0, 1.5, size=(h, w, 4)).astype(np.float32)
            px[..., 3] = 1.0
            if k == 2:
                px.reshape(-1)[self.r.integers(px.size, size=3)] = self.pick([math.nan, math.inf, -5.0, 1e38, 0.0])
                if self.chance(0.2):
                    px[...] = 0.0
            img.pixels.foreach_set(px.reshape(-1))
            if self.chance(0.2):
                img.pack()
            return img
        path = os.path.join(self.tmp, f"sky{int(self.r.integers(1000))}." + self.pick(["exr", "hdr", "png"]))
        # (Not an EXR cut short: Blender's own reader crashes on some -- city.exr's first 81,628
        # bytes -- before the add-on sees a pixel; wenv's reader refuses them, tests/fuzz/fuzz_exr.c.)
        if k == 3:
            path = "/nonexistent/sky.exr"
        else:
            with open(path, "wb") as f:
                f.write(self.r.bytes(int(self.pick([0, 10, 4000]))))
        if self.verbose:
            print(f"  World image file {path} ({os.path.getsize(path) if os.path.exists(path) else 'missing'} bytes)")
        return bpy.data.images.load(path, check_existing=False)

    def world(self, scene):
        """Mostly a World the add-on shades (so that the shading itself is reached), else one of
        every odd kind."""
        k = int(self.r.integers(20))
        if k == 0:
            scene.world = None
            return
        if scene.world is None or self.chance(0.1):
            scene.world = bpy.data.worlds.new("World")
        world = scene.world
        if world.node_tree is None:
            world.use_nodes = True
        tree = world.node_tree
        bg = tree.nodes.get("Background")
        if bg is None:
            return
        self.assign(bg.inputs["Strength"], "default_value", self.number(1.0, 0.1))
        if k <= 3:
            self.assign(bg.inputs["Color"], "default_value", (*self.colour(0.1), 1.0))
            return
        tex = tree.nodes.new("ShaderNodeTexEnvironment")
        tree.links.new(tex.outputs["Color"], bg.inputs["Color"])
        tex.projection = "MIRROR_BALL" if self.chance(0.2) else "EQUIRECTANGULAR"
        if k > 4:
            try:
                tex.image = self.image(odd=k >= 17)
            except RuntimeError:  # Blender itself refuses the file
                self.log("image refused")
        if self.chance(0.2):
            mapping = tree.nodes.new("ShaderNodeMapping")
            coords = tree.nodes.new("ShaderNodeTexCoord")
            output = "Generated" if self.chance(0.8) else self.pick(["Object", "Normal"])
            tree.links.new(coords.outputs[output], mapping.inputs["Vector"])
            tree.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
            rot = [0.0, 0.0, self.number(1.0, 0.2)]
            if self.chance(0.1):
                rot[int(self.r.integers(2))] = self.number(0.5)
            self.assign(mapping.inputs["Rotation"], "default_value", rot)
            if self.chance(0.1):
                self.assign(mapping.inputs["Scale"], "default_value", self.colour(0.5))
        if self.chance(0.05):
            other = tree.nodes.new(self.pick(["ShaderNodeTexSky", "ShaderNodeValue", "ShaderNodeTexNoise"]))
            tree.links.new(other.outputs[0], bg.inputs[self.pick(["Color", "Strength"])])

    # ---- meshes and materials ----------------------------------------------------------------
    def odd_mesh(self):
        mesh = bpy.data.meshes.new("odd")
        k = int(self.r.integers(4))
        if k == 0:
            return mesh  # empty
        verts = self.r.normal(size=(int(self.pick([1, 3, 4, 12])), 3)).tolist()
        if k == 1:  # loose vertices and edges, no faces
            mesh.from_pydata(verts, [(0, i) for i in range(1, len(verts))], [])
        else:
            faces = [(0, i, i + 1) for i in range(1, len(verts) - 1)]
            if k == 3 and verts:
                verts[0] = self.pick([[math.nan, 0.0, 0.0], [math.inf, 1.0, 0.0], verts[-1]])  # NaN or repeated
            mesh.from_pydata(verts, [], faces)
        mesh.update()
        return mesh

    def mesh_object(self, scene):
        k = int(self.r.integers(8))
        if k < 5:
            op = self.pick([bpy.ops.mesh.primitive_cube_add, bpy.ops.mesh.primitive_monkey_add,
                            bpy.ops.mesh.primitive_plane_add, bpy.ops.mesh.primitive_ico_sphere_add])
            op(location=tuple(self.r.normal(size=3)))
            obj = bpy.context.object
        elif k < 7:
            obj = bpy.data.objects.new("odd", self.odd_mesh())
            scene.collection.objects.link(obj)
        else:
            obj = bpy.data.objects.new("empty", None) if self.chance(0.5) else None
            if obj is None:
                bpy.ops.object.text_add()
                return bpy.context.object
            sources = [o for o in scene.objects if o.type in ("MESH", "FONT")]
            if sources and self.chance(0.5):  # a collection instance of another object's data
                held = bpy.data.collections.new("held")
                src = self.pick(sources)
                held.objects.link(bpy.data.objects.new("held", src.data))
                obj.instance_type, obj.instance_collection = "COLLECTION", held
            scene.collection.objects.link(obj)
            return obj
        if self.chance(0.2):
            self.assign(obj, "scale", self.pick([(0, 0, 0), (-1, 1, 1), (1e-6,) * 3, (1e6,) * 3, (1, 1, 0)]))
        if self.chance(0.3) and obj.data.polygons:
            (obj.data.shade_smooth if self.chance(0.5) else obj.data.shade_flat)()
        if self.chance(0.2) and obj.data.loops:
            normals = self.r.normal(size=(len(obj.data.loops), 3))
            if self.chance(0.3):
                normals[0] = 0.0
            try:
                obj.data.normals_split_custom_set(normals.tolist())
            except RuntimeError:
                self.log("custom normals refused")
        if self.chance(0.3):
            kind = self.pick(["SUBSURF", "DECIMATE", "DISPLACE", "ARRAY", "SOLIDIFY"])
            mod = obj.modifiers.new("mod", kind)
            if kind == "DECIMATE":
                mod.ratio = float(self.r.uniform(0.0, 1.0))
            elif kind == "DISPLACE":
                self.assign(mod, "strength", self.number(0.3))
        return obj

    def merl_file(self):
        k = int(self.r.integers(6))
        path = os.path.join(self.tmp, f"brdf{int(self.r.integers(1000))}.binary")
        if k == 0:
            return self.pick(["/nonexistent/x.binary", "//relative.binary", self.tmp, ""])
        if k in (1, 5):
            table = merl_files.tabulate(merl_files.cook_torrance(float(self.r.uniform(0.05, 0.5))), 8, 8, 16)
            merl_files.write_merl(path, table)
        else:
            with open(path, "wb") as f:
                f.write(self.r.bytes(int(self.pick([0, 12, 3000]))) if k == 2 else
                        np.array([4, 4, 8], np.int32).tobytes() + self.r.bytes(8 * 3 * 128))
        return path

    def material(self):
        mat = bpy.data.materials.new("m")
        st = mat.wenv
        model = self.pick(["PRINCIPLED", "PRINCIPLED", "COOK_TORRANCE", "LAMBERT", "MEASURED"])
        nodes = mat.node_tree.nodes if mat.node_tree else None
        node = nodes.get("Principled BSDF") if nodes else None
        if model == "PRINCIPLED" and node is not None:
            for name in PRINCIPLED:
                if name in node.inputs and self.chance(0.3):
                    value = node.inputs[name].default_value
                    self.assign(node.inputs[name], "default_value",
                                (*self.colour(), 1.0) if hasattr(value, "__len__") else self.number(0.5))
            if self.chance(0.1):
                tex = nodes.new(self.pick(["ShaderNodeTexNoise", "ShaderNodeValue"]))
                mat.node_tree.links.new(tex.outputs[0], node.inputs[self.pick(["Base Color", "Roughness", "Normal"])])
            if self.chance(0.1):
                node.distribution = self.pick(["GGX", "MULTI_GGX"])
            if self.chance(0.1):
                nodes.remove(node)
        self.assign(st, "model", model)
        if model in ("COOK_TORRANCE", "LAMBERT"):
            self.assign(st, "diffuse", self.colour())
            for _ in range(int(self.pick([0, 1, 1, 2, 3]))):
                lobe = st.lobes.add()
                self.assign(lobe, "alpha", self.number(0.2, 0.3))
                self.assign(lobe, "ior", self.number(1.5, 0.3))
                self.assign(lobe, "specular", self.colour())
                self.assign(lobe, "distribution", self.pick(["GGX", "BECKMANN"]))
            self.assign(st, "shadowing", self.pick(["SMITH", "V_CAVITY"]))
            st.initialized = True
        elif model == "MEASURED":
            self.assign(st, "brdf_path", self.merl_file())
        return mat

    def scene_settings(self, scene):
        st = scene.wenv
        self.assign(st, "quality", self.pick([i.identifier for i in st.bl_rna.properties["quality"].enum_items]))
        if st.quality == "HIGH" and self.chance(0.7):
            st.quality = "DRAFT"  # high's slices cost seconds per material: seldom
        for name in ("view_source", "tone_mapping"):
            self.assign(st, name, self.pick([i.identifier for i in st.bl_rna.properties[name].enum_items]))
        self.assign(st, "target_error", self.number(1.0, 0.3))
        self.assign(st, "memory_budget", int(self.pick([16, 64, 1024, 65536, -1, 10 ** 9])))
        self.assign(st, "max_luminance", self.number(10.0, 0.3))
        for name in ("shade_only_seen", "refine_at_rest", "preview_changes"):
            self.assign(st, name, self.chance(0.5))
        cam = scene.camera
        if cam is not None:
            if self.chance(0.03):
                scene.camera = None
            elif self.chance(0.5):
                cam.location = tuple(self.r.normal(size=3) * 6)
                cam.rotation_euler = tuple(self.r.uniform(-3, 3, size=3))
                cam.data.type = self.pick(["PERSP", "ORTHO", "PANO"])
                self.assign(cam.data, "lens", self.number(50.0, 0.2))

    def build(self):
        bpy.ops.wm.read_homefile(use_factory_startup=True)
        scene = bpy.context.scene
        self.scene_settings(scene)
        self.world(scene)
        objs = [self.mesh_object(scene) for _ in range(int(self.pick([1, 1, 2, 3])))]
        for obj in objs:
            if obj.type == "MESH":
                for _ in range(int(self.pick([0, 1, 1, 2]))):
                    obj.data.materials.append(self.material() if self.chance(0.9) else None)
                if len(obj.data.materials) > 1 and obj.data.polygons:
                    slots = self.r.integers(len(obj.data.materials), size=len(obj.data.polygons))
                    obj.data.polygons.foreach_set("material_index", slots.astype(np.int32))
        for o in bpy.context.view_layer.objects:
            o.select_set(self.chance(0.8))
        bpy.context.view_layer.objects.active = self.pick(objs)
        return scene, objs

    # ---- use ---------------------------------------------------------------------------------
    def op(self, name, **kw):
        """An operator: it finishes, is cancelled, or fails with a report -- never a traceback."""
        fn = getattr(bpy.ops.wenv, name)
        try:
            result = fn(**kw)
        except RuntimeError as exc:
            if "Traceback" in str(exc):
                raise Found(f"bpy.ops.wenv.{name}({kw}) failed with a Python error:\n{exc}") from None
            self.log(f"{name} reported: {str(exc).splitlines()[0][7:67]}")
            return False
        self.log(f"{name} {sorted(result)[0]}")
        return "FINISHED" in result

    def check_colours(self, objs):
        for obj in objs:
            if obj.type != "MESH" or meshes.ATTRIBUTE not in obj.data.color_attributes:
                continue
            attr = obj.data.color_attributes[meshes.ATTRIBUTE]
            rgba = np.empty(len(attr.data) * 4, np.float32)
            attr.data.foreach_get("color", rgba)
            if not (np.isfinite(rgba).all() and (rgba >= 0).all()):
                bad = rgba[~(np.isfinite(rgba) & (rgba >= 0))][:4]
                raise Found(f"'{obj.name}' was written colours that are not finite and non-negative: {bad}")

    def live(self, objs):
        names = [o.name for o in objs if o.type == "MESH"]
        session = live.LiveSession(names)
        try:
            for _ in range(int(self.pick([1, 2, 4]))):
                for _ in range(4):  # the pass, then what follows it while the view rests
                    session.tick(bpy.context)
                    if not session.wait(self.slow):
                        raise Found("the live session's worker did not finish")
                if session.last_error is not None and not isinstance(session.last_error, str):
                    raise Found(f"last_error is {session.last_error!r}")
                self.log(f"live error: {session.last_error[:60]}" if session.last_error else "live ok")
                if self.chance(0.5):  # something changes between ticks
                    mats = [m for m in bpy.data.materials if m.users]
                    if mats:
                        self.material_edit(self.pick(mats))
        finally:
            session.stop()

    def material_edit(self, mat):
        node = mat.node_tree.nodes.get("Principled BSDF") if mat.node_tree else None
        if node is not None and self.chance(0.5):
            self.assign(node.inputs["Roughness"], "default_value", self.number(0.3, 0.3))
        elif mat.wenv.lobes:
            self.assign(mat.wenv.lobes[0], "roughness", self.number(0.3, 0.3))
        else:
            self.assign(mat.wenv, "model", self.pick(["PRINCIPLED", "COOK_TORRANCE", "LAMBERT"]))

    def act(self, scene, objs):
        k = int(self.r.integers(14))
        if k <= 3:
            kw = {"view": self.pick(["CAMERA", "CAMERA", "SCENE", "VIEWPORT", "MATRIX"])}
            if kw["view"] == "MATRIX":
                m = self.pick([np.eye(4), self.r.normal(size=(4, 4)), np.zeros((4, 4)), np.full((4, 4), np.nan)])
                kw["view_matrix"] = [tuple(float(x) for x in row) for row in m]
                kw["perspective"] = self.chance(0.5)
            if self.chance(0.2):
                kw["target"] = "SHADED"
            self.op("shade", **kw)
            self.check_colours(objs)
        elif k == 4:
            self.live(objs)
            self.check_colours(objs)
        elif k == 5:
            self.op("clear")
        elif k == 6:
            self.op(self.pick(["from_principled", "lobe_add", "lobe_remove", "precompute"]))
            obj = bpy.context.object
            if obj is not None and obj.type == "MESH" and self.chance(0.3):  # a shade while a mesh is edited
                bpy.ops.object.mode_set(mode="EDIT")
                self.op("shade", view="CAMERA")
                bpy.ops.object.mode_set(mode="OBJECT")
                self.log("edit mode")
        elif k == 7:
            self.op("fit_roughness", target=self.pick([50.0, 0.0, 1e6, 95.0, 5.0, math.nan]),
                    geometry=self.pick(["20", "60", "85"]))
        elif k == 8:
            for mat in bpy.data.materials:
                for name in ("gloss_20", "gloss_60", "gloss_85", "haze"):
                    value = getattr(mat.wenv, name)
                    if not isinstance(value, float):
                        raise Found(f"{mat.name}.wenv.{name} is {value!r}")
            self.log("gloss read")
        elif k == 9:
            scene.wenv.shade_on_frame_change = True
            scene.frame_set(int(self.r.integers(1, 250)))
            self.log("frame change")
            self.check_colours(objs)
        elif k == 10:
            path = os.path.join(self.tmp, "fuzz.blend")
            bpy.ops.wm.save_as_mainfile(filepath=path, check_existing=False)
            bpy.ops.wm.open_mainfile(filepath=path)
            self.log("saved and reloaded")
            return False  # the objects are new Python objects now
        elif k == 11:
            self.edit(scene)
        elif k == 13:
            self.draw_panels()
        else:  # an edit undone, and perhaps redone (handlers.undo_post re-reads what was shaded)
            bpy.ops.ed.undo_push(message="before")
            self.edit(scene)
            self.op("shade", view="CAMERA")
            bpy.ops.ed.undo_push(message="after")
            bpy.ops.ed.undo()
            if self.chance(0.5):
                bpy.ops.ed.redo()
            self.check_colours(list(bpy.context.scene.objects))
            self.log("undo")
            return False  # the data are undo's copies now
        return True

    def draw_panels(self):
        """The sidebar's panels drawn for the active object (an exception in a draw is Blender's
        "Python: Traceback" in the panel)."""
        try:
            for cls in ui.classes:
                if issubclass(cls, bpy.types.Panel) and (not hasattr(cls, "poll") or cls.poll(bpy.context)):
                    cls.draw(FakePanel(), bpy.context)
            obj = bpy.context.object
            mat = obj.active_material if obj is not None else None
            for i, lobe in enumerate(mat.wenv.lobes if mat is not None else ()):
                ui.WENV_UL_lobes.draw_item(None, bpy.context, FakeLayout(), mat.wenv, lobe, 0, mat.wenv,
                                           "active_lobe", i)
        except Exception:
            raise Found("a panel's draw failed:\n" + traceback.format_exc()) from None
        self.log("panels drawn")

    def edit(self, scene):
        mats = [m for m in bpy.data.materials if m.users]
        if mats:
            self.material_edit(self.pick(mats))
        if self.chance(0.3):
            self.world(scene)
        else:
            self.scene_settings(scene)

    def iteration(self):
        scene, objs = self.build()
        for _ in range(int(self.r.integers(1, 7))):
            if not self.act(scene, objs):
                scene = bpy.context.scene
                objs = list(scene.objects)


def run(seed, iterations, only=None, slow=60.0, verbose=False):
    """Runs the iterations; returns (summary dict, finding or None)."""
    hooked = []
    sys.excepthook = lambda kind, value, tb: hooked.append("".join(traceback.format_exception(kind, value, tb)))
    addon.register()
    # a World other than an image is rendered by Cycles in a process of its own: small here, since
    # the run shades many such Worlds and asks only that they shade (tests/test_addon.py holds the
    # render's truth)
    world.RENDER_WIDTH, world.RENDER_SAMPLES = 64, 2
    counts = collections.Counter()
    t0 = time.perf_counter()
    finding = None
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["WENV_CACHE_DIR"] = os.path.join(tmp, "cache")
        for i in ([only] if only is not None else range(iterations)):
            fuzzer = AddonFuzzer(np.random.default_rng([seed, i]), tmp, slow, verbose)
            print(f"[iteration {i}]", flush=True)  # the last one printed names a crash's
            start, cpu = time.perf_counter(), time.process_time()
            try:
                fuzzer.iteration()
                if hooked:
                    raise Found("an exception in a property's getter or update, or in a handler:\n" + hooked[0])
                took = time.process_time() - cpu
                if took > slow * 2 or time.perf_counter() - start > 6 * slow:
                    raise Found(f"iteration took {took:.1f} s of CPU")
            except Found as e:
                finding = {"iteration": i, "seed": seed, "what": str(e)}
            except Exception as e:  # raised by the fuzzer's own use of bpy: shown, so it can be told apart
                finding = {"iteration": i, "seed": seed, "what": "".join(traceback.format_exception(e))}
            counts += fuzzer.counts
            if finding:
                break
        live.LiveState.reset()
        engine.shaders.clear()
    n = (finding["iteration"] if finding else iterations) if only is None else 1
    return {"iterations": n, "seconds": time.perf_counter() - t0, "counts": dict(counts)}, finding


def main():
    args = arguments(__doc__, 300, 60.0, "an iteration taking more than twice this many seconds of CPU (or six "
                     "times it of wall-clock time) is a finding")
    report(args, *run(args.seed, args.iterations, args.only, args.slow, verbose=args.only is not None))


if __name__ == "__main__":
    main()
