"""Textured reflectance and emission: a colour that varies over a face enters the solve as its mean
over the face.

The library holds one reflectance and one emission per element (a face today), and the solve is
linear in each, so what a face reflects or emits in total is its area-mean reflectance or
emission. The emission's mean is a per-face scale of the material's emission (strength x white
where the Emission Color is textured, colour x 1 where the strength is), so animated strengths
keep applying. The means are computed here by sampling the material's colour node chain (Base
Color; Emission Color x Emission Strength, multiplied per sample) over each face's UV triangles
(Blender's ``loop_triangles``), area-weighted:

- Readable chains, evaluated per sample with numpy: an Image Texture (flat projection; Linear,
  Closest or Cubic (read as Linear) interpolation; Repeat, Extend, Clip or Mirror extension; its
  UV map from a UV Map node or the mesh's active render map), an RGB node, a Mix Color node
  (Mix, Multiply, Add, Subtract, Screen, Darken, Lighten; the legacy MixRGB too), a Value node, a
  Math node (``MATH``), Reroutes, and unlinked inputs. A colour into a float input is its
  luminance (``luminance_weights``), a float into a colour grey. ``constant`` evaluates a chain
  without a texture to one value (a Value-driven strength, read per frame). Anything else (a
  Mapping node, a procedural texture, ...) is reported by node type, and the material keeps
  its default reflectance (an unreadable emission counts as none).
- Colour images are read as Blender does: an 8-bit or float image whose colour space is sRGB is
  decoded with the sRGB transfer function to scene-linear; Non-Color and linear spaces are used as
  stored. The alpha output reads the image's alpha as grey.
- Samples: the barycentric centroids of an m x m subdivision of each UV triangle, with m chosen
  so that a sub-triangle covers at most about one texel (4 <= m <= 256), so a face spanning many
  checker squares is averaged over all of them.
"""

from __future__ import annotations

import numpy as np

from ..core import materials as core

# Node types read, for the report of what is not.
READ = {"ShaderNodeTexImage", "ShaderNodeRGB", "ShaderNodeMix", "ShaderNodeMixRGB", "NodeReroute",
        "ShaderNodeUVMap", "ShaderNodeTexCoord", "ShaderNodeValue", "ShaderNodeMath"}
MIN_SUBDIVISION, MAX_SUBDIVISION = 4, 256


def luminance_weights() -> np.ndarray:
    """The weights of Blender's colour-to-float conversion (a colour output linked into a float
    input): Cycles' film.rgb_to_y (svm convert: dot(rgb, rgb_to_y)), the Y row of the scene-linear
    to XYZ transform, which mathutils gives. They follow the file's scene-linear space: in bpy
    4.5 Rec.709's 0.2126741, 0.7151515, 0.0721754; in 5.0 0.2126391, 0.7151691, 0.0721927
    (tests/python/test_textures.py measures them in a Cycles EMIT bake)."""
    from mathutils import Color

    return np.array([Color(c).from_scene_linear_to_xyz_d65()[1] for c in np.eye(3)], np.float32)


