"""ctypes binding of the galerkin-radiosity C ABI (``include/galerkin_radiosity.h``). bpy-free.

Arrays cross the boundary as numpy buffers (``ndarray.ctypes.data_as``), never element by element.
Every function of the ABI has its ``argtypes`` and ``restype`` declared in ``_declare``.

Threads: ctypes releases the GIL during native calls, so ``Session.cancel()`` from another thread
stops a running ``solve_frame``. The progress callback is called from the library's worker threads
(one call at a time); an exception it raises is caught, cancels the solve, and is raised again from
``solve_frame``.
"""

from __future__ import annotations

import ctypes
import json
import os
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from ctypes import (
    CFUNCTYPE,
    POINTER,
    Structure,
    c_char_p,
    c_double,
    c_float,
    c_int32,
    c_size_t,
    c_uint32,
    c_uint64,
    c_void_p,
)
from pathlib import Path

import numpy as np

ABI_VERSION = 3
ENV = "GALERKIN_RADIOSITY_LIB"

# GrStatus (tests/python/test_binding.py checks these against include/galerkin_radiosity.h)
OK = 0
NULL_POINTER = 1
INVALID_ARGUMENT = 2
INVALID_SCENE = 3
CANCELLED = 4
NOT_SOLVED = 5
INTERNAL = 6
OUT_OF_MEMORY = 7
#: Not a GrStatus: the library could not be found or loaded.
NOT_LOADED = -1

METHODS = {"incremental": 0, "exact": 1, "full": 2, "hierarchical": 3}

_ADDON = Path(__file__).resolve().parent.parent
_REPO = _ADDON.parent


class RadiosityError(Exception):
    """A call failed; ``status`` is its GrStatus (``NOT_LOADED`` when the library is missing)."""

    def __init__(self, message: str, status: int = INTERNAL):
        super().__init__(message)
        self.status = status


class Cancelled(RadiosityError):
    """The solve was cancelled (progress returned False, or ``Session.cancel()``)."""

    def __init__(self, message: str = "cancelled", status: int = CANCELLED):
        super().__init__(message, status)


class _Settings(Structure):
    """``GrSettings``; ``gr_settings_default`` sets ``struct_size`` (tests/python/test_binding.py
    checks the fields against the header)."""

    _fields_ = [
        ("struct_size", c_uint32),
        ("basis_order", c_uint32),
        ("quadrature_order", c_uint32),
        ("visibility", c_uint32),
        ("visibility_samples", c_uint32),
        ("threads", c_uint32),
        ("method", c_uint32),
        ("corner_gather", c_uint32),
        ("tolerance", c_double),
        ("memory_budget_mb", c_uint64),
        ("accuracy", c_double),
        ("reflecting_backs", c_uint32),
    ]


class _Light(Structure):
    """``GrLight`` (src/ffi/lights.rs): one light as it is at the coming frame."""

    _fields_ = [
        ("struct_size", c_uint32),
        ("kind", c_uint32),
        ("shape", c_uint32),
        ("matrix", c_double * 16),
        ("color", c_double * 3),
        ("power", c_double),
        ("radius", c_double),
        ("spot_size", c_double),
        ("spot_blend", c_double),
        ("angle", c_double),
        ("area_size", c_double * 2),
        ("soft_falloff", c_uint32),
    ]


class _Mesh(Structure):
    """``GrMesh`` (src/ffi/builder.rs): one object for ``gr_scene_builder_add_mesh``."""

    _fields_ = [
        ("struct_size", c_uint32),
        ("vertex_count", c_uint32),
        ("vertices", POINTER(c_float)),
        ("face_count", c_uint32),
        ("face_vertex_counts", POINTER(c_uint32)),
        ("face_materials", POINTER(c_uint32)),
        ("face_indices", POINTER(c_uint32)),
        ("face_indices_len", c_size_t),
        ("matrix", POINTER(c_float)),
    ]


