"""Reads a Blender material into a ``core.materials.MaterialSpec``.

Readable: the shader plugged into the active Material Output's Surface (through reroutes) is a
Principled BSDF (Base Color; Emission Color x Emission Strength), a Diffuse BSDF (Color) or an
Emission shader (Color x Strength, reflectance 0). A texture on Base Color (Color) whose node
chain ``textures`` can sample is read per face by ``textures.polygon_reflectance`` (the material's
own reflectance stays the default, unused where the faces are read). A readable texture on the
emission colour makes the material's emission its strength x white, and
``textures.polygon_emission`` scales each face by the texture's mean over it (so an animated
strength keeps applying). A linked strength is read where its chain is constant (a Value
node, Math of constants: ``textures.constant``, at the current frame, so keyframes on them are
followed) or holds a readable texture (then the material's strength is 1 and the faces carry
colour x strength, ``textures.polygon_emission``). Any other linked input falls back to the
default grey, a linked emission to none, and the spec says why (naming the node). Any other
shader, or no material at all, gives the default (grey 0.8, no emission).
"""

from __future__ import annotations

import bpy

from ..core import materials as core
from . import textures

NODES_ALWAYS = bpy.app.version >= (5, 0, 0)  # Material.use_nodes is deprecated in 5.0
LIGHT_GROUP_TAG = "radiosity_light"  # the custom property marking light_nodes' inserted group node


def output_node(tree):
    """The node tree's active Material Output (the first one when none is marked), or None."""
    out = None
    try:
        out = tree.get_output_node("ALL")
    except (AttributeError, TypeError):
        out = None
    if out is None:
        outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
        out = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
    return out


def through_reroutes(socket):
    """The node that feeds `socket`'s node through any Reroute nodes (None: a dangling one)."""
    node = socket.node
    while node is not None and node.bl_idname == "NodeReroute":
        node = node.inputs[0].links[0].from_node if node.inputs[0].is_linked else None
    return node


def _surface_node(mat):
    tree = mat.node_tree
    if tree is None:
        return None
    out = output_node(tree)
    if out is None or not out.inputs["Surface"].is_linked:
        return None
    node = through_reroutes(out.inputs["Surface"].links[0].from_socket)
    # Apply to Materials' own group (``light_nodes``, tagged) sits between the artist's shader
    # and the output until Clear: a re-bake reads the shader it wraps, not the baked light.
    if node is not None and node.bl_idname == "ShaderNodeGroup" and node.get(LIGHT_GROUP_TAG) == 1:
        shader = node.inputs.get("Shader")
        if shader is None or not shader.is_linked:
            return None
        node = through_reroutes(shader.links[0].from_socket)
    return node


def _value(node, name, problems, what, textured: bool = False):
    """An unlinked input's value; None (and why, in `problems`) for a linked one, except a
    readable texture where `textured` (read per face instead)."""
    sock = node.inputs.get(name)
    if sock is None:
        problems.append(f"{what}: no input {name!r}")
        return None
    if sock.is_linked:
        bad = textures.is_readable(sock) if textured else None
        fed = sock.links[0].from_node
        if textured and bad is None:
            return None
        problems.append(f"{name} is linked to {bad or fed.bl_label or fed.bl_idname}, not read")
        return None
    return sock.default_value


def _strength(node, name, problems, what):
    """An emission strength: its value where unlinked or linked to a constant chain (a Value
    node, Math of constants; read at the current frame, so keyframes on them are followed like
    a keyed input's), None where it holds a texture (read per face) or cannot be read (and why,
    in `problems`)."""
    sock = node.inputs.get(name)
    if sock is None or not sock.is_linked:
        return _value(node, name, problems, what)
    bad = textures.is_readable(sock)
    if bad is None:
        try:
            return textures.constant(sock)
        except textures.Textured:
            return None
        except textures.Unreadable as e:
            bad = str(e)
    problems.append(f"{name} is linked to {bad}, not read")
    return None


