"""The bake job: export, solve frame by frame, write colours, keep the switch consistent.

A job runs in phases so that the operator can put the native solve on a worker thread:
``start()``, then per frame ``prepare()`` (main thread: frame_set, sample, hand changes to the
session), ``solve()`` (any thread: the long native call, which releases the GIL) and ``commit()``
(main thread: write the frame's colours), then ``finish()``. ``run()`` does it all synchronously
(headless, or an operator without an event loop).

Colours are written only when a frame has completed, and under staging names (``RadNew_0001``,
staging copies) beside the previous bake, which stays as it was while the bake runs. ``finish()``
either swaps the new frames in (the bake succeeded, or it was stopped but only added frames past
the previous bake's last one: a first bake, a longer range, a headless chunk) and removes what is
stale, or, when a cancelled or failed bake would have replaced frames of the previous bake,
drops what it wrote: the previous bake is left exactly as it was, playable.

The session is kept for the Blender session (``held()``), keyed by file and scene: a re-bake, or
the live preview, continues from its last solution when the scene's key still matches.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import bpy
import numpy as np

from ..core import frames as core_frames
from ..core.grids import Grid, subdivide
from ..core.marshal import with_object_names
from ..core.materials import radiance_from_radiosity
from ..core.record import BakeRecord, FrameState, first_changed
from ..core.settings import BakeSettings, SettingsError, large_flat_hint, library_message
from . import attributes, light_nodes, switch, world
from .export import TopologyChanged, collect, export, sample

RECORD_PROPERTY = "radiosity_bake"

# Observers of every bake: fn(event: dict) -> False to cancel. Events:
#   {"kind": "progress", "frame", "index", "total", "fraction", "stage"}  (may come from a worker thread)
#   {"kind": "frame", "frame", "index", "total", "seconds"}               (main thread, after a commit)
listeners: list = []

# Jobs between start() and finish(): the live preview stands aside while one runs (the bake's own
# frame changes must not trigger it, and a session runs one call at a time).
running: set = set()


class BakeError(Exception):
    """A problem the user can fix; the message is one line."""


def binding():
    from ..native import binding as _binding

    return _binding


# ---------------------------------------------------------------------------------------------
# Sessions held for the Blender session


@dataclass
class Held:
    session: object
    scene_key: str
    state: FrameState            # what the session holds now (matrices, geometry, emission digests)
    frame: float | None = None   # last solved frame
    export: object = None        # the Export the session was built from

    def close(self):
        try:
            self.session.close()
        except Exception as e:  # noqa: BLE001 - closing must not mask the caller's error
            print(f"Radiosity: closing a session failed: {e}")


_held: dict[str, Held] = {}


def scene_id(scene) -> str:
    return f"{bpy.data.filepath}|{scene.name}"


def held(scene) -> Held | None:
    return _held.get(scene_id(scene))


def drop_held(scene=None) -> None:
    keys = list(_held) if scene is None else [scene_id(scene)]
    for k in keys:
        h = _held.pop(k, None)
        if h is not None:
            h.close()


def session_key(settings: BakeSettings, exp) -> str:
    """Sessions are reused while this stays the same: solve settings, objects, topology, reflectances."""
    return exp.scene_key(settings.session_signature())


def new_session(
    settings: BakeSettings, exp, state: FrameState, scene_key: str, animated: bool = False
) -> Held:
    """A session of the exported scene; ``animated``: frames will follow the first (an animation's
    bake, the live preview), so that the hierarchy keeps what lets its updates coarsen."""
    b = binding()
    rho, emission = exp.materials.arrays()
    objects = [o.data.native() for o in exp.objects]
    try:
        session = b.Session(settings.native(), rho, emission, objects)
        if exp.lights:
            session.set_lights(exp.lights)
        world.apply(session, exp.world, exp.two_sided)
        session.set_animated(animated)
    except b.RadiosityError as e:
        fits = None
        if str(e).startswith("over the memory budget") and settings.method != "hierarchical":
            fits = _hierarchy_fits(settings, rho, emission, objects)
        raise BakeError(library_message(str(e), settings.method, fits)) from e
    return Held(session, scene_key, state, None, exp)


def _hierarchy_fits(settings: BakeSettings, rho, emission, objects) -> bool:
    """Whether a hierarchical session of the same scene passes its own memory check: the session
    is made (the check runs before anything is allocated) and freed at once."""
    b = binding()
    try:
        b.Session(settings.replace(method="hierarchical").native(), rho, emission, objects).close()
    except b.RadiosityError:
        return False
    return True


def apply_sample(h: Held, smp, state: FrameState) -> int:
    """Hands the matrices and emissions that changed since the session's state to it."""
    changed = 0
    for i, (new, old) in enumerate(zip(state.matrices, h.state.matrices, strict=True)):
        if new != old:
            h.session.set_object_matrix(i, smp.matrices[i])
            changed += 1
    if state.emission != h.state.emission:
        for m, rgb in enumerate(smp.emission):
            h.session.set_material_emission(m, tuple(float(x) for x in rgb))
        h.session.set_lights(smp.lights)
        world.apply(h.session, smp.world, smp.two_sided)
        changed += 1
    h.state = FrameState(list(state.matrices), list(h.state.geometry), state.emission)
    return changed


