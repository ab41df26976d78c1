"""Two-Sided Open Surfaces (``reflecting_backs``, issue 19) through the real add-on: a sheet's back
reflects what reaches it, as Cycles' diffuse surfaces do, only when the option is on."""

import numpy as np
import scenes


def _lamp_floor_and_sheet(bpy):
    """A 1 m lamp facing up at z = 0 beside a 1 m grey floor square (both facing up, so the floor
    gets no light from the lamp directly), under a 2 x 1 m grey sheet at z = 1 whose front faces
    up, away from both: whatever reaches the floor comes off the sheet's back."""
    grey = scenes.material(bpy, "Grey", (0.8, 0.8, 0.8))
    lamp_mat = scenes.material(bpy, "Lamp", (0.0, 0.0, 0.0), emission=(1.0, 1.0, 1.0), strength=10.0)
    v, f = scenes.grid_quad((0, 0, 0), (1, 0, 0), (0, 1, 0), 1)
    lamp = scenes.mesh_object(bpy, "Lamp", v, f, lamp_mat)
    v, f = scenes.grid_quad((1, 0, 0), (1, 0, 0), (0, 1, 0), 2)
    floor = scenes.mesh_object(bpy, "Floor", v, f, grey)
    v, f = scenes.grid_quad((0, 0, 1), (2, 0, 0), (0, 1, 0), 4)
    sheet = scenes.mesh_object(bpy, "Sheet", v, f, grey)
    return lamp, floor, sheet


def test_an_open_sheet_reflects_from_its_back_only_when_two_sided(blender):
    bpy = blender
    bpy.context.scene.frame_start = bpy.context.scene.frame_end = 1
    lamp, floor, sheet = _lamp_floor_and_sheet(bpy)
    assert scenes.bake(bpy, basis_order=1, reflecting_backs=False) == {"FINISHED"}
    one_sided = scenes.stored(floor.data, 1)
    front = scenes.stored(sheet.data, 1)
    assert np.all(one_sided == 0.0), "one-sided: light reached the floor"
    assert np.all(front == 0.0), "one-sided: the sheet's front, facing nothing, is lit"

    assert scenes.bake(bpy, basis_order=1, reflecting_backs=True) == {"FINISHED"}
    two_sided = scenes.stored(floor.data, 1)
    # The sheet's back over the lamp reaches about 0.8 x 10 x F (F ~ 0.2, a 1 m square 1 m
    # away): ~1.6; the floor, 1 m below it and beside the lamp, gets a share of that again.
    assert two_sided.mean() > 0.05, f"two-sided: the floor's mean {two_sided.mean()}"
    assert two_sided.max() < 1.6
    # What is read back is the sheet's front: still unlit.
    assert np.all(scenes.stored(sheet.data, 1) == 0.0), "two-sided: the sheet's front is lit"
    # The lamp shows its own radiance either way (black: it reflects nothing).
    np.testing.assert_allclose(scenes.stored(lamp.data, 1), 10.0, rtol=1e-3)
