"""Where a flat-shaded Suzanne differs from Cycles, and how much of it is the quads (issue 19).

    .venv/bin/python -m tools.bend_error [--samples 512] [--smooth]

The scene of tests/python/test_smooth_shading.py (Suzanne on a floor under a Point light, flat
shaded), baked by the add-on and by Cycles' DIFFUSE bake, twice: as modelled (468 quads, median
bend 8 degrees between a quad's two triangles), and as the triangles Blender renders (a mesh
made of the first mesh's own ``loop_triangles``, in their order). Blender renders, and Cycles
bakes, a quad as those two triangles; the library takes it as the bilinear patch through its
four corners, a different surface with a different normal at each corner.

Prints the error by the bend of the corner's quad (a markdown table), then each bake of the
triangles read back onto the quads' corners: a quad's corner takes the value of one triangle
holding it (the first, or the last, in ``loop_triangles`` order) or their mean. Cycles' bake of
the quads equals its bake of the triangles read with the first triangle to within its noise:
that is how Cycles writes a quad's corners, and what the library would bake if it split bent
quads the same way. The add-on now does (``addon/core/polygons.py``), so the first table shows
the split quads' error.

``--smooth`` then bakes the model smooth shaded and prints where its error against Cycles'
per-vertex mean sits: at vertices whose faces all face the light, all face away, or both (the
light's terminator crosses the vertex).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def bend(mesh, p) -> float:
    """Degrees between the normals of quad `p`'s triangles (0, 1, 2) and (0, 2, 3); 0 for others."""
    if len(p.vertices) != 4:
        return 0.0
    v = [np.array(mesh.vertices[i].co) for i in p.vertices]
    n1, n2 = np.cross(v[1] - v[0], v[2] - v[0]), np.cross(v[2] - v[0], v[3] - v[0])
    c = n1 @ n2 / (np.linalg.norm(n1) * np.linalg.norm(n2))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def rel_rms(a, b) -> float:
    return float(np.sqrt(((a - b) ** 2).mean()) / b.mean())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--samples", type=int, default=512)
    p.add_argument("--smooth", action="store_true", help="also break down the smooth-shaded bake's error")
    args = p.parse_args(argv)
    for d in (REPO, REPO / "tests" / "python"):
        sys.path.insert(0, str(d))
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="blender-user-"))
    import bpy
    import test_smooth_shading as scene
    from scenes import bake, stored

    import addon
    from tools import bakes

    addon.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    _, model = scene._scene(bpy, "suzanne")
    scene._shade(model, False)

    def both(seed=1):
        """(Cycles, ours) per corner of the model's mesh, channel 0."""
        bakes.cycles_bake(bpy, [model], args.samples, attr="Cycles", seed=seed)
        if bake(bpy, method="FULL") != {"FINISHED"}:
            raise SystemExit("bend_error: the bake failed")
        return (scene.stored_attr(model, "Cycles")[:, 0].astype(float),
                stored(model.data, 1)[:, 0].astype(float))

    quads = model.data
    quad_corners = [(poly.index, quads.loops[li].vertex_index) for poly in quads.polygons
                    for li in poly.loop_indices]
    bends = np.array([bend(quads, quads.polygons[f]) for f, _ in quad_corners])
    cycles, ours = both()
    bakes.cycles_bake(bpy, [model], args.samples, attr="Cycles", seed=2)
    noise = rel_rms(scene.stored_attr(model, "Cycles")[:, 0].astype(float), cycles) / np.sqrt(2)

    err = ours - cycles
    total = float((err ** 2).sum())
    print(f"Suzanne flat, {len(quads.polygons)} faces, against Cycles {args.samples} spp (its noise "
          f"{100 * noise:.1f}%): relative RMSE {100 * rel_rms(ours, cycles):.1f}%, by the bend of the "
          "corner's quad:\n")
    print("| bend of the quad | corners | share of the squared error | relative RMS error |")
    print("|---|---|---|---|")
    for lo, hi in ((0, 2), (2, 5), (5, 10), (10, 180)):
        m = (bends >= lo) & (bends < hi)
        print(f"| {lo}-{hi} degrees | {m.sum()} | {100 * (err[m] ** 2).sum() / total:.0f}% | "
              f"{100 * np.sqrt((err[m] ** 2).mean()) / cycles.mean():.1f}% |")

    # The same model as the triangles Blender renders, each knowing its quad.
    quads.calc_loop_triangles()
    tris = [(t.polygon_index, [quads.loops[li].vertex_index for li in t.loops])
            for t in quads.loop_triangles]
    mesh = bpy.data.meshes.new("Triangles")
    mesh.from_pydata([tuple(v.co) for v in quads.vertices], [], [v for _, v in tris])
    mesh.materials.append(quads.materials[0])
    model.data = mesh
    tri_cycles, tri_ours = both()
    holders: dict[tuple[int, int], list[int]] = {}   # (quad, vertex) -> the triangles' corners
    for poly in mesh.polygons:
        for li in poly.loop_indices:
            holders.setdefault((tris[poly.index][0], mesh.loops[li].vertex_index), []).append(li)
    print(f"\nThe triangles ({len(mesh.polygons)}) read back onto the quads' corners, against Cycles' "
          f"bake of the quads (ours of the triangles against Cycles' of the triangles: "
          f"{100 * rel_rms(tri_ours, tri_cycles):.1f}%):\n")
    print("| a quad's corner takes | Cycles (triangles) | ours (triangles) |")
    print("|---|---|---|")
    for rule, pick in (("the first triangle's", lambda c: c[:1]), ("the last triangle's", lambda c: c[-1:]),
                       ("their mean", lambda c: c)):
        read = [pick(holders[k]) for k in quad_corners]
        c = np.array([tri_cycles[r].mean() for r in read])
        o = np.array([tri_ours[r].mean() for r in read])
        print(f"| {rule} | {100 * rel_rms(c, cycles):.1f}% | {100 * rel_rms(o, cycles):.1f}% |")
    if args.smooth:
        model.data = quads
        scene._shade(model, True)
        smooth_breakdown(bpy, model, *both())
    return 0


