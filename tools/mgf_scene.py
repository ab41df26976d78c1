"""A scene file of an MGF model (the Materials and Geometry Format that RenderPark reads and
Radiance's converters write), for baking RenderPark's own scenes with this library (issues 19
and 20: the 13,780-polygon office `etc/office1/graz.mgf` of RenderPark's repository, which the
first round's solver could not bake; docs/validation-real.md, "RenderPark's office").

    python3 -m tools.mgf_scene graz.mgf office.json
    target/release/galerkin-radiosity bake office.json -o out.json --hierarchy --no-corner-gather

The subset of MGF 2.0 those scenes use: named vertices (`v NAME =` then `p x y z`; a name may be
defined again, a face takes its value at the time), polygons (`f v1 v2 ...`, counter-clockwise
seen from the front, as the library's faces; more than four corners cut into triangles),
materials (`m NAME =` or `m NAME = OTHER`, then `c`, `cxy x y`, `rd`, `ed`; `m NAME` takes a
defined one back), objects (`o NAME` ... `o`), transforms `xf` of scaling (`-s`) and
translation (`-t`), and `ring` (a disk or annulus, as a fan of quads). Other entities are
reported and passed over, as MGF's own parser does (the office holds three stray file paths
from the mail it came in). Specular and transmitted parts (`rs`, `ts`, `ir`) are left out: the
library is diffuse only (a glass pane becomes an opaque black occluder).

A colour is a CIE xy chromaticity and `rd` and `ed` its luminance Y, turned into RGB with
Radiance's primaries and equal-energy white (the scenes came from Radiance: its grey `cxy 0.3333
0.3333` stays grey). Reflectances are clamped per channel to `MAX_REFLECTANCE` (the library
takes reflectances in [0, 1)), as RenderPark clamps them: the office has two materials of `rd
1.0000`, and a saturated colour at a high luminance can exceed 1 in one channel. The tool names
every material it clamps.

Closed pieces are turned outward ([`outward`]): Radiance renders both sides of a polygon, and
half the office's slabs face into themselves. Objects are the MGF objects merged by name (the
office's 4,099 are named after their material: 66 objects).
"""

from __future__ import annotations

import argparse
import json
import math

MAX_REFLECTANCE = 0.999999

# Radiance's RGB primaries (CIE xy) with the equal-energy white (1/3, 1/3): the colour space the
# MGF scenes were converted from (`cxy 0.3333 0.3333` is grey, R = G = B).
PRIMARIES = ((0.640, 0.330), (0.290, 0.600), (0.150, 0.060))
WHITE = (1.0 / 3.0, 1.0 / 3.0)


def _xyz(xy: tuple[float, float], luminance: float) -> tuple[float, float, float]:
    x, y = xy
    return (x * luminance / y, luminance, (1.0 - x - y) * luminance / y)


def _solve3(m: list[list[float]], v: list[float]) -> list[float]:
    """`m^-1 v` by Cramer's rule."""

    def det(a):
        return (
            a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
        )

    d = det(m)
    out = []
    for k in range(3):
        mk = [[v[i] if j == k else m[i][j] for j in range(3)] for i in range(3)]
        out.append(det(mk) / d)
    return out


def _rgb_to_xyz() -> list[list[float]]:
    """The matrix whose columns are the primaries' XYZ, scaled so that R = G = B = 1 is the white
    at luminance 1."""
    columns = [_xyz(p, 1.0) for p in PRIMARIES]
    m = [[columns[j][i] for j in range(3)] for i in range(3)]
    scale = _solve3(m, list(_xyz(WHITE, 1.0)))
    return [[m[i][j] * scale[j] for j in range(3)] for i in range(3)]


RGB_TO_XYZ = _rgb_to_xyz()

RING_SEGMENTS = 16


class MgfError(ValueError):
    """An MGF line this tool does not read, named by file and line."""