#: ``GrLightKind`` and ``GrLightShape`` values by Blender's names.
LIGHT_KINDS = {"POINT": 0, "SPOT": 1, "SUN": 2, "AREA": 3}
LIGHT_SHAPES = {"SQUARE": 0, "RECTANGLE": 1, "DISK": 2, "ELLIPSE": 3}

_PROGRESS = CFUNCTYPE(c_int32, c_double, c_char_p, c_void_p)
_F32 = POINTER(c_float)
_U32 = POINTER(c_uint32)
_SESSION = c_void_p
_BUILDER = c_void_p


def _library_name() -> str:
    if sys.platform == "darwin":
        return "libgalerkin_radiosity.dylib"
    if sys.platform in ("win32", "cygwin"):
        return "galerkin_radiosity.dll"
    return "libgalerkin_radiosity.so"


def library_candidates() -> list[Path]:
    """Where ``load()`` looks, in order: $GALERKIN_RADIOSITY_LIB (a file, or a folder holding the
    library), the add-on's own ``lib/`` (packaged extension), then the repository's
    ``target/release`` and ``target/debug``."""
    name = _library_name()
    out = []
    env = os.environ.get(ENV)
    if env:
        p = Path(env)
        out.append(p / name if p.is_dir() else p)
    out += [_ADDON / "lib" / name, _REPO / "target" / "release" / name, _REPO / "target" / "debug" / name]
    return out


def _declare(lib: ctypes.CDLL) -> None:
    sigs = {
        "gr_abi_version": ([], c_uint32),
        "gr_version_string": ([], c_char_p),
        "gr_settings_default": ([POINTER(_Settings)], c_uint32),
        "gr_last_error": ([ctypes.c_char_p, c_size_t], c_size_t),
        "gr_session_new": (
            [POINTER(_Settings), c_uint32, _F32, _F32, c_uint32, _U32, _F32, _U32, _U32, _U32, _U32,
             _F32, c_size_t, c_size_t, POINTER(_SESSION)],
            c_uint32,
        ),
        "gr_scene_builder_new": ([POINTER(_BUILDER)], c_uint32),
        "gr_scene_builder_set_settings": ([_BUILDER, POINTER(_Settings)], c_uint32),
        "gr_scene_builder_add_material": ([_BUILDER, _F32, _F32, _U32], c_uint32),
        "gr_mesh_default": ([POINTER(_Mesh)], c_uint32),
        "gr_scene_builder_add_mesh": ([_BUILDER, POINTER(_Mesh), _U32], c_uint32),
        "gr_scene_builder_add_light": ([_BUILDER, POINTER(_Light)], c_uint32),
        "gr_scene_builder_build": ([_BUILDER, POINTER(_SESSION)], c_uint32),
        "gr_scene_builder_free": ([_BUILDER], None),
        "gr_session_set_object_matrix": ([_SESSION, c_uint32, _F32], c_uint32),
        "gr_session_set_material_emission": ([_SESSION, c_uint32, _F32], c_uint32),
        "gr_light_default": ([POINTER(_Light)], c_uint32),
        "gr_session_set_lights": ([_SESSION, POINTER(_Light), c_size_t], c_uint32),
        "gr_session_set_world": ([_SESSION, POINTER(c_double), c_double, _F32, c_uint32, c_uint32], c_uint32),
        "gr_session_set_two_sided": ([_SESSION, c_uint32, c_uint32], c_uint32),
        "gr_session_set_object_surface": ([_SESSION, c_uint32, _F32, c_size_t, _F32, c_size_t], c_uint32),
        "gr_session_set_object_face_emission": ([_SESSION, c_uint32, _F32, c_size_t], c_uint32),
        "gr_session_solve_frame": ([_SESSION, c_double, _PROGRESS, c_void_p], c_uint32),
        "gr_session_set_preview": ([_SESSION, c_uint32], c_uint32),
        "gr_session_set_animated": ([_SESSION, c_uint32], c_uint32),
        "gr_session_refine": ([_SESSION, _PROGRESS, c_void_p, _U32], c_uint32),
        "gr_session_cancel": ([_SESSION], c_uint32),
        "gr_session_frame_stats_json": ([_SESSION, c_char_p, c_size_t, POINTER(c_size_t)], c_uint32),
        "gr_session_object_count": ([_SESSION, _U32], c_uint32),
        "gr_session_face_count": ([_SESSION, c_uint32, _U32], c_uint32),
        "gr_session_corner_count": ([_SESSION, c_uint32, _U32], c_uint32),
        "gr_session_face_radiosity": ([_SESSION, c_uint32, _F32, c_size_t], c_uint32),
        "gr_session_corner_radiosity": ([_SESSION, c_uint32, _F32, c_size_t], c_uint32),
        "gr_session_eval": ([_SESSION, c_size_t, _U32, _U32, _F32, _F32], c_uint32),
        "gr_session_corner_irradiance": ([_SESSION, c_uint32, _F32, c_size_t], c_uint32),
        "gr_session_eval_irradiance": ([_SESSION, c_size_t, _U32, _U32, _F32, _F32], c_uint32),
        "gr_session_free": ([_SESSION], None),
    }
    for name, (args, res) in sigs.items():
        fn = getattr(lib, name)
        fn.argtypes = args
        fn.restype = res


