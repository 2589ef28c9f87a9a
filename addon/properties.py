"""Settings stored in the .blend: Scene.wenv (shading) and Material.wenv (reflectance model), undone
with the data; each 3D viewport's shading to set back (View3DShading.wenv) and the Show in Viewports
switch (WindowManager.wenv), which belong to the interface and stay out of undo."""
import math

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty, StringProperty)

from . import engine, gloss, materials, shading, views

DISTRIBUTIONS = [("GGX", "GGX", "Trowbridge-Reitz / GGX, alpha = Blender's roughness squared"),
                 ("BECKMANN", "Beckmann", "Beckmann, alpha = RMS microfacet slope")]


def _get_roughness(self):
    return engine.roughness_from_alpha(self.alpha)


def _set_roughness(self, value):
    # the core's one conversion (r^2, floored as Cycles floors it), within what a lobe accepts; a
    # setter cannot refuse, so a NaN a script sets leaves the lobe as it was
    if math.isnan(value):
        return
    alpha = engine.alpha_from_roughness(min(max(value, 0.0), 1e6))
    self.alpha = min(max(alpha, engine.ALPHA_RANGE[0]), engine.ALPHA_RANGE[1])


class WENV_LobeSettings(bpy.types.PropertyGroup):
    specular: FloatVectorProperty(name="Specular", subtype="COLOR", size=3, min=0.0, soft_max=1.0,
                                  default=(1.0, 1.0, 1.0), description="Colour scale of the lobe (times Fresnel)")
    alpha: FloatProperty(name="Alpha", min=engine.ALPHA_RANGE[0], max=engine.ALPHA_RANGE[1],
                         soft_max=1.0, default=0.2, precision=4,
                         description="The distribution's alpha: Beckmann RMS slope or GGX alpha (Blender's "
                                     "Roughness squared)")
    # not stored: Blender's roughness, the alpha above through the core's one conversion
    roughness: FloatProperty(name="Roughness", min=0.0, soft_max=1.0, precision=4, get=_get_roughness,
                             set=_set_roughness,
                             description="Roughness as Blender's BSDF nodes take it (alpha = roughness^2)")
    ior: FloatProperty(name="IOR", min=engine.IOR_MIN, max=engine.IOR_RANGE[1], soft_max=3.0, default=1.5, precision=3,
                       description="Index of refraction of the lobe's Fresnel term")
    distribution: EnumProperty(name="Distribution", items=DISTRIBUTIONS, default="GGX")


def _gloss_getter(geometry):
    def get(self):
        r = gloss.gloss_readings(gloss.reading_key(self.id_data)[0])
        return r[geometry] if isinstance(r, dict) else math.nan
    return get


