"""Galerkin Radiosity: bakes animated Galerkin radiosity into colour attributes.

Layout (in the spirit of glTF-Blender-IO): ``core/`` is bpy-free (settings, marshalling, n-gon
splitting, material maths, display grids); ``blender/`` talks to Blender (export, attributes,
the Geometry Nodes switch, the bake job, live preview); ``native/`` loads the library.
Registering imports only the properties, operators and panels; the rest loads on first use.

From a checkout: ``sys.path.insert(0, REPO); import addon; addon.register()``.
"""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from . import operators, properties, ui

classes = properties.classes + operators.classes + ui.classes


@persistent
def _on_load_post(*_args):
    """A new file: sessions held for the old one are closed; live preview restarts if saved on."""
    from .blender import bake, live

    bake.drop_held()
    if any(s.radiosity.live_preview for s in bpy.data.scenes):
        live.enable(next(s for s in bpy.data.scenes if s.radiosity.live_preview))
    else:
        live.disable()


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    properties.register_properties()
    if _on_load_post not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(_on_load_post)


def unregister():
    import sys

    if _on_load_post in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_on_load_post)
    live = sys.modules.get(__name__ + ".blender.live")
    if live is not None:
        for lst, fn in ((bpy.app.handlers.frame_change_post, live.on_frame_change),
                        (bpy.app.handlers.depsgraph_update_post, live.on_depsgraph_update)):
            while fn in lst:
                lst.remove(fn)
    bake = sys.modules.get(__name__ + ".blender.bake")
    if bake is not None:
        bake.drop_held()
    properties.unregister_properties()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