# ---------------------------------------------------------------------------------------------
# Where each object's colours go


@dataclass
class Target:
    index: int            # library object index
    obj: object
    mode: str             # "mesh" or "copy"
    mesh: object          # the mesh holding the Rad_NNNN attributes
    copy: object = None   # copy mode: the unlinked object the switch reads
    grid: Grid | None = None
    level: int = 0

    staged_copy: bool = False  # copy mode: `copy` and `mesh` are this bake's staging copy

    def values(self, session, split, light: bool = False) -> np.ndarray:
        """This frame's B / pi (with `light`, the irradiance H / pi) at the target's corners,
        (n,3) float32."""
        corners = session.corner_irradiance if light else session.corner_radiosity
        if self.mode == "mesh":
            b = split.to_loops(corners(self.index))
        elif self.level == 0:
            b = corners(self.index)
        else:
            g = self.grid
            b = session.eval(np.full(len(g.corner_face), self.index, np.int64), g.corner_face, g.corner_st,
                             irradiance=light)
        return radiance_from_radiosity(b)


def read_record(scene) -> BakeRecord | None:
    return BakeRecord.loads(scene.get(RECORD_PROPERTY))


def clear_object(obj, stored: dict | None = None) -> int:
    """Removes an object's bake: switch, frame attributes, Radiosity attribute, copy."""
    n = 0
    switch.remove(obj)
    if obj.type == "MESH" and obj.data is not None and obj.data.library is None:
        n += attributes.remove_frames(obj.data)
        attributes.remove_staged(obj.data)
        attributes.remove_result(obj.data)
    attributes.remove_copy(bpy, obj.name)
    attributes.remove_copy(bpy, obj.name, staging=True)
    return n


# ---------------------------------------------------------------------------------------------
# The job


