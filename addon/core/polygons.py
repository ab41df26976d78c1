"""Faces for the library: triangles and flat convex quads as they are, everything else split into
triangles, with the map that brings per-corner results back to the mesh's loops.

- A quad that is concave or bent is split into Blender's own two triangles (its
  ``loop_triangles``: (0,1,2), (0,2,3), or (0,1,3), (1,2,3) when the first pair faces opposite
  ways). The library models a quad as the bilinear patch X(s,t), which folds over when the quad is
  concave and is a different surface from the two triangles Blender renders when it is bent (its
  normal at a corner is the plane of that corner's two edges): Suzanne's flat bake was 18.6% from
  Cycles as bilinear quads and 4.3% as Blender's triangles (docs/validation-real.md, "Bent
  quads"). A quad counts as bent when its two triangles' normals differ by more than
  ``BEND_LIMIT_DEGREES``; flatter quads (a room's walls) keep one element.
- An n-gon (5+ corners) is ear-clipped in its best-fit plane (Newell normal); a convex n-gon
  gives the same triangles as a fan from its first corner. If ear clipping fails (self-intersecting
  outline) the n-gon falls back to a fan.
- A loop of a split polygon takes the value of the first triangle that holds it, as Cycles bakes
  a colour attribute (the differential test in docs/validation-real.md: 2.4% against 24% for the
  last triangle and 12% for the mean).

Triangles keep the winding of their source face, so they keep its front side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Beyond this bend between its two triangles a quad is split: the bilinear patch's corner normals
# then differ from the triangles' by at most this, under 1% of the irradiance at 60 degrees'
# incidence (tan 60 x 0.25 degrees), and a quad this flat costs one element instead of two.
BEND_LIMIT_DEGREES = 0.25


@dataclass
class FaceSplit:
    """Library faces made from a mesh's polygons and the way back to its loops."""

    face_sizes: np.ndarray      # (F',) uint32, 3 or 4
    face_indices: np.ndarray    # (sum face_sizes,) uint32 vertex indices
    source_face: np.ndarray     # (F',) int64: the polygon each library face comes from
    corner_loop: np.ndarray     # (sum face_sizes,) int64: the mesh loop of each library corner
    n_loops: int
    split_polygons: int         # polygons that were split (n-gons, concave and bent quads)
    loop_corner: np.ndarray | None = None  # (n_loops,) int64: each loop's first library corner

    @property
    def identity(self) -> bool:
        """True when library faces are the polygons themselves (no polygon was split)."""
        return self.split_polygons == 0

    def fits(self, face_sizes: np.ndarray, face_indices: np.ndarray) -> bool:
        """True when these faces split a mesh of these polygons (sizes and loop vertex indices):
        the same loops, each on the same vertex, and every source polygon there."""
        face_indices = np.asarray(face_indices, np.int64)
        return (self.n_loops == len(face_indices) and len(face_sizes) > self.source_face.max(initial=-1)
                and bool((self.face_indices == face_indices[self.corner_loop]).all()))

    def to_loops(self, corner_values: np.ndarray) -> np.ndarray:
        """Per-library-corner values (C', k) to per-loop values (n_loops, k): each loop takes its
        first library corner's (the first triangle holding it, as Cycles does)."""
        corner_values = np.asarray(corner_values)
        if self.identity:
            return corner_values.astype(np.float32, copy=True)
        return corner_values[self.loop_corner].astype(np.float32)


def newell_normal(points: np.ndarray) -> np.ndarray:
    """Area-weighted normal of a polygon (Newell's method); its length is twice the area."""
    nxt = np.roll(points, -1, axis=0)
    return np.cross(points, nxt).sum(axis=0)


