"""Sidebar panels in the 3D viewport (N panel, tab "wenv")."""
import math

import bpy

from . import bake, engine, gloss, handlers, lamps, materials, world
from .live import LiveState


class _SidebarPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "wenv"


def _property_column(layout):
    """A column with labels left of the fields, as Blender's own property panels."""
    col = layout.column()
    col.use_property_split = True
    col.use_property_decorate = False
    return col


def _active_material(context):
    obj = context.object
    return obj.active_material if obj is not None else None


class WENV_PT_shading(_SidebarPanel, bpy.types.Panel):
    bl_label = "Environment Shading"

    def draw(self, context):
        layout = self.layout
        st = context.scene.wenv
        col = _property_column(layout)
        col.prop(st, "quality")
        if st.quality == "AUTO":
            col.prop(st, "target_error")
            col.prop(st, "memory_budget")
        col.prop(st, "view_source")
        sub = col.column()
        sub.active = st.view_source == "VIEWPORT"
        sub.prop(st, "shade_only_seen")
        col.prop(st, "shadows")
        sub = col.column()
        sub.active = st.shadows
        sub.prop(st, "bounce_light")
        sub = sub.column()
        sub.active = st.shadows and st.bounce_light
        sub.prop(st, "glossy_bounce")
        obj = context.active_object
        if st.shadows and obj is not None and obj.type == "MESH":
            col.prop(obj.wenv, "casts_shadows", text=f"'{obj.name}' Casts Shadows")
        col.prop(st, "tone_mapping")
        sub = col.column()
        sub.active = st.tone_mapping == "LOG"
        sub.prop(st, "max_luminance")
        sub = col.column()
        sub.active = engine.quality_value(st.quality) in engine.REFINABLE
        sub.prop(st, "refine_at_rest")
        sub = col.column()
        sub.active = engine.quality_value(st.quality) != engine.PREVIEW_QUALITY
        sub.prop(st, "preview_changes")
        col.prop(st, "shade_on_frame_change")
        if st.shade_on_frame_change and not context.scene.render.use_lock_interface:
            col.label(text="Renders re-shade frames only with Render > Lock Interface", icon="INFO")

        row = layout.row(align=True)
        row.scale_y = 1.3
        row.operator("wenv.shade", icon="SHADING_RENDERED")
        live = LiveState.running()
        row.operator("wenv.live", text="Stop Live" if live else "Live", icon="PAUSE" if live else "PLAY",
                     depress=live)
        status = LiveState.session.refine_status if live else None
        if status is not None:
            if status[0] == "REFINING":
                _, fraction, shown, making = status
                goal = " (within 1 %)" if making == engine.REFINE_QUALITY else ""
                layout.label(text=f"{shown.title()} shown, refining to {making.title()}{goal}: {100 * fraction:.0f} %",
                             icon="TIME")
            else:
                layout.label(text="Refined to High: within 1 % of the reference for roughness 0.1 and up",
                             icon="CHECKMARK")
        row = layout.row(align=True)
        row.prop(context.window_manager.wenv, "show_in_viewports", toggle=True, icon="HIDE_OFF")
        row.operator("wenv.clear", icon="X")

        box = layout.box()
        try:
            box.label(text="World: " + world.world_spec(context.scene.world).describe(), icon="WORLD")
        except engine.SetupError as exc:
            box.alert = True
            box.label(text=str(exc), icon="ERROR")
        lights = lamps.summary(context.scene)
        if lights:
            box.label(text=lights, icon="LIGHT")
        problems = [p for p in ((LiveState.session.last_error if live else None), handlers.last_error()) if p]
        for problem in problems:
            row = layout.row()
            row.alert = True
            row.label(text=problem, icon="ERROR")
        quality = engine.quality_value(st.quality)
        if not engine.shaders.has(quality) and engine.needs_matrices(quality):
            layout.label(text="Rotation matrices: precomputed on first use", icon="INFO")


class WENV_PT_bake(_SidebarPanel, bpy.types.Panel):
    bl_label = "Bake to Image"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        st = scene.wenv
        obj = context.active_object
        layout.template_ID(st, "bake_image", new="image.new", open="image.open")
        col = _property_column(layout)
        image = st.bake_image
        if image is None:
            col.prop(st, "bake_resolution")
            col.prop(st, "bake_float")
        else:
            col.label(text=f"{image.size[0]} x {image.size[1]}, {image.colorspace_settings.name}"
                           + (", float" if image.is_float else ", bytes"))
        col.prop(st, "bake_margin")
        if obj is not None and obj.type == "MESH":
            col.prop_search(st, "bake_uv_map", obj.data, "uv_layers", text="UV Map")
        col.prop(st, "bake_view")
        col.prop(st, "bake_show")
        if image is not None:
            sub = col.column()
            sub.active = st.shade_on_frame_change
            sub.prop(image.wenv, "bake_on_frame_change")
        row = layout.row(align=True)
        row.scale_y = 1.3
        row.operator("wenv.bake", icon="RENDER_STILL")
        row.operator("wenv.bake_hide", icon="X")
        if image is None or not image.wenv.baked_object:
            return
        record = image.wenv
        where = {"CAMERA": "the camera", "VIEWPORT": "a viewport", "MATRIX": "a given view"}.get(record.view, "a view")
        box = layout.box()
        box.label(text=f"'{record.baked_object}': {record.texels} texels through '{record.uv_map}' from {where}, "
                       f"frame {record.frame}", icon="IMAGE_DATA")
        why = bake.staleness(image, scene, context)
        if why:
            box.alert = True
            box.label(text=f"Stale: {why} since the bake", icon="ERROR")
        else:
            box.label(text="Current: shows the scene as it is", icon="CHECKMARK")


