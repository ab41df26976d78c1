"""The "Radiosity" panel in Render properties and the per-object panel in Object properties."""

from __future__ import annotations

import bpy


class RENDER_PT_radiosity(bpy.types.Panel):
    bl_label = "Radiosity"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        p = context.scene.radiosity
        row = layout.row(align=True)
        row.scale_y = 1.4
        row.operator("radiosity.bake", icon="RENDER_ANIMATION")
        row.operator("radiosity.clear", text="", icon="TRASH")
        # Grouped by what an artist trades: how fine the light is, what it shows, how it is run.
        col = layout.column()
        col.prop(p, "basis_order")
        col.prop(p, "quality")
        col.prop(p, "tolerance")
        col = layout.column(heading="Light")
        col.prop(p, "visibility")
        col.prop(p, "corner_gather")
        col.prop(p, "reflecting_backs")
        col = layout.column()
        col.prop(p, "method")
        if p.method == "HIERARCHICAL":
            col.prop(p, "hierarchy_accuracy")
        col.prop(p, "threads")
        col.prop(p, "memory_limit_mb")
        col.prop(p, "collection")
        layout.prop(p, "live_preview")
        row = layout.row()
        row.active = p.live_preview
        row.prop(p, "live_refine_when_idle")


class RENDER_PT_radiosity_frames(bpy.types.Panel):
    bl_label = "Frames"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    bl_parent_id = "RENDER_PT_radiosity"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        p = context.scene.radiosity
        layout.prop(p, "use_scene_range")
        col = layout.column(align=True)
        col.enabled = not p.use_scene_range
        col.prop(p, "frame_start")
        col.prop(p, "frame_end")
        layout.prop(p, "frame_step")


class RENDER_PT_radiosity_output(bpy.types.Panel):
    bl_label = "Output"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    bl_parent_id = "RENDER_PT_radiosity"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        p = context.scene.radiosity
        layout.prop(p, "display_subdivision")
        layout.prop(p, "preview_material")
        layout.prop(p, "apply_to_materials")


class OBJECT_PT_radiosity(bpy.types.Panel):
    bl_label = "Radiosity"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        p = context.object.radiosity
        layout.prop(p, "exclude")
        col = layout.column()
        col.enabled = not p.exclude
        col.prop(p, "emission_multiplier")
        col.prop(p, "two_sided")


classes = (RENDER_PT_radiosity, RENDER_PT_radiosity_frames, RENDER_PT_radiosity_output, OBJECT_PT_radiosity)