_lib: ctypes.CDLL | None = None
_lib_lock = threading.Lock()


def _open(path: Path) -> ctypes.CDLL:
    lib = ctypes.CDLL(str(path))
    _declare(lib)  # AttributeError when a symbol is missing (an old build)
    abi = lib.gr_abi_version()
    if abi != ABI_VERSION:
        raise OSError(f"ABI version {abi}, this binding needs {ABI_VERSION}")
    return lib


def load(path: str | os.PathLike | None = None) -> ctypes.CDLL:
    """The library, loaded once (from ``path`` if given, else the first usable candidate)."""
    global _lib
    with _lib_lock:
        if path is None and _lib is not None:
            return _lib
        candidates = [Path(path)] if path is not None else library_candidates()
        looked = []
        for c in candidates:
            if not c.is_file():
                looked.append(f"{c} (no such file)")
                continue
            try:
                _lib = _open(c)
                return _lib
            except (OSError, AttributeError) as e:
                looked.append(f"{c} ({e})")
        raise RadiosityError(
            "galerkin-radiosity native library not found or not usable; looked in: "
            + "; ".join(looked)
            + f". Build it with `cargo build --release` or set {ENV}.",
            NOT_LOADED,
        )


def abi_version() -> int:
    return int(load().gr_abi_version())


def version() -> str:
    return load().gr_version_string().decode()


def _last_error(lib: ctypes.CDLL) -> str:
    n = lib.gr_last_error(None, 0)
    buf = ctypes.create_string_buffer(n + 1)
    lib.gr_last_error(buf, n + 1)
    return buf.value.decode("utf-8", errors="replace")


def _check(lib: ctypes.CDLL, status: int) -> None:
    if status == OK:
        return
    message = _last_error(lib) or f"status {status}"
    if status == CANCELLED:
        raise Cancelled(message)
    raise RadiosityError(message, status)


def _invalid(message: str) -> RadiosityError:
    return RadiosityError(message, INVALID_ARGUMENT)


def _floats(a, shape: tuple, what: str) -> np.ndarray:
    """A C-contiguous float32 copy (or view) of ``a`` with ``shape`` (-1: any length)."""
    try:
        arr = np.ascontiguousarray(a, dtype=np.float32)
    except (TypeError, ValueError) as e:
        raise _invalid(f"{what}: not an array of numbers ({e})") from e
    if arr.ndim != len(shape) or any(s not in (-1, n) for s, n in zip(shape, arr.shape, strict=True)):
        raise _invalid(f"{what}: shape {arr.shape}, expected {tuple('n' if s == -1 else s for s in shape)}")
    return arr


