"""The ctypes binding (addon/native/binding.py) against the built library; no bpy.

The binding is loaded from its file so that the add-on package (which imports bpy) is not.
Needs the library: `cargo build --release` (or `cargo build`), or GALERKIN_RADIOSITY_LIB.
"""

import ctypes
import importlib.util
import re
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
HOWELL_C11 = 0.199825  # unit squares, parallel, opposed, unit distance apart


def _load_binding():
    name = "galerkin_radiosity_native_binding"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, REPO / "addon" / "native" / "binding.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def b():
    binding = _load_binding()
    try:
        binding.load()
    except binding.RadiosityError as e:
        pytest.fail(f"{e}\nBuild the library first: `cargo build --release` in {REPO}.")
    return binding


def _quad(z, up):
    """A unit square at height z, facing +z (up) or -z."""
    v = np.array([[0, 0, z], [1, 0, z], [1, 1, z], [0, 1, z]], np.float32)
    idx = np.array([0, 1, 2, 3] if up else [0, 3, 2, 1], np.uint32)
    return v, idx


def two_patches(bad_index=False):
    """Receiver (reflectance 0.5) at z = 0 facing up; black emitter (1 W/m^2) at z = 1 facing
    down, modelled at z = 0 and placed by its matrix."""
    rv, ri = _quad(0.0, True)
    ev, ei = _quad(0.0, False)
    if bad_index:
        ei = ei.copy()
        ei[2] = 7
    lift = np.eye(4)
    lift[2, 3] = 1.0  # row-major: translation in the last column
    objects = [
        dict(vertices=rv, face_sizes=np.array([4]), face_indices=ri, face_materials=np.array([0])),
        dict(vertices=ev, face_sizes=np.array([4]), face_indices=ei, face_materials=np.array([1]),
             matrix=lift),
    ]
    rho = np.array([[0.5, 0.5, 0.5], [0.0, 0.0, 0.0]])
    emission = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    return rho, emission, objects


def closed_box(n):
    """A unit box of six inward walls, n x n quads each; the ceiling (object 1) emits."""
    walls = [  # origin, u, v with u x v pointing inward
        ((0, 0, 0), (1, 0, 0), (0, 1, 0)),
        ((0, 0, 1), (0, 1, 0), (1, 0, 0)),
        ((0, 0, 0), (0, 1, 0), (0, 0, 1)),
        ((1, 0, 0), (0, 0, 1), (0, 1, 0)),
        ((0, 0, 0), (0, 0, 1), (1, 0, 0)),
        ((0, 1, 0), (1, 0, 0), (0, 0, 1)),
    ]
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    a, c = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    vid = lambda p, q: (p * (n + 1) + q).ravel()  # noqa: E731
    faces = np.stack([vid(a, c), vid(a + 1, c), vid(a + 1, c + 1), vid(a, c + 1)], axis=1).ravel()
    objects = []
    for k, (o, u, v) in enumerate(walls):
        o, u, v = (np.array(x, np.float32) for x in (o, u, v))
        verts = o + (i.ravel()[:, None] / n) * u + (j.ravel()[:, None] / n) * v
        objects.append(dict(vertices=verts, face_sizes=np.full(n * n, 4), face_indices=faces,
                            face_materials=np.full(n * n, 1 if k == 1 else 0)))
    rho = np.array([[0.7, 0.7, 0.7], [0.0, 0.0, 0.0]])
    emission = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    return rho, emission, objects


def test_versions(b):
    assert b.abi_version() == b.ABI_VERSION == 3
    cargo = (REPO / "Cargo.toml").read_text()
    assert b.version() == re.search(r'(?m)^version = "([^"]+)"', cargo).group(1)


HEADER = REPO / "include" / "galerkin_radiosity.h"


def _strip_comments(c_text):
    return re.sub(r"/\*.*?\*/|//[^\n]*", "", c_text, flags=re.S)


