"""Per-object relative RMSE and mean ratio of a CLI bake against a Cycles reference per corner
(as tools/validate_real.py --reference writes it; the comparison of tests/python/test_validation_real.py).

    target/release/galerkin-radiosity bake /work/cache/ref/room_scene.json -o out.json
    .venv/bin/python -m tools.compare_ref out.json /work/cache/ref/room_cycles.json
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def _corners(result: str, reference: str) -> dict:
    """Per object of the reference, (Cycles' corners, ours): ours the mean of the channels, the
    object's first corners (a scene with faces appended, tools/two_sided.py, has more)."""
    ref = json.loads(open(reference).read())
    frame = json.loads(open(result).read())["frames"][0]
    ours = {o["name"]: np.asarray(o["corner_radiosity"], np.float64).mean(axis=1) for o in frame["objects"]}
    return {name: (np.asarray(v), ours[name][: len(v)]) for name, v in ref["objects"].items()}


def compare(result: str, reference: str) -> dict:
    out = {}
    for name, (cyc, b) in _corners(result, reference).items():
        # (An object black in Cycles, its corners all buried, reads nan or inf.)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[name] = (float(np.sqrt(np.mean((b - cyc) ** 2)) / cyc.mean()), float(b.mean() / cyc.mean()))
    return out


def compare_all(result: str, reference: str) -> tuple[float, float]:
    """[`compare`] over every corner of every object of the reference at once."""
    pairs = _corners(result, reference).values()
    cyc = np.concatenate([c for c, _ in pairs])
    b = np.concatenate([o for _, o in pairs])
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
