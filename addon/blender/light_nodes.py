"""Apply to Materials: the baked light inside the artist's own materials.

The bake stores, beside the outgoing radiance B / pi (``Radiosity``), the irradiance H / pi
(``Radiosity Light``): the light a surface receives, without its colour and emission, so that
``B = E + rho H``. A material's own colour at full resolution (its Base Color texture) times
``Radiosity Light`` is the light it reflects, with the texture's detail inside each face.

``apply(mat)`` inserts one node, a group "Radiosity Light", between the shader plugged into the
active Material Output's Surface and that output; the Material Output's Surface link is the one
link it changes (it now comes from the group, whose Shader input takes the original shader).
The group's Color, Emission Color and Emission Strength inputs get new links from whatever feeds
the shader's own inputs (the artist's links stay as they were), or the shader's values when those
are not linked. Inside:

    baked   = Emission(Color x Attribute("Radiosity Light"), 1) + Emission(Emission Color, Strength)
    surface = Mix Shader(Factor, Shader, baked)          (Factor 1: the baked light)

so the surface shows ``rho(x) H / pi + E / pi``, which is the baked B / pi where the colour is
uniform, as emission: it renders the same in Cycles and EEVEE and does not depend on the render's
lights, World or EEVEE's own indirect light. Multiplying H into Base Color instead would be lit
again by the render (light counted twice), and adding it as emission beside the BSDF likewise
adds the render's direct light on top of the baked one. Factor 0 gives the original shader back.

``remove(mat)`` relinks the group's Shader source to the Material Output and deletes the group
node (and with it the links it added): the node tree is as before ``apply``.
"""

from __future__ import annotations

from ..core.frames import LIGHT_ATTRIBUTE
from .materials import LIGHT_GROUP_TAG, output_node, through_reroutes

GROUP = "Radiosity Light"
NODE_TAG = LIGHT_GROUP_TAG   # materials.py reads through the tagged node on a re-bake
VERSION = 1

# Per readable shader: its (colour, emission colour, emission strength) inputs (None: not there).
SHADERS = {
    "ShaderNodeBsdfPrincipled": ("Base Color", "Emission Color", "Emission Strength"),
    "ShaderNodeBsdfDiffuse": ("Color", None, None),
    "ShaderNodeEmission": (None, "Color", "Strength"),
}


def node_group(bpy):
    ng = bpy.data.node_groups.get(GROUP)
    if ng is not None and ng.get("radiosity_version") == VERSION:
        return ng
    if ng is None:
        ng = bpy.data.node_groups.new(GROUP, "ShaderNodeTree")
    else:
        ng.nodes.clear()
        ng.interface.clear()
    ng["radiosity_version"] = VERSION
    iface = ng.interface
    iface.new_socket("Shader", in_out="OUTPUT", socket_type="NodeSocketShader")
    iface.new_socket("Shader", in_out="INPUT", socket_type="NodeSocketShader")
    color = iface.new_socket("Color", in_out="INPUT", socket_type="NodeSocketColor")
    color.default_value = (0.8, 0.8, 0.8, 1.0)
    emission = iface.new_socket("Emission Color", in_out="INPUT", socket_type="NodeSocketColor")
    emission.default_value = (0.0, 0.0, 0.0, 1.0)
    strength = iface.new_socket("Emission Strength", in_out="INPUT", socket_type="NodeSocketFloat")
    strength.default_value = 0.0
    factor = iface.new_socket("Factor", in_out="INPUT", socket_type="NodeSocketFloat")
    factor.default_value, factor.min_value, factor.max_value = 1.0, 0.0, 1.0
    nodes, links = ng.nodes, ng.links
    gi, go = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    gi.location, go.location = (-700, 0), (500, 0)
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_type = "GEOMETRY"
    attr.attribute_name = LIGHT_ATTRIBUTE
    attr.location = (-500, 250)
    mul = nodes.new("ShaderNodeMix")
    mul.data_type = "RGBA"
    mul.blend_type = "MULTIPLY"
    mul.inputs["Factor"].default_value = 1.0
    mul.location = (-300, 200)
    links.new(gi.outputs["Color"], mul.inputs["A"])
    links.new(attr.outputs["Color"], mul.inputs["B"])
    reflected = nodes.new("ShaderNodeEmission")
    reflected.inputs["Strength"].default_value = 1.0
    reflected.location = (-100, 200)
    links.new(mul.outputs["Result"], reflected.inputs["Color"])
    own = nodes.new("ShaderNodeEmission")
    own.location = (-100, -50)
    links.new(gi.outputs["Emission Color"], own.inputs["Color"])
    links.new(gi.outputs["Emission Strength"], own.inputs["Strength"])
    add = nodes.new("ShaderNodeAddShader")
    add.location = (100, 100)
    links.new(reflected.outputs[0], add.inputs[0])
    links.new(own.outputs[0], add.inputs[1])
    mix = nodes.new("ShaderNodeMixShader")
    mix.location = (300, 0)
    links.new(gi.outputs["Factor"], mix.inputs["Fac"])
    links.new(gi.outputs["Shader"], mix.inputs[1])
    links.new(add.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], go.inputs["Shader"])
    return ng