def test_the_binding_agrees_with_the_header():
    """Issue 22, item 1: the status codes, the ABI version and the settings and light structs
    the binding declares are the header's, so that they cannot drift apart."""
    binding = _load_binding()
    header = _strip_comments(HEADER.read_text())
    statuses = {m[1]: int(m[2]) for m in re.finditer(r"\bGR_STATUS_(\w+)\s*=\s*(\d+)", header)}
    assert statuses and "OUT_OF_MEMORY" in statuses
    for name, value in statuses.items():
        assert getattr(binding, name, None) == value, f"binding.{name} is not GR_STATUS_{name} = {value}"
    assert int(re.search(r"#define GR_ABI_VERSION (\d+)", header)[1]) == binding.ABI_VERSION

    def fields(struct):
        """(type, name, "[n]" or "") of each field of the header's `struct`."""
        body = re.search(r"typedef struct " + struct + r" \{(.*?)\} " + struct + ";", header, re.S)[1]
        return [(m[1], m[2], m[3] or "") for m in re.finditer(r"\b(\w+) (\w+)(\[\d+\])?;", body)]

    c_types = {ctypes.c_uint32: "uint32_t", ctypes.c_uint64: "uint64_t", ctypes.c_double: "double"}
    for struct, declared in (("GrSettings", binding._Settings), ("GrLight", binding._Light)):
        got = []
        for name, t in declared._fields_:
            array = hasattr(t, "_length_")
            c_type = c_types[t._type_ if array else t]
            got.append((c_type, name, f"[{t._length_}]" if array else ""))
        # GrMethod is a uint32_t enum in C.
        want = [("uint32_t" if ty == "GrMethod" else ty, n, a) for ty, n, a in fields(struct)]
        assert got == want, f"{declared.__name__} differs from the header's {struct}"
    # GrMesh holds pointers: its field names in order.
    body = re.search(r"typedef struct GrMesh \{(.*?)\} GrMesh;", header, re.S)[1]
    assert [n for n, _ in binding._Mesh._fields_] == re.findall(r"(\w+);", body)


def test_two_patches_value_and_shapes(b):
    with b.Session({}, *two_patches()) as s:
        stats = s.solve_frame(1.0)
        assert stats["frame"] == 1.0 and stats["elements"] == 2
        face = s.face_radiosity(0)
        assert face.shape == (1, 3) and face.dtype == np.float32
        want = 0.5 * HOWELL_C11
        assert np.all(np.abs(face - want) / want < 0.01), face
        assert s.face_radiosity(1) == pytest.approx(np.ones((1, 3)))
        corners = s.corner_radiosity(0)
        assert corners.shape == (4, 3) and corners.dtype == np.float32
        assert np.all(corners < face[0, 0])
        centre = s.eval(0, [0], [[0.5, 0.5]])
        assert centre.shape == (1, 3) and centre[0, 0] > face[0, 0]
        assert s.frame_stats() == stats
        # Emission doubled from the next frame on.
        s.set_material_emission(1, (2.0, 2.0, 2.0))
        s.solve_frame(2.0)
        assert s.face_radiosity(0) == pytest.approx(2 * face, rel=1e-4)


def test_triangles_and_quads_shapes(b):
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], np.float32)
    obj = dict(vertices=v, face_sizes=np.array([4, 3], np.int32),
               face_indices=np.array([0, 1, 2, 3, 1, 4, 2], np.int64),
               face_materials=np.array([0, 0]))
    with b.Session({"basis_order": 1, "method": "full"}, [[0.5] * 3], [[1.0] * 3], [obj]) as s:
        s.solve_frame(0.0)
        assert s.face_radiosity(0).shape == (2, 3)
        assert s.corner_radiosity(0).shape == (7, 3)
        assert s.face_radiosity(0) == pytest.approx(np.ones((2, 3)), rel=1e-5)  # coplanar: emission only


def test_invalid_scene_names_the_face(b):
    with pytest.raises(b.RadiosityError) as err:
        b.Session({}, *two_patches(bad_index=True))
    assert err.value.status == b.INVALID_SCENE
    assert "face" in str(err.value) and "object 1" in str(err.value)
    assert not isinstance(err.value, b.Cancelled)


def test_bad_arguments_are_radiosity_errors(b):
    rho, em, objs = two_patches()
    with pytest.raises(b.RadiosityError, match="unknown setting"):
        b.Session({"colour": 1}, rho, em, objs)
    with pytest.raises(b.RadiosityError, match="method"):
        b.Session({"method": "magic"}, rho, em, objs)
    with pytest.raises(b.RadiosityError, match="emission"):
        b.Session({}, rho, em[:1], objs)
    bad = [dict(objs[0], face_indices=np.array([0, 1, 2, -1]))]
    with pytest.raises(b.RadiosityError, match="face_indices"):
        b.Session({}, rho, em, bad)
    with pytest.raises(b.RadiosityError) as err:
        b.Session({"basis_order": 9}, rho, em, objs)
    assert err.value.status == b.INVALID_SCENE and "basis_order" in str(err.value)
    with b.Session({}, rho, em, objs) as s:
        with pytest.raises(b.RadiosityError) as err:
            s.face_radiosity(0)
        assert err.value.status == b.NOT_SOLVED
        with pytest.raises(b.RadiosityError, match="not finite"):
            s.set_object_matrix(1, np.full((4, 4), np.nan))
        with pytest.raises(b.RadiosityError, match="4x4"):
            s.set_object_matrix(1, np.eye(3))
        s.set_object_matrix(1, tuple(np.eye(4).ravel()))  # 16 numbers will do
        with pytest.raises(b.RadiosityError, match="out of range"):
            s.set_material_emission(5, (1, 1, 1))
        s.solve_frame(1)
        with pytest.raises(b.RadiosityError, match="outside"):
            s.eval([0], [0], [[0.5, 2.0]])


