"""The Geometry Nodes switch that plays the baked frames back without the add-on.

Node group "Radiosity Switch" (shared by all baked objects), as a modifier at the end of the stack:

    geometry = Use Copy ? ObjectInfo(Copy, Original).Geometry : Group Input
    frame    = clamp(round(Scene Time.Frame), First Frame, Last Frame)
    name     = "Rad_" + slice(value_to_string(frame + 10000), 1, 4)        -> "Rad_0042"
    geometry = Store Named Attribute(geometry, CORNER, FLOAT_COLOR, "Radiosity",
                                     Named Attribute(FLOAT_COLOR, name))
    geometry = Store Named Attribute(geometry, CORNER, FLOAT_COLOR, "Radiosity Light",
                                     Named Attribute(FLOAT_COLOR, "Irr_" + the same digits))
    geometry = Preview ? Set Material(geometry, Preview Material) : geometry

The String Join node joins its multi-input in reverse link order, so the digits are linked
first and the "Rad_" prefix second (the tests check the joined name through evaluated meshes).
Frames outside the baked range hold the first or last baked frame.
"""

from __future__ import annotations

from ..core import frames
from .export import SWITCH_GROUP, SWITCH_MODIFIER, is_switch_modifier

VERSION = 2  # 2: the irradiance (Irr_NNNN -> Radiosity Light)

INPUTS = (
    ("First Frame", "NodeSocketInt"),
    ("Last Frame", "NodeSocketInt"),
    ("Use Copy", "NodeSocketBool"),
    ("Copy", "NodeSocketObject"),
    ("Preview", "NodeSocketBool"),
    ("Preview Material", "NodeSocketMaterial"),
)


def _store_switched(nodes, links, digits, geometry, prefix, stored, row):
    """Nodes storing the corner attribute `prefix` + `digits` of `geometry` as `stored`; returns
    the Store Named Attribute node. (String Join joins its multi-input in reverse link order:
    the digits are linked first, then the prefix.)"""
    dy = 250 * row
    head = nodes.new("FunctionNodeInputString")
    head.string = prefix
    head.location = (100, 550 + dy)
    join = nodes.new("GeometryNodeStringJoin")
    join.location = (300, 450 + dy)
    links.new(digits.outputs[0], join.inputs["Strings"])
    links.new(head.outputs[0], join.inputs["Strings"])
    named = nodes.new("GeometryNodeInputNamedAttribute")
    named.data_type = "FLOAT_COLOR"
    named.location = (450 + 100 * row, 300)
    links.new(join.outputs[0], named.inputs["Name"])
    store = nodes.new("GeometryNodeStoreNamedAttribute")
    store.data_type = "FLOAT_COLOR"
    store.domain = "CORNER"
    store.inputs["Name"].default_value = stored
    store.location = (450 + 100 * row, 0)
    links.new(geometry.outputs[0], store.inputs["Geometry"])
    links.new(named.outputs["Attribute"], store.inputs["Value"])
    return store