def rgb(xy: tuple[float, float], luminance: float) -> list[float]:
    """Radiance RGB of the chromaticity `xy` at luminance `luminance` (negative channels
    clipped)."""
    if xy[1] <= 0.0:
        return [0.0, 0.0, 0.0]
    return [max(0.0, c) for c in _solve3(RGB_TO_XYZ, list(_xyz(xy, luminance)))]


class Material:
    def __init__(self, name: str):
        self.name = name
        self.xy = (1.0 / 3.0, 1.0 / 3.0)
        self.reflectance = [0.0, 0.0, 0.0]
        self.emission = [0.0, 0.0, 0.0]
        self.clamped = False

    def copy(self, name: str) -> Material:
        m = Material(name)
        m.xy, m.reflectance, m.emission = self.xy, list(self.reflectance), list(self.emission)
        return m


class Reader:
    """The parser's state: materials, vertices, transforms and the faces made so far."""

    def __init__(self):
        self.materials: dict[str, Material] = {}
        self.material: Material | None = None
        self.vertex_names: dict[str, list[float]] = {}
        self.normals: dict[str, list[float]] = {}
        self.vertex: str | None = None
        self.transforms: list[tuple[float, list[float]]] = []
        self.objects: list[str] = []
        # Per object name, its vertices, its faces (corner indices) and each face's material.
        self.meshes: dict[str, tuple[list[list[float]], list[list[int]], list[int]]] = {}
        # Per object name, per face, the MGF object it came from (`o` entities counted in order).
        self.instances: dict[str, list[int]] = {}
        self.instance = 0
        self.material_index: dict[str, int] = {}
        self.skipped: dict[str, int] = {}
        self.unknown: list[str] = []

    def place(self, p: list[float]) -> list[float]:
        # The innermost transform applies first.
        for scale, shift in reversed(self.transforms):
            p = [scale * c + t for c, t in zip(p, shift, strict=True)]
        return p

    def current_material(self) -> int:
        m = self.material or self.materials.setdefault("default", Material("default"))
        if m.name not in self.material_index:
            self.material_index[m.name] = len(self.material_index)
        return self.material_index[m.name]

    def add_polygon(self, corners: list[list[float]]) -> None:
        name = self.objects[0] if self.objects else "Untitled"
        vertices, faces, mats = self.meshes.setdefault(name, ([], [], []))
        base = len(vertices)
        vertices.extend(corners)
        index = list(range(base, base + len(corners)))
        material = self.current_material()
        pieces = [index] if len(index) <= 4 else [[index[k] for k in t] for t in ear_clip(corners)]
        for piece in pieces:
            faces.append(piece)
            mats.append(material)
            self.instances.setdefault(name, []).append(self.instance)

    def line(self, words: list[str], where: str) -> None:
        key, args = words[0], words[1:]
        if key == "m":
            self.vertex = None
            if len(args) >= 2 and args[1] == "=":
                base = self.materials.get(args[2]) if len(args) > 2 else None
                m = base.copy(args[0]) if base else Material(args[0])
                self.materials[args[0]] = m
                self.material = m
            elif len(args) == 1:
                if args[0] not in self.materials:
                    raise MgfError(f"{where}: material {args[0]!r} used before it is defined")
                self.material = self.materials[args[0]]
            else:
                raise MgfError(f"{where}: cannot read {' '.join(words)!r}")
        elif key == "c":
            # A colour context of its own (`c NAME = ...`) is not read; `c` alone resets to white.
            if args:
                raise MgfError(f"{where}: named colours are not read ({' '.join(words)!r})")
            if self.material:
                self.material.xy = (1.0 / 3.0, 1.0 / 3.0)
        elif key == "cxy":
            if self.material:
                self.material.xy = (float(args[0]), float(args[1]))
        elif key == "rd":
            m = self.material
            if m:
                m.reflectance = rgb(m.xy, float(args[0]))
                if max(m.reflectance) > MAX_REFLECTANCE:
                    m.reflectance = [min(c, MAX_REFLECTANCE) for c in m.reflectance]
                    m.clamped = True
        elif key == "ed":
            if self.material:
                self.material.emission = rgb(self.material.xy, float(args[0]))
        elif key in ("rs", "ts", "ir", "sides"):
            self.skipped[key] = self.skipped.get(key, 0) + 1
        elif key == "v":
            if len(args) >= 2 and args[1] == "=":
                self.vertex = args[0]
                # (`v NAME = OTHER` starts from another vertex's point.)
                start = self.vertex_names.get(args[2], [0.0] * 3) if len(args) > 2 else [0.0] * 3
                self.vertex_names[args[0]] = list(start)
            else:
                raise MgfError(f"{where}: cannot read {' '.join(words)!r}")
        elif key == "p":
            if self.vertex is None:
                raise MgfError(f"{where}: a point outside a vertex definition")
            self.vertex_names[self.vertex] = self.place([float(a) for a in args[:3]])
        elif key == "n":
            # (Only a ring's axis reads it: faces are flat.)
            if self.vertex is not None:
                self.normals[self.vertex] = [float(a) for a in args[:3]]
        elif key == "f":
            try:
                corners = [self.vertex_names[a] for a in args]
            except KeyError as e:
                raise MgfError(f"{where}: vertex {e.args[0]!r} used before it is defined") from None
            if len(corners) >= 3:
                self.add_polygon(corners)
        elif key == "ring":
            self.ring(args, where)
        elif key == "o":
            if args:
                self.objects.append(args[0])
                self.instance += 1
            elif self.objects:
                self.objects.pop()
        elif key == "xf":
            if not args:
                if not self.transforms:
                    raise MgfError(f"{where}: xf ends a transform never begun")
                self.transforms.pop()
            else:
                self.transforms.append(transform(args, where))
        else:
            # As MGF's own parser does, an unknown entity is reported and passed over (the
            # office holds three stray file paths from the mail it came in).
            self.unknown.append(f"{where}: {key}")

    def ring(self, args: list[str], where: str) -> None:
        """A disk or annulus around the vertex `args[0]` (its normal the ring's) from radius
        `args[1]` to `args[2]`, as `RING_SEGMENTS` quads (triangles for a disk)."""
        name, r0, r1 = args[0], float(args[1]), float(args[2])
        centre = self.vertex_names.get(name)
        normal = self.normals.get(name)
        if centre is None or normal is None:
            raise MgfError(f"{where}: ring around {name!r}, which has no point and normal")
        scale = math.prod(s for s, _ in self.transforms) if self.transforms else 1.0
        r0, r1 = r0 * scale, r1 * scale
        length = math.sqrt(sum(c * c for c in normal))
        n = [c / length for c in normal]
        helper = [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0]
        u = cross(n, helper)
        lu = math.sqrt(sum(c * c for c in u))
        u = [c / lu for c in u]
        w = cross(n, u)
        for k in range(RING_SEGMENTS):
            a, b = (2 * math.pi * k / RING_SEGMENTS, 2 * math.pi * (k + 1) / RING_SEGMENTS)

            def at(r, t):
                return [centre[i] + r * (math.cos(t) * u[i] + math.sin(t) * w[i]) for i in range(3)]

            outer = [at(r1, a), at(r1, b)]
            inner = [at(r0, b), at(r0, a)] if r0 > 0.0 else [centre]
            self.add_polygon(outer + inner)