class BakeJob:
    def __init__(self, context, settings: BakeSettings, collection=None, verbose: bool = False, log=print):
        self.context = context
        self.scene = context.scene
        self.view_layer = context.view_layer
        self.settings = settings
        self.collection = collection
        self.verbose = verbose
        self.log = log
        self.warnings: list[str] = []
        # Advice known when the bake starts (a large scene on a flat method), logged at once.
        self.hints: list[str] = []
        self.cancel_event = threading.Event()
        self.cancelled = False
        self.failed = False  # set by whoever catches a failure before calling finish()
        self.restored = False  # finish() dropped this bake's frames and kept the previous bake
        self.finished = False
        self.fraction = 0.0
        self.stage = ""
        self.done = 0
        self.total = 0
        self.seconds_solving = 0.0
        self.seconds_saved = 0.0
        self.kept = 0
        self.rebuilt = 0
        self.summary = ""
        self._last_print = (None, -1)

    # -- start ----------------------------------------------------------------------------------

    def start(self) -> None:
        s = self.settings
        try:
            s.validate()
        except SettingsError as e:
            raise BakeError(str(e)) from e
        try:
            binding().load()  # a missing library fails here, before anything is touched
        except ImportError as e:
            raise BakeError(f"the add-on's native binding is missing: {e}") from e
        except binding().RadiosityError as e:
            raise BakeError(str(e)) from e
        self.frames = s.baked_frames()
        self.original_frame = self.scene.frame_current
        self.t0 = time.perf_counter()
        where = f"collection {self.collection.name!r}" if self.collection else f"scene {self.scene.name!r}"
        sel = collect(self.scene, self.view_layer, self.collection)
        self.warnings += sel.notes()
        if any(o.mode == "EDIT" for o in sel.objects):
            raise BakeError("leave Edit Mode before baking (edits are not in the evaluated mesh yet)")
        if not sel.objects:
            raise BakeError(f"nothing to bake: no visible, renderable mesh objects in {where}"
                            + ("; " + "; ".join(sel.notes()) if sel.notes() else ""))
        running.add(self)
        self.muted = {o.name: switch.set_muted(o, True) for o in sel.objects}
        try:
            self._start(sel, where)
        except BaseException:
            self._unmute()
            self.scene.frame_set(self.original_frame)
            running.discard(self)
            raise

    def _start(self, sel, where) -> None:
        s = self.settings
        self.scene.frame_set(self.frames[0])
        dg = self.context.evaluated_depsgraph_get()
        self.rest = rest = export(dg, sel.objects, sel.light_objects)
        faces = sum(len(o.data.split.face_sizes) for o in rest.objects)
        if faces == 0:
            raise BakeError(f"nothing to bake: the mesh objects in {where} have no faces ("
                            + ", ".join(o.obj.name for o in rest.objects) + ")")
        good = faces - sum(len(o.data.degenerate) for o in rest.objects)
        if good == 0:
            raise BakeError(f"nothing to bake: every face in {where} has zero area")
        for line in (rest.problems_line(), rest.degenerate_line()):
            if line:
                self.warnings.append(line)
        if hint := large_flat_hint(good, s.method):
            self.hints.append(hint)
            self.log(f"Radiosity: note: {hint}")
        self.names = [o.obj.name for o in rest.objects]
        level = s.display_subdivision
        modes = []
        claimed = set()
        for o in rest.objects:
            mesh = o.obj.data
            own = level == 0 and o.original_topology and mesh.name not in claimed and mesh.library is None
            modes.append("mesh" if own else "copy")
            claimed.add(mesh.name)
        self.session_key = session_key(s, rest)
        self.scene_key = rest.scene_key(s.solve_signature(), extra=f"L{level}:" + ",".join(modes))
        if line := world.problems_line(rest.world):
            self.warnings.append(line)
        if not rest.light_objects and rest.world.strength == 0.0 and not self._has_emitter(dg):
            raise BakeError(f"no emitters: no Light object, no World and no material in {where} emits "
                            f"light in frames {self.frames[0]}-{self.frames[-1]} (add a light, give the "
                            "World a Strength > 0, give a Principled BSDF an Emission Strength > 0, or "
                            "use an Emission shader)")
        # Storage targets.
        self.targets = []
        copies = [o for o, m in zip(rest.objects, modes, strict=True) if m == "copy"]
        if copies and any(o.deforms for o in copies):
            self.warnings.append("stored on a bake-time copy, which does not follow deformation: "
                                 + ", ".join(o.obj.name for o in copies if o.deforms))
        linked = [o.obj.name for o in rest.objects if o.obj.library is not None]
        if linked:
            self.warnings.append("linked objects light the scene but cannot store colours (make them local): "
                                 + ", ".join(linked))
        for i, (o, mode) in enumerate(zip(rest.objects, modes, strict=True)):
            if o.obj.library is not None:
                continue
            if mode == "mesh":
                self.targets.append(Target(i, o.obj, "mesh", o.obj.data))
            else:
                self.targets.append(Target(i, o.obj, "copy", None, level=level))
        # What the previous bake left that can be kept: solved frames up to the first change,
        # as long as their colours are all still there.
        record = read_record(self.scene)
        reusable = record is not None and record.reusable(
            self.scene_key, self.frames[0], s.frame_step, self.names)
        self._state_cache = {}
        k = first_changed(record, self.frames, self._state_at) if reusable else 0
        for t in self.targets:
            if t.mode != "copy":
                continue
            o = rest.objects[t.index]
            t.grid = subdivide(o.data.vertices, o.data.split.face_sizes, o.data.split.face_indices, t.level)
            existing = bpy.data.meshes.get(attributes.COPY_PREFIX + t.obj.name)
            if reusable and existing is not None and len(existing.loops) == len(t.grid.face_indices):
                t.mesh = existing
                t.copy = bpy.data.objects.get(attributes.COPY_PREFIX + t.obj.name)
            if reusable and (t.mesh is None or t.copy is None):
                t.mesh = t.copy = None  # built (as a staging copy) when the first frame commits
                k = 0
        for t in self.targets:
            if t.mesh is not None:
                attributes.remove_staged(t.mesh)  # of a bake that never finished (Blender quit)
        for t in self.targets if reusable else ():
            if t.mesh is None:
                continue
            have = set(attributes.complete_frames(t.mesh))
            k = next((i for i, f in enumerate(self.frames[:k]) if f not in have), k)
        self.previous = record  # for objects that left the bake
        self.reusable = reusable
        # Whether stopping this bake must restore the previous one: it would replace some of its
        # frames (a fresh bake, or solved frames up to its last one were not all kept).
        self.previous_complete = record.complete if record is not None else None
        last = self.previous_complete[1] if self.previous_complete else None
        self.replaces_previous = last is not None and not (reusable and k and self.frames[k - 1] >= last)
        if reusable:
            self.record = record
            self.record.solved = {f: v for f, v in record.solved.items() if f in self.frames[:k]}
            self.record.complete = (self.frames[0], self.frames[k - 1]) if k else None
        else:
            self.record = BakeRecord(self.scene_key, s.frame_step, self.frames[0], self.names)
        self.kept = k
        self.seconds_saved = sum(v["seconds"] for v in self.record.solved.values())
        self.queue = list(self.frames[k:])
        self.total = len(self.queue)
        # Frame values of the last kept solved frame, for interpolation.
        self.prev = None
        if self.kept:
            f = self.frames[self.kept - 1]
            self.prev = (f, [(attributes.read_frame(t.mesh, f), attributes.read_light_frame(t.mesh, f))
                             for t in self.targets])
        # The session: the held one if it is for this scene key, else a new one.
        h = held(self.scene)
        if h is None or h.scene_key != self.session_key:
            drop_held(self.scene)
            h = new_session(s, rest, self._state_at(self.frames[0]), self.session_key, len(self.frames) > 1)
            _held[scene_id(self.scene)] = h
        self.held = h

    def _build_copy(self, t: Target) -> None:
        """This bake's copy, under the staging name until the bake ends."""
        o = self.rest.objects[t.index]
        smooth = o.polygon_smooth[o.data.split.source_face]
        slots = self._polygon_slots(o)[o.data.split.source_face]
        t.copy, t.mesh = attributes.build_copy(bpy, t.obj.name, t.grid, slots, smooth, o.slot_materials,
                                               staging=True)
        t.staged_copy = True

    def _polygon_slots(self, o) -> np.ndarray:
        """Material slot index per library face of an exported object (for the copy)."""
        dg = self.context.evaluated_depsgraph_get()
        ev = o.obj.evaluated_get(dg)
        mesh = ev.to_mesh()
        try:
            mats = np.empty(len(mesh.polygons), np.int32)
            mesh.polygons.foreach_get("material_index", mats)
        finally:
            ev.to_mesh_clear()
        if len(mats) != o.data.polygon_count:
            mats = np.zeros(o.data.polygon_count, np.int32)
        return mats

    def _state_at(self, frame: int) -> FrameState:
        if frame not in self._state_cache:
            self.scene.frame_set(frame)
            smp = sample(self.context.evaluated_depsgraph_get(), self.rest)
            self._state_cache[frame] = smp.state(self.rest)
        return self._state_cache[frame]

    def _has_emitter(self, dg) -> bool:
        _, e = self.rest.materials.arrays()
        if (e > 0).any():
            return True
        from .export import frame_emission

        for f in self.frames[1:]:
            self.scene.frame_set(f)
            if (frame_emission(self.rest) > 0).any():
                return True
        self.scene.frame_set(self.frames[0])
        return False

    # -- per frame ------------------------------------------------------------------------------

    def has_next(self) -> bool:
        return bool(self.queue) and not self.cancel_event.is_set()

    def prepare(self) -> None:
        f = self.queue[0]
        self.scene.frame_set(f)
        dg = self.context.evaluated_depsgraph_get()
        try:
            smp = sample(dg, self.rest)
        except TopologyChanged as e:
            raise BakeError(f"object {e} changes its number of vertices or corners at frame {f}; "
                            "a bake needs the same topology on every frame") from e
        state = smp.state(self.rest)
        h = self.held
        if state.geometry != h.state.geometry:
            # Deformed: rebuild the session on this frame's meshes and solve from scratch.
            exp = export(dg, [o.obj for o in self.rest.objects], self.rest.light_objects, rest=self.rest)
            topology = [o.data.topology_key() for o in exp.objects]
            if topology != [o.data.topology_key() for o in self.rest.objects]:
                raise BakeError(f"the meshes' faces changed at frame {f}; "
                                "a bake needs the same topology on every frame")
            h.close()
            h = new_session(self.settings, exp, state, self.session_key)
            _held[scene_id(self.scene)] = self.held = h
            self.rebuilt += 1
        else:
            apply_sample(h, smp, state)
        self.current = (f, state)
        self.fraction, self.stage = 0.0, "start"

    def _progress(self, fraction: float, stage: str) -> bool:
        self.fraction, self.stage = fraction, stage
        f = self.current[0]
        event = {"kind": "progress", "frame": f, "index": self.done, "total": self.total,
                 "fraction": fraction, "stage": stage}
        for fn in list(listeners):
            if fn(event) is False:
                self.cancel_event.set()
        if self.verbose:
            bucket = int(fraction * 4)
            if (stage, bucket) != self._last_print:
                self._last_print = (stage, bucket)
                self.log(f"Radiosity: frame {f} ({self.done + 1}/{self.total}) {stage} {100 * fraction:.0f}%")
        return not self.cancel_event.is_set()

    def solve(self) -> None:
        """The long native call. Raises ``binding.Cancelled`` when cancelled."""
        f = self.current[0]
        t = time.perf_counter()
        self.stats = self.held.session.solve_frame(float(f), progress=self._progress)
        lines = [with_object_names(w, self.names) for w in self.stats.get("warnings", [])]
        self.warnings += [w for w in lines if w not in self.warnings]
        self.held.frame = float(f)
        self.frame_seconds = time.perf_counter() - t
        self.seconds_solving += self.frame_seconds

    def commit(self) -> None:
        f, state = self.current
        h = self.held
        values = []
        for t in self.targets:
            if t.mesh is None:
                self._build_copy(t)
            split = self.rest.objects[t.index].data.split
            rgb, light = t.values(h.session, split), t.values(h.session, split, light=True)
            attributes.write_staged(t.mesh, f, rgb, light)
            values.append((rgb, light))
        if self.prev is not None:
            f0, v0 = self.prev
            for g, w in core_frames.between(f0, f):
                for t, (a, la), (b, lb) in zip(self.targets, v0, values, strict=True):
                    attributes.write_staged(t.mesh, g, (1.0 - w) * a + w * b, (1.0 - w) * la + w * lb)
        self.prev = (f, values)
        self.record.solved[f] = {"state": state, "seconds": self.frame_seconds}
        self.record.complete = (self.frames[0], f)
        self.queue.pop(0)
        self.done += 1
        if self.verbose:
            self.log(f"Radiosity: frame {f} done ({self.done}/{self.total}) in {self.frame_seconds:.2f} s")
        event = {"kind": "frame", "frame": f, "index": self.done, "total": self.total,
                 "seconds": self.frame_seconds}
        for fn in list(listeners):
            if fn(event) is False:
                self.cancel_event.set()

    def _remove_previous_storage(self) -> None:
        """A fresh bake swapped in: remove what the previous bake stored where this one does not
        (the other storage mode of each object) and on objects that left the bake. Runs over all
        targets before any promotion: linked duplicates share one mesh."""
        names = set(self.names)
        for t in self.targets:
            if t.mode == "mesh":
                attributes.remove_copy(bpy, t.obj.name)
            elif t.obj.data.library is None:
                attributes.remove_frames(t.obj.data)
                attributes.remove_result(t.obj.data)
        if self.previous is not None:
            for name in self.previous.objects:
                obj = bpy.data.objects.get(name)
                if name not in names and obj is not None:
                    clear_object(obj)

    def cancel(self) -> None:
        """Thread-safe: stops after (or inside) the current frame."""
        self.cancel_event.set()
        try:
            self.held.session.cancel()
        except AttributeError:
            pass

    # -- end ------------------------------------------------------------------------------------

    def _unmute(self) -> None:
        for name, before in getattr(self, "muted", {}).items():
            obj = bpy.data.objects.get(name)
            if obj is not None and before is not None:
                switch.set_muted(obj, not before)

    def finish(self) -> str:
        if self.finished:
            return self.summary
        self.finished = True
        try:
            self._finish()
        finally:
            self._unmute()
            self.scene.frame_set(self.original_frame)
            running.discard(self)
        if self.scene.radiosity.live_preview:
            from . import live

            live.update(self.scene)
        return self.summary

    def _stopped(self) -> bool:
        return self.failed or self.cancelled or self.cancel_event.is_set()

    def _finish(self) -> None:
        if self._stopped() and self.replaces_previous or self.record.complete is None:
            self._drop_staged()
        else:
            self._swap_in()
        self.summary = "Radiosity: " + "; ".join(self._summary_parts())

    def _drop_staged(self) -> None:
        """Nothing of this bake is kept: the file is as it was before it started."""
        self.restored = self.replaces_previous
        for t in self.targets:
            if t.mesh is not None:
                attributes.remove_staged(t.mesh)
            if t.staged_copy:
                attributes.remove_copy(bpy, t.obj.name, staging=True)

    def _swap_in(self) -> None:
        s = self.settings
        first, last = self.record.complete
        preview = None
        if s.preview_material:
            from .preview import preview_material

            preview = preview_material(bpy)
        if not self.reusable:
            self._remove_previous_storage()
        # A re-bake keeps the solved frames before its first change (all inside the complete
        # range); a fresh bake keeps none of the previous bake's.
        keep_live = (lambda f: first <= f <= last) if self.reusable else (lambda f: False)
        for t in self.targets:
            if t.staged_copy:
                t.copy, t.mesh = attributes.promote_copy(bpy, t.obj.name)
                t.staged_copy = False
            attributes.promote_frames(t.mesh, keep_live=keep_live)
            attributes.remove_frames(t.mesh, keep=lambda f: first <= f <= last)
            current = min(max(self.original_frame, first), last)
            attributes.ensure_result(t.mesh, attributes.read_frame(t.mesh, current),
                                     attributes.read_light_frame(t.mesh, current))
            switch.install(bpy, t.obj, first, last, copy=t.copy if t.mode == "copy" else None,
                           preview_material=preview)
            self.muted.pop(t.obj.name, None)
        # Apply to Materials follows the option: inserted (again) when on, taken out when off.
        objects = [t.obj for t in self.targets]
        if s.apply_to_materials:
            if line := light_nodes.apply_to(bpy, objects):
                self.warnings.append(line)
        else:
            light_nodes.remove_from(light_nodes.materials_of(objects))
        self.record.stored = {t.obj.name: {"mode": t.mode, "mesh": t.mesh.name} for t in self.targets}
        self.scene[RECORD_PROPERTY] = self.record.dumps()

    def _summary_parts(self) -> list[str]:
        elapsed = time.perf_counter() - self.t0
        complete = None if self.restored else self.record.complete
        parts = []
        if self.done:
            parts.append(f"solved {self.done} frame(s) in {elapsed:.1f} s")
        if self.restored:
            kept = self.previous_complete
            parts.append(f"kept the previous bake (frames {kept[0]}-{kept[1]}) unchanged")
        if complete:
            parts.append(f"colours for frames {complete[0]}-{complete[1]}")
        if self.kept and not self.restored:
            parts.append(f"kept {self.kept} unchanged solved frame(s), "
                         f"saving about {self.seconds_saved:.1f} s")
        if self.rebuilt:
            parts.append(f"rebuilt the session on {self.rebuilt} deformed frame(s)")
        if self.failed:
            parts.insert(0, "failed")
        elif self.cancelled or self.cancel_event.is_set():
            parts.insert(0, "cancelled")
        if not complete and not self.restored:
            parts.append("nothing written")
        return parts

    # -- synchronous ----------------------------------------------------------------------------

    def run(self) -> str:
        self.start()
        b = binding()
        try:
            while self.has_next():
                self.prepare()
                try:
                    self.solve()
                except b.Cancelled:
                    self.cancelled = True
                    break
                self.commit()
        except b.RadiosityError as e:
            self.failed = True
            self.finish()
            raise BakeError(library_message(str(e), self.settings.method)) from e
        except BaseException:
            self.failed = True
            self.finish()
            raise
        if self.cancel_event.is_set():
            self.cancelled = True
        return self.finish()