def smooth_breakdown(bpy, model, cycles, ours) -> None:
    """Per vertex, ours against the mean of Cycles' loops, by how the vertex's faces face the lamp."""
    me = model.data
    loop_vertex = np.array([lp.vertex_index for lp in me.loops])
    n = len(me.vertices)
    count = np.maximum(np.bincount(loop_vertex, minlength=n), 1)
    ref = np.bincount(loop_vertex, cycles, n) / count
    got = np.bincount(loop_vertex, ours, n) / count
    m = np.array(model.matrix_world)
    lamp = np.array(bpy.data.objects["Lamp"].matrix_world.translation)
    co = np.array([m[:3, :3] @ np.array(v.co) + m[:3, 3] for v in me.vertices])
    toward, away = np.zeros(n, bool), np.zeros(n, bool)
    for poly in me.polygons:
        normal = m[:3, :3] @ np.array(poly.normal)
        for v in poly.vertices:
            (toward if normal @ (lamp - co[v]) >= 0.0 else away)[v] = True
    err = got - ref
    total = float((err ** 2).sum())
    print(f"\nSmooth shaded, {n} vertices, ours against the mean of Cycles' loops per vertex: relative "
          f"RMSE {100 * np.sqrt((err ** 2).mean()) / ref.mean():.1f}%, by the vertex's faces:\n")
    print("| the vertex's faces | vertices | share of squared error | relative RMS error | ours / Cycles |")
    print("|---|---|---|---|---|")
    for name, sel in (("all face the lamp", toward & ~away), ("some face it, some away", toward & away),
                      ("all face away", away & ~toward)):
        print(f"| {name} | {sel.sum()} | {100 * (err[sel] ** 2).sum() / total:.0f}% | "
              f"{100 * np.sqrt((err[sel] ** 2).mean()) / ref.mean():.1f}% | "
              f"{got[sel].sum() / ref[sel].sum():.3f} |")


if __name__ == "__main__":
    raise SystemExit(main())