def ear_clip(corners: list[list[float]]) -> list[tuple[int, int, int]]:
    """Triangles (corner indices, the polygon's winding) of a planar polygon, convex or not, by
    ear clipping in the plane of its largest normal component (the office has a concave
    hexagon, which a fan would fold over itself)."""
    n = len(corners)
    # Newell's normal.
    normal = [0.0, 0.0, 0.0]
    for i in range(n):
        a, b = corners[i], corners[(i + 1) % n]
        for k in range(3):
            u, v = (k + 1) % 3, (k + 2) % 3
            normal[k] += (a[u] - b[u]) * (a[v] + b[v])
    k = max(range(3), key=lambda i: abs(normal[i]))
    u, v = (k + 1) % 3, (k + 2) % 3
    sign = 1.0 if normal[k] >= 0.0 else -1.0
    pts = [(c[u], c[v]) for c in corners]

    def turn(a, b, c):
        return sign * (
            (pts[b][0] - pts[a][0]) * (pts[c][1] - pts[a][1])
            - (pts[b][1] - pts[a][1]) * (pts[c][0] - pts[a][0])
        )

    def inside(p, a, b, c):
        return turn(a, b, p) >= 0.0 and turn(b, c, p) >= 0.0 and turn(c, a, p) >= 0.0

    left = list(range(n))
    out = []
    while len(left) > 3:
        for i in range(len(left)):
            a, b, c = left[i - 1], left[i], left[(i + 1) % len(left)]
            if turn(a, b, c) > 0.0 and not any(inside(p, a, b, c) for p in left if p not in (a, b, c)):
                out.append((a, b, c))
                left.pop(i)
                break
        else:
            # (Degenerate: no ear left; fan the rest.)
            out.extend((left[0], left[j], left[j + 1]) for j in range(1, len(left) - 1))
            return out
    out.append(tuple(left))
    return out