def settings_from_scene(scene) -> BakeSettings:
    """Flattens the scene's Radiosity properties into a BakeSettings."""
    p = scene.radiosity
    start, end = (scene.frame_start, scene.frame_end) if p.use_scene_range else (p.frame_start, p.frame_end)
    return BakeSettings(
        basis_order=int(p.basis_order),
        quality=p.quality,
        tolerance=p.tolerance,
        visibility=p.visibility,
        corner_gather=p.corner_gather,
        threads=p.threads,
        method=p.method.lower(),
        frame_start=start,
        frame_end=end,
        frame_step=p.frame_step,
        display_subdivision=p.display_subdivision,
        preview_material=p.preview_material,
        apply_to_materials=p.apply_to_materials,
        memory_limit_mb=p.memory_limit_mb,
        hierarchy_accuracy=p.hierarchy_accuracy,
        reflecting_backs=p.reflecting_backs,
    )


def clear_bake(scene, objects=None) -> int:
    """Removes the bake from `objects` (default: every object the record or a switch names)."""
    record = read_record(scene)
    whole = objects is None
    if whole:
        names = set(record.objects if record else [])
        names |= {o.name for o in scene.objects if switch.find(o) is not None}
        objects = [bpy.data.objects[n] for n in sorted(names) if n in bpy.data.objects]
    n = 0
    for obj in objects:
        n += 1
        clear_object(obj)
    # Apply to Materials: out of every material (a whole Clear), or out of the cleared objects'
    # materials that no object still baked uses.
    if whole:
        light_nodes.remove_from(bpy.data.materials)
        group = bpy.data.node_groups.get(light_nodes.GROUP)
        if group is not None and group.users == 0:
            bpy.data.node_groups.remove(group)
    else:
        still = {m.name_full for m in light_nodes.materials_of(
            o for o in bpy.data.objects if switch.find(o) is not None)}
        light_nodes.remove_from(m for m in light_nodes.materials_of(objects) if m.name_full not in still)
    if RECORD_PROPERTY in scene:
        del scene[RECORD_PROPERTY]
    drop_held(scene)
    if whole:
        _remove_leftovers()
    return n


