"""Real-mesh validation against checked-in Cycles numbers (issue 19), without running Cycles.

tests/data/real/bunny_scene.json is the "bunny" scene of tools/validate_real.py (pybullet's
bunny.obj decimated by Blender to 300 triangles, a closed mesh standing on a ground plane under
a one-sided light quad) as the add-on hands it to the library; bunny_cycles.json is Cycles'
DIFFUSE bake of it (16384 spp) as radiosity per face corner, with Cycles' own per-corner noise
measured from two seeds. The CLI bakes the scene file at the add-on's default settings and
every object is compared per corner.

Regenerate the data (about 4 minutes):
    .venv/bin/python -m tools.validate_real --scene bunny --samples 16384 --noise --reference tests/data/real
"""

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tools import real_meshes
from tools.validate_cycles import cli

DATA = Path(__file__).resolve().parents[1] / "data" / "real"
# Relative RMSE per corner allowed per object. Measured before the issue-19 fixes (main 62ea4c7):
# Bunny 7.42%, Ground 1.36%; after the triangle apex inset and the near-contact feet: Bunny
# 5.21%, Ground 1.36%; after the ground is split next to the bunny (src/contact_split.rs): Bunny
# 3.71%, Ground 1.16% (this test, -s). Issue 19's goal is 3%: tighten these when the solver
# reaches it.
MAX_RMSE = {"Bunny": 0.04, "Ground": 0.0125}
# |mean ratio ours / Cycles - 1| allowed per object (before: Bunny 1.1%, Ground 0.35%).
MAX_MEAN_ERROR = 0.02


def reference():
    ref = json.loads((DATA / "bunny_cycles.json").read_text())
    scene = json.loads((DATA / ref["scene_file"]).read_text())
    return ref, scene


def test_reference_matches_its_scene():
    ref, scene = reference()
    objects = {o["name"]: o for o in scene["objects"]}
    for name, values in ref["objects"].items():
        assert len(values) == sum(len(f) for f in objects[name]["faces"]), name
        assert min(values) > 0.0, f"{name}: a black corner in an open scene lit from above"
    # The reference must be far less noisy than the error it is meant to detect.
    assert ref["cycles_noise_per_corner"]["all"] < 0.005, ref["cycles_noise_per_corner"]


def test_bunny_agrees_with_cycles(tmp_path):
    ref, _ = reference()
    out = tmp_path / "result.json"
    subprocess.run([str(cli()), "bake", str(DATA / ref["scene_file"]), "-o", str(out), "--quiet"], check=True)
    frame = json.loads(out.read_text())["frames"][0]
    ours = {o["name"]: np.asarray(o["corner_radiosity"], np.float64) for o in frame["objects"]}
    failures = []
    for name, values in ref["objects"].items():
        cyc = np.asarray(values)
        b = ours[name].mean(axis=1)  # grey scene: the three channels agree
        rmse = float(np.sqrt(np.mean((b - cyc) ** 2)) / cyc.mean())
        ratio = float(b.mean() / cyc.mean())
        line = (f"{name}: relative RMSE {100 * rmse:.2f}% (bound {100 * MAX_RMSE[name]:.3g}%), mean ratio "
                f"{ratio:.4f}; Cycles noise {100 * ref['cycles_noise_per_corner'][name]:.2f}%")
        print(line)
        if rmse > MAX_RMSE[name] or abs(ratio - 1) > MAX_MEAN_ERROR:
            failures.append(line)
    assert not failures, failures


def tetrahedron(offset):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64) + offset
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return v, f


def test_pieces_and_closedness():
    (v1, f1), (v2, f2) = tetrahedron(0.0), tetrahedron(5.0)
    mesh = real_meshes.Mesh("two", np.concatenate([v1, v2]), np.concatenate([f1, f2 + 4]))
    labels = real_meshes.piece_labels(mesh.faces, len(mesh.vertices))
    assert len(set(labels[:4])) == 1 and len(set(labels[4:])) == 1 and labels[0] != labels[4]
    assert real_meshes.is_closed(mesh)
    assert not real_meshes.is_closed(real_meshes.Mesh("open", mesh.vertices, mesh.faces[1:]))
    flipped = mesh.faces.copy()
    flipped[0] = flipped[0][::-1]
    assert not real_meshes.is_closed(real_meshes.Mesh("flipped", mesh.vertices, flipped))
    # The larger tetrahedron is kept first; a budget of 4 faces keeps one piece.
    big = real_meshes.Mesh("big", np.concatenate([v1, 3 * v2]), mesh.faces)
    kept, n_kept, n_all = real_meshes.largest_pieces(big, 4)
    assert (n_kept, n_all) == (1, 2) and kept.vertices.min() == pytest.approx(15.0)


def test_welding_joins_seam_duplicates():
    v, f = tetrahedron(0.0)
    # Vertex 3 duplicated (as along a UV seam): one face uses the copy, so the mesh looks open.
    v = np.concatenate([v, v[3:4] + 1e-6])
    f = f.copy()
    f[3] = [1, 2, 4]
    mesh = real_meshes.Mesh("seam", v, f)
    assert not real_meshes.is_closed(mesh)
    w = real_meshes.welded(mesh)
    assert len(w.vertices) == 4 and real_meshes.is_closed(w)
