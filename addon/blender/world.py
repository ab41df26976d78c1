"""The scene's World as the solver's light from infinitely far (issue 22, item 2).

Read from the evaluated World at each baked frame (keyframes and drivers on it count):
- with a node tree (always in Blender 5; ``use_nodes`` before): the Background node linked into
  the active World Output's Surface, its Strength, and its Color: a constant, or an Environment
  Texture node (Equirectangular) whose image is handed over as pixels, box-filtered down to at
  most ``MAX_WIDTH x MAX_WIDTH / 2`` (the solver integrates the sky over the hemisphere with a
  few hundred directions per point, so finer texels are averaged anyway);
- without: ``World.color`` at strength 1.

What cannot be read (other nodes in between, a Vector input, a Mirror Ball projection, a
missing image) is reported in one line, and the Background's own colour is used instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.marshal import digest

MAX_WIDTH = 256


@dataclass
class WorldState:
    color: tuple = (0.0, 0.0, 0.0)
    strength: float = 0.0
    image: np.ndarray | None = None     # (H, W, 3) float32 linear, bottom row first
    problems: list[str] = field(default_factory=list)

    def native(self) -> dict:
        """Keyword arguments of ``binding.Session.set_world``."""
        return {"color": self.color, "strength": self.strength, "image": self.image}

    def key(self) -> str:
        """A digest of what lights the scene (part of a frame's emission state)."""
        if self.strength == 0.0:
            return ""
        parts = [np.asarray([*self.color, self.strength], np.float64)]
        if self.image is not None:
            parts.append(np.asarray(self.image, np.float64))
        return "W" + digest(*parts, decimals=6)


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _box_filter(pixels: np.ndarray, width: int) -> np.ndarray:
    """(H, W, 3) averaged over blocks down to at most `width` columns and `width / 2` rows."""
    h, w, _ = pixels.shape
    out_w, out_h = min(w, width), min(h, max(width // 2, 1))
    if (out_w, out_h) == (w, h):
        return pixels
    cols = np.floor(np.arange(out_w) * w / out_w).astype(int)
    rows = np.floor(np.arange(out_h) * h / out_h).astype(int)
    summed = np.add.reduceat(np.add.reduceat(pixels.astype(np.float64), rows, axis=0), cols, axis=1)
    counts = np.diff(np.append(rows, h))[:, None, None] * np.diff(np.append(cols, w))[None, :, None]
    return (summed / counts).astype(np.float32)


def image_pixels(image, max_width: int = MAX_WIDTH) -> np.ndarray:
    """An image's linear RGB, bottom row first (as Blender stores it), box-filtered."""
    w, h = image.size
    buf = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(buf)
    rgb = buf.reshape(h, w, 4)[:, :, :3]
    if not image.is_float and image.colorspace_settings.name == "sRGB":
        rgb = _srgb_to_linear(rgb).astype(np.float32)
    return _box_filter(np.maximum(rgb, 0.0), max_width)


def _background(tree):
    """The Background node feeding the active World Output, or (None, why)."""
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    out = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    if out is None:
        return None, "no World Output node"
    links = out.inputs["Surface"].links
    if not links:
        return None, None  # nothing connected: black
    node = links[0].from_node
    if node.bl_idname != "ShaderNodeBackground":
        return None, f"{node.bl_idname} into the World Output (a Background node is read)"
    return node, None


def read_world(world, max_width: int = MAX_WIDTH) -> WorldState:
    """The World as the solver takes it (``world`` evaluated, or None: black)."""
    if world is None:
        return WorldState()
    tree = world.node_tree
    uses_nodes = tree is not None and (bpy.app.version >= (5, 0, 0) or world.use_nodes)
    if not uses_nodes:
        return WorldState(tuple(float(c) for c in world.color), 1.0)
    state = WorldState()
    bg, why = _background(tree)
    if bg is None:
        if why:
            state.problems.append(why)
        return state
    strength = bg.inputs["Strength"]
    if strength.links:
        state.problems.append("a linked Background Strength (its value is used)")
    state.strength = float(strength.default_value)
    color = bg.inputs["Color"]
    state.color = tuple(float(c) for c in color.default_value[:3])
    if not color.links:
        return state
    node = color.links[0].from_node
    if node.bl_idname != "ShaderNodeTexEnvironment":
        state.problems.append(f"{node.bl_idname} into the Background Color (its own colour is used)")
        return state
    if node.image is None:
        state.problems.append("an Environment Texture without an image (its own colour is used)")
    elif node.projection != "EQUIRECTANGULAR":
        state.problems.append(f"a {node.projection} Environment Texture (its own colour is used)")
    else:
        if node.inputs["Vector"].links:
            state.problems.append("the Environment Texture's Vector input (the default mapping is used)")
        try:
            state.image = image_pixels(node.image, max_width)
            state.color = (1.0, 1.0, 1.0)
        except (RuntimeError, ValueError) as e:  # an image whose pixels cannot be loaded
            state.problems.append(f"image {node.image.name!r} could not be read ({e})")
    return state


def world_state(depsgraph) -> WorldState:
    """The depsgraph's scene's World at its current frame."""
    return read_world(depsgraph.scene_eval.world)


def two_sided(objects) -> list[bool]:
    """Per library object: its Radiosity setting "Two-Sided Emitter"."""
    return [bool(getattr(getattr(o, "radiosity", None), "two_sided", False)) for o in objects]


def apply(session, world: WorldState, sided: list[bool]) -> None:
    """Hands the World and the two-sided flags to a session."""
    session.set_world(**world.native())
    for i, on in enumerate(sided):
        session.set_two_sided(i, on)


def problems_line(world: WorldState) -> str | None:
    if not world.problems:
        return None
    return "World not fully read: " + "; ".join(world.problems)
