"""The opt-in preview material: Color Attribute "Radiosity" -> Emission (strength 1) -> Output.

It is never put in the artist's material slots: the switch's Set Material node applies it to the
evaluated geometry when "Preview material" is ticked, and clearing the bake (or unticking and
re-baking) takes it away. Rendered with the Standard view transform it shows the baked radiance.
"""

from __future__ import annotations

NAME = "Radiosity Preview"


def preview_material(bpy):
    mat = bpy.data.materials.get(NAME)
    if mat is not None and mat.get("radiosity_preview") == 1:
        return mat
    if mat is None:
        mat = bpy.data.materials.new(NAME)
    mat["radiosity_preview"] = 1
    if bpy.app.version < (5, 0, 0) and not mat.use_nodes:
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    attr = nodes.new("ShaderNodeVertexColor")
    attr.layer_name = "Radiosity"
    attr.location = (-400, 0)
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    emit.location = (-150, 0)
    out = nodes.new("ShaderNodeOutputMaterial")
    out.location = (100, 0)
    links.new(attr.outputs["Color"], emit.inputs["Color"])
    links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return mat