def _indices(a, length: int | None, what: str) -> np.ndarray:
    """A C-contiguous uint32 array from integers in 0..2^32-1."""
    arr = np.asarray(a)
    if arr.ndim != 1:
        raise _invalid(f"{what}: shape {arr.shape}, expected (n,)")
    if arr.size and not (np.issubdtype(arr.dtype, np.integer) or arr.dtype == np.bool_):
        raise _invalid(f"{what}: dtype {arr.dtype} is not an integer type")
    if arr.size and (int(arr.min()) < 0 or int(arr.max()) > 0xFFFFFFFF):
        raise _invalid(f"{what}: values must be in 0..2^32-1")
    if length is not None and arr.shape[0] != length:
        raise _invalid(f"{what}: {arr.shape[0]} entries, expected {length}")
    return np.ascontiguousarray(arr, dtype=np.uint32)


def _matrix(m, what: str) -> np.ndarray:
    """A 4x4 row-major float32 matrix from a (4, 4) array or 16 numbers."""
    arr = _floats(m, (-1,) * np.ndim(m), what) if np.ndim(m) else None
    if arr is None or arr.size != 16:
        raise _invalid(f"{what}: expected a 4x4 matrix")
    return np.ascontiguousarray(arr.reshape(4, 4))


def _ptr(arr: np.ndarray, kind):
    return arr.ctypes.data_as(kind)


def _u32(value, what: str) -> int:
    try:
        v = int(value)
    except (TypeError, ValueError) as e:
        raise _invalid(f"{what}: {value!r} is not an integer") from e
    if not 0 <= v <= 0xFFFFFFFF:
        raise _invalid(f"{what}: {v} is outside 0..2^32-1")
    return v


def _settings(lib: ctypes.CDLL, settings: dict) -> _Settings:
    s = _Settings()
    _check(lib, lib.gr_settings_default(ctypes.byref(s)))
    for key, value in (settings or {}).items():
        if key == "method":
            if value not in METHODS:
                raise _invalid(f"settings.method {value!r} is not one of {', '.join(METHODS)}")
            s.method = METHODS[value]
        elif key in ("tolerance", "accuracy"):
            setattr(s, key, float(value))
        elif key in ("visibility", "corner_gather", "reflecting_backs"):
            setattr(s, key, _u32(value, f"settings.{key}"))  # True/False or 1/0
        elif key in ("basis_order", "quadrature_order", "visibility_samples", "threads"):
            setattr(s, key, _u32(value, f"settings.{key}"))
        elif key == "memory_budget_mb":
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**64:
                raise _invalid(f"settings.memory_budget_mb {value!r} is not a whole number of MiB >= 0")
            s.memory_budget_mb = value
        else:
            raise _invalid(f"unknown setting {key!r}")
    return s