def _remove_leftovers() -> None:
    """What a whole Clear leaves otherwise: copies named after an object since renamed (their
    source is gone or carries no bake), and the preview material once no switch uses it."""
    from .preview import NAME as PREVIEW

    baked = {o.name for o in bpy.data.objects if switch.find(o) is not None}
    prefix = attributes.COPY_PREFIX
    for obj in [o for o in bpy.data.objects if o.name.startswith(prefix)]:
        if obj.name[len(prefix):] not in baked:
            bpy.data.objects.remove(obj)
    for mesh in [m for m in bpy.data.meshes if m.name.startswith(prefix)]:
        if mesh.users == 0 and mesh.name[len(prefix):] not in baked:
            bpy.data.meshes.remove(mesh)
    # Staging copies exist only while a bake runs (a Clear cannot run then): these are left
    # over from a bake that never finished.
    staging = attributes.STAGING_COPY_PREFIX
    for obj in [o for o in bpy.data.objects if o.name.startswith(staging)]:
        bpy.data.objects.remove(obj)
    for mesh in [m for m in bpy.data.meshes if m.name.startswith(staging) and m.users == 0]:
        bpy.data.meshes.remove(mesh)
    mat = bpy.data.materials.get(PREVIEW)
    if mat is not None and mat.get("radiosity_preview") == 1 and not baked:
        bpy.data.materials.remove(mat)

