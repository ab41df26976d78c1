"""A scene file with every face of one object given a back (issue 19, the monastery): the
library's faces are one-sided (a ray that meets a face from behind takes 0, and the back
reflects nothing), Cycles' Diffuse BSDF is two-sided (the underside of a roof modelled as a
single sheet is lit by the ground and lights the ground in turn). Appending each face again,
reversed, to the same object gives the library the backs Cycles has; the object's first corners
are still the original faces', in the same order, so a Cycles reference of the original scene
compares with them as it is (tools/compare_ref.py reads only as many corners as it holds).

    .venv/bin/python -m tools.two_sided SCENE.json OUT.json --object Monastery [--back-black]

`--back-black` gives the backs a black material: the same light as the one-sided scene, with
the same geometry as the two-sided one (what changes with the coincident backs alone, e.g. the
corner gather's choice of rays next to an occluder, separated from the light they reflect).
"""

from __future__ import annotations

import argparse
import json


def two_sided(scene: dict, name: str, back_black: bool = False) -> dict:
    out = json.loads(json.dumps(scene))
    ob = next(o for o in out["objects"] if o["name"] == name)
    faces = ob["faces"]
    mats = ob["face_materials"]
    if back_black:
        out["materials"].append({"name": "Back (black)", "reflectance": [0.0] * 3, "emission": [0.0] * 3})
        back = [len(out["materials"]) - 1] * len(faces)
    else:
        back = list(mats)
    ob["faces"] = faces + [list(reversed(f)) for f in faces]
    ob["face_materials"] = mats + back
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("out")
    p.add_argument("--object", default="Monastery")
    p.add_argument("--back-black", action="store_true")
    a = p.parse_args(argv)
    scene = json.loads(open(a.scene).read())
    json.dump(two_sided(scene, a.object, a.back_black), open(a.out, "w"))


if __name__ == "__main__":
    main()
