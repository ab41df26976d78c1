"""Per-object relative RMSE and mean ratio of a CLI bake against a Cycles reference per corner
(as tools/validate_real.py --reference writes it; the comparison of tests/python/test_validation_real.py).

    target/release/galerkin-radiosity bake /work/cache/ref/room_scene.json -o out.json
    .venv/bin/python -m tools.compare_ref out.json /work/cache/ref/room_cycles.json
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def compare(result: str, reference: str) -> dict:
    ref = json.loads(open(reference).read())
    frame = json.loads(open(result).read())["frames"][0]
    ours = {o["name"]: np.asarray(o["corner_radiosity"], np.float64).mean(axis=1) for o in frame["objects"]}
    out = {}
    for name, values in ref["objects"].items():
        cyc = np.asarray(values)
        b = ours[name][: len(cyc)]  # a scene with faces appended (tools/two_sided.py): the first corners
        # (An object black in Cycles, its corners all buried, reads nan or inf.)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[name] = (float(np.sqrt(np.mean((b - cyc) ** 2)) / cyc.mean()), float(b.mean() / cyc.mean()))
    return out


def compare_all(result: str, reference: str) -> tuple[float, float]:
    """[`compare`] over every corner of every object of the reference at once."""
    ref = json.loads(open(reference).read())
    frame = json.loads(open(result).read())["frames"][0]
    ours = {o["name"]: np.asarray(o["corner_radiosity"], np.float64).mean(axis=1) for o in frame["objects"]}
    cyc = np.concatenate([np.asarray(v) for v in ref["objects"].values()])
    b = np.concatenate([ours[name][: len(v)] for name, v in ref["objects"].items()])
    return float(np.sqrt(np.mean((b - cyc) ** 2)) / cyc.mean()), float(b.mean() / cyc.mean())


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("result")
    p.add_argument("reference")
    a = p.parse_args(argv)
    print("| object | relative RMSE | mean ratio |\n|---|---|---|")
    for name, (rmse, ratio) in compare(a.result, a.reference).items():
        print(f"| {name} | {100 * rmse:.2f}% | {ratio:.3f} |")
    rmse, ratio = compare_all(a.result, a.reference)
    print(f"| (every corner) | {100 * rmse:.2f}% | {ratio:.3f} |")


if __name__ == "__main__":
    main()
