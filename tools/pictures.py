"""Pictures of baked colour attributes: each attribute rendered as emission (Cycles, a few
samples, view transform Standard, so pixels show the stored radiance), then stitched side by
side into one PNG with numpy."""

from pathlib import Path

import numpy as np


def _show_material(bpy, attr):
    mat = bpy.data.materials.new(f"Show {attr}")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    col = nt.nodes.new("ShaderNodeVertexColor")
    col.layer_name = attr
    nt.links.new(col.outputs["Color"], em.inputs["Color"])
    em.inputs["Strength"].default_value = 1.0
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def render_attribute(bpy, objects, attr, path, size=256, skip=()):
    """Renders the scene's camera view with every object (but those in `skip`) showing `attr`."""
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.samples = 16
    sc.cycles.use_denoising = False
    sc.cycles.max_bounces = 0
    sc.render.resolution_x = sc.render.resolution_y = size
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    sc.render.image_settings.file_format = "PNG"
    show = _show_material(bpy, attr)
    saved = {}
    for ob in objects.values():
        if ob.name in skip:
            continue
        saved[ob.name] = [s.material for s in ob.material_slots]
        for s in ob.material_slots:
            s.material = show
    sc.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    for name, mats in saved.items():
        for s, m in zip(objects[name].material_slots, mats, strict=True):
            s.material = m
    return Path(path)


def stitch(bpy, paths, out, gap=4):
    """Places PNGs of equal size side by side (white gaps) into one PNG."""
    return grid(bpy, paths, out, columns=len(paths), gap=gap)


def grid(bpy, paths, out, columns, gap=4):
    """Places PNGs of equal size in rows of ``columns`` (left to right, top to bottom; white
    gaps, a short last row padded white) into one PNG."""
    tiles = []
    for p in paths:
        img = bpy.data.images.load(str(p))
        w, h = img.size
        tiles.append(np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4))
        bpy.data.images.remove(img)
    h, w = tiles[0].shape[:2]
    rows = -(-len(tiles) // columns)
    sheet = np.ones((rows * h + (rows - 1) * gap, columns * w + (columns - 1) * gap, 4), np.float32)
    for k, t in enumerate(tiles):
        r, c = divmod(k, columns)
        # Blender's pixels run bottom row first: the first row of tiles goes at the top.
        y = (rows - 1 - r) * (h + gap)
        sheet[y:y + h, c * (w + gap):c * (w + gap) + w] = t
    H, W = sheet.shape[:2]
    img = bpy.data.images.new("grid", W, H, alpha=True)
    img.pixels.foreach_set(sheet.ravel())
    img.filepath_raw = str(out)
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)
    return Path(out)


def side_by_side(bpy, objects, attrs, out, emitters=(), size=256):
    """Renders each attribute and stitches them left to right. Emitter objects keep their own
    material (their light shows in every tile)."""
    out = Path(out)
    skip = {
        ob.name
        for ob in objects.values()
        if any(s.material and s.material.name in emitters for s in ob.material_slots)
    }
    tiles = [
        render_attribute(bpy, objects, a, out.with_name(f"{out.stem}_{a}.png"), size=size, skip=skip)
        for a in attrs
    ]
    return stitch(bpy, tiles, out)