def _shader_input(mat, names: dict):
    """The input of `mat`'s surface shader named by ``names[shader node type]``, or None."""
    use_nodes = True if NODES_ALWAYS else mat.use_nodes
    node = _surface_node(mat) if use_nodes else None
    if node is None:
        return None
    name = names.get(node.bl_idname)
    return node.inputs.get(name) if name else None


def reflectance_socket(mat):
    """The input socket that holds `mat`'s diffuse colour (Principled Base Color, Diffuse
    Color), or None."""
    return _shader_input(mat, {"ShaderNodeBsdfPrincipled": "Base Color", "ShaderNodeBsdfDiffuse": "Color"})


def emission_socket(mat):
    """The input socket that holds `mat`'s emission colour (Principled Emission Color, an
    Emission shader's Color), or None."""
    return _shader_input(mat, {"ShaderNodeBsdfPrincipled": "Emission Color", "ShaderNodeEmission": "Color"})


def strength_socket(mat):
    """The input socket that holds `mat`'s emission strength (Principled Emission Strength, an
    Emission shader's Strength), or None."""
    return _shader_input(mat, {"ShaderNodeBsdfPrincipled": "Emission Strength",
                               "ShaderNodeEmission": "Strength"})


def _emission(node, names, color, strength, multiplier):
    """Colour x strength x multiplier as exitance. A readable texture on the colour (`color`
    None) counts as white, one on the strength as 1: the faces carry their product's mean
    (``textures.polygon_emission``). Any other missing value: no emission."""
    color_sock, strength_sock = (node.inputs.get(n) for n in names)
    if color is None:
        if color_sock is None or not color_sock.is_linked or textures.is_readable(color_sock) is not None:
            return (0.0, 0.0, 0.0)
        color = (1.0, 1.0, 1.0)
    if strength is None:
        if strength_sock is None or not textures.varies(strength_sock):
            return (0.0, 0.0, 0.0)
        strength = 1.0
    return core.exitance(color, strength, multiplier)


def read_material(mat, multiplier: float = 1.0, owner: str = "") -> core.MaterialSpec:
    """The library material for `mat` (None: no material) on an object of emitter `multiplier`."""
    if mat is None:
        return core.MaterialSpec(name=f"<no material> on {owner}" if owner else "<no material>",
                                 problem="no material")
    name = mat.name if multiplier == 1.0 else f"{mat.name} x{multiplier:g}"
    use_nodes = True if NODES_ALWAYS else mat.use_nodes
    node = _surface_node(mat) if use_nodes else None
    if node is None:
        why = "no node tree" if not use_nodes else "nothing plugged into the Material Output's Surface"
        return core.MaterialSpec(name=name, problem=why)
    problems: list[str] = []
    rho = core.DEFAULT_REFLECTANCE
    emission = (0.0, 0.0, 0.0)
    kind = node.bl_idname
    if kind == "ShaderNodeBsdfPrincipled":
        base = _value(node, "Base Color", problems, "Principled BSDF", textured=True)
        if base is not None:
            rho = core.reflectance(base)
        color = _value(node, "Emission Color", problems, "Principled BSDF", textured=True)
        strength = _strength(node, "Emission Strength", problems, "Principled BSDF")
        emission = _emission(node, ("Emission Color", "Emission Strength"), color, strength, multiplier)
    elif kind == "ShaderNodeBsdfDiffuse":
        base = _value(node, "Color", problems, "Diffuse BSDF", textured=True)
        if base is not None:
            rho = core.reflectance(base)
    elif kind == "ShaderNodeEmission":
        rho = (0.0, 0.0, 0.0)
        color = _value(node, "Color", problems, "Emission", textured=True)
        strength = _strength(node, "Strength", problems, "Emission")
        emission = _emission(node, ("Color", "Strength"), color, strength, multiplier)
    else:
        problems.append(f"shader {node.bl_label or kind} is not read")
    return core.MaterialSpec(name=name, reflectance=rho, emission=emission,
                             problem="; ".join(problems) or None)
