"""Where an object's per-corner error against Cycles goes (issue 19; written for the monastery):
the gather, the brute force from the same solution (examples/corner_truth.rs) and three Cycles
bakes of the same scene side by side, per class of corner.

    cargo run --release --example corner_truth -- SCENE.json truth.csv --rays 1024 --object NAME
    .venv/bin/python -m tools.validate_real --scene S --skip-ours --cycles-cache C --reference R
    .venv/bin/python -m tools.validate_real --scene S --skip-ours --cycles-cache C --reference R1 \\
        --one-sided
    .venv/bin/python -m tools.validate_real --scene S --skip-ours --cycles-cache C --reference RD \\
        --direct-only
    .venv/bin/python -m tools.error_budget SCENE.json truth.csv R/S_cycles.json \\
        --one-sided R1/S_cycles.json --direct RD/S_cycles.json --object NAME [--near near.csv]

The Cycles bakes: as artists bake (the Diffuse BSDF is two-sided: the back of an open sheet is
lit and reflects), with the receivers' back faces black (`--one-sided`, the library's surfaces),
and the direct light alone (`--direct-only`). Every figure is irradiance `H = B / rho`, relative
RMS of the object's mean `H` in the first (two-sided) bake. Per corner, the gather's error is cut
into steps, each the difference of two neighbours in the chain

    gather -> brute force from the solution -> brute force, direct at the vertex (Cycles'
    direct) -> [near hits gathered again] -> Cycles one-sided -> Cycles two-sided

so the steps add up to the error corner by corner (not their squares): `gather` is the gather's
own error against its solution, `point` what the corner's direct light changes between the
gathered point (inset into its face) and the vertex Cycles bakes, `polynomials` the indirect
light the brute force gains when hits nearer than `--reach` take `B` gathered again at the hit
point (from `--near`, a corner_truth run with `--near D`; only on its corners), `rest` the
brute force's indirect light against Cycles' one-sided indirect light after that, `two-sided`
the reference's back faces. The table gives each step's RMS per class, and the error left if the
step alone were removed (`without`).

A corner's classes: its piece (faces joined through shared, welded vertices), its face's
smallest angle (decimated meshes have long slivers), how far its gathered point lies from its
vertex, the share of its rays that meet a face from behind (the inside of an open shell), its
facing, and its direct share (Cycles).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from tools.hull_error import pieces, world_mesh


def rms(x, mean):
    return float(np.sqrt(np.mean(x**2)) / mean) if len(x) else float("nan")


def smallest_angles(v, faces) -> np.ndarray:
    out = []
    for f in faces:
        p = v[f]
        a = []
        for i in range(len(f)):
            e1, e2 = p[(i + 1) % len(f)] - p[i], p[i - 1] - p[i]
            c = e1 @ e2 / max(np.linalg.norm(e1) * np.linalg.norm(e2), 1e-300)
            a.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
        out.append(min(a))
    return np.asarray(out)


def load_cycles(path, name, corner, rho):
    return np.asarray(json.loads(open(path).read())["objects"][name])[corner] / rho


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("truth")
    p.add_argument("cycles", help="Cycles as baked (two-sided)")
    p.add_argument("--one-sided", required=True, help="Cycles with the receivers' backs black")
    p.add_argument("--direct", required=True, help="Cycles' direct light alone")
    p.add_argument("--object", default="Monastery")
    p.add_argument("--near", help="a corner_truth CSV with --near D (its corners only)")
    p.add_argument("--reach", default="n4self", help="the --near CSV's column of re-gathered hits")
    a = p.parse_args(argv)
    scene = json.loads(open(a.scene).read())
    order = [o["name"] for o in scene["objects"]]
    v, faces = world_mesh(scene, a.object)
    piece_of_face = pieces(v, faces)
    angle_of_face = smallest_angles(v, faces)

    rows = np.genfromtxt(a.truth, delimiter=",", names=True)
    r = rows[rows["object"] == order.index(a.object)]
    corner, face, rho = r["corner"].astype(int), r["face"].astype(int), r["rho"]
    c2 = load_cycles(a.cycles, a.object, corner, rho)
    c1 = load_cycles(a.one_sided, a.object, corner, rho)
    cd = load_cycles(a.direct, a.object, corner, rho)
    mean = float(np.asarray(json.loads(open(a.cycles).read())["objects"][a.object]).mean() / rho.mean())
    ours, bf_dir, bf_ind = r["h_ours"], r["h_dir"], r["h_ind"]
    bf_ind2 = bf_ind.copy()
    has_near = np.zeros(len(r), bool)
    if a.near:
        nr = np.genfromtxt(a.near, delimiter=",", names=True)
        nr = nr[nr["object"] == order.index(a.object)]
        at = {int(c): k for k, c in enumerate(corner)}
        for row in nr:
            k = at[int(row["corner"])]
            bf_ind2[k] = row[a.reach] - row["h_ind"] + bf_ind[k]  # same seed: the difference only
            has_near[k] = True

    # The chain, corner by corner.
    steps = {
        "gather": ours - (bf_dir + bf_ind),
        "point": bf_dir - cd,
        "polynomials": bf_ind - bf_ind2,
        "rest": bf_ind2 - (c1 - cd),
        "two-sided": c1 - c2,
    }
    total = ours - c2
    assert np.allclose(sum(steps.values()), total)

    vert = v[[faces[f][k] for f, k in zip(face, r["k"].astype(int), strict=True)]]
    x = np.stack([r["x"], r["y"], r["z"]], axis=1)
    offset = np.linalg.norm(x - vert, axis=1)
    nz = r["nz"]
    share = np.where(c2 > 0, cd / np.maximum(c2, 1e-30), 0.0)
    piece = piece_of_face[face]
    angle = angle_of_face[face]
    back = r["back"]

    if a.near:  # only the corners of the --near run: the others' polynomial step is unknown
        keep = has_near
        corner, ours, c2, total = corner[keep], ours[keep], c2[keep], total[keep]
        steps = {k: x[keep] for k, x in steps.items()}
        offset, nz, share = offset[keep], nz[keep], share[keep]
        piece, angle, back = piece[keep], angle[keep], back[keep]

    def table(title, classes):
        names = list(steps)
        print(f"\n{title}")
        head = " | ".join(names)
        print(f"| class | corners | share of sq. error | gather vs Cycles, ratio | {head} |")
        print("|---|---|---|---|" + "---|" * len(names))
        tot = float(np.sum(total**2))
        for name, m in classes:
            if not m.any():
                continue
            cells = [
                f"{100 * rms(steps[n][m], mean):.1f}% (w/o {100 * rms(total[m] - steps[n][m], mean):.1f}%)"
                for n in names
            ]
            share_ = 100 * float(np.sum(total[m] ** 2)) / tot
            ratio = ours[m].mean() / c2[m].mean()
            err = 100 * rms(total[m], mean)
            print(
                f"| {name} | {int(m.sum())} | {share_:.0f}% | {err:.1f}%, {ratio:.3f} | "
                + " | ".join(cells)
                + " |"
            )

    print(
        f"{a.object}: {len(corner)} corners, mean H (Cycles, all corners) {mean:.4f}"
        + (f"; near hits gathered again ({a.reach})" if a.near else "")
    )
    table("all", [("all", np.ones(len(corner), bool))])
    big = np.argsort([-np.sum(total[piece == c] ** 2) for c in range(piece.max() + 1)])[:4]
    table(
        "by piece (the largest shares)",
        [(f"piece {c}", piece == c) for c in big] + [("the others", ~np.isin(piece, big))],
    )
    table(
        "by the face's smallest angle",
        [("under 2 degrees", angle < 2), ("2-10", (angle >= 2) & (angle < 10)), ("10 or more", angle >= 10)],
    )
    table(
        "by the gathered point's distance from the vertex",
        [
            ("under 1 cm", offset < 0.01),
            ("1-3 cm", (offset >= 0.01) & (offset < 0.03)),
            ("3 cm or more", offset >= 0.03),
        ],
    )
    table(
        "by the share of rays meeting a back face",
        [("none", back == 0), ("under 20%", (back > 0) & (back < 0.2)), ("20% or more", back >= 0.2)],
    )
    table(
        "by facing",
        [("up (nz > 0.5)", nz > 0.5), ("side", np.abs(nz) <= 0.5), ("down (nz < -0.5)", nz < -0.5)],
    )
    table(
        "by Cycles' direct share",
        [
            ("under 1%", share < 0.01),
            ("1-50%", (share >= 0.01) & (share < 0.5)),
            ("50% or more", share >= 0.5),
        ],
    )


if __name__ == "__main__":
    main()
