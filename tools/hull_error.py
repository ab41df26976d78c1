"""Where the per-corner error of an object made of closed pieces that pass through each other
sits (issue 19; pybullet's teddy is 15 convex hulls of one object): the corners classed by the
signed distance of their vertex to the nearest other piece (negative inside it) and by the
buried share of their face, with the corner gather, the brute force from the same solution
(examples/corner_truth.rs) and Cycles side by side; and the corners black in one of the gather
and Cycles and lit in the other (below 5% and above 20% of the object's mean).

    cargo run --release --example corner_truth -- SCENE.json truth.csv --rays 1024 --object Teddy
    .venv/bin/python -m tools.hull_error SCENE.json truth.csv CYCLES.json --object Teddy

A *piece* is a set of the object's faces connected through shared vertices (welded within 1e-6
of the object's size). A point is inside another piece when that piece's generalized winding
number there (its triangles' signed solid angles over 4 pi) is at least 1/2. A face's buried
fraction is the share of 45 points spread over it that are inside another piece.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from tools.corner_error import rel_rmse

FACE_SAMPLES = 8  # points per edge of the barycentric grid spread over each face


def world_mesh(scene: dict, name: str) -> tuple[np.ndarray, list[list[int]]]:
    ob = next(o for o in scene["objects"] if o["name"] == name)
    m = np.asarray(ob.get("matrix", np.eye(4).ravel()), np.float64).reshape(4, 4)
    v = np.asarray(ob["vertices"], np.float64) @ m[:3, :3].T + m[:3, 3]
    return v, ob["faces"]


def pieces(v: np.ndarray, faces: list[list[int]]) -> np.ndarray:
    """The piece of every face (faces joined through shared, welded vertices)."""
    scale = np.linalg.norm(v.max(0) - v.min(0))
    key = np.round(v / (1e-6 * scale)).astype(np.int64)
    _, weld = np.unique(key, axis=0, return_inverse=True)
    parent = list(range(len(faces)))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    first = {}
    for f, face in enumerate(faces):
        for k in face:
            w = int(weld[k])
            if w in first:
                parent[find(f)] = find(first[w])
            else:
                first[w] = f
    roots = [find(f) for f in range(len(faces))]
    _, label = np.unique(roots, return_inverse=True)
    return label


def triangles(v: np.ndarray, faces: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles (n, 3, 3) and the face of each."""
    tris, owner = [], []
    for f, face in enumerate(faces):
        for k in range(1, len(face) - 1):
            tris.append(v[[face[0], face[k], face[k + 1]]])
            owner.append(f)
    return np.asarray(tris), np.asarray(owner)


