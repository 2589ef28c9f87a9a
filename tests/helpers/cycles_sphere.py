"""Cycles (through bpy) rendering an unoccluded sphere under a bundled HDRI, and what wenv needs to shade
the same pixels: the test of wenv.Principled against Cycles (tests/test_principled.py) and the full
grid (benchmarks/principled_vs_cycles.py) read it.

The scene: a smooth UV sphere (256 x 128) of radius 1 at the origin, an orthographic camera on -Y
looking along +Y that frames it, the World an Environment Texture of the HDRI with "Closest"
interpolation (the piecewise-constant pixels wenv.reference integrates; Blender's default "Linear"
blurs the lighting by about a pixel, which lobes a few pixels wide reflecting the sunset's sun of a
few pixels tell apart by a few per cent at the highlight), no denoising, no adaptive
sampling, a pixel filter 0.01 pixels wide (every sample at the pixel's centre, so a pixel is one
(normal, view) pair), "Standard" view transform, 32-bit EXR output (scene-linear, as wenv's
radiance).  The sphere is convex, so every ray that leaves it sees the World: one bounce is exact.

Each pixel's normal is Cycles' own shading normal, rendered as the colour of an emission shader
(Geometry > Normal), and the view is -Y (towards the camera).

With `ground`, a square under the sphere touching it shadows its lower half (seen edge-on, it covers
no pixel of its own): each pixel's position is rendered as well (Geometry > Position), and Cycles
with Max Bounces 0 (direct light through every shadow ray) is compared with wenv.reference casting
every pixel's ray against the same triangles.  `image` (float32 (H, W, 3), row 0 the top) lights
the scene instead of a bundled HDRI: a small one keeps that reference fast."""
import math
import os
import tempfile

import numpy as np
import wenv

from tests.helpers.measure import bundled_hdri
from tests.helpers.blender_versions import node_material, use_world_nodes

# Principled BSDF node inputs by wenv.Principled's names: the core's one list of them
SOCKETS = {row["name"]: row["socket"] for row in wenv.Principled.INPUTS}


