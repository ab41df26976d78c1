"""Bake settings as a plain dataclass, flattened from the Blender properties by the operator.

Quality presets map to the library's ``quadrature_order`` (Gauss points per axis for a pair of
well-separated patches) and ``visibility_samples`` (rays per link = samples^4).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from . import frames as _frames

# name: (quadrature_order, visibility_samples, description)
QUALITY = {
    "DRAFT": (2, 1, "2 Gauss points per axis (basis order + 1 at least), 1 visibility ray per link"),
    "MEDIUM": (4, 2, "4 Gauss points per axis, 16 visibility rays per link (library default)"),
    "HIGH": (6, 3, "6 Gauss points per axis, 81 visibility rays per link"),
    "ULTRA": (8, 4, "8 Gauss points per axis, 256 visibility rays per link"),
}

METHODS = ("incremental", "exact", "full", "hierarchical")

# The flat methods link every pair of faces (memory and time grow with the square of the face
# count); "hierarchical" refines below faces and clusters above them (about linear).
FLAT_METHODS = ("incremental", "exact", "full")

# The hierarchical method's Refinement Threshold (the library's ``accuracy``): its default, and the
# range the panel offers. The library takes any value in (0, 1); the 61-face test box's first
# frame made 1,114 elements and 4.6k links at 1e-3, 27,907 and 398k (0.6 GB, 10 s) at 1e-6, and
# above 0.1 a link may carry a tenth of the light unrefined.
DEFAULT_HIERARCHY_ACCURACY = 1e-3
HIERARCHY_ACCURACY_RANGE = (1e-6, 0.5)

# A flat bake of this many faces or more gets a note to use the hierarchy. Measured through the
# bake operator on a 2,407-face room, Detail 2, Sharp Corners on, two frames, 2 shared cores: the
# flat Update 26 s and 3.1 GB, the hierarchy 6.6 s and about 50 MB.
LARGE_FLAT_FACES = 2000

MAX_DISPLAY_SUBDIVISION = 4


class SettingsError(ValueError):
    """A setting is out of range; the message names it."""


@dataclass(frozen=True)
class BakeSettings:
    basis_order: int = 2
    quality: str = "MEDIUM"
    tolerance: float = 1e-4
    visibility: bool = True
    corner_gather: bool = True
    threads: int = 0
    method: str = "incremental"
    frame_start: int = 1
    frame_end: int = 1
    frame_step: int = 1
    display_subdivision: int = 0
    preview_material: bool = False
    apply_to_materials: bool = False  # insert the "Radiosity Light" node group (light_nodes.py)
    memory_limit_mb: int = 0  # 0: automatic (80% of the memory available when the bake starts)
    hierarchy_accuracy: float = DEFAULT_HIERARCHY_ACCURACY  # Refinement Threshold: hierarchy only
    reflecting_backs: bool = False  # Two-Sided Open Surfaces

    def validate(self) -> BakeSettings:
        if not 0 <= self.basis_order <= 3:
            raise SettingsError(f"basis order {self.basis_order} is outside 0..3")
        if self.quality not in QUALITY:
            raise SettingsError(f"quality {self.quality!r} is not one of {', '.join(QUALITY)}")
        if not 0.0 < self.tolerance < 1.0:
            raise SettingsError(f"tolerance {self.tolerance} is outside (0, 1)")
        if not 0 <= self.threads <= 1024:
            raise SettingsError(f"threads {self.threads} is outside 0..1024 (0 = all cores)")
        if self.method not in METHODS:
            raise SettingsError(f"method {self.method!r} is not one of {', '.join(METHODS)}")
        lo, hi = HIERARCHY_ACCURACY_RANGE
        # The property holds a float32: its minimum reads back as 9.99999997e-07.
        within = lo * (1 - 1e-6) <= self.hierarchy_accuracy <= hi * (1 + 1e-6)
        if self.method == "hierarchical" and not within:
            raise SettingsError(
                f"refinement threshold {self.hierarchy_accuracy:g} is outside {lo:g}..{hi:g} "
                "(smaller is finer and slower; the default is 0.001)"
            )
        if self.frame_step < 1:
            raise SettingsError(f"frame step {self.frame_step} must be at least 1")
        if self.frame_start > self.frame_end:
            raise SettingsError(f"frame range {self.frame_start}-{self.frame_end}: start is after end")
        _frames.check_frame(self.frame_start)
        _frames.check_frame(self.frame_end)
        if not 0 <= self.display_subdivision <= MAX_DISPLAY_SUBDIVISION:
            raise SettingsError(
                f"display subdivision {self.display_subdivision} is outside 0..{MAX_DISPLAY_SUBDIVISION}"
            )
        if not 0 <= self.memory_limit_mb < 2**63:
            raise SettingsError(f"memory limit {self.memory_limit_mb} MB must be 0 (automatic) or more")
        return self

    def native(self) -> dict:
        """The settings dict of ``binding.Session``."""
        quadrature, visibility_samples, _ = QUALITY[self.quality]
        # A rule of n points integrates degree 2n - 1: below basis order + 1 it cannot integrate the
        # basis products, the projection is wrong, and random scenes made the library's solve
        # diverge with it. Draft keeps its speed at low orders only.
        quadrature = max(quadrature, self.basis_order + 1)
        native = {
            "basis_order": self.basis_order,
            "quadrature_order": quadrature,
            "visibility_samples": visibility_samples,
            "tolerance": self.tolerance,
            "visibility": self.visibility,
            "corner_gather": self.corner_gather,
            "threads": self.threads,
            "method": self.method,
            "memory_budget_mb": self.memory_limit_mb,
        }
        # Only the hierarchy reads it: left out otherwise, so that changing it does not make a
        # flat bake's re-bake solve everything again.
        if self.method == "hierarchical":
            native["accuracy"] = self.hierarchy_accuracy
        # Left out when off (the library's default), so that bakes made before the option
        # existed keep their solve signature.
        if self.reflecting_backs:
            native["reflecting_backs"] = True
        return native

    def solve_signature(self) -> dict:
        """What changes the solution of a frame (threads and the memory limit do not)."""
        native = self.native()
        native.pop("threads")
        native.pop("memory_budget_mb")
        return native

    def session_signature(self) -> dict:
        """What a held session was made with: the solve signature and the memory limit (checked
        when a session is made, so a changed limit makes a new one)."""
        return {**self.solve_signature(), "memory_budget_mb": self.memory_limit_mb}

    def baked_frames(self) -> list[int]:
        return _frames.baked_frames(self.frame_start, self.frame_end, self.frame_step)

    def replace(self, **changes) -> BakeSettings:
        return dataclasses.replace(self, **changes)


# The library's names in its messages, and what the Radiosity panel calls them.
PANEL_NAMES = (
    ("settings.memory_budget_mb", "Memory Limit (MB)"),
    ("memory_budget_mb", "Memory Limit (MB)"),
    ("settings.basis_order", "Detail"),
    ("basis_order", "Detail"),
    ("settings.accuracy", "Refinement Threshold"),  # the hierarchical budget's message
    ("a lower basis order", "a lower Detail"),  # the out-of-memory message
    ("turn corner_gather off", "turn Sharp Corners off"),
    ("bake fewer frames at once, ", ""),  # the add-on writes each frame as it is solved
)


def in_panel_words(message: str) -> str:
    """A library message with its setting names as the panel shows them."""
    for library, panel in PANEL_NAMES:
        message = message.replace(library, panel)
    return message


def is_memory_refusal(message: str) -> bool:
    """The library refused a bake for its memory: over the budget before it started
    (``src/budget.rs``), or an allocation failed while building."""
    return message.startswith(("over the memory budget", "out of memory"))


def library_message(message: str, method: str, hierarchy_fits: bool | None = None) -> str:
    """A library error as the bake reports it: in the panel's words and, when a flat method ran
    out of memory, with the hint to use the hierarchy. ``hierarchy_fits``: whether the
    hierarchy's own estimate is within the budget (False: no hint, since the hierarchy plans
    more than the flat path below about 400 faces; None: not asked, an allocation failed)."""
    message = in_panel_words(message)
    if method not in FLAT_METHODS or not is_memory_refusal(message) or hierarchy_fits is False:
        return message
    if hierarchy_fits:
        return (f"{message}; or set Method to Large Scenes (Hierarchy), whose estimate for this "
                "scene is within the limit (its memory grows about linearly with the faces)")
    return (f"{message}; or set Method to Large Scenes (Hierarchy), whose memory grows about "
            "linearly with the faces")


def large_flat_hint(faces: int, method: str) -> str | None:
    """A note for a flat bake of many faces (one that fits its memory budget will still be slow)."""
    if method not in FLAT_METHODS or faces < LARGE_FLAT_FACES:
        return None
    return (
        f"{faces:,} faces: the Update and From Scratch methods link every pair of faces, so their "
        "memory and time grow with the square of the face count; set Method to Large Scenes "
        "(Hierarchy), whose memory and time grow about linearly with the faces"
    )