def winding(tris: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Generalized winding number of the triangles at points p (m, 3) (Van Oosterom-Strackee)."""
    a = tris[None, :, 0, :] - p[:, None, :]
    b = tris[None, :, 1, :] - p[:, None, :]
    c = tris[None, :, 2, :] - p[:, None, :]
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    det = np.einsum("mnk,mnk->mn", a, np.cross(b, c))
    den = (
        la * lb * lc
        + np.einsum("mnk,mnk->mn", a, b) * lc
        + np.einsum("mnk,mnk->mn", b, c) * la
        + np.einsum("mnk,mnk->mn", c, a) * lb
    )
    return (2.0 * np.arctan2(det, den)).sum(axis=1) / (4.0 * np.pi)


def inside_other(tris, tri_piece, points, own_piece, chunk=256) -> np.ndarray:
    """Whether each point lies inside a piece other than `own_piece` (per point)."""
    out = np.zeros(len(points), bool)
    for c in np.unique(tri_piece):
        sel = own_piece != c
        if not sel.any():
            continue
        t = tris[tri_piece == c]
        lo, hi = t.reshape(-1, 3).min(0), t.reshape(-1, 3).max(0)
        idx = np.nonzero(sel & np.all((points >= lo) & (points <= hi), axis=1))[0]
        for s in range(0, len(idx), chunk):
            k = idx[s : s + chunk]
            out[k] |= winding(t, points[k]) >= 0.5
    return out


def point_triangle_distance(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Distance from the point p (3,) to each triangle of t (n, 3, 3)."""
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    d = np.einsum("nk,nk->n", p - a, n)
    q = p - d[:, None] * n
    inside = np.ones(len(t), bool)
    for x, y in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("nk,nk->n", np.cross(y - x, q - x), n) >= 0.0

    def segment(x, y):
        e = y - x
        s = np.clip(np.einsum("nk,nk->n", p - x, e) / np.einsum("nk,nk->n", e, e), 0.0, 1.0)
        return np.linalg.norm(p - (x + s[:, None] * e), axis=1)

    edges = np.minimum(np.minimum(segment(a, b), segment(b, c)), segment(c, a))
    return np.where(inside, np.abs(d), edges)


def distance_to_other(tris, tri_piece, points, own_piece) -> np.ndarray:
    """Distance from each point to the nearest triangle of another piece."""
    return np.array(
        [
            point_triangle_distance(p, tris[tri_piece != c]).min()
            for p, c in zip(points, own_piece, strict=True)
        ]
    )


def face_buried_fraction(v, faces, tris, tri_piece, face_piece) -> np.ndarray:
    n = FACE_SAMPLES
    grid = np.asarray([(i, j) for i in range(n + 1) for j in range(n + 1 - i)], np.float64) / n
    grid = grid * 0.98 + 0.01  # off the edges
    pts, who = [], []
    for f, face in enumerate(faces):
        a, b, c = v[face[0]], v[face[1]], v[face[-1]] if len(face) == 3 else v[face[2]]
        normal = np.cross(b - a, c - a)
        normal /= np.linalg.norm(normal)
        p = a + grid[:, :1] * (b - a) + grid[:, 1:] * (c - a)
        pts.append(p + normal * 1e-6)
        who.append(np.full(len(p), f))
    pts, who = np.concatenate(pts), np.concatenate(who)
    buried = inside_other(tris, tri_piece, pts, face_piece[who])
    return np.bincount(who, buried, len(faces)) / np.bincount(who, minlength=len(faces))


def report(title, classes, columns, mean):
    print(f"\n{title}")
    head = " | ".join(f"{c} vs Cycles: RMS, ratio" for c, _ in columns[1:])
    print(f"| class | corners | share of sq. error (gather) | {head} |")
    print("|---|---|---|" + "---|" * (len(columns) - 1))
    cyc = columns[0][1]
    ours = columns[1][1]
    total = float(np.sum((ours - cyc) ** 2))
    for name, m in classes:
        if not m.any():
            continue
        share = float(np.sum((ours[m] - cyc[m]) ** 2)) / total
        cells = []
        for _, x in columns[1:]:
            ratio = f"{x[m].mean() / cyc[m].mean():.3f}" if cyc[m].mean() > 0 else "-"
            cells.append(f"{100 * rel_rmse(x[m], cyc[m], mean):.1f}%, {ratio}")
        print(f"| {name} | {int(m.sum())} | {100 * share:.0f}% | " + " | ".join(cells) + " |")


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("scene")
    p.add_argument("truth")
    p.add_argument("cycles")
    p.add_argument("--object", default="Teddy")
    p.add_argument("--save", help="write the per-corner classes to this .npz")
    a = p.parse_args(argv)
    scene = json.loads(open(a.scene).read())
    ref = json.loads(open(a.cycles).read())
    order = [o["name"] for o in scene["objects"]]
    v, faces = world_mesh(scene, a.object)
    face_piece = pieces(v, faces)
    tris, tri_face = triangles(v, faces)
    tri_piece = face_piece[tri_face]
    print(f"{a.object}: {len(faces)} faces in {face_piece.max() + 1} pieces")

    rows = np.genfromtxt(a.truth, delimiter=",", names=True)
    r = rows[rows["object"] == order.index(a.object)]
    corner = r["corner"].astype(int)
    face = r["face"].astype(int)
    h_cyc = np.asarray(ref["objects"][a.object])[corner] / r["rho"]
    mean = float(h_cyc.mean())
    ours, bf = r["h_ours"], r["h_dir"] + r["h_ind"]
    # The corner's own vertex (the CSV holds the gather's point, a hair inside the face).
    vert = v[[faces[f][k] for f, k in zip(face, r["k"].astype(int), strict=True)]]
    x = np.stack([r["x"], r["y"], r["z"]], axis=1)
    n = np.stack([r["nx"], r["ny"], r["nz"]], axis=1)
    piece = face_piece[face]
    # The vertex's signed distance to the nearest other piece (negative inside one).
    inside = inside_other(tris, tri_piece, vert, piece)
    sd = np.where(inside, -1.0, 1.0) * distance_to_other(tris, tri_piece, vert, piece)
    frac = face_buried_fraction(v, faces, tris, tri_piece, face_piece)[face]
    lo, hi = 0.05 * mean, 0.2 * mean
    binary = ((ours < lo) & (h_cyc > hi)) | ((h_cyc < lo) & (ours > hi))
    black_cyc = h_cyc < 1e-3 * h_cyc.max()
    print(
        f"corners {len(r)}: vertex inside another piece {int(inside.sum())}, black in ours "
        f"{int((ours == 0).sum())}, black in Cycles {int(black_cyc.sum())}; on faces partly buried "
        f"{int(((frac > 0) & (frac < 1)).sum())}"
    )
    total = float(np.sum((ours - h_cyc) ** 2))
    for name, m in [
        ("black in Cycles, lit in ours", (h_cyc < lo) & (ours > hi)),
        ("lit in Cycles, black in ours", (ours < lo) & (h_cyc > hi)),
    ]:
        share = float(np.sum((ours[m] - h_cyc[m]) ** 2)) / total
        print(
            f"{name} (< 5% / > 20% of the mean): {int(m.sum())} corners, "
            f"{100 * share:.0f}% of the squared error"
        )
    others = ~binary
    print(
        f"all: gather {100 * rel_rmse(ours, h_cyc, mean):.2f}%, "
        f"brute force {100 * rel_rmse(bf, h_cyc, mean):.2f}%; "
        f"without those: gather {100 * np.sqrt(np.sum((ours - h_cyc)[others] ** 2) / len(r)) / mean:.2f}%"
    )
    columns = [("Cycles", h_cyc), ("gather", ours), ("brute force", bf)]
    if "h_ind2" in r.dtype.names and np.any(r["h_ind2"] != r["h_ind"]):
        columns.append(("brute force, near again", r["h_dir"] + r["h_ind2"]))
    mm = 1e-3
    report(
        f"{a.object}: by the vertex's signed distance to another piece (relative RMS of the object's "
        f"Cycles mean H {mean:.4f}; mean ratio)",
        [
            ("inside, deeper than 0.1 mm", sd < -0.1 * mm),
            ("inside, 0-0.1 mm", (sd >= -0.1 * mm) & (sd < 0)),
            ("outside, 0-0.1 mm", (sd >= 0) & (sd < 0.1 * mm)),
            ("outside, 0.1-1 mm", (sd >= 0.1 * mm) & (sd < 1 * mm)),
            ("outside, 1-10 mm", (sd >= 1 * mm) & (sd < 10 * mm)),
            ("outside, 10 mm or more", sd >= 10 * mm),
        ],
        columns,
        mean,
    )
    report(
        f"{a.object}: the same without the corners black in one and lit in the other",
        [
            ("within 1 mm of another piece", others & (np.abs(sd) < 1 * mm)),
            ("1 mm or more from another piece", others & (np.abs(sd) >= 1 * mm)),
        ],
        columns,
        mean,
    )
    free = sd >= 0
    report(
        f"{a.object}: vertices outside the other pieces, by the buried share of their face",
        [
            ("over 50%", free & (frac > 0.5)),
            ("1-50%", free & (frac > 0) & (frac <= 0.5)),
            ("none", free & (frac == 0)),
        ],
        columns,
        mean,
    )
    nz = n[:, 2]
    report(
        f"{a.object}: free corners by facing",
        [
            ("up (nz > 0.5)", free & (nz > 0.5)),
            ("side", free & (np.abs(nz) <= 0.5)),
            ("down (nz < -0.5)", free & (nz < -0.5)),
        ],
        columns,
        mean,
    )
    share = np.where(bf > 0, r["h_dir"] / np.maximum(bf, 1e-30), 0)
    report(
        f"{a.object}: free corners by direct share of H (brute force)",
        [
            ("< 1%", free & (share < 0.01)),
            ("1-30%", free & (share >= 0.01) & (share < 0.3)),
            (">= 30%", free & (share >= 0.3)),
        ],
        columns,
        mean,
    )
    if a.save:
        np.savez(
            a.save,
            corner=corner,
            face=face,
            piece=piece,
            sd=sd,
            frac=frac,
            h_cyc=h_cyc,
            ours=ours,
            bf=bf,
            h_dir=r["h_dir"],
            h_ours_dir=r["h_ours_dir"],
            n=n,
            x=x,
            vertex=vert,
            back=r["back"],
        )


if __name__ == "__main__":
    main()