# Math node operations read (Cycles' svm_math semantics: a zero divisor gives 0, a negative base
# with a fractional exponent gives 0).
MATH = {"ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "MINIMUM", "MAXIMUM", "ABSOLUTE", "POWER"}


class Unreadable(Exception):
    """A node chain the sampler does not evaluate; the message names the node type."""


class Textured(Exception):
    """A chain evaluated as a constant reached a texture coordinate: it varies over a face."""


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB transfer function's inverse (IEC 61966-2-1), as Blender's "sRGB" colour space."""
    c = np.asarray(c, np.float32)
    high = ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4
    return np.where(c <= 0.04045, c / 12.92, high).astype(np.float32)


def triangle_samples(m: int) -> np.ndarray:
    """Barycentric (b1, b2) of the centroids of the m^2 congruent sub-triangles of a triangle."""
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    up = (i + j) <= m - 1
    down = (i + j) <= m - 2
    pts = [np.stack([(i[up] + 1 / 3) / m, (j[up] + 1 / 3) / m], axis=1),
           np.stack([(i[down] + 2 / 3) / m, (j[down] + 2 / 3) / m], axis=1)]
    return np.concatenate(pts).astype(np.float64)


def _link(socket):
    """The (node, output socket) feeding `socket`, through reroutes; None when unlinked."""
    if not socket.is_linked:
        return None
    link = socket.links[0]
    node, out = link.from_node, link.from_socket
    while node.bl_idname == "NodeReroute":
        if not node.inputs[0].is_linked:
            return None
        link = node.inputs[0].links[0]
        node, out = link.from_node, link.from_socket
    return node, out


def _label(node) -> str:
    return node.bl_label or node.bl_idname


class Sampler:
    """Evaluates colour sockets at UV sample points of one mesh. Images are read once."""

    def __init__(self, mesh):
        self.mesh = mesh
        self.luminance = luminance_weights()
        self._uv: dict[str, np.ndarray] = {}
        self._images: dict[str, np.ndarray] = {}

    # -- inputs ---------------------------------------------------------------------------------

    def loop_uv(self, name: str | None) -> np.ndarray:
        """(L, 2) UVs per loop of the named map (None: the active render map)."""
        layers = self.mesh.uv_layers
        if name:
            layer = layers.get(name)
            if layer is None:
                raise Unreadable(f"UV map {name!r} not on the mesh")
        else:
            layer = next((u for u in layers if u.active_render), None) or layers.active
            if layer is None:
                raise Unreadable("no UV map")
        key = layer.name
        if key not in self._uv:
            uv = np.empty(len(self.mesh.loops) * 2, np.float32)
            layer.uv.foreach_get("vector", uv)
            self._uv[key] = uv.reshape(-1, 2)
        return self._uv[key]

    def pixels(self, image) -> np.ndarray:
        """(H, W, 4) scene-linear float32 pixels of `image` (sRGB decoded, alpha as stored)."""
        key = image.name
        if key not in self._images:
            w, h = image.size
            if w == 0 or h == 0:
                raise Unreadable(f"image {image.name!r} has no pixels")
            px = np.empty(w * h * image.channels, np.float32)
            image.pixels.foreach_get(px)
            px = px.reshape(h, w, image.channels)
            if image.channels < 4:
                pad = np.ones((h, w, 4 - image.channels), np.float32)
                if image.channels == 1:
                    px = np.repeat(px, 3, axis=2)
                    pad = pad[..., :1]
                px = np.concatenate([px, pad], axis=2)
            if image.colorspace_settings.name.lower().startswith("srgb"):
                px = np.concatenate([srgb_to_linear(px[..., :3]), px[..., 3:]], axis=2)
            self._images[key] = px
        return self._images[key]

    # -- evaluation -----------------------------------------------------------------------------

    def socket(self, socket, uv_of) -> np.ndarray:
        """(N, 3) colour of an input socket at the samples; `uv_of(name)` gives (N, 2) UVs."""
        fed = _link(socket)
        if fed is None:
            v = socket.default_value
            try:
                rgb = np.asarray(v[:3], np.float32)
            except TypeError:
                rgb = np.full(3, float(v), np.float32)
            return np.broadcast_to(rgb, (uv_of.count, 3))
        node, out = fed
        kind = node.bl_idname
        if kind in ("ShaderNodeValue", "ShaderNodeMath"):
            return np.repeat(self.scalar(socket, uv_of), 3, axis=1)   # a float into a colour: grey
        if kind == "ShaderNodeRGB":
            return np.broadcast_to(np.asarray(out.default_value[:3], np.float32), (uv_of.count, 3))
        if kind == "ShaderNodeTexImage":
            return self.image(node, out, uv_of)
        if kind in ("ShaderNodeMix", "ShaderNodeMixRGB"):
            return self.mix(node, uv_of)
        raise Unreadable(_label(node))

    def scalar(self, socket, uv_of) -> np.ndarray:
        """(N, 1) value of a float input socket at the samples (a colour fed in: its luminance)."""
        fed = _link(socket)
        if fed is None:
            v = socket.default_value
            if hasattr(v, "__len__"):   # a colour input read as a float
                v = np.dot(np.asarray(v[:3], np.float32), self.luminance)
            return np.full((uv_of.count, 1), float(v), np.float32)
        node, out = fed
        if node.bl_idname == "ShaderNodeValue":
            return np.full((uv_of.count, 1), float(out.default_value), np.float32)
        if node.bl_idname == "ShaderNodeMath":
            return self.math(node, uv_of)
        if out.type in ("VALUE", "INT", "BOOLEAN"):   # a float output (an image's Alpha)
            return self.socket(socket, uv_of)[:, :1]
        return (self.socket(socket, uv_of) @ self.luminance)[:, None]

    def math(self, node, uv_of) -> np.ndarray:
        op = node.operation
        if op not in MATH:
            raise Unreadable(f"Math ({op.replace('_', ' ').title()})")
        a = self.scalar(node.inputs[0], uv_of)
        b = self.scalar(node.inputs[1], uv_of) if op != "ABSOLUTE" else None
        with np.errstate(all="ignore"):
            if op == "ADD":
                r = a + b
            elif op == "SUBTRACT":
                r = a - b
            elif op == "MULTIPLY":
                r = a * b
            elif op == "DIVIDE":
                r = np.where(b != 0, a / np.where(b != 0, b, 1), 0)
            elif op == "MULTIPLY_ADD":
                r = a * b + self.scalar(node.inputs[2], uv_of)
            elif op == "MINIMUM":
                r = np.minimum(a, b)
            elif op == "MAXIMUM":
                r = np.maximum(a, b)
            elif op == "ABSOLUTE":
                r = np.abs(a)
            else:   # POWER
                r = np.where((a < 0) & (b != np.floor(b)), 0, np.power(a, b))
        r = np.asarray(r, np.float32)
        return np.clip(r, 0.0, 1.0) if node.use_clamp else r

    def image(self, node, out, uv_of) -> np.ndarray:
        if node.image is None:
            raise Unreadable("Image Texture without an image")
        if node.projection != "FLAT":
            raise Unreadable(f"Image Texture projection {node.projection}")
        vec = node.inputs["Vector"]
        fed = _link(vec)
        if fed is None:
            uv = uv_of(None)
        elif fed[0].bl_idname == "ShaderNodeUVMap":
            uv = uv_of(fed[0].uv_map or None)
        elif fed[0].bl_idname == "ShaderNodeTexCoord" and fed[1].name == "UV":
            uv = uv_of(None)
        else:
            raise Unreadable(f"{_label(fed[0])} into an Image Texture's Vector")
        px = self.pixels(node.image)
        rgba = bilinear(px, uv, node.extension, node.interpolation == "Closest")
        if out.name == "Alpha":
            return np.repeat(rgba[:, 3:4], 3, axis=1)
        return rgba[:, :3]

    def mix(self, node, uv_of) -> np.ndarray:
        if node.bl_idname == "ShaderNodeMix":
            if node.data_type != "RGBA":
                raise Unreadable(f"Mix ({node.data_type})")
            ins = {s.identifier: s for s in node.inputs}
            fac_socket = ins["Factor_Float"] if node.factor_mode == "UNIFORM" else ins["Factor_Vector"]
            a_socket, b_socket = ins["A_Color"], ins["B_Color"]
            clamp_fac, clamp_out = node.clamp_factor, node.clamp_result
        else:
            fac_socket, a_socket, b_socket = node.inputs["Fac"], node.inputs["Color1"], node.inputs["Color2"]
            clamp_fac, clamp_out = True, node.use_clamp
        uniform = node.bl_idname == "ShaderNodeMixRGB" or node.factor_mode == "UNIFORM"
        f = self.scalar(fac_socket, uv_of) if uniform else self.socket(fac_socket, uv_of)
        if clamp_fac:
            f = np.clip(f, 0.0, 1.0)
        a, b = self.socket(a_socket, uv_of), self.socket(b_socket, uv_of)
        blend = node.blend_type
        if blend == "MIX":
            r = a + f * (b - a)
        elif blend == "MULTIPLY":
            r = a * (1.0 - f + f * b)
        elif blend == "ADD":
            r = a + f * b
        elif blend == "SUBTRACT":
            r = a - f * b
        elif blend == "SCREEN":
            r = 1.0 - (1.0 - f + f * (1.0 - b)) * (1.0 - a)
        elif blend == "DARKEN":
            r = a + f * (np.minimum(a, b) - a)
        elif blend == "LIGHTEN":
            r = a + f * (np.maximum(a, b) - a)
        else:
            raise Unreadable(f"Mix ({blend.title()})")
        return np.clip(r, 0.0, 1.0) if clamp_out else r


class _NoUV:
    """The UVs of one sample that has none: asking for them means the chain is textured."""

    count = 1

    def __call__(self, name):
        raise Textured()


def constant(socket) -> float:
    """The value of float input `socket` where its chain holds no texture (Value nodes, Math,
    RGB, Mix, unlinked inputs). Raises Textured (it varies over a face) or Unreadable."""
    return float(Sampler(None).scalar(socket, _NoUV())[0, 0])


def bilinear(px: np.ndarray, uv: np.ndarray, extension: str, closest: bool) -> np.ndarray:
    """(N, 4) samples of (H, W, 4) pixels at UVs, texel centres at (i + 0.5) / W as Cycles'."""
    h, w = px.shape[:2]
    x = uv[:, 0].astype(np.float64) * w - 0.5
    y = uv[:, 1].astype(np.float64) * h - 0.5
    outside = None
    if extension == "CLIP":
        outside = (uv[:, 0] < 0) | (uv[:, 0] > 1) | (uv[:, 1] < 0) | (uv[:, 1] > 1)

    def index(i, n):
        if extension == "REPEAT":
            return np.mod(i, n)
        if extension == "MIRROR":
            p = np.mod(i, 2 * n)
            return np.where(p < n, p, 2 * n - 1 - p)
        return np.clip(i, 0, n - 1)

    if closest:
        xi = index(np.floor(x + 0.5).astype(np.int64), w)
        yi = index(np.floor(y + 0.5).astype(np.int64), h)
        out = px[yi, xi].astype(np.float32)
    else:
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
        xa, xb, ya, yb = index(x0, w), index(x0 + 1, w), index(y0, h), index(y0 + 1, h)
        out = ((px[ya, xa] * (1 - fx) + px[ya, xb] * fx) * (1 - fy)
               + (px[yb, xa] * (1 - fx) + px[yb, xb] * fx) * fy).astype(np.float32)
    if outside is not None:
        out[outside] = 0.0
    return out


class _UVs:
    """UVs at the samples of a set of loop triangles: ``uv_of(name)`` interpolates that map."""

    def __init__(self, sampler: Sampler, tri_loops: np.ndarray, bary: np.ndarray):
        self.sampler, self.tri_loops, self.bary = sampler, tri_loops, bary   # (T,3), (K,2)
        self.count = len(tri_loops) * len(bary)

    def __call__(self, name):
        uv = self.sampler.loop_uv(name)[self.tri_loops]                      # (T,3,2)
        b1, b2 = self.bary[:, 0][None, :, None], self.bary[:, 1][None, :, None]
        p = uv[:, None, 0] * (1 - b1 - b2) + uv[:, None, 1] * b1 + uv[:, None, 2] * b2
        return p.reshape(-1, 2)


def _texel_area(sampler: Sampler, sockets, tri_loops: np.ndarray) -> np.ndarray:
    """Per triangle, its area in texels of the largest image feeding `sockets` (0: none)."""
    images = []

    def walk(s):
        fed = _link(s)
        if fed is None:
            return
        node = fed[0]
        if node.bl_idname == "ShaderNodeTexImage" and node.image is not None:
            images.append(node.image.size[0] * node.image.size[1])
        for i in node.inputs:
            walk(i)

    for s in sockets:
        walk(s)
    if not images:
        return np.zeros(len(tri_loops))
    try:
        uv = sampler.loop_uv(None)[tri_loops].astype(np.float64)
    except Unreadable:
        return np.zeros(len(tri_loops))
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) * max(images)


