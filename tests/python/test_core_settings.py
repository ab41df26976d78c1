"""Settings, frame plans, material maths and the bake record (no bpy)."""

import math

import numpy as np
import pytest

from addon.core import frames, materials, record
from addon.core.settings import QUALITY, BakeSettings, SettingsError


def test_native_settings_follow_quality():
    s = BakeSettings(basis_order=1, quality="HIGH", frame_start=1, frame_end=10).validate()
    n = s.native()
    assert (n["quadrature_order"], n["visibility_samples"]) == QUALITY["HIGH"][:2]
    assert n["basis_order"] == 1 and n["method"] == "incremental"
    assert "threads" not in s.solve_signature()


def test_two_sided_open_surfaces_reach_the_library_only_when_on():
    # Off is the library's default and stays out of the signature, so that bakes made before the
    # option keep theirs; on, it is passed and changes the signature (a re-bake solves again).
    off = BakeSettings().validate()
    on = BakeSettings(reflecting_backs=True).validate()
    assert "reflecting_backs" not in off.native()
    assert on.native()["reflecting_backs"] is True
    assert on.solve_signature() != off.solve_signature()


@pytest.mark.parametrize("order, points", [(0, 2), (1, 2), (2, 3), (3, 4)])
def test_draft_quality_keeps_enough_points_for_the_basis(order, points):
    n = BakeSettings(basis_order=order, quality="DRAFT").validate().native()
    assert n["quadrature_order"] == points and n["visibility_samples"] == 1


@pytest.mark.parametrize("bad, match", [
    (dict(basis_order=4), "basis order"),
    (dict(quality="SUPER"), "quality"),
    (dict(tolerance=0.0), "tolerance"),
    (dict(frame_step=0), "frame step"),
    (dict(frame_start=5, frame_end=2), "start is after end"),
    (dict(frame_start=-1), "outside 0..9999"),
    (dict(method="magic"), "method"),
    (dict(display_subdivision=9), "display subdivision"),
])
def test_bad_settings_name_the_setting(bad, match):
    with pytest.raises(SettingsError, match=match):
        BakeSettings(**bad).validate()


def test_baked_frames_and_interpolation():
    assert frames.baked_frames(1, 10, 3) == [1, 4, 7, 10]
    assert frames.baked_frames(1, 11, 3) == [1, 4, 7, 10, 11]
    assert frames.baked_frames(5, 5, 2) == [5]
    assert frames.between(4, 7) == [(5, pytest.approx(1 / 3)), (6, pytest.approx(2 / 3))]
    assert frames.attribute_name(7) == "Rad_0007"
    assert frames.frame_of_attribute("Rad_0123") == 123
    assert frames.frame_of_attribute("Radiosity") is None
    # Staging names are never read as frames (the switch and re-bakes ignore them).
    assert frames.staging_name(7) == "RadNew_0007"
    assert frames.frame_of_attribute("RadNew_0007") is None
    assert frames.frame_of_attribute("RadNew_0007", frames.STAGING_PREFIX) == 7


def test_material_maths():
    assert materials.reflectance((1.2, 0.5, -0.1, 1.0)) == (0.999, 0.5, 0.0)
    e = materials.exitance((1.0, 0.5, 0.0, 1.0), 2.0, 3.0)
    assert e == pytest.approx((6 * math.pi, 3 * math.pi, 0.0))
    np.testing.assert_allclose(materials.radiance_from_radiosity([[math.pi, 0, 2 * math.pi]]), [[1, 0, 2]],
                               rtol=1e-6)
    t = materials.MaterialTable()
    a = t.add(("A", 1.0), lambda: materials.MaterialSpec("A", problem="Base Color is linked"))
    b = t.add(("A", 1.0), lambda: materials.MaterialSpec("A2"))
    assert a == b == 0
    assert t.problems() == ["A (Base Color is linked)"]


def test_record_round_trip_and_first_change():
    st = lambda m: record.FrameState([m], ["g"], "e")  # noqa: E731
    r = record.BakeRecord("key", 1, 1, ["A"])
    for f in (1, 2, 3):
        r.solved[f] = {"state": st(f"m{f}"), "seconds": 1.5}
    r.complete = (1, 3)
    r2 = record.BakeRecord.loads(r.dumps())
    assert r2 == r
    assert r2.reusable("key", 1, 1, ["A"])
    assert not r2.reusable("other", 1, 1, ["A"])
    assert record.first_changed(r2, [1, 2, 3], lambda f: st(f"m{f}")) == 3
    assert record.first_changed(r2, [1, 2, 3], lambda f: st("moved" if f == 2 else f"m{f}")) == 1
    assert record.BakeRecord.loads("not json") is None


