"""What a bake recorded, to re-bake only from the first frame that changed.

The record is JSON kept in the scene (custom property ``radiosity_bake``), so it survives saving
and re-opening. A frame's state is the digest of every object's world matrix and object-space
vertices and of every material's emission at that frame; the scene's key covers the settings
that change a solution, the objects, their topology and the reflectances. A re-bake keeps every
solved frame before the first one whose state differs, and all frames interpolated between kept
solved frames.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

VERSION = 1


@dataclass
class FrameState:
    matrices: list[str]
    geometry: list[str]
    emission: str

    def to_json(self) -> dict:
        return {"m": self.matrices, "g": self.geometry, "e": self.emission}

    @classmethod
    def from_json(cls, d) -> FrameState:
        return cls(list(d["m"]), list(d["g"]), d["e"])


@dataclass
class BakeRecord:
    scene_key: str = ""
    step: int = 1
    start: int = 0
    objects: list[str] = field(default_factory=list)      # object names, in library order
    stored: dict = field(default_factory=dict)            # object name -> {"mode", "target"}
    solved: dict = field(default_factory=dict)            # frame -> {"state": FrameState, "seconds": float}
    complete: tuple[int, int] | None = None               # first and last frame with colours

    def dumps(self) -> str:
        return json.dumps({
            "version": VERSION,
            "scene_key": self.scene_key,
            "step": self.step,
            "start": self.start,
            "objects": self.objects,
            "stored": self.stored,
            "solved": {str(f): {"state": v["state"].to_json(), "seconds": v["seconds"]}
                       for f, v in sorted(self.solved.items())},
            "complete": list(self.complete) if self.complete else None,
        })

    @classmethod
    def loads(cls, text: str | None) -> BakeRecord | None:
        if not text:
            return None
        try:
            d = json.loads(text)
            if d.get("version") != VERSION:
                return None
            return cls(
                scene_key=d["scene_key"],
                step=int(d["step"]),
                start=int(d["start"]),
                objects=list(d["objects"]),
                stored=dict(d["stored"]),
                solved={int(f): {"state": FrameState.from_json(v["state"]), "seconds": float(v["seconds"])}
                        for f, v in d["solved"].items()},
                complete=tuple(d["complete"]) if d.get("complete") else None,
            )
        except (ValueError, KeyError, TypeError):
            return None

    def reusable(self, scene_key: str, start: int, step: int, objects: list[str]) -> bool:
        """True when the previous bake's solved frames may be kept at all."""
        return (self.scene_key == scene_key and self.start == start and self.step == step
                and self.objects == objects and bool(self.solved))


def first_changed(record: BakeRecord | None, frames: list[int], state_of) -> int:
    """Index into `frames` of the first solved frame to recompute. `state_of(frame)` gives the
    current FrameState (it may be costly: it is called in order and stops at the first change)."""
    if record is None:
        return 0
    for i, f in enumerate(frames):
        old = record.solved.get(f)
        if old is None or old["state"] != state_of(f):
            return i
    return len(frames)