class WENV_UL_lobes(bpy.types.UIList):
    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        row = layout.row(align=True)
        row.label(text=f"Lobe {index + 1}")
        row.label(text=f"{item.distribution.title()} roughness {item.roughness:.3g}, IOR {item.ior:.3g}")


# The node's inputs wenv shades (in full or in part: the core's list of them), drawn from the node
# itself: editing them here edits the node.
PRINCIPLED_SHOWN = tuple(row["socket"] for row in engine.PRINCIPLED_INPUTS if row["shaded"] != "no")


def _draw_principled(layout, mat):
    node = materials.principled_node(mat)
    if node is None:
        layout.label(text="No Principled BSDF: shaded as Lambertian with the viewport colour", icon="INFO")
        return
    layout.label(text=f"From the node '{node.name}', as Cycles evaluates it", icon="NODE_MATERIAL")
    col = _property_column(layout)
    for name in PRINCIPLED_SHOWN:
        sock = node.inputs.get(name)
        if sock is not None and not sock.is_linked:
            col.prop(sock, "default_value", text=name)
    col.prop(node, "distribution")
    notes = materials.principled_notes(mat)
    if notes:
        box = layout.box()
        box.label(text="Not shaded by wenv:", icon="ERROR")
        for note in notes:
            box.label(text=note)
    layout.operator("wenv.from_principled", text="Convert to Cook-Torrance", icon="NODE_MATERIAL")


class WENV_PT_material(_SidebarPanel, bpy.types.Panel):
    bl_label = "Material"

    @classmethod
    def poll(cls, context):
        return _active_material(context) is not None

    def draw(self, context):
        layout = self.layout
        mat = _active_material(context)
        st = mat.wenv
        layout.label(text=mat.name, icon="MATERIAL")
        col = _property_column(layout)
        col.prop(st, "model")
        if st.model == "PRINCIPLED":
            _draw_principled(layout, mat)
            return
        layout.operator("wenv.from_principled", icon="NODE_MATERIAL")
        if st.model == "MEASURED":
            col.prop(st, "brdf_path")
            try:
                table = engine.material_from_key(materials.material_key(st))
            except engine.SetupError as exc:
                row = layout.row()
                row.alert = True
                row.label(text=str(exc), icon="ERROR")
                return
            n_h, n_d, n_p = table.shape
            layout.label(text=f"Table {n_h} x {n_d} x {n_p} (theta_h, theta_d, phi_d)", icon="CHECKMARK")
            layout.label(text="Diffuse floor " + ", ".join(f"{c:.3g}" for c in table.diffuse))
            return
        col.prop(st, "diffuse")
        if st.model != "COOK_TORRANCE":
            return
        col.prop(st, "shadowing")
        row = layout.row()
        row.template_list("WENV_UL_lobes", "", st, "lobes", st, "active_lobe", rows=2)
        ops = row.column(align=True)
        ops.operator("wenv.lobe_add", icon="ADD", text="")
        ops.operator("wenv.lobe_remove", icon="REMOVE", text="")
        if 0 <= st.active_lobe < len(st.lobes):
            lobe = st.lobes[st.active_lobe]
            col = _property_column(layout)
            col.prop(lobe, "specular")
            col.prop(lobe, "roughness")
            col.prop(lobe, "alpha")
            col.prop(lobe, "ior")
            col.prop(lobe, "distribution")



class WENV_PT_gloss(_SidebarPanel, bpy.types.Panel):
    bl_label = "Glossmeter"

    @classmethod
    def poll(cls, context):
        return _active_material(context) is not None

    def draw(self, context):
        layout = self.layout
        st = _active_material(context).wenv
        key, texture_note = gloss.reading_key(_active_material(context))
        readings = gloss.gloss_readings(key)
        if texture_note:
            layout.label(text=texture_note, icon="TEXTURE")
        if isinstance(readings, str):
            layout.alert = True
            layout.label(text=readings, icon="ERROR")
            return
        used = gloss.instrument_geometry(readings[60])
        col = layout.column(align=True)
        for geometry in gloss.GEOMETRIES:
            row = col.row()
            row.label(text=f"{geometry}°")
            row.label(text=f"{readings[geometry]:.2f} GU")
            # The instrument's own choice for this material (60° reading: 10-70 GU -> 60°, above -> 20°,
            # below -> 85°) is marked.
            row.label(text="instrument" if geometry == used else "", icon="CHECKMARK" if geometry == used else "BLANK1")
        row = col.row()
        row.label(text="Haze")
        row.label(text=f"{readings['haze']:.2f} HU")
        row.label(text="", icon="BLANK1")
        layout.separator()
        if st.model in ("MEASURED", "LAMBERT"):
            return  # nothing to fit: a measurement or a Lambertian surface has no roughness to set
        col = _property_column(layout)
        col.prop(st, "target_gloss")
        col.prop(st, "target_geometry")
        col.operator("wenv.fit_roughness", icon="DRIVER_DISTANCE")
        if math.isnan(st.gloss_60):
            layout.label(text="No reading", icon="ERROR")


classes = (WENV_PT_shading, WENV_PT_bake, WENV_UL_lobes, WENV_PT_material, WENV_PT_gloss)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
