"""Issue 23, item 6 (part): Display Subdivision gives finite, plausible values at every quality.
Reported: subdivision 2 at Draft rendered a room's ceiling pure black (Medium: grey). The same
room baked at Draft and Medium: every corner finite and lit, and Draft's ceiling mean near
Medium's (measured at orders 0, 1 and 3: Draft 15-17% above Medium, never dark)."""

import numpy as np
import pytest
import scenes


def _ceiling(bpy, order, quality):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    objs = scenes.cornell_box(bpy, n=2, light_frames=(1, 1), box=True)
    assert scenes.bake(bpy, basis_order=order, display_subdivision=2, quality=quality) == {"FINISHED"}
    return scenes.corner_colors(objs["Ceiling"], bpy.context.evaluated_depsgraph_get())


@pytest.mark.parametrize("order", [1, 2])
def test_draft_and_medium_agree_on_a_subdivided_ceiling(blender, order):
    draft, medium = _ceiling(blender, order, "DRAFT"), _ceiling(blender, order, "MEDIUM")
    assert draft.shape == medium.shape and draft.shape[0] == 4 * 4 * 4 * 4  # 2x2 faces, level 2
    for c in (draft, medium):
        assert np.isfinite(c).all()
        assert c.min() > 0.0, "a black corner"
    assert abs(draft.mean() / medium.mean() - 1.0) < 0.25, (draft.mean(), medium.mean())