class Session:
    """A baking session: the scene, its thread pool and the last solved frame.

    ``settings``: optional keys basis_order, quadrature_order, tolerance, visibility,
    visibility_samples, threads, method ('incremental' | 'exact' | 'full' | 'hierarchical'),
    accuracy (the hierarchical method's), corner_gather, reflecting_backs (open surfaces reflect
    from both sides),
    memory_budget_mb (0: 80% of the available memory; a scene estimated over it is refused).
    ``reflectance``, ``emission``: (M, 3) per material. ``objects``: dicts with ``vertices``
    (N, 3), ``face_sizes`` (F,) of 3 or 4, ``face_indices`` (sum of face_sizes,) local to the
    object, ``face_materials`` (F,), and optionally ``matrix`` (4, 4) row-major world-from-object
    (Blender's ``np.array(obj.matrix_world)``), ``corner_normals`` and ``face_reflectance``
    (see ``set_object_surface``) and ``face_emission`` (see ``set_object_face_emission``).
    """

    def __init__(self, settings: dict, reflectance, emission, objects: list[dict]):
        self._lib = lib = load()
        self._ptr: int | None = None
        self._lock = threading.Lock()
        self._calls = 0
        self._closing = False
        s = _settings(lib, settings)
        rho = _floats(reflectance, (-1, 3), "reflectance")
        em = _floats(emission, (rho.shape[0], 3), "emission")
        meshes, sizes = [], []
        for i, o in enumerate(objects):
            try:
                v = _floats(o["vertices"], (-1, 3), f"object {i} vertices")
                fs = _indices(o["face_sizes"], None, f"object {i} face_sizes")
                fi = _indices(o["face_indices"], None, f"object {i} face_indices")
                fm = _indices(o["face_materials"], fs.shape[0], f"object {i} face_materials")
            except KeyError as e:
                raise _invalid(f"object {i}: missing key {e}") from e
            m = o.get("matrix")
            m = None if m is None else _matrix(m, f"object {i} matrix")
            meshes.append((v, fs, fi, fm, m))  # kept alive until the build has copied them
            sizes.append(fs)
        # The scene builder (ABI version 2): one call per material and object.
        builder = _BUILDER()
        _check(lib, lib.gr_scene_builder_new(ctypes.byref(builder)))
        out = _SESSION()
        try:
            _check(lib, lib.gr_scene_builder_set_settings(builder, ctypes.byref(s)))
            for k in range(rho.shape[0]):
                _check(lib, lib.gr_scene_builder_add_material(builder, _ptr(rho[k], _F32),
                                                              _ptr(em[k], _F32), None))
            for v, fs, fi, fm, m in meshes:
                mesh = _Mesh()
                _check(lib, lib.gr_mesh_default(ctypes.byref(mesh)))
                mesh.vertex_count, mesh.vertices = len(v), _ptr(v, _F32)
                mesh.face_count, mesh.face_vertex_counts = len(fs), _ptr(fs, _U32)
                mesh.face_materials, mesh.face_indices = _ptr(fm, _U32), _ptr(fi, _U32)
                mesh.face_indices_len = fi.size
                if m is not None:
                    mesh.matrix = _ptr(m, _F32)
                _check(lib, lib.gr_scene_builder_add_mesh(builder, ctypes.byref(mesh), None))
            status = lib.gr_scene_builder_build(builder, ctypes.byref(out))
        finally:
            lib.gr_scene_builder_free(builder)
        face_counts = np.array([len(f) for f in sizes], np.uint32)
        _check(lib, status)
        self._ptr = out.value
        self._faces = face_counts
        self._corners = np.array([int(f.sum()) for f in sizes], np.int64)
        try:
            for i, o in enumerate(objects):
                if o.get("corner_normals") is not None or o.get("face_reflectance") is not None:
                    self.set_object_surface(i, o.get("corner_normals"), o.get("face_reflectance"))
                if o.get("face_emission") is not None:
                    self.set_object_face_emission(i, o["face_emission"])
        except RadiosityError:
            self.close()
            raise

    # -- lifetime -------------------------------------------------------------------------------

    @contextmanager
    def _use(self) -> Iterator[int]:
        """The session pointer for one call; a close() during the call frees after it."""
        with self._lock:
            if self._ptr is None or self._closing:
                raise _invalid("the session is closed")
            self._calls += 1
            ptr = self._ptr
        try:
            yield ptr
        finally:
            free = None
            with self._lock:
                self._calls -= 1
                if self._closing and self._calls == 0 and self._ptr is not None:
                    free, self._ptr = self._ptr, None
            if free is not None:
                self._lib.gr_session_free(free)

    def close(self) -> None:
        """Frees the native session (a running solve is cancelled and freed when it returns)."""
        lock = getattr(self, "_lock", None)
        if lock is None:
            return
        with lock:
            if self._ptr is None or self._closing:
                return
            self._closing = True
            if self._calls:
                self._lib.gr_session_cancel(self._ptr)
                return
            ptr, self._ptr = self._ptr, None
        self._lib.gr_session_free(ptr)

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - nothing may escape __del__ (interpreter shutdown)
            pass

    def _call(self, name: str, *args) -> None:
        """Calls ``name(session, *args)`` and raises on a failed status."""
        with self._use() as p:
            _check(self._lib, getattr(self._lib, name)(p, *args))

    # -- changes --------------------------------------------------------------------------------

    def set_object_matrix(self, index: int, matrix) -> None:
        """Object ``index``'s world-from-object matrix (4x4 row-major) from the next frame on."""
        m = _matrix(matrix, "matrix")
        self._call("gr_session_set_object_matrix", _u32(index, "object"), _ptr(m, _F32))

    def set_material_emission(self, index: int, rgb) -> None:
        """Material ``index``'s emission (RGB, W/m^2) from the next frame on."""
        e = _floats(rgb, (3,), "rgb")
        self._call("gr_session_set_material_emission", _u32(index, "material"), _ptr(e, _F32))

    def set_object_surface(self, index: int, corner_normals=None, face_reflectance=None) -> None:
        """Object ``index``'s shading normals, (sum of face sizes, 3) object space (a zero row:
        the face's own normal), and reflectance per face, (F, 3) in [0,1); None for neither."""
        n = _floats(np.zeros((0, 3)) if corner_normals is None else corner_normals, (-1, 3), "corner_normals")
        r = _floats(np.zeros((0, 3)) if face_reflectance is None else face_reflectance, (-1, 3),
                    "face_reflectance")
        self._call("gr_session_set_object_surface", _u32(index, "object"),
                   _ptr(n, _F32) if n.size else None, n.size, _ptr(r, _F32) if r.size else None, r.size)

    def set_object_face_emission(self, index: int, face_emission=None) -> None:
        """Object ``index``'s emission colour scale per face, (F, 3), >= 0, multiplying its faces'
        material emission (an Emission Color texture's mean); None for 1 everywhere. Its other
        surface data (``set_object_surface``) stays."""
        e = _floats(np.zeros((0, 3)) if face_emission is None else face_emission, (-1, 3), "face_emission")
        self._call("gr_session_set_object_face_emission", _u32(index, "object"),
                   _ptr(e, _F32) if e.size else None, e.size)

    def set_lights(self, lights) -> None:
        """Replaces the lights from the next frame on. ``lights``: dicts with ``type`` (POINT, SPOT,
        SUN, AREA), ``matrix`` (4x4 row-major world-from-light), and optionally ``color`` (RGB),
        ``power`` (W; sun: strength W/m^2), ``radius``, ``soft_falloff`` (point and spot of radius
        > 0: a disk facing the receiver, the default, or False a sphere), ``spot_size``,
        ``spot_blend`` (radians, [0,1]), ``angle``, ``shape`` (SQUARE, RECTANGLE, DISK, ELLIPSE),
        ``size`` ((x, y) m)."""
        arr = (_Light * max(len(lights), 1))()
        for i, d in enumerate(lights):
            g = arr[i]
            _check(self._lib, self._lib.gr_light_default(ctypes.byref(g)))
            kind = str(d.get("type", "")).upper()
            if kind not in LIGHT_KINDS:
                raise _invalid(f"lights[{i}]: type {d.get('type')!r} is not one of {sorted(LIGHT_KINDS)}")
            g.kind = LIGHT_KINDS[kind]
            shape = str(d.get("shape", "SQUARE")).upper()
            if shape not in LIGHT_SHAPES:
                raise _invalid(f"lights[{i}]: shape {d.get('shape')!r} is not one of {sorted(LIGHT_SHAPES)}")
            g.shape = LIGHT_SHAPES[shape]
            _matrix(d["matrix"], f"lights[{i}].matrix")  # checks the shape
            g.matrix[:] = [float(x) for x in np.asarray(d["matrix"], np.float64).reshape(-1)]
            if "color" in d:
                g.color[:] = [float(x) for x in _floats(d["color"], (3,), f"lights[{i}].color")]
            for key in ("power", "radius", "spot_size", "spot_blend", "angle"):
                if key in d:
                    setattr(g, key, float(d[key]))
            if "soft_falloff" in d:
                g.soft_falloff = 1 if d["soft_falloff"] else 0
            if "size" in d:
                g.area_size[:] = [float(x) for x in _floats(d["size"], (2,), f"lights[{i}].size")]
        self._call("gr_session_set_lights", arr, len(lights))

    def set_world(self, color=(0.0, 0.0, 0.0), strength: float = 0.0, image=None) -> None:
        """The World from the next frame on: radiance ``strength * color`` from every direction,
        times ``image`` ((H, W, 3) linear RGB, bottom row first, Blender's equirectangular
        mapping) where given; strength 0 removes it."""
        rgb = (c_double * 3)(*[float(x) for x in _floats(color, (3,), "color")])
        if image is None:
            pixels, w, h = None, 0, 0
        else:
            arr = _floats(image, (-1, -1, 3), "image")
            pixels, (h, w) = _ptr(arr, _F32), arr.shape[:2]
        self._call("gr_session_set_world", rgb, float(strength), pixels, w, h)

    def set_two_sided(self, index: int, on: bool) -> None:
        """Object ``index``'s emitting faces emit from both sides (``on``) from the next frame on."""
        self._call("gr_session_set_two_sided", _u32(index, "object"), 1 if on else 0)

    # -- solving --------------------------------------------------------------------------------

    def solve_frame(self, frame: float, progress: Callable[[float, str], bool | None] | None = None) -> dict:
        """Solves ``frame``; returns its statistics. ``progress(fraction, stage)`` returning False
        cancels (raises ``Cancelled``); it is called from worker threads."""
        with self._use() as p:
            solve = self._lib.gr_session_solve_frame
            self._with_progress(progress, lambda cb: solve(p, float(frame), cb, None))
            return self._stats(p)

    def set_preview(self, on: bool) -> None:
        """While ``on``, ``solve_frame`` solves previews: to a looser tolerance (ten times the
        settings', at most 1e-3) and without the corner gather (the corners are the face
        polynomials'), until ``refine``. For a preview while the timeline is scrubbed."""
        with self._use() as p:
            _check(self._lib, self._lib.gr_session_set_preview(p, 1 if on else 0))

    def set_animated(self, on: bool) -> None:
        """Says that frames will follow the next one (an animation's bake, a scrubbed preview): the
        hierarchy then keeps its refinement's record, so that updates link coarser again where a
        move has passed. Set before the first frame."""
        with self._use() as p:
            _check(self._lib, self._lib.gr_session_set_animated(p, 1 if on else 0))

    def refine(self, progress: Callable[[float, str], bool | None] | None = None) -> dict | None:
        """Brings a preview frame to what a solve without previews gives (the rest of its solve,
        then its corner gather); returns the frame's statistics, or None when it was no preview.
        Cancelling as for ``solve_frame``; then the frame stays readable as far as it came."""
        refined = c_uint32(0)
        with self._use() as p:
            self._with_progress(
                progress, lambda cb: self._lib.gr_session_refine(p, cb, None, ctypes.byref(refined))
            )
            return self._stats(p) if refined.value else None

    def _with_progress(self, progress, call) -> None:
        """Runs ``call(callback)`` with ``progress`` behind a C callback (NULL when None), then
        raises what the callback raised, or the call's error."""
        raised: list[BaseException] = []

        def trampoline(fraction, stage, _user):
            if raised:
                return 0
            try:
                r = progress(fraction, stage.decode() if stage else "")
            except BaseException as e:  # noqa: BLE001 - must not cross into C; re-raised below
                raised.append(e)
                return 0
            return 0 if (r is not None and not r) else 1

        callback = _PROGRESS(trampoline) if progress is not None else _PROGRESS()  # NULL
        status = call(callback)
        del callback  # kept alive until here, after the call returned
        if raised:
            raise raised[0]
        _check(self._lib, status)

    def cancel(self) -> None:
        """Thread-safe: a running ``solve_frame`` stops soon and raises ``Cancelled``."""
        try:
            with self._use() as p:
                self._lib.gr_session_cancel(p)
        except RadiosityError:
            pass  # closed: nothing runs

    def _stats(self, p) -> dict:
        needed = c_size_t(0)
        status = self._lib.gr_session_frame_stats_json(p, None, 0, ctypes.byref(needed))
        if status != INVALID_ARGUMENT:
            _check(self._lib, status)
        buf = ctypes.create_string_buffer(needed.value)
        _check(self._lib, self._lib.gr_session_frame_stats_json(p, buf, needed.value, ctypes.byref(needed)))
        return json.loads(buf.value.decode())

    def frame_stats(self) -> dict:
        """The last solved frame's statistics."""
        with self._use() as p:
            return self._stats(p)

    # -- results --------------------------------------------------------------------------------

    @property
    def object_count(self) -> int:
        return len(self._faces)

    def _object(self, obj) -> int:
        o = _u32(obj, "object")
        if o >= len(self._faces):
            raise _invalid(f"object {o} out of range (0..{len(self._faces)})")
        return o

    def face_radiosity(self, obj: int) -> np.ndarray:
        """Area-mean radiosity per face of object ``obj``: (F, 3) float32, W/m^2."""
        o = self._object(obj)
        out = np.empty((int(self._faces[o]), 3), np.float32)
        self._call("gr_session_face_radiosity", o, _ptr(out, _F32), out.size)
        return out

    def corner_radiosity(self, obj: int) -> np.ndarray:
        """Radiosity at each face corner of object ``obj`` (faces in order, corners in face
        order): (C, 3) float32, W/m^2."""
        o = self._object(obj)
        out = np.empty((int(self._corners[o]), 3), np.float32)
        self._call("gr_session_corner_radiosity", o, _ptr(out, _F32), out.size)
        return out

    def corner_irradiance(self, obj: int) -> np.ndarray:
        """The irradiance H at each face corner of object ``obj`` (the light it receives, so
        that B = E + rho H), laid out as ``corner_radiosity``: (C, 3) float32, W/m^2."""
        o = self._object(obj)
        out = np.empty((int(self._corners[o]), 3), np.float32)
        self._call("gr_session_corner_irradiance", o, _ptr(out, _F32), out.size)
        return out

    def eval(self, objects, faces, st, irradiance: bool = False) -> np.ndarray:
        """Radiosity at face parameters ``st`` (n, 2) in [0,1]^2 of ``faces`` (n,) of ``objects``
        (n,) or one object index: (n, 3) float32. With ``irradiance``, the irradiance H there,
        (B - E) / rho of the face polynomial (0 where rho < 1e-4)."""
        f = _indices(faces, None, "faces")
        n = f.shape[0]
        obj = np.asarray(objects)
        if obj.ndim == 0:
            obj = np.full(n, obj)
        o = _indices(obj, n, "objects")
        st = _floats(np.asarray(st, dtype=np.float32).reshape(-1, 2), (n, 2), "st")
        out = np.empty((n, 3), np.float32)
        name = "gr_session_eval_irradiance" if irradiance else "gr_session_eval"
        self._call(name, n, _ptr(o, _U32), _ptr(f, _U32), _ptr(st, _F32), _ptr(out, _F32))
        return out
