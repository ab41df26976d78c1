"""N-gons and triangles bake; a numeric check against a closed-form form factor."""

import math

import numpy as np
import pytest
import scenes


def test_ngons_and_triangles_bake_and_map_back_to_loops(blender):
    bpy = blender
    white = scenes.material(bpy, "White", (0.6, 0.6, 0.6))
    # A regular hexagon (one n-gon) centred under the light, a concave L n-gon, and a triangle fan.
    ang = np.linspace(0, 2 * np.pi, 7)[:-1]
    hexagon = np.stack([0.5 * np.cos(ang), 0.5 * np.sin(ang), np.zeros(6)], axis=1)
    hexo = scenes.mesh_object(bpy, "Hexagon", hexagon, [tuple(range(6))], white)
    ell = [(1, 0, 0), (3, 0, 0), (3, 1, 0), (2, 1, 0), (2, 2, 0), (1, 2, 0)]
    scenes.mesh_object(bpy, "Ell", ell, [tuple(range(6))], white)
    fan = [(-1, -1, 0), (-2, -1, 0), (-2, -2, 0), (-1, -2, 0)]
    tris = scenes.mesh_object(bpy, "Tris", fan, [(0, 1, 2), (0, 2, 3)], white)
    scenes.emitter_quad(bpy, "Light", 0.5, 1.0, 5.0)
    assert scenes.bake(bpy, basis_order=2, frame_start=1, frame_end=1, use_scene_range=False) == {"FINISHED"}
    hx = scenes.stored(hexo.data, 1)
    assert hx.shape == (6, 3)
    # Six-fold symmetry under a square light: corners at 0/180 deg match, all within a few %.
    assert hx[0].mean() == pytest.approx(hx[3].mean(), rel=0.02)
    assert hx.mean(axis=1).min() > 0.85 * hx.mean(axis=1).max()
    ell_vals = scenes.stored(bpy.data.objects["Ell"].data, 1)
    assert ell_vals.shape == (6, 3) and ell_vals.min() > 0
    # The reflex corner (2,1) is nearer the light than the far corner (3,0).
    assert ell_vals[3].mean() > ell_vals[1].mean()
    assert scenes.stored(tris.data, 1).shape == (6, 3)
    assert scenes.stored(tris.data, 1).min() > 0


def test_floor_under_a_square_emitter_matches_the_closed_form(blender):
    """Emitter a x a at height h facing down over a floor (reflectance rho, nothing else): at the
    point under its centre B = rho E F with F = 4 F_corner(a/2, a/2, h) (Howell C-11), so the
    stored B/pi = rho L F for an emission strength L."""
    bpy = blender
    rho, strength, a, h = 0.5, 4.0, 0.6, 0.8
    floor_mat = scenes.material(bpy, "Floor", (rho, rho, rho))
    verts, faces = scenes.grid_quad((-1, -1, 0), (2, 0, 0), (0, 2, 0), 4)
    floor = scenes.mesh_object(bpy, "Floor", verts, faces, floor_mat)
    scenes.emitter_quad(bpy, "Light", a, h, strength)
    assert scenes.bake(bpy, basis_order=2, quality="HIGH", frame_start=1, frame_end=1,
                       use_scene_range=False) == {"FINISHED"}
    values = scenes.stored(floor.data, 1)
    me = floor.data
    centre = [i for i, lp in enumerate(me.loops) if me.vertices[lp.vertex_index].co.length < 1e-6]
    assert len(centre) == 4
    form_factor = 4 * scenes.square_form_factor(a / 2, a / 2, h)
    expected = rho * strength * form_factor
    got = values[centre].mean()
    assert got == pytest.approx(expected, rel=0.03), (got, expected)
    # And at a floor corner, farther away: F from four rectangles by superposition.
    corner = [i for i, lp in enumerate(me.loops)
              if tuple(round(c, 6) for c in me.vertices[lp.vertex_index].co) == (-1.0, -1.0, 0.0)]
    x0, x1 = 1 - a / 2, 1 + a / 2
    f = (scenes.square_form_factor(x1, x1, h) - 2 * scenes.square_form_factor(x0, x1, h)
         + scenes.square_form_factor(x0, x0, h))
    assert values[corner].mean() == pytest.approx(rho * strength * f, rel=0.05)
    assert math.isfinite(got)