def halved_hdri(name):
    """A bundled HDRI at half its width and height, each pixel the mean of the four it covers (row 0
    the top, as SphereScene's `image`): the same sky with a quarter of the pixels, for tests whose
    reference sums over every one of them."""
    px = wenv.load_environment(bundled_hdri(name)).pixels
    h, w = px.shape[0] // 2 * 2, px.shape[1] // 2 * 2
    return np.ascontiguousarray(px[:h, :w].reshape(h // 2, 2, w // 2, 2, 3).mean(axis=(1, 3)), np.float32)


class SphereScene:
    """The scene above, built in the current bpy session (it replaces whatever is loaded)."""

    def __init__(self, hdri="sunset", size=64, samples=256, image=None, ground=False):
        import bpy
        self.bpy = bpy
        self.hdri = hdri
        self.image = image
        bpy.ops.wm.read_factory_settings(use_empty=True)
        sc = bpy.context.scene
        self.scene = sc
        sc.render.engine = "CYCLES"
        sc.cycles.device = "CPU"
        sc.cycles.samples = samples
        sc.cycles.use_denoising = False
        sc.cycles.use_adaptive_sampling = False
        sc.cycles.filter_width = 0.01
        sc.render.resolution_x = sc.render.resolution_y = size
        sc.render.resolution_percentage = 100
        sc.view_settings.view_transform = "Standard"
        sc.view_settings.look = "None"
        sc.view_settings.exposure = 0.0
        sc.view_settings.gamma = 1.0
        sc.render.image_settings.file_format = "OPEN_EXR"
        sc.render.image_settings.color_depth = "32"
        world = bpy.data.worlds.new("wenv-cycles")
        sc.world = world
        use_world_nodes(self.bpy, world)
        nt = world.node_tree
        env = nt.nodes.new("ShaderNodeTexEnvironment")
        if image is None:
            env.image = bpy.data.images.load(bundled_hdri(hdri))
        else:
            h, w = image.shape[:2]
            img = bpy.data.images.new("wenv-sky", w, h, float_buffer=True)
            rgba = np.ones((h, w, 4), np.float32)
            rgba[..., :3] = image[::-1]  # Blender's rows start at the bottom
            img.pixels.foreach_set(rgba.ravel())
            img.pack()
            env.image = img
        env.interpolation = "Closest"
        nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
        bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=1.0)
        self.sphere = bpy.context.active_object
        self.sphere.data.shade_smooth()
        self.ground = None
        if ground:
            bpy.ops.mesh.primitive_plane_add(size=6.0, location=(0.0, 0.0, -1.0))
            self.ground = bpy.context.active_object
        cam_data = bpy.data.cameras.new("wenv-cycles")
        cam_data.type = "ORTHO"
        cam_data.ortho_scale = 2.1
        cam = bpy.data.objects.new("wenv-cycles", cam_data)
        sc.collection.objects.link(cam)
        sc.camera = cam
        cam.location = (0.0, -5.0, 0.0)
        cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
        self.folder = tempfile.mkdtemp(prefix="wenv-cycles-")
        self._use(self._geometry_material("Normal"))
        normals = self.render(seed=0)
        self.mask = np.abs(np.linalg.norm(normals, axis=2) - 1.0) < 1e-3
        if ground:
            self._use(self._geometry_material("Position"))
            positions = self.render(seed=0)
            self.mask &= np.abs(np.linalg.norm(positions, axis=2) - 1.0) < 2e-2  # the sphere's pixels
            self.positions = np.ascontiguousarray(positions[self.mask], np.float32)
        self.normals = np.ascontiguousarray(normals[self.mask], np.float32)
        self.views = np.tile(np.float32([0.0, -1.0, 0.0]), (len(self.normals), 1))

    def add_light(self, kind, name, location, rotation=(0.0, 0.0, 0.0), **settings):
        """A Light object of `kind` with these Light settings (Blender's names), placed and turned."""
        data = self.bpy.data.lights.new(name, kind)
        for key, value in settings.items():
            setattr(data, key, value)
        obj = self.bpy.data.objects.new(name, data)
        self.scene.collection.objects.link(obj)
        obj.location, obj.rotation_euler = location, rotation
        return obj

    def _use(self, material):
        self.sphere.data.materials.clear()
        self.sphere.data.materials.append(material)

    def _geometry_material(self, output):
        """An emission shader whose colour is the shading point's Geometry `output` (Normal, Position)."""
        mat = node_material(self.bpy, "wenv-" + output.lower())
        nt = mat.node_tree
        for n in list(nt.nodes):
            if n.bl_idname != "ShaderNodeOutputMaterial":
                nt.nodes.remove(n)
        geo, em = nt.nodes.new("ShaderNodeNewGeometry"), nt.nodes.new("ShaderNodeEmission")
        nt.links.new(geo.outputs[output], em.inputs["Color"])
        nt.links.new(em.outputs["Emission"], nt.nodes["Material Output"].inputs["Surface"])
        return mat

    def principled(self, **inputs):
        """Gives the sphere a Principled BSDF with these inputs (wenv.Principled's names; the
        distribution keyword sets the node's distribution)."""
        mat = node_material(self.bpy, "wenv-principled")
        node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
        for key, value in inputs.items():
            if key == "distribution":
                node.distribution = {"ggx": "GGX", "multiscatter_ggx": "MULTI_GGX"}[value]
                continue
            socket = node.inputs[SOCKETS[key]]
            if isinstance(value, (tuple, list)) and len(socket.default_value) == 4:
                value = tuple(value) + (1.0,)
            socket.default_value = value
        self._use(mat)

    def render(self, seed=0):
        """The sphere's pixels, float32 (size, size, 3), row 0 the top."""
        bpy, sc = self.bpy, self.scene
        sc.cycles.seed = seed
        path = os.path.join(self.folder, f"render_{seed}.exr")
        sc.render.filepath = path
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(path)
        px = np.array(img.pixels[:], np.float32).reshape(img.size[1], img.size[0], 4)[::-1, :, :3]
        bpy.data.images.remove(img)
        os.remove(path)
        return px

    def occluders(self):
        """The sphere and the ground as Cycles holds them (world space), a wenv.Occluders."""
        parts, base = [], 0
        for obj in (self.sphere, self.ground):
            me = obj.data
            me.calc_loop_triangles()
            p = np.empty(len(me.vertices) * 3, np.float32)
            me.vertices.foreach_get("co", p)
            p = p.reshape(-1, 3) + np.float32(obj.location)
            t = np.empty(len(me.loop_triangles) * 3, np.int64)
            me.loop_triangles.foreach_get("vertices", t)
            parts.append((p, t.reshape(-1, 3) + base))
            base += len(p)
        return wenv.Occluders(np.vstack([p for p, _ in parts]), np.vstack([t for _, t in parts]))

    def environment(self):
        """The World's lighting as wenv reads it: `image`, or the bundled HDRI."""
        return wenv.Environment(self.image) if self.image is not None else wenv.load_environment(bundled_hdri(self.hdri))

    def compare_shadowed(self, material, seeds=(1, 2)):
        """With the ground: Cycles with Max Bounces 0 (two seeds) against wenv.reference casting every
        pixel's ray against the sphere and the ground; as compare()."""
        env = self.environment()
        self.scene.cycles.max_bounces = 0
        a, b = (self.render(seed)[self.mask].astype(np.float64) for seed in seeds)
        ref = wenv.reference(env, material, self.normals, self.views, positions=self.positions,
                             occluders=self.occluders()).astype(np.float64)
        scale = math.sqrt(float(np.mean(ref ** 2)))
        noise = math.sqrt(float(np.mean((a - b) ** 2)) / 2) / scale
        error = math.sqrt(float(np.mean(((a + b) / 2 - ref) ** 2))) / scale
        return {"noise": noise, "noise_of_mean": noise / math.sqrt(2), "error": error, "cycles": (a + b) / 2,
                "reference": ref}

    def compare(self, material, seeds=(1, 2)):
        """Cycles' render of the sphere (two seeds) against wenv.reference of `material` on the same
        pixels: {'noise': one render's relative RMSE from the other's (/ sqrt 2), 'error': the two
        renders' mean against the reference, 'noise_of_mean': what the mean's own noise adds,
        'ratio': mean radiance per channel, Cycles over wenv}."""
        env = self.environment()
        a, b = (self.render(seed)[self.mask].astype(np.float64) for seed in seeds)
        ref = wenv.reference(env, material, self.normals, self.views).astype(np.float64)
        scale = math.sqrt(float(np.mean(ref ** 2)))
        noise = math.sqrt(float(np.mean((a - b) ** 2)) / 2) / scale
        error = math.sqrt(float(np.mean(((a + b) / 2 - ref) ** 2))) / scale
        return {"noise": noise, "noise_of_mean": noise / math.sqrt(2), "error": error,
                "ratio": ((a + b) / 2).mean(axis=0) / ref.mean(axis=0), "cycles": (a + b) / 2, "reference": ref}


# Light objects set up in a SphereScene (tests/test_lamps_cycles.py, benchmarks/lamps_vs_cycles.py)
LAMP_SETUPS = {
    "four lamps": lambda sc: [
        sc.add_light("SUN", "sun", (0, 0, 5), (0.6, 0.0, 0.9), energy=1.5, angle=0.15),
        sc.add_light("POINT", "point", (-1.6, -2.0, 1.2), energy=150.0, shadow_soft_size=0.3),
        sc.add_light("SPOT", "spot", (1.8, -2.2, 1.8), (1.0, 0.0, 0.7), energy=400.0, shadow_soft_size=0.15,
                     spot_size=0.9, spot_blend=0.4),
        sc.add_light("AREA", "area", (0.0, -1.5, 2.4), (0.6, 0.0, 0.0), energy=120.0, shape="RECTANGLE", size=1.2,
                     size_y=0.6)],
    "close point lamp": lambda sc: [sc.add_light("POINT", "close", (0.6, -1.1, 0.5), energy=20.0,
                                                 shadow_soft_size=0.25)],
    "large area lamp": lambda sc: [sc.add_light("AREA", "large", (0.0, -0.8, 2.2), (0.35, 0.0, 0.0), energy=150.0,
                                                size=3.0)],
}