def cross(a: list[float], b: list[float]) -> list[float]:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def transform(args: list[str], where: str) -> tuple[float, list[float]]:
    """An `xf` of `-s` and `-t` options as (scale, translation), applied scale first."""
    scale, shift = 1.0, [0.0, 0.0, 0.0]
    k = 0
    while k < len(args):
        if args[k] == "-s":
            scale *= float(args[k + 1])
            shift = [c * float(args[k + 1]) for c in shift]
            k += 2
        elif args[k] == "-t":
            shift = [c + float(a) for c, a in zip(shift, args[k + 1 : k + 4], strict=True)]
            k += 4
        else:
            raise MgfError(f"{where}: the transform option {args[k]!r} is not read by this tool")
    return scale, shift


def read(path: str) -> Reader:
    reader = Reader()
    with open(path, encoding="latin-1") as f:
        for number, raw in enumerate(f, 1):
            words = raw.split("#", 1)[0].split()
            if words:
                reader.line(words, f"{path}:{number}")
    return reader


WELD = 1e-6


def outward(reader: Reader) -> tuple[int, int]:
    """Turns every closed piece outward, in place; returns (pieces, pieces turned).

    Radiance, which these scenes were converted from, renders both sides of a polygon, and its
    modellers did not care which way one faces: the office's floor is a slab whose six faces all
    face into it, its walls alike. The library's faces are one-sided, so such a slab is black
    seen from the room. A piece is a set of faces joined through shared edges (corners welded
    across objects to `WELD` of the model's size); one in which every edge joins exactly two
    faces is closed: its faces are made to agree with each other across every edge (walked from
    one face), then all turned over if they enclose a negative volume. Open pieces keep their
    faces as they are.
    """
    meshes = reader.meshes
    faces = [(name, k) for name, (_, fs, _) in meshes.items() for k in range(len(fs))]
    points = [p for v, _, _ in meshes.values() for p in v]
    if not points:
        return 0, 0
    size = max(max(p[i] for p in points) - min(p[i] for p in points) for i in range(3))
    ids: dict[tuple[int, ...], int] = {}

    def key(p):
        return tuple(round(c / (WELD * size)) for c in p)

    loops = []
    for name, k in faces:
        vertices, fs, _ = meshes[name]
        instance = reader.instances[name][k]
        loops.append([ids.setdefault((instance, *key(vertices[i])), len(ids)) for i in fs[k]])
    edges: dict[tuple[int, int], list[int]] = {}
    for f, loop in enumerate(loops):
        for a, b in zip(loop, loop[1:] + loop[:1], strict=True):
            if a != b:
                edges.setdefault((min(a, b), max(a, b)), []).append(f)
    seen = [False] * len(loops)
    pieces = turned = 0
    for start in range(len(loops)):
        if seen[start]:
            continue
        # Walk the piece, each face flipped or not so that it agrees with the one it came from.
        flip = {start: False}
        order, stack, closed = [start], [start], True
        seen[start] = True
        while stack:
            f = stack.pop()
            loop = loops[f][::-1] if flip[f] else loops[f]
            for a, b in zip(loop, loop[1:] + loop[:1], strict=True):
                if a == b:
                    continue
                users = edges[(min(a, b), max(a, b))]
                if len(users) != 2:
                    closed = False
                    continue
                g = users[0] if users[1] == f else users[1]
                # Agreeing neighbours run a shared edge in opposite directions.
                # (`g` is to be flipped when, as written, it runs the edge as `f` runs it now.)
                g_edges = zip(loops[g], loops[g][1:] + loops[g][:1], strict=True)
                want = any(x == a and y == b for x, y in g_edges)
                if g in flip:
                    closed &= flip[g] == want
                    continue
                flip[g] = want
                seen[g] = True
                order.append(g)
                stack.append(g)
        pieces += 1
        if not closed:
            continue
        volume = 0.0
        for f in order:
            name, k = faces[f]
            vertices, fs, _ = meshes[name]
            loop = fs[k][::-1] if flip[f] else fs[k]
            p0 = vertices[loop[0]]
            for i in range(1, len(loop) - 1):
                p1, p2 = vertices[loop[i]], vertices[loop[i + 1]]
                volume += sum(p0[j] * cross(p1, p2)[j] for j in range(3)) / 6.0
        inside_out = volume < 0.0
        changed = False
        for f in order:
            if flip[f] != inside_out:
                name, k = faces[f]
                fs = meshes[name][1]
                fs[k] = fs[k][::-1]
                changed = True
        turned += changed
    return pieces, turned