class Chain:
    """What a material feeds into one quantity: a colour socket, or the product of a colour socket
    and a float socket (the emission: colour x strength), either one possibly absent (1). The
    product is taken per sample, so a face's mean is the mean of colour x strength over it."""

    def __init__(self, color=None, strength=None):
        self.color, self.strength = color, strength
        self.sockets = [s for s in (color, strength) if s is not None]

    def __call__(self, sampler: Sampler, uvs) -> np.ndarray:
        out = np.ones((uvs.count, 3), np.float32)
        for sock, read in ((self.color, sampler.socket), (self.strength, sampler.scalar)):
            if sock is None:
                continue
            try:
                out = out * read(sock, uvs)
            except Unreadable as e:
                raise Unreadable(f"{sock.name} is linked to {e}") from e
        return out


def socket_means(sampler: Sampler, chain: Chain, tri_loops: np.ndarray) -> np.ndarray:
    """(T, 3) mean of `chain` over each loop triangle."""
    texels = _texel_area(sampler, chain.sockets, tri_loops)
    m = np.clip(np.ceil(np.sqrt(np.maximum(texels, 0.0))), MIN_SUBDIVISION, MAX_SUBDIVISION).astype(np.int64)
    m = 2 ** np.ceil(np.log2(m)).astype(np.int64)   # few distinct levels, each one vectorized call
    out = np.zeros((len(tri_loops), 3), np.float64)
    for level in np.unique(m):
        sel = np.flatnonzero(m == level)
        bary = triangle_samples(int(level))
        # Chunks keep the sample arrays to a few million points.
        step = max(1, 2_000_000 // len(bary))
        for c in range(0, len(sel), step):
            part = sel[c:c + step]
            uvs = _UVs(sampler, tri_loops[part], bary)
            values = np.asarray(chain(sampler, uvs), np.float64).reshape(len(part), len(bary), 3)
            out[part] = values.mean(axis=1)
    return out


def _loop_triangles(mesh):
    """The mesh's loop triangles: (T, 3) loops, (T,) polygon and (T,) area of each."""
    mesh.calc_loop_triangles()
    n_t = len(mesh.loop_triangles)
    tri_loops = np.empty(n_t * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", tri_loops)
    tri_poly = np.empty(n_t, np.int32)
    mesh.loop_triangles.foreach_get("polygon_index", tri_poly)
    area = np.empty(n_t, np.float32)
    mesh.loop_triangles.foreach_get("area", area)
    return tri_loops.reshape(-1, 3).astype(np.int64), tri_poly, area


def _area_means(means: np.ndarray, polys: np.ndarray, w: np.ndarray, out: np.ndarray) -> None:
    """Writes into `out` (P, 3) each polygon's area-weighted mean of its triangles' `means`."""
    n_p = len(out)
    total = np.bincount(polys, weights=w, minlength=n_p)
    has = total > 0
    for c in range(3):
        s = np.bincount(polys, weights=w * means[:, c], minlength=n_p)
        out[has, c] = s[has] / total[has]
    # A zero-area polygon keeps its mean over the samples alone.
    for p in np.unique(polys[total[polys] == 0]):
        out[p] = means[polys == p].mean(axis=0)


def polygon_socket_means(mesh, slots, polygon_slots, chain_of, untextured, problems: list):
    """Per polygon of `mesh`, the mean over it of what its slot material feeds into the chain
    ``chain_of(mat)`` (a ``Chain``, or None where nothing varies over a face), else
    ``untextured(mat, linked)`` (`mat` may be None; `linked`: a chain that could not be read).
    Returns ((P, 3) float64, whether any polygon was read), or None when no slot material has a
    chain. What cannot be read is appended to `problems`, once per material and reason."""
    textured = {}
    for k, mat in enumerate(slots or []):
        chain = chain_of(mat) if mat is not None else None
        if chain is not None:
            textured[k] = (mat, chain)
    if not textured:
        return None
    n_p = len(mesh.polygons)
    slot = np.clip(np.asarray(polygon_slots, np.int64), 0, max(len(slots) - 1, 0))
    tri_loops, tri_poly, area = _loop_triangles(mesh)
    values = np.empty((n_p, 3), np.float64)
    for k in range(len(slots) or 1):
        mat = slots[k] if slots else None
        values[slot == k] = untextured(mat, k in textured)
    sampler = Sampler(mesh)
    any_read = False
    for k, (mat, chain) in textured.items():
        tris = np.flatnonzero(slot[tri_poly] == k)
        if len(tris) == 0:
            continue
        try:
            means = socket_means(sampler, chain, tri_loops[tris])
        except Unreadable as e:
            line = f"{mat.name} ({e}, not read)"
            if line not in problems:
                problems.append(line)
            continue
        any_read = True
        _area_means(means, tri_poly[tris], area[tris].astype(np.float64), values)
    return values, any_read


def polygon_reflectance(mesh, slots, polygon_slots, problems: list) -> np.ndarray | None:
    """(P, 3) reflectance per polygon of `mesh` (its slot materials' textured colour averaged
    over the polygon, untextured materials their constant), or None when no slot material has
    a readable textured colour. What cannot be read is appended to `problems`, once per material
    and reason."""
    from .materials import read_material, reflectance_socket

    def untextured(mat, _linked):
        # A linked colour that could not be read: the material's own, the default grey.
        return read_material(mat).reflectance if mat is not None else core.DEFAULT_REFLECTANCE

    def chain_of(mat):
        sock = reflectance_socket(mat)
        return Chain(color=sock) if sock is not None and sock.is_linked else None

    found = polygon_socket_means(mesh, slots, polygon_slots, chain_of, untextured, problems)
    if found is None or not found[1]:
        return None
    rho = found[0]
    return np.array([core.reflectance(r) for r in rho], np.float64) if len(rho) else np.zeros((0, 3))


def varies(socket) -> bool:
    """Whether float input `socket` is linked to a readable chain holding a texture (so it is
    read per face; a constant chain, e.g. a Value node, is read by ``constant``)."""
    if not socket.is_linked or is_readable(socket) is not None:
        return False
    try:
        constant(socket)
    except Textured:
        return True
    except Unreadable:
        return False
    return False


def emission_chain(mat) -> Chain | None:
    """The emission's per-face chain of `mat`: its linked emission colour (read or not: a
    texture, or one that reports why not) and its strength where that holds a texture; None
    when neither varies over a face."""
    from .materials import emission_socket, strength_socket

    color, strength = emission_socket(mat), strength_socket(mat)
    color = color if color is not None and color.is_linked else None
    strength = strength if strength is not None and varies(strength) else None
    return Chain(color, strength) if color is not None or strength is not None else None


def polygon_emission(mesh, slots, polygon_slots, problems: list) -> np.ndarray | None:
    """(P, 3) emission scale per polygon of `mesh`: where its slot material's emission colour or
    strength is textured, the mean over the polygon of the textured colour x the textured
    strength (the material's emission holding the rest, ``materials.read_material``: white for a
    textured colour, 1 for a textured strength); 1 where nothing is textured (already in the
    material's emission); 0 where it is linked but could not be read (a linked emission counts
    as none, as before). None when no slot material has a per-face chain."""

    def untextured(_mat, linked):
        return (0.0, 0.0, 0.0) if linked else (1.0, 1.0, 1.0)

    found = polygon_socket_means(mesh, slots, polygon_slots, emission_chain, untextured, problems)
    if found is None:
        return None
    scale = np.where(np.isfinite(found[0]), found[0], 0.0)
    return np.maximum(scale, 0.0)


def is_readable(socket) -> str | None:
    """None when `socket`'s chain uses only readable nodes, else the first unreadable node type
    (checked without evaluating: for the material's one-line report)."""
    seen = set()

    def walk(s) -> str | None:
        fed = _link(s)
        if fed is None:
            return None
        node = fed[0]
        if node.name in seen:
            return None
        seen.add(node.name)
        if node.bl_idname not in READ:
            return _label(node)
        if node.bl_idname == "ShaderNodeTexImage":
            if node.image is None:
                return "Image Texture without an image"
            vec = _link(node.inputs["Vector"])
            if vec is not None and vec[0].bl_idname not in ("ShaderNodeUVMap", "ShaderNodeTexCoord"):
                return f"{_label(vec[0])} into an Image Texture's Vector"
            return None
        for i in node.inputs:
            bad = walk(i)
            if bad:
                return bad
        return None

    return walk(socket)

