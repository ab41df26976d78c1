"""tools/mgf_scene.py: MGF scenes (RenderPark's, converted from Radiance) as scene files.

A small MGF written here holds what RenderPark's office holds: a floor slab whose six faces all
face into it (Radiance renders both sides, so its modellers never cared), a light quad facing
down inside `xf -s` millimetres, a grey and a coloured material, a reflectance of 1, a pentagon,
a ring, and a stray line that is no MGF entity. The CLI bakes the converted scene on the
hierarchy: the slab's top is lit once the converter has turned it outward, and black as the file
orients it.
"""

import json
import subprocess

import pytest

from tools import mgf_scene
from tools.validate_cycles import cli

MGF = """\
# A test room in millimetres.
xf -s .001
m lamp =
\tc
\t\tcxy 0.3333 0.3333
\ted 100
o lamp
v l0 =
\tp 400 400 1000
v l1 =
\tp 400 600 1000
v l2 =
\tp 600 600 1000
v l3 =
\tp 600 400 1000
f l0 l1 l2 l3
o
m grey =
\tc
\t\tcxy 0.3333 0.3333
\trd 0.5000
\tc
\trs 0.0500 0.0800
o floor
v a =
\tp 0 0 0
v b =
\tp 1000 0 0
v c =
\tp 1000 1000 0
v d =
\tp 0 1000 0
v e =
\tp 0 0 -10
v f =
\tp 1000 0 -10
v g =
\tp 1000 1000 -10
v h =
\tp 0 1000 -10
f a d c b
f e f g h
f a b f e
f b c g f
f c d h g
f d a e h
o
/stray/path/from/a/mail.rad
m green =
\tc
\t\tcxy 0.2900 0.6000
\trd 0.6000
m white =
\tc
\t\tcxy 0.3333 0.3333
\trd 1.0000
m green
o plate
v p0 =
\tp 100 100 1
v p1 =
\tp 200 100 1
v p2 =
\tp 250 150 1
v p3 =
\tp 150 220 1
v p4 =
\tp 50 150 1
f p0 p1 p2 p3 p4
m white
v cent =
\tp 800 800 1
\tn 0 0 1
ring cent 10 40
o
xf
"""


def convert(tmp_path, *args):
    src = tmp_path / "room.mgf"
    src.write_text(MGF)
    out = tmp_path / "room.json"
    mgf_scene.main([str(src), str(out), *args])
    return json.loads(out.read_text())


def normal(vertices, face):
    p = [vertices[i] for i in face]
    u = [p[1][i] - p[0][i] for i in range(3)]
    w = [p[2][i] - p[0][i] for i in range(3)]
    return [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]


def test_the_file_is_read_as_written(tmp_path, capsys):
    scene = convert(tmp_path)
    report = capsys.readouterr().out
    objects = {o["name"]: o for o in scene["objects"]}
    materials = {m["name"]: m for m in scene["materials"]}
    # Millimetres scaled to metres; the light faces down.
    lamp = objects["lamp"]
    assert max(abs(c) for v in lamp["vertices"] for c in v) == pytest.approx(1.0)
    assert normal(lamp["vertices"], lamp["faces"][0])[2] < 0.0
    assert materials["lamp"]["emission"] == pytest.approx([100.0] * 3, rel=1e-3)
    # Radiance's grey stays grey (`cxy 0.3333 0.3333`, within 1e-4 of its white); a green is
    # green; a reflectance of 1 is clamped and named.
    assert materials["grey"]["reflectance"] == pytest.approx([0.5] * 3, rel=1e-3)
    r, g, b = materials["green"]["reflectance"]
    assert g > 0.5 and r < 0.1 and b < 0.1
    assert max(materials["white"]["reflectance"]) == mgf_scene.MAX_REFLECTANCE
    assert "white" in report and "clamped" in report
    # The pentagon as three triangles, the annulus as 16 quads, the stray line passed over.
    plate = objects["plate"]
    assert [len(f) for f in plate["faces"]] == [3, 3, 3] + [4] * mgf_scene.RING_SEGMENTS
    assert "/stray/path/from/a/mail.rad" in report


def test_closed_pieces_are_turned_outward(tmp_path):
    kept = convert(tmp_path, "--keep-orientation")
    floor = {o["name"]: o for o in kept["objects"]}["floor"]
    # As written, the slab's top (z = 0) faces down into it.
    assert normal(floor["vertices"], floor["faces"][0])[2] < 0.0
    turned = convert(tmp_path)
    objects = {o["name"]: o for o in turned["objects"]}
    floor = objects["floor"]
    top = normal(floor["vertices"], floor["faces"][0])
    bottom = normal(floor["vertices"], floor["faces"][1])
    assert top[2] > 0.0 and bottom[2] < 0.0
    # Open pieces (the light, the plate) are left as they are.
    assert normal(objects["lamp"]["vertices"], objects["lamp"]["faces"][0])[2] < 0.0


def test_the_turned_floor_is_lit_on_the_hierarchy(tmp_path):
    means = {}
    for label, args in [("turned", []), ("as written", ["--keep-orientation"])]:
        scene = convert(tmp_path, *args)
        path = tmp_path / f"{label}.json"
        path.write_text(json.dumps(scene))
        out = tmp_path / f"{label}_out.json"
        subprocess.run(
            [str(cli()), "bake", str(path), "-o", str(out), "--hierarchy", "--no-corner-gather", "--quiet"],
            check=True,
        )
        frame = json.loads(out.read_text())["frames"][0]
        floor = {o["name"]: o for o in frame["objects"]}["floor"]
        means[label] = sum(floor["face_radiosity"][0]) / 3
    # The top, 1 m under a 0.2 m light of exitance 100 and grey 0.5: a few W/m^2 (its direct
    # light alone 0.5 x 100 x F, F about 0.012 at its middle).
    assert means["turned"] > 0.1, means
    assert means["as written"] < 1e-6 * means["turned"], means


def test_a_concave_polygon_is_cut_into_triangles_that_cover_it_once():
    # An L-shaped hexagon (area 3), counter-clockwise seen from +z, in the plane z = 1: a fan from
    # its first corner would cross the notch.
    hexagon = [[0, 0, 1], [2, 0, 1], [2, 1, 1], [1, 1, 1], [1, 2, 1], [0, 2, 1]]
    for start in range(6):
        corners = hexagon[start:] + hexagon[:start]
        triangles = mgf_scene.ear_clip(corners)
        assert len(triangles) == 4
        areas = [normal(corners, t)[2] / 2 for t in triangles]
        # Each triangle faces as the polygon does, and together they cover its area once.
        assert all(a > 0 for a in areas), (start, triangles)
        assert sum(areas) == pytest.approx(3.0)
