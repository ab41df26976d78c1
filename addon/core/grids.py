"""Display subdivision: a finer mesh over the library's faces on which the radiosity polynomial
is evaluated (``Session.eval``) at every corner.

Level L cuts each face into a 2^L x 2^L grid in its parameters: a quad into bilinear sub-quads at
(s,t) = (i/k, j/k), a triangle into k^2 sub-triangles on its barycentric lattice (k = 2^L). The
triangle's (s,t) follow the library's map, the quad (P0, P1, P2, P2): w0 = (1-s)(1-t),
w1 = s(1-t), w2 = t, so s = w1 / (1 - t) (any s at the apex; 0.5 is used).

Points on an edge are shared by the faces on both sides (welded by the edge's two vertices and
the step along it), so the copy shades smoothly where the source mesh did.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Grid:
    vertices: np.ndarray      # (V',3) float64, object space
    face_sizes: np.ndarray    # (F',) uint32
    face_indices: np.ndarray  # (C',) uint32
    source_face: np.ndarray   # (F',) int64: library face of each grid face
    corner_face: np.ndarray   # (C',) int64: library face of each grid corner
    corner_st: np.ndarray     # (C',2) float64: (s,t) of each grid corner in its library face
    corner_weights: np.ndarray  # (C',4) float64: weights of the library face's corners (a triangle's 4th: 0)
    corner_source: np.ndarray   # (C',4) int64: library corner index each weight applies to

    def interpolate(self, corner_values: np.ndarray) -> np.ndarray:
        """Per-library-corner values (C,k) to per-grid-corner values (C',k)."""
        v = np.asarray(corner_values, np.float64)
        return np.einsum("cw,cwk->ck", self.corner_weights, v[self.corner_source])


def _lattice(n: int, k: int):
    """Lattice points (i,j), their weights, their class, and the sub-faces, for a face of n corners."""
    pts = []
    if n == 4:
        for j in range(k + 1):
            for i in range(k + 1):
                pts.append((i, j))
    else:
        for j in range(k + 1):
            for i in range(k + 1 - j):
                pts.append((i, j))
    where = {p: q for q, p in enumerate(pts)}
    weights = np.zeros((len(pts), 4))
    st = np.zeros((len(pts), 2))
    # class: ("c", corner) | ("e", c0, c1, m) | ("i",)
    cls = []
    for q, (i, j) in enumerate(pts):
        s, t = i / k, j / k
        if n == 4:
            weights[q] = [(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t]
            st[q] = (s, t)
            corners = {(0, 0): 0, (k, 0): 1, (k, k): 2, (0, k): 3}
            if (i, j) in corners:
                cls.append(("c", corners[(i, j)]))
            elif j == 0:
                cls.append(("e", 0, 1, i))
            elif i == k:
                cls.append(("e", 1, 2, j))
            elif j == k:
                cls.append(("e", 3, 2, i))
            elif i == 0:
                cls.append(("e", 0, 3, j))
            else:
                cls.append(("i",))
        else:
            w1, w2 = s, t
            weights[q] = [1 - w1 - w2, w1, w2, 0.0]
            st[q] = (w1 / (1 - w2) if w2 < 1 else 0.5, w2)
            corners = {(0, 0): 0, (k, 0): 1, (0, k): 2}
            if (i, j) in corners:
                cls.append(("c", corners[(i, j)]))
            elif j == 0:
                cls.append(("e", 0, 1, i))
            elif i + j == k:
                cls.append(("e", 1, 2, j))
            elif i == 0:
                cls.append(("e", 0, 2, j))
            else:
                cls.append(("i",))
    faces = []
    if n == 4:
        for j in range(k):
            for i in range(k):
                faces.append((where[(i, j)], where[(i + 1, j)], where[(i + 1, j + 1)], where[(i, j + 1)]))
    else:
        for j in range(k):
            for i in range(k - j):
                faces.append((where[(i, j)], where[(i + 1, j)], where[(i, j + 1)]))
                if i + j <= k - 2:
                    faces.append((where[(i + 1, j)], where[(i + 1, j + 1)], where[(i, j + 1)]))
    return np.clip(weights, 0.0, 1.0), st, cls, faces


def subdivide(vertices: np.ndarray, face_sizes: np.ndarray, face_indices: np.ndarray, level: int) -> Grid:
    """The display grid of `level` (0 = the faces themselves) over faces of 3 or 4 corners."""
    vertices = np.asarray(vertices, np.float64)
    face_sizes = np.asarray(face_sizes, np.int64)
    face_indices = np.asarray(face_indices, np.int64)
    if ((face_sizes != 3) & (face_sizes != 4)).any():
        raise ValueError("display subdivision needs faces of 3 or 4 corners")
    k = 2**level
    starts = np.concatenate([[0], np.cumsum(face_sizes)[:-1]]).astype(np.int64)
    n_v = len(vertices)
    # Edge points are keyed (a, b, m) with a < b: collect them first, then number them.
    parts = []
    edge_keys = []
    interior_count = 0
    for n in (3, 4):
        sel = np.flatnonzero(face_sizes == n)
        if not len(sel):
            continue
        weights, st, cls, subfaces = _lattice(n, k)
        vid = face_indices[starts[sel][:, None] + np.arange(n)]  # (P,n)
        ids = np.full((len(sel), len(cls)), -1, np.int64)
        kinds = np.zeros(len(cls), np.int64)  # 0 corner, 1 edge, 2 interior
        edge_cols = []
        interior_cols = []
        for q, c in enumerate(cls):
            if c[0] == "c":
                ids[:, q] = vid[:, c[1]]
            elif c[0] == "e":
                kinds[q] = 1
                edge_cols.append(q)
                _, c0, c1, m = c
                a, b = vid[:, c0], vid[:, c1]
                swap = a > b
                key = np.stack([np.where(swap, b, a), np.where(swap, a, b), np.where(swap, k - m, m)], axis=1)
                edge_keys.append((len(parts), q, key))
            else:
                kinds[q] = 2
                interior_cols.append(q)
        if interior_cols:
            n_int = len(sel) * len(interior_cols)
            serial = np.arange(n_int).reshape(len(sel), len(interior_cols))
            ids[:, interior_cols] = -2 - (interior_count + serial)
            interior_count += n_int
        parts.append(dict(sel=sel, n=n, weights=weights, st=st, subfaces=np.asarray(subfaces),
                          ids=ids, vid=vid))
    # Number the edge points (after the mesh's vertices), then the interior points.
    if edge_keys:
        all_keys = np.concatenate([key for _, _, key in edge_keys])
        uniq, inverse = np.unique(all_keys, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        pos = 0
        for pi, q, key in edge_keys:
            parts[pi]["ids"][:, q] = n_v + inverse[pos:pos + len(key)]
            pos += len(key)
        n_edge = len(uniq)
    else:
        n_edge = 0
    positions = np.zeros((n_v + n_edge + interior_count, 3))
    positions[:n_v] = vertices
    out_faces = []
    for part in parts:
        ids = part["ids"]
        interior = ids <= -2
        ids[interior] = n_v + n_edge + (-2 - ids[interior])
        # Positions: corners are the mesh's own; others from the face's corner weights.
        pts = np.einsum("qw,pwc->pqc", part["weights"][:, : part["n"]], vertices[part["vid"]])
        positions[ids.reshape(-1)] = pts.reshape(-1, 3)
        positions[part["vid"].reshape(-1)] = vertices[part["vid"].reshape(-1)]
        out_faces.append(part)
    # Assemble faces in library-face order.
    order_faces, sizes, corners, corner_face, corner_st, corner_w, corner_src = [], [], [], [], [], [], []
    for part in out_faces:
        sel, n, sub = part["sel"], part["n"], part["subfaces"]
        ns, m = sub.shape
        face_of = np.repeat(sel, ns)
        order_faces.append(face_of)
        sizes.append(np.full(len(face_of), m))
        corners.append(part["ids"][:, sub].reshape(-1, m))
        corner_face.append(np.repeat(face_of, m).reshape(-1, m))
        corner_st.append(np.broadcast_to(part["st"][sub], (len(sel), ns, m, 2)).reshape(-1, m, 2))
        corner_w.append(np.broadcast_to(part["weights"][sub], (len(sel), ns, m, 4)).reshape(-1, m, 4))
        src = starts[sel][:, None] + np.minimum(np.arange(4), n - 1)  # (P,4) library corners
        corner_src.append(np.broadcast_to(src[:, None, None, :], (len(sel), ns, m, 4)).reshape(-1, m, 4))
    if not order_faces:
        return Grid(np.zeros((0, 3)), np.zeros(0, np.uint32), np.zeros(0, np.uint32), np.zeros(0, np.int64),
                    np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 4)), np.zeros((0, 4), np.int64))
    face_of = np.concatenate(order_faces)
    order = np.argsort(face_of, kind="stable")
    sizes = np.concatenate(sizes)[order]
    # Faces of both kinds are stacked per kind; reorder corner blocks by face.
    flat = []
    for arrs in (corners, corner_face, corner_st, corner_w, corner_src):
        rows = [row for a in arrs for row in a]
        flat.append([rows[i] for i in order])
    corners_l, cface_l, cst_l, cw_l, csrc_l = flat
    face_indices_out = np.concatenate(corners_l)
    used, remap = np.unique(face_indices_out, return_inverse=True)
    return Grid(
        vertices=positions[used],
        face_sizes=sizes.astype(np.uint32),
        face_indices=remap.reshape(-1).astype(np.uint32),
        source_face=face_of[order],
        corner_face=np.concatenate(cface_l).astype(np.int64),
        corner_st=np.concatenate(cst_l),
        corner_weights=np.concatenate(cw_l),
        corner_source=np.concatenate(csrc_l).astype(np.int64),
    )