def scene(reader: Reader, order: int = 2) -> dict:
    names = sorted(reader.material_index, key=reader.material_index.get)
    materials = [
        {
            "name": n,
            "reflectance": reader.materials[n].reflectance if n in reader.materials else [0.0] * 3,
            "emission": reader.materials[n].emission if n in reader.materials else [0.0] * 3,
        }
        for n in names
    ]
    objects = [
        {"name": name, "vertices": v, "faces": f, "face_materials": m}
        for name, (v, f, m) in reader.meshes.items()
    ]
    return {
        "version": 1,
        "settings": {"basis_order": order},
        "frames": [1, 1],
        "materials": materials,
        "objects": objects,
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mgf")
    p.add_argument("out")
    p.add_argument("--order", type=int, default=2, help="the basis order of the scene's settings (default 2)")
    p.add_argument(
        "--keep-orientation",
        action="store_true",
        help="leave every face as the file orients it (closed pieces are turned outward otherwise)",
    )
    a = p.parse_args(argv)
    try:
        reader = read(a.mgf)
    except MgfError as e:
        raise SystemExit(f"error: {e}") from None
    pieces, turned = (0, 0) if a.keep_orientation else outward(reader)
    s = scene(reader, a.order)
    with open(a.out, "w") as f:
        json.dump(s, f)
    faces = sum(len(o["faces"]) for o in s["objects"])
    emitters = [m["name"] for m in s["materials"] if max(m["emission"]) > 0.0]
    clamped = [m.name for m in reader.materials.values() if m.clamped]
    print(f"wrote {a.out}: {len(s['objects'])} objects, {faces} faces, {len(s['materials'])} materials")
    if not a.keep_orientation:
        print(f"closed pieces turned outward: {turned} of {pieces} pieces")
    print(f"emitters: {', '.join(emitters) or 'none'}")
    if clamped:
        print(f"reflectance clamped to {MAX_REFLECTANCE} in a channel: {', '.join(clamped)}")
    if reader.unknown:
        shown = "; ".join(reader.unknown[:5]) + (" ..." if len(reader.unknown) > 5 else "")
        print(f"not MGF entities this tool reads, passed over ({len(reader.unknown)}): {shown}")
    if reader.skipped:
        print("left out: " + ", ".join(f"{k} x{n}" for k, n in sorted(reader.skipped.items())))


if __name__ == "__main__":
    main()