# Blender 4.5+ warns about "//" paths in a property that does not declare it takes them; older
# versions know no such option (and need none).
_BLEND_RELATIVE = ({"PATH_SUPPORTS_BLEND_RELATIVE"}
                   if "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties else set())


def _set_up_by_user(self, context):
    # A model or file the user chose is the material's set-up: the first shading must not replace it
    # with values from the Principled BSDF.
    self.initialized = True


class WENV_MaterialSettings(bpy.types.PropertyGroup):
    # explicit numbers: what a .blend stores, so items may be added in any order
    model: EnumProperty(name="Model", default="PRINCIPLED", update=_set_up_by_user, items=[
        ("PRINCIPLED", "Principled BSDF", "The material's own Principled BSDF, read from its node at every pass "
                                          "and shaded as Cycles evaluates it", 3),
        ("LAMBERT", "Lambert", "Ideal diffuse reflector", 0),
        ("COOK_TORRANCE", "Cook-Torrance", "Diffuse plus microfacet lobes set here", 1),
        ("MEASURED", "Measured", "A measured isotropic BRDF read from a MERL .binary file", 2)])
    brdf_path: StringProperty(name="BRDF File", subtype="FILE_PATH", default="", update=_set_up_by_user,
                              options=_BLEND_RELATIVE,
                              description="MERL .binary file of a measured BRDF (// at the start: relative to "
                                          "the .blend file)")
    diffuse: FloatVectorProperty(name="Diffuse", subtype="COLOR", size=3, min=0.0, max=1.0,
                                 default=engine.DEFAULT_GREY, description="Lambertian albedo")
    lobes: CollectionProperty(type=WENV_LobeSettings, name="Lobes")
    active_lobe: IntProperty(name="Active Lobe", default=0, min=0)
    shadowing: EnumProperty(name="Shadowing", default="SMITH", items=[
        ("SMITH", "Smith", "Height-correlated Smith shadowing-masking"),
        ("VCAVITY", "V-cavity", "Cook and Torrance's original V-cavity term")])
    initialized: BoolProperty(name="Initialized", default=False,
                              description="Settings were set (otherwise the first shading fills them from "
                                          "the Principled BSDF)")
    # Read-only readings, computed from the settings above when read (memoised), so always current.
    gloss_20: FloatProperty(name="Gloss 20", get=_gloss_getter(20), precision=2,
                            description="Specular gloss at 20 degrees, GU (ISO 2813)")
    gloss_60: FloatProperty(name="Gloss 60", get=_gloss_getter(60), precision=2,
                            description="Specular gloss at 60 degrees, GU (ISO 2813)")
    gloss_85: FloatProperty(name="Gloss 85", get=_gloss_getter(85), precision=2,
                            description="Specular gloss at 85 degrees, GU (ISO 2813)")
    haze: FloatProperty(name="Haze", get=_gloss_getter("haze"), precision=2,
                        description="Reflection haze, HU (ASTM E430 method B, 20 degree instrument)")
    target_gloss: FloatProperty(name="Target Gloss", default=50.0, min=0.0, soft_max=200.0, precision=2,
                                description="Gloss, GU, that 'Set Roughness' aims for")
    target_geometry: EnumProperty(name="Geometry", default="60", items=[
        ("20", "20°", "High-gloss geometry"), ("60", "60°", "Universal geometry"),
        ("85", "85°", "Low-gloss (sheen) geometry")])


# What each preset is for, in a Blender user's terms (roughness as the Principled BSDF's: alpha = r^2);
# docs/performance.md, "Speed against accuracy" and "Interactive rates".
QUALITY_NOTES = {
    "draft": "fastest, coarse (rotation matrices, 29 MB, built once)",
    "default": "interactive: within 3 % of the reference from roughness 0.45 up, ~30 ms per view of 126k vertices",
    "high": "within 1 % of the reference from roughness 0.32 up, ~0.1 s per view of 126k vertices",
}


def _quality_items():
    """The core's presets (engine.QUALITIES, cheapest first) as enum items, then Auto; identifiers
    are the names upper-cased (engine.quality_value turns them back)."""
    items = []
    for name in engine.QUALITIES:
        q = engine.QUALITY_PRESETS[name]
        text = f"{q['global']}x{q['global']} lighting map, {q['local']}x{q['local']} slices"
        note = QUALITY_NOTES.get(name)
        items.append((name.upper(), name.title(), f"{text}: {note}" if note else text))
    items.append((engine.AUTO.upper(), engine.AUTO.title(),
                  "The cheapest setting predicted to meet the target error for this World, material "
                  "and mesh (no matrices to precompute)"))
    return items


class WENV_SceneSettings(bpy.types.PropertyGroup):
    quality: EnumProperty(name="Quality", default="DEFAULT", items=_quality_items())
    target_error: FloatProperty(name="Target Error", default=1.0, min=0.1, max=50.0, subtype="PERCENTAGE",
                                description="Relative RMSE against the brute-force reference that Auto aims for")
    memory_budget: IntProperty(name="Memory Budget", default=1024, min=16, max=65536,
                               description="Largest memory, in MB, Auto may give one material's shader")
    view_source: EnumProperty(name="View", default="VIEWPORT", items=[
        ("VIEWPORT", "Viewport", "The active 3D viewport's view (perspective or orthographic)"),
        ("CAMERA", "Camera", "The scene camera")])
    tone_mapping: EnumProperty(name="Tone Mapping", default="NONE", items=[
        ("NONE", "None", "Write linear radiance"),
        ("LOG", "Logarithmic", "The thesis's global operator log(1 + L) / log(1 + Lmax), values in [0, 1]")])
    max_luminance: FloatProperty(name="Max Luminance", default=10.0, min=1e-3, soft_max=1000.0,
                                 description="Luminance that maps to white in logarithmic tone mapping")
    shade_only_seen: BoolProperty(name="Shade Only What Is Seen", default=True,
                                  description="From a viewport, shade only the vertices facing it and on screen; "
                                              "the rest keep their colours (camera views, renders and bakes always "
                                              "shade every vertex)")
    refine_at_rest: BoolProperty(name="Refine at Rest", default=True,
                                 description="In live mode at Draft or Default, while the view, World and "
                                             "materials stay still, refine the colours in the background to "
                                             "High (within 1 % of the reference for roughness 0.1 and up); any "
                                             "change shows the quality set at once and drops the refinement")
    shadows: BoolProperty(name="Shadows", default=True,
                          description="The scene's meshes block each vertex's sky and lamps (rays cast once per "
                                      "mesh state).  A convex mesh alone is shaded as without: it blocks nothing")
    bounce_light: BoolProperty(name="Bounce Light", default=True,
                               description="With Shadows, what a mesh blocks sends back its diffuse light (the "
                                           "first bounce, which fills creases as Cycles' bounces do); off, the "
                                           "blocked directions are black, as Cycles with Max Bounces 0")
    glossy_bounce: BoolProperty(name="Glossy Bounce", default=False,
                                description="With Bounce Light, what a mesh blocks sends back its whole light "
                                            "towards each vertex it blocks, its glossy part included (a metal's "
                                            "mirror image of its surroundings), and light bounces twice: each "
                                            "blocking mesh is shaded at 8 x 8 directions per vertex, twice, per "
                                            "change of lighting, material or mesh (seconds for 30,000 vertices); "
                                            "off, its albedo is sent as if diffuse")
    preview_changes: BoolProperty(name="Draft While Remaking", default=True,
                                  description="In live mode at Default, High or Auto, a change that makes the "
                                              "setting remake its slices (a new World image, a material edit) "
                                              "shows Draft at once (~20 ms for 126k vertices), then the setting "
                                              "itself once it is made (~0.3 s for an image, ~0.7 s for a "
                                              "material at Default); a World rotation or strength and a view "
                                              "change need no remaking")
    shade_on_frame_change: BoolProperty(name="Shade on Frame Change", default=False,
                                        description="Re-shade the shaded objects from the scene camera on every "
                                                    "frame change (animation playback and rendering)")
    bake_image: PointerProperty(name="Bake Image", type=bpy.types.Image,
                                description="The image Bake writes into (none: a new one of Bake Resolution)")
    bake_resolution: IntProperty(name="Bake Resolution", default=1024, min=1, max=65536,
                                 description="Side in texels of the image Bake makes when no Bake Image is set")
    bake_float: BoolProperty(name="32-bit Float", default=True,
                             description="The image Bake makes holds linear floats (radiance above 1 kept); off: "
                                         "bytes in sRGB, clipped at 1")
    bake_margin: IntProperty(name="Margin", default=16, min=0, max=256, subtype="PIXEL",
                             description="Texels by which the UV islands' colours are extended outwards, so that "
                                         "filtering near an island's edge reads the island")
    bake_uv_map: StringProperty(name="UV Map", default="",
                                description="The UV map Bake shades through (empty: the mesh's active render one)")
    bake_view: EnumProperty(name="Bake View", default="CAMERA", items=[
        ("CAMERA", "Camera", "The scene camera"),
        ("VIEWPORT", "Viewport", "The active 3D viewport's view")])
    bake_show: BoolProperty(name="Show Bake", default=True,
                            description="After baking, show the image in the object's materials (an Image Texture "
                                        "node, the active one, for Solid mode's Texture colour; emitted into a "
                                        "Material Output for EEVEE: Material Preview) and set open viewports to "
                                        "Solid, Flat, Texture")
    # Undone and saved with the colours, so after an undo or redo the colours' frame is known
    # (handlers.undo_post).
    shaded_frame: IntProperty(name="Shaded Frame", default=shading.NO_FRAME, options={"HIDDEN"},
                              description="The frame at which colours were last written")


class WENV_ImageSettings(bpy.types.PropertyGroup):
    """What an image's last bake was made of (bake.py): the panel reads it, a change to any of it marks
    the bake stale, a frame change bakes it again.  Undone with the image, so `bake_step` tells which
    bake's pixels an undo or redo puts back."""
    baked_object: StringProperty(name="Baked Object", description="The object whose texels the image holds")
    uv_map: StringProperty(name="UV Map", description="The UV map the bake went through")
    margin: IntProperty(name="Margin", default=0, min=0)
    view: StringProperty(name="View", description="Where the bake was seen from: CAMERA, VIEWPORT or MATRIX")
    view_key: StringProperty(name="View Key", options={"HIDDEN"}, description="The view baked for")
    reads_camera: BoolProperty(name="Reads the Camera", default=False, options={"HIDDEN"},
                               description="The bake read the camera's space or frame (a Texture Coordinate's "
                                           "Camera or Window): its turn or lens changes the bake too")
    state_key: StringProperty(name="State Key", options={"HIDDEN"},
                              description="The mesh, World, materials and lamps baked with")
    frame: IntProperty(name="Frame", default=0)
    texels: IntProperty(name="Texels", default=0, min=0)
    stale: StringProperty(name="Stale", description="What changed since the bake (empty: nothing)")
    bake_step: IntProperty(name="Bake Step", default=0, options={"HIDDEN"})
    bake_on_frame_change: BoolProperty(name="Bake on Frame Change", default=False,
                                       description="With Shade on Frame Change, bake this image again from the "
                                                   "scene camera on every frame change (renders of camera moves)")


class WENV_ObjectSettings(bpy.types.PropertyGroup):
    casts_shadows: BoolProperty(name="Casts Shadows", default=True,
                                description="This mesh blocks the sky of the meshes wenv shades (itself included) "
                                            "when the scene's Shadows is on")


class WENV_ViewportBackup(bpy.types.PropertyGroup):
    """A 3D viewport's own shading while it shows wenv's colours.  Kept in the viewport itself
    (View3DShading): saved with the screens and, like them, outside undo, so an undo never parts a
    viewport from what it is to be set back to."""
    showing: BoolProperty(name="Showing wenv's Colours", default=False)
    type: StringProperty(name="Shading Type")
    light: StringProperty(name="Lighting")
    color_type: StringProperty(name="Colour")


def _get_show_in_viewports(self):
    return views.showing_attribute_colors(self.id_data)


def _set_show_in_viewports(self, value):
    if value:
        views.show_attribute_colors(self.id_data)
    else:
        views.restore_viewports(bpy.data.screens)


class WENV_WindowSettings(bpy.types.PropertyGroup):
    """On the window manager, as the viewports' own settings: what the interface shows is no step of
    the undo history (Blender makes none for screen and window-manager properties)."""
    show_in_viewports: BoolProperty(name="Show in Viewports", get=_get_show_in_viewports,
                                    set=_set_show_in_viewports,
                                    description="Show the shaded colours in every open 3D viewport (solid, flat, "
                                                "attribute colours); off sets each viewport back as it was")


classes = (WENV_LobeSettings, WENV_MaterialSettings, WENV_SceneSettings, WENV_ImageSettings, WENV_ObjectSettings,
           WENV_ViewportBackup, WENV_WindowSettings)


# Settings a .blend may hold under an earlier name: (collection of the settings, old key, new property).
# A lobe's alpha was stored as "roughness" until `roughness` took Blender's meaning (alpha = r^2);
# the old key, now no property's storage, is read once into the new one and removed.
_RENAMED_LOBE_KEYS = (("roughness", "alpha"),)


def migrate(blend_data):
    """Brings settings saved under an earlier name up to date in every material of `blend_data` (run
    when a file is loaded); returns how many values moved."""
    moved = 0
    for material in blend_data.materials:
        if material.library is not None:  # linked data is the library's to migrate, and read-only here
            continue
        for lobe in material.wenv.lobes:
            for old, new in _RENAMED_LOBE_KEYS:
                if old in lobe.keys():
                    setattr(lobe, new, float(lobe[old]))
                    del lobe[old]
                    moved += 1
    return moved


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.wenv = PointerProperty(type=WENV_SceneSettings)
    bpy.types.Material.wenv = PointerProperty(type=WENV_MaterialSettings)
    bpy.types.Object.wenv = PointerProperty(type=WENV_ObjectSettings)
    bpy.types.Image.wenv = PointerProperty(type=WENV_ImageSettings)
    bpy.types.View3DShading.wenv = PointerProperty(type=WENV_ViewportBackup)
    bpy.types.WindowManager.wenv = PointerProperty(type=WENV_WindowSettings)


def unregister():
    del bpy.types.WindowManager.wenv
    del bpy.types.View3DShading.wenv
    del bpy.types.Image.wenv
    del bpy.types.Object.wenv
    del bpy.types.Material.wenv
    del bpy.types.Scene.wenv
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
