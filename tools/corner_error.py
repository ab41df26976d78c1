"""Where the per-corner error against Cycles sits (issue 19): the corner gather's irradiance, the
brute-force irradiance from the same solution (examples/corner_truth.rs) and Cycles', per object
and by class of corner.

    cargo run --release --example corner_truth -- SCENE.json truth.csv --rays 1024 --near 0.05
    .venv/bin/python -m tools.corner_error truth.csv CYCLES.json [--object Bunny]

CYCLES.json is a reference as tools/validate_real.py --reference writes it (radiosity B per
library corner). Irradiance is compared (H = (B - E) / rho); the relative RMSE of H is that of B
on a receiver of one reflectance. Each table gives, per class, the corners, their share of the
object's squared error, the relative RMS error (of the object's mean) and the mean ratio.
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def load(truth, cycles):
    rows = np.genfromtxt(truth, delimiter=",", names=True)
    ref = json.loads(open(cycles).read())
    names = list(ref["objects"])
    scene = json.loads(open(cycles.replace("_cycles.json", "_scene.json")).read())
    order = [o["name"] for o in scene["objects"]]
    return rows, ref, names, order


def rel_rmse(a, b, mean):
    return float(np.sqrt(np.mean((a - b) ** 2)) / mean) if len(a) else float("nan")


def report(title, mask_sets, ours, cyc, mean):
    total = float(np.sum((ours - cyc) ** 2))
    print(f"\n{title}\n| class | corners | share of squared error | relative RMS error | mean ratio |")
    print("|---|---|---|---|---|")
    for name, m in mask_sets:
        if not m.any():
            continue
        share = float(np.sum((ours[m] - cyc[m]) ** 2)) / total
        ratio = float(ours[m].mean() / cyc[m].mean()) if cyc[m].mean() > 0 else float("nan")
        print(
            f"| {name} | {int(m.sum())} | {100 * share:.0f}% | {100 * rel_rmse(ours[m], cyc[m], mean):.1f}% "
            f"| {ratio:.3f} |"
        )


def bins(values, edges, fmt):
    out = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        out.append((fmt.format(lo, hi), (values >= lo) & (values < hi)))
    return out


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("truth")
    p.add_argument("cycles")
    p.add_argument("--object", action="append")
    a = p.parse_args(argv)
    rows, ref, names, order = load(a.truth, a.cycles)
    for name in a.object or names:
        o = order.index(name)
        r = rows[rows["object"] == o]
        b_cyc = np.asarray(ref["objects"][name])[r["corner"].astype(int)]
        rho = r["rho"]
        h_cyc = b_cyc / rho  # receivers emit nothing
        mean = float(h_cyc.mean())
        ours = r["h_ours"]
        bf = r["h_dir"] + r["h_ind"]
        bf2 = r["h_dir"] + r["h_ind2"]
        ours_ind = ours - r["h_ours_dir"]
        print(f"\n## {name}: {len(r)} corners, mean H (Cycles) {mean:.4f}")
        print(
            f"ours vs Cycles {100 * rel_rmse(ours, h_cyc, mean):.2f}% (mean ratio {ours.mean() / mean:.4f})"
        )
        print(
            f"brute force from the solution vs Cycles {100 * rel_rmse(bf, h_cyc, mean):.2f}% "
            f"(mean ratio {bf.mean() / mean:.4f})"
        )
        print(
            f"brute force, near hits gathered again, vs Cycles {100 * rel_rmse(bf2, h_cyc, mean):.2f}% "
            f"(mean ratio {bf2.mean() / mean:.4f})"
        )
        print(f"ours vs brute force (the gather's own error) {100 * rel_rmse(ours, bf, mean):.2f}%")
        print(
            f"  direct: ours vs brute force {100 * rel_rmse(r['h_ours_dir'], r['h_dir'], mean):.2f}%, "
            f"indirect {100 * rel_rmse(ours_ind, r['h_ind'], mean):.2f}%"
        )
        print(
            f"  mean direct share (brute force) {r['h_dir'].sum() / bf.sum():.3f}; back-face rays "
            f"{100 * r['back'].mean():.2f}%"
        )
        # The Cycles indirect: Cycles minus our brute-force direct (exact up to its noise).
        cyc_ind = h_cyc - r["h_dir"]
        print(
            "  indirect alone: brute force vs Cycles - direct "
            f"{100 * rel_rmse(r['h_ind'], cyc_ind, mean):.2f}%, "
            f"near gathered again {100 * rel_rmse(r['h_ind2'], cyc_ind, mean):.2f}%"
        )
        nz = r["nz"]
        facing = [("up (nz > 0.5)", nz > 0.5), ("side", np.abs(nz) <= 0.5), ("down (nz < -0.5)", nz < -0.5)]
        dir_share = np.where(bf > 0, r["h_dir"] / np.maximum(bf, 1e-30), 0)
        lit = bins(dir_share, [0, 0.01, 0.3, 0.6, 0.9, 1.01], "direct share {:.2f}-{:.2f}")
        near = bins(r["near"], [0, 0.05, 0.2, 0.5, 1.01], "near share {:.2f}-{:.2f}")
        z = r["z"]
        zmin = z.min()
        height = bins(z - zmin, [0, 0.01, 0.03, 0.1, 0.3, 100], "height above lowest {:.2f}-{:.2f} m")
        area = r["area"]
        q = np.quantile(area, [0, 0.25, 0.5, 0.75, 1.0])
        q[-1] += 1
        sizes = bins(area, q, "face area {:.2g}-{:.2g}")
        for title, sets in [
            ("facing", facing),
            ("direct share of H", lit),
            ("share of indirect from near hits", near),
            ("height", height),
            ("face area", sizes),
        ]:
            report(f"{name}, ours vs Cycles, by {title}", sets, ours, h_cyc, mean)
        report(f"{name}, the gather vs brute force (same solution), by facing", facing, ours, bf, mean)
        report(f"{name}, brute force vs Cycles, by facing", facing, bf, h_cyc, mean)
        report(f"{name}, brute force vs Cycles, by near share", near, bf, h_cyc, mean)
        report(f"{name}, brute force vs Cycles, by direct share", lit, bf, h_cyc, mean)


if __name__ == "__main__":
    main()