def inserted(mat):
    """The group node ``apply`` inserted into `mat`, or None."""
    tree = mat.node_tree
    if tree is None:
        return None
    return next((n for n in tree.nodes if n.get(NODE_TAG) == 1), None)


def apply(bpy, mat) -> str | None:
    """Inserts the group into `mat` (again, if it was: removed first). Returns why it could not,
    or None."""
    if mat.library is not None:
        return "linked from a library"
    tree = mat.node_tree
    if tree is None or (bpy.app.version < (5, 0, 0) and not mat.use_nodes):
        return "does not use nodes"
    remove(mat)
    out = output_node(tree)
    if out is None:
        return "has no Material Output"
    surface = out.inputs["Surface"]
    if not surface.is_linked:
        return "has no shader on its Material Output"
    link = surface.links[0]
    source = link.from_socket
    shader = through_reroutes(source)
    names = SHADERS.get(shader.bl_idname) if shader is not None else None
    if names is None:
        return f"its shader {shader.bl_label if shader else 'nothing'} is not read"
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = node_group(bpy)
    node.name = node.label = GROUP
    node[NODE_TAG] = 1
    node.location = (out.location.x, out.location.y + 220)
    for name, own in zip(("Color", "Emission Color", "Emission Strength"), names, strict=True):
        into = node.inputs[name]
        if own is None:
            if name == "Color":
                into.default_value = (0.0, 0.0, 0.0, 1.0)
            continue
        sock = shader.inputs[own]
        if sock.is_linked:
            tree.links.new(sock.links[0].from_socket, into)
        else:
            into.default_value = sock.default_value
    tree.links.remove(link)
    tree.links.new(source, node.inputs["Shader"])
    tree.links.new(node.outputs["Shader"], surface)
    return None


def remove(mat) -> bool:
    """Takes the group out of `mat`, restoring the Material Output's link; True if it was there."""
    node = inserted(mat)
    if node is None:
        return False
    tree = mat.node_tree
    targets = [lk.to_socket for lk in node.outputs["Shader"].links]
    shader_in = node.inputs["Shader"]
    source = shader_in.links[0].from_socket if shader_in.is_linked else None
    tree.nodes.remove(node)
    if source is not None:
        for sock in targets:
            tree.links.new(source, sock)
    return True


def materials_of(objects) -> list:
    """The distinct materials in the slots of `objects`, in order."""
    seen, out = set(), []
    for obj in objects:
        for slot in getattr(obj, "material_slots", ()):
            mat = slot.material
            if mat is not None and mat.name_full not in seen:
                seen.add(mat.name_full)
                out.append(mat)
    return out


def apply_to(bpy, objects) -> str | None:
    """Applies the group to every material of `objects`; one line naming those skipped, or None."""
    skipped = []
    for mat in materials_of(objects):
        if mat.get("radiosity_preview") == 1:
            continue
        why = apply(bpy, mat)
        if why is not None:
            skipped.append(f"{mat.name} ({why})")
    if not skipped:
        return None
    return "Apply to Materials skipped: " + ", ".join(skipped)


def remove_from(materials) -> int:
    return sum(1 for mat in materials if mat.library is None and remove(mat))