def test_progress_false_cancels_and_keeps_the_last_frame(b):
    with b.Session({}, *two_patches()) as s:
        s.solve_frame(1.0)
        before = s.face_radiosity(0)
        calls = []

        def stop(fraction, stage):
            calls.append((fraction, stage))
            return False

        s.set_material_emission(1, (5.0, 5.0, 5.0))
        with pytest.raises(b.Cancelled) as err:
            s.solve_frame(2.0, progress=stop)
        assert err.value.status == b.CANCELLED
        assert len(calls) == 1 and 0.0 <= calls[0][0] <= 1.0 and calls[0][1]
        assert np.array_equal(s.face_radiosity(0), before)
        assert s.frame_stats()["frame"] == 1.0
        # None (or True) goes on.
        assert s.solve_frame(2.0, progress=lambda f, st: None)["frame"] == 2.0


def test_preview_and_refine(b):
    """A preview frame's corners are the polynomials'; refining it gives what solving without
    previews gives; a cancelled refinement keeps the frame readable."""
    rho, em, objs = two_patches()
    settings = {"tolerance": 1e-8}  # two shooting paths to it agree far closer than checked
    with b.Session(settings, rho, em, objs) as at_once, b.Session(settings, rho, em, objs) as s:
        at_once.solve_frame(1.0)
        s.set_preview(True)
        stats = s.solve_frame(1.0)
        assert stats["preview"] and stats["gather_seconds"] == 0.0
        polynomial = s.corner_radiosity(0)
        assert not np.allclose(polynomial, at_once.corner_radiosity(0), rtol=1e-3)
        with pytest.raises(b.Cancelled):
            s.refine(progress=lambda f, st: False)
        np.testing.assert_array_equal(s.corner_radiosity(0), polynomial)
        stats = s.refine()
        assert stats["frame"] == 1.0 and not stats["preview"] and stats["gather_seconds"] > 0.0
        np.testing.assert_allclose(s.corner_radiosity(0), at_once.corner_radiosity(0), rtol=1e-6)
        assert s.refine() is None  # nothing left to refine


def test_exception_in_progress_is_raised_after_the_call(b):
    class Boom(Exception):
        pass

    def bad(fraction, stage):
        raise Boom(stage)

    with b.Session({}, *two_patches()) as s:
        with pytest.raises(Boom):
            s.solve_frame(1.0, progress=bad)
        s.solve_frame(1.0)  # still usable
        assert s.face_radiosity(0).shape == (1, 3)


def test_cancel_from_another_thread(b):
    with b.Session({"threads": 0}, *closed_box(12)) as s:
        started = threading.Event()
        outcome = {}

        def progress(fraction, stage):
            started.set()
            return True

        def run():
            try:
                outcome["stats"] = s.solve_frame(1.0, progress=progress)
            except b.Cancelled as e:
                outcome["cancelled"] = e
            outcome["done"] = time.perf_counter()

        t = threading.Thread(target=run)
        t.start()
        assert started.wait(60), "the solve never reported progress"
        time.sleep(0.05)
        at = time.perf_counter()
        s.cancel()
        t.join(60)
        assert not t.is_alive()
        assert "cancelled" in outcome, f"the solve finished before the cancel: {outcome}"
        latency = outcome["done"] - at
        print(f"cancel latency from Python: {latency * 1e3:.1f} ms")
        assert latency < 2.0
        with pytest.raises(b.RadiosityError) as err:
            s.face_radiosity(0)
        assert err.value.status == b.NOT_SOLVED


def test_close_is_idempotent_and_final(b):
    s = b.Session({}, *two_patches())
    s.close()
    s.close()
    s.cancel()  # no-op once closed
    with pytest.raises(b.RadiosityError, match="closed"):
        s.solve_frame(1.0)


def test_library_candidates_and_missing_library(b, monkeypatch, tmp_path):
    monkeypatch.setenv(b.ENV, str(tmp_path))
    c = b.library_candidates()
    name = c[-1].name
    assert c == [tmp_path / name, REPO / "addon" / "lib" / name,
                 REPO / "target" / "release" / name, REPO / "target" / "debug" / name]
    missing = tmp_path / "nothing.so"
    with pytest.raises(b.RadiosityError) as err:
        b.load(missing)
    assert str(missing) in str(err.value) and err.value.status == b.NOT_LOADED