def _plane_coords(points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """2D coordinates of points in the plane of `normal`, counter-clockwise seen from its front."""
    n = normal / np.linalg.norm(normal)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(helper, n)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return np.stack([points @ u, points @ v], axis=1)


def _cross2(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _inside_triangle(p, a, b, c, eps) -> bool:
    return _cross2(a, b, p) > eps and _cross2(b, c, p) > eps and _cross2(c, a, p) > eps


def ear_clip(points: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles (indices into `points`, counter-clockwise about the Newell normal) of a simple
    polygon; a fan from corner 0 when the polygon is degenerate or not simple."""
    n = len(points)
    fan = [(0, i, i + 1) for i in range(1, n - 1)]
    normal = newell_normal(points)
    if not np.isfinite(normal).all() or np.linalg.norm(normal) == 0.0:
        return fan
    p2 = _plane_coords(points, normal)
    scale = float(np.ptp(p2, axis=0).max()) or 1.0
    eps = 1e-12 * scale * scale
    idx = list(range(n))
    tris = []
    guard = 0
    while len(idx) > 3:
        guard += 1
        if guard > 2 * n * n:
            return fan
        m = len(idx)
        clipped = False
        for k in range(m):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % m]
            a, b, c = p2[i0], p2[i1], p2[i2]
            if _cross2(a, b, c) <= eps:
                continue  # reflex or flat corner
            if any(_inside_triangle(p2[j], a, b, c, -eps) and j not in (i0, i1, i2) for j in idx):
                continue
            tris.append((i0, i1, i2))
            idx.pop(k)
            clipped = True
            break
        if not clipped:
            return fan
    tris.append((idx[0], idx[1], idx[2]))
    return tris


def blender_quad_normals(q: np.ndarray):
    """For quads (Q,4,3): the area normals of Blender's two triangles of each and whether Blender
    flips the split to the (1,3) diagonal (the (0,2) triangles face opposite ways: a quad
    concave at corner 1 or 3), as ``loop_triangles`` (``mesh_tessellate``) splits a quad."""
    d1, d2, d3 = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0], q[:, 3] - q[:, 0]
    a, b = np.cross(d1, d2), np.cross(d2, d3)
    flip = np.einsum("qc,qc->q", a, -b) > 0.0
    # Flipped: triangles (0,1,3) and (1,2,3).
    fa = np.cross(d1, d3)
    fb = np.cross(q[:, 2] - q[:, 1], q[:, 3] - q[:, 1])
    return np.where(flip[:, None], fa, a), np.where(flip[:, None], fb, b), flip


def bend_degrees(na: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """The angle between normals (Q,3) per row, in degrees (0 where either is zero)."""
    la, lb = np.linalg.norm(na, axis=1), np.linalg.norm(nb, axis=1)
    ok = (la > 0.0) & (lb > 0.0)
    cos = np.einsum("qc,qc->q", na, nb) / np.where(ok, la * lb, 1.0)
    return np.where(ok, np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))), 0.0)


def split_faces(vertices: np.ndarray, face_sizes: np.ndarray, face_indices: np.ndarray) -> FaceSplit:
    """Split a mesh's polygons (sizes and concatenated vertex indices, in loop order)."""
    vertices = np.asarray(vertices, np.float64)
    face_sizes = np.asarray(face_sizes, np.int64)
    face_indices = np.asarray(face_indices, np.int64)
    if (face_sizes < 3).any():
        bad = int(np.flatnonzero(face_sizes < 3)[0])
        raise ValueError(f"face {bad} has {face_sizes[bad]} corners; a face needs at least 3")
    starts = np.concatenate([[0], np.cumsum(face_sizes)[:-1]]).astype(np.int64)
    n_loops = int(face_sizes.sum())
    split = np.zeros(len(face_sizes), bool)
    split[face_sizes > 4] = True
    quads = np.flatnonzero(face_sizes == 4)
    flipped = np.zeros(len(face_sizes), bool)
    if len(quads):
        q = vertices[face_indices[starts[quads][:, None] + np.arange(4)]]  # (Q,4,3)
        tri_a, tri_b, flip = blender_quad_normals(q)
        flipped[quads] = flip
        # Concave: a corner turns against the Newell normal.
        nrm = np.cross(q, np.roll(q, -1, axis=1)).sum(axis=1)
        e_in = q - np.roll(q, 1, axis=1)
        e_out = np.roll(q, -1, axis=1) - q
        turn = np.einsum("qkc,qc->qk", np.cross(e_in, e_out), nrm)
        concave = (turn < 0.0).any(axis=1) & (np.linalg.norm(nrm, axis=1) > 0.0)
        split[quads] = concave | (bend_degrees(tri_a, tri_b) > BEND_LIMIT_DEGREES)
    if not split.any():
        return FaceSplit(
            face_sizes=face_sizes.astype(np.uint32),
            face_indices=face_indices.astype(np.uint32),
            source_face=np.arange(len(face_sizes), dtype=np.int64),
            corner_loop=np.arange(n_loops, dtype=np.int64),
            n_loops=n_loops,
            split_polygons=0,
        )
    out_sizes, out_loops, out_source = [], [], []
    for f in range(len(face_sizes)):
        s, n = int(starts[f]), int(face_sizes[f])
        loops = np.arange(s, s + n)
        if not split[f]:
            out_sizes.append(n)
            out_loops.append(loops)
            out_source.append(f)
            continue
        if n == 4:
            tris = [(0, 1, 3), (1, 2, 3)] if flipped[f] else [(0, 1, 2), (0, 2, 3)]
        else:
            tris = ear_clip(vertices[face_indices[loops]])
        for t in tris:
            out_sizes.append(3)
            out_loops.append(loops[list(t)])
            out_source.append(f)
    corner_loop = np.concatenate(out_loops).astype(np.int64)
    _, loop_corner = np.unique(corner_loop, return_index=True)
    return FaceSplit(
        face_sizes=np.asarray(out_sizes, np.uint32),
        face_indices=face_indices[corner_loop].astype(np.uint32),
        source_face=np.asarray(out_source, np.int64),
        corner_loop=corner_loop,
        n_loops=n_loops,
        split_polygons=int(split.sum()),
        loop_corner=loop_corner,
    )


def face_areas(vertices: np.ndarray, face_sizes: np.ndarray, face_indices: np.ndarray) -> np.ndarray:
    """Area of each face (half the Newell normal's length), in the vertices' space."""
    vertices = np.asarray(vertices, np.float64)
    face_sizes = np.asarray(face_sizes, np.int64)
    starts = np.concatenate([[0], np.cumsum(face_sizes)[:-1]]).astype(np.int64)
    areas = np.zeros(len(face_sizes))
    for n in np.unique(face_sizes):
        sel = np.flatnonzero(face_sizes == n)
        p = vertices[np.asarray(face_indices, np.int64)[starts[sel][:, None] + np.arange(n)]]
        areas[sel] = 0.5 * np.linalg.norm(np.cross(p, np.roll(p, -1, axis=1)).sum(axis=1), axis=1)
    return areas


def degenerate_faces(vertices, face_sizes, face_indices, fraction: float = 1e-12) -> np.ndarray:
    """Faces whose area is below `fraction` x the squared bounding-box diagonal (the library's
    rule: it skips them and shows their own exitance)."""
    vertices = np.asarray(vertices, np.float64)
    if len(vertices) == 0:
        return np.zeros(0, np.int64)
    diag2 = float(((vertices.max(axis=0) - vertices.min(axis=0)) ** 2).sum())
    areas = face_areas(vertices, face_sizes, face_indices)
    return np.flatnonzero(~(areas > fraction * diag2))