def node_group(bpy):
    ng = bpy.data.node_groups.get(SWITCH_GROUP)
    if ng is not None and ng.get("radiosity_version") == VERSION:
        return ng
    if ng is None:
        ng = bpy.data.node_groups.new(SWITCH_GROUP, "GeometryNodeTree")
    else:
        ng.nodes.clear()
        ng.interface.clear()
    ng["radiosity_version"] = VERSION
    iface = ng.interface
    iface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    iface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    for name, kind in INPUTS:
        iface.new_socket(name, in_out="INPUT", socket_type=kind)
    nodes, links = ng.nodes, ng.links
    gi = nodes.new("NodeGroupInput")
    go = nodes.new("NodeGroupOutput")
    gi.location, go.location = (-900, 0), (900, 0)

    info = nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "ORIGINAL"
    info.location = (-650, -250)
    links.new(gi.outputs["Copy"], info.inputs["Object"])
    source = nodes.new("GeometryNodeSwitch")
    source.input_type = "GEOMETRY"
    source.location = (-400, 0)
    links.new(gi.outputs["Use Copy"], source.inputs["Switch"])
    links.new(gi.outputs["Geometry"], source.inputs["False"])
    links.new(info.outputs["Geometry"], source.inputs["True"])

    time = nodes.new("GeometryNodeInputSceneTime")
    time.location = (-900, 400)
    rnd = nodes.new("ShaderNodeMath")
    rnd.operation = "ROUND"
    rnd.location = (-700, 400)
    links.new(time.outputs["Frame"], rnd.inputs[0])
    clamp = nodes.new("ShaderNodeClamp")
    clamp.location = (-500, 400)
    links.new(rnd.outputs[0], clamp.inputs["Value"])
    links.new(gi.outputs["First Frame"], clamp.inputs["Min"])
    links.new(gi.outputs["Last Frame"], clamp.inputs["Max"])
    offset = nodes.new("ShaderNodeMath")
    offset.operation = "ADD"
    offset.inputs[1].default_value = 10000.0
    offset.location = (-300, 400)
    links.new(clamp.outputs[0], offset.inputs[0])
    text = nodes.new("FunctionNodeValueToString")
    text.location = (-100, 400)
    links.new(offset.outputs[0], text.inputs["Value"])
    digits = nodes.new("FunctionNodeSliceString")
    digits.inputs["Position"].default_value = 1
    digits.inputs["Length"].default_value = 4
    digits.location = (100, 400)
    links.new(text.outputs[0], digits.inputs["String"])
    # B / pi from "Rad_" + the frame's digits as "Radiosity", then the irradiance from "Irr_" +
    # the same digits as "Radiosity Light".
    store = _store_switched(nodes, links, digits, source, frames.ATTRIBUTE_PREFIX, frames.RESULT_ATTRIBUTE, 0)
    store = _store_switched(nodes, links, digits, store, frames.LIGHT_PREFIX, frames.LIGHT_ATTRIBUTE, 1)

    setmat = nodes.new("GeometryNodeSetMaterial")
    setmat.location = (650, -150)
    links.new(store.outputs[0], setmat.inputs["Geometry"])
    links.new(gi.outputs["Preview Material"], setmat.inputs["Material"])
    preview = nodes.new("GeometryNodeSwitch")
    preview.input_type = "GEOMETRY"
    preview.location = (750, 0)
    links.new(gi.outputs["Preview"], preview.inputs["Switch"])
    links.new(store.outputs[0], preview.inputs["False"])
    links.new(setmat.outputs[0], preview.inputs["True"])
    links.new(preview.outputs[0], go.inputs[0])
    return ng


def _identifier(ng, name: str) -> str:
    for item in ng.interface.items_tree:
        if getattr(item, "in_out", None) == "INPUT" and item.name == name:
            return item.identifier
    raise KeyError(name)


def find(obj):
    return next((m for m in obj.modifiers if is_switch_modifier(m)), None)


def install(bpy, obj, first: int, last: int, copy=None, preview_material=None):
    """Adds (or updates) the switch modifier on `obj`, last in its stack."""
    ng = node_group(bpy)
    mod = find(obj)
    if mod is None:
        mod = obj.modifiers.new(SWITCH_MODIFIER, "NODES")
    mod.node_group = ng
    values = {
        "First Frame": int(first),
        "Last Frame": int(last),
        "Use Copy": copy is not None,
        "Copy": copy,
        "Preview": preview_material is not None,
        "Preview Material": preview_material,
    }
    for name, value in values.items():
        mod[_identifier(ng, name)] = value
    # Keep the switch last, so it sees the fully evaluated geometry.
    index = list(obj.modifiers).index(mod)
    if index != len(obj.modifiers) - 1:
        obj.modifiers.move(index, len(obj.modifiers) - 1)
    mod.show_viewport = True
    mod.show_render = True
    obj.update_tag()
    return mod


def remove(obj) -> bool:
    mod = find(obj)
    if mod is None:
        return False
    obj.modifiers.remove(mod)
    return True


def set_muted(obj, muted: bool) -> bool | None:
    """Hides the switch in the viewport (export and live preview must not see it); returns the
    previous visibility, None if there is no switch."""
    mod = find(obj)
    if mod is None:
        return None
    before = mod.show_viewport
    mod.show_viewport = not muted
    return before