def test_the_memory_limit_goes_to_the_session_but_does_not_change_the_solution():
    from addon.core.settings import BakeSettings, SettingsError, in_panel_words

    s = BakeSettings(memory_limit_mb=512)
    assert s.native()["memory_budget_mb"] == 512
    assert "memory_budget_mb" not in s.solve_signature()  # kept frames stay reusable
    assert s.session_signature() != BakeSettings().session_signature()  # a new session checks it
    assert BakeSettings().native()["memory_budget_mb"] == 0
    with pytest.raises(SettingsError, match="memory limit -1 MB"):
        BakeSettings(memory_limit_mb=-1).validate()
    assert in_panel_words("a lower settings.basis_order, or raise memory_budget_mb") == (
        "a lower Detail, or raise Memory Limit (MB)")
    assert "a lower Detail" in in_panel_words("use fewer faces or a lower basis order (a lower ...)")


def test_the_hierarchy_takes_its_refinement_threshold_as_accuracy():
    """Method hierarchical hands the Refinement Threshold to the library as ``accuracy``; the flat
    methods leave it out, so changing it does not re-bake a flat bake."""
    s = BakeSettings(method="hierarchical", hierarchy_accuracy=1e-4).validate()
    assert s.native()["method"] == "hierarchical" and s.native()["accuracy"] == 1e-4
    assert s.solve_signature() != s.replace(hierarchy_accuracy=1e-3).solve_signature()
    flat = BakeSettings(method="incremental", hierarchy_accuracy=1e-4).validate()
    assert "accuracy" not in flat.native()
    assert flat.solve_signature() == flat.replace(hierarchy_accuracy=1e-2).solve_signature()
    # The binding takes every key (a key it does not know is an error there).
    from addon.native import binding

    assert binding.METHODS["hierarchical"] == 3


@pytest.mark.parametrize("bad", [0.0, -1e-3, 1e-7, 0.6, 1.0, float("nan"), float("inf")])
def test_a_refinement_threshold_out_of_range_is_one_line(bad):
    with pytest.raises(SettingsError) as info:
        BakeSettings(method="hierarchical", hierarchy_accuracy=bad).validate()
    line = str(info.value)
    assert "\n" not in line and line.startswith(f"refinement threshold {bad:g} is outside 1e-06..0.5")
    BakeSettings(method="full", hierarchy_accuracy=bad).validate()  # not read by the flat methods


def test_the_headless_refinement_range_is_the_settings_one():
    import importlib.util
    from pathlib import Path

    from addon.core.settings import HIERARCHY_ACCURACY_RANGE

    path = Path(__file__).resolve().parents[2] / "addon" / "headless.py"
    spec = importlib.util.spec_from_file_location("headless_for_test", path)
    headless = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(headless)
    assert headless.REFINEMENT_RANGE == HIERARCHY_ACCURACY_RANGE


def test_memory_refusals_of_flat_bakes_suggest_the_hierarchy():
    from addon.core.settings import large_flat_hint, library_message

    over = ("over the memory budget: this bake needs up to 9 MB (...) but the budget is 1 MB "
            "(settings.memory_budget_mb); use fewer faces or a lower settings.basis_order, turn "
            "corner_gather off, bake fewer frames at once, or raise memory_budget_mb")
    plain = ("over the memory budget: this bake needs up to 9 MB (...) but the budget is 1 MB (Memory Limit "
             "(MB)); use fewer faces or a lower Detail, turn Sharp Corners off, or raise Memory Limit (MB)")
    assert library_message(over, "incremental", hierarchy_fits=False) == plain
    assert library_message(over, "full", hierarchy_fits=True) == (
        plain + "; or set Method to Large Scenes (Hierarchy), whose estimate for this scene is within the "
        "limit (its memory grows about linearly with the faces)")
    oom = "out of memory while building the link store: could not allocate 94 MB; use a lower basis order"
    assert library_message(oom, "exact").endswith(
        "a lower Detail; or set Method to Large Scenes (Hierarchy), whose memory grows about linearly "
        "with the faces")
    assert library_message(oom, "hierarchical") == oom.replace("basis order", "Detail")
    assert library_message("settings.accuracy 2 is outside (0,1)", "hierarchical") == (
        "Refinement Threshold 2 is outside (0,1)")
    assert library_message("no emitters", "incremental") == "no emitters"
    assert large_flat_hint(1999, "incremental") is None and large_flat_hint(10**5, "hierarchical") is None
    assert large_flat_hint(12345, "full").startswith("12,345 faces: ")
