"""Operators: bake (modal with a worker thread when there is a UI, synchronous headless) and
clear. Heavy modules are imported inside the methods."""

from __future__ import annotations

import threading
import time
import weakref

import bpy

# Each running modal bake's progress meter (core/progress.Meter), fed at every timer tick.
_meters: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _show_progress(context, job) -> None:
    """The window's progress (per mille of the bake), the status bar and the header of the area
    the bake was started from: frame, stage, the frame's and the bake's percentage, the time spent
    and an estimate of the time left. The job's raw (fraction, stage) falls back at every stage
    and frame; the meter maps it onto the bake, monotone."""
    from .core.progress import Meter, job_gathers, status_text

    now = time.perf_counter()
    meter = _meters.get(job)
    if meter is None:
        meter = _meters[job] = Meter(job.total, now, gathers=job_gathers(job))
    while meter.done < job.done:
        meter.frame_done(now)
    # After the last commit the job's fraction is the finished frame's: nothing more to report.
    r = meter.report(job.fraction, job.stage, now) if job.done < job.total else meter.reading(now)
    context.window_manager.progress_update(int(1000 * r.bake_fraction))
    frame = job.current[0] if getattr(job, "current", None) else ""
    text = status_text(frame, min(job.done + 1, job.total), job.total, job.stage, r)
    context.workspace.status_text_set(text)
    area = getattr(context, "area", None)
    if area is not None:
        area.header_text_set(text)


class RADIOSITY_OT_bake(bpy.types.Operator):
    """Bake animated radiosity into per-frame colour attributes, switched by a Geometry Nodes modifier"""

    bl_idname = "radiosity.bake"
    bl_label = "Bake Radiosity"
    bl_options = {"REGISTER", "UNDO"}

    _job = None
    _thread = None
    _timer = None
    _error = None

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def _make_job(self, context, verbose):
        from .blender import bake

        settings = bake.settings_from_scene(context.scene)
        return bake.BakeJob(context, settings, context.scene.radiosity.collection, verbose=verbose)

    def _report_end(self, job):
        for line in job.hints + job.warnings:
            self.report({"WARNING"}, line)
        self.report({"INFO"}, job.summary)

    # -- synchronous (headless, scripts) ---------------------------------------------------------

    def execute(self, context):
        from .blender import bake
        from .core.progress import Lines

        job = self._make_job(context, verbose=False)
        lines = Lines(0)  # monotone progress lines with the time left, on stdout
        lines.expect(job)
        bake.listeners.append(lines.listen)
        try:
            with lines.heartbeat():  # a line every second even while the library is silent
                job.run()
        except bake.BakeError as e:
            for line in job.warnings:
                self.report({"WARNING"}, line)
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        finally:
            bake.listeners.remove(lines.listen)
        self._report_end(job)
        print(job.summary)
        return {"FINISHED"}

    # -- modal (UI): the solve runs on a worker thread, a timer polls it -------------------------

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        from .blender import bake

        job = self._make_job(context, verbose=False)
        try:
            job.start()
        except bake.BakeError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        for line in job.hints:  # in the status bar while the bake runs, not only at its end
            self.report({"WARNING"}, line)
        self._job = job
        if not job.has_next():
            job.finish()
            self._report_end(job)
            return {"FINISHED"}
        wm = context.window_manager
        wm.progress_begin(0, 1000)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        if not self._begin_frame(context):
            return self._end(context, failed=True)
        return {"RUNNING_MODAL"}

    def _begin_frame(self, context) -> bool:
        from .blender import bake

        try:
            self._job.prepare()
        except bake.BakeError as e:
            self._error = str(e)
            return False
        self._error = None
        self._outcome = None
        self._thread = threading.Thread(target=self._solve, name="radiosity-solve", daemon=True)
        self._thread.start()
        return True

    def _solve(self):
        try:
            self._job.solve()
        except Exception as e:  # noqa: BLE001 - handed to the main thread, which reports it
            self._outcome = e

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"RUNNING_MODAL"}  # the UI is blocked while baking (the viewport still redraws)
        _show_progress(context, job)
        frame = job.current[0] if getattr(job, "current", None) else ""
        if self._thread is not None and self._thread.is_alive():
            return {"RUNNING_MODAL"}
        from .blender import bake

        b = bake.binding()
        outcome = self._outcome
        if isinstance(outcome, b.Cancelled):
            job.cancelled = True
            return self._end(context)
        if outcome is not None:
            from .core.settings import library_message

            self._error = library_message(str(outcome), job.settings.method)
            return self._end(context, failed=True)
        try:
            job.commit()  # the frame completed: keep it, even if Esc came meanwhile
        except Exception as e:  # noqa: BLE001 - reported, and the complete frames are kept
            self._error = f"writing frame {frame}: {e}"
            return self._end(context, failed=True)
        if job.cancel_event.is_set():
            job.cancelled = True
            return self._end(context)
        if job.has_next():
            if not self._begin_frame(context):
                return self._end(context, failed=True)
            return {"RUNNING_MODAL"}
        return self._end(context)

    def _end(self, context, failed=False):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        _show_progress(context, self._job)  # the last frame's commit: 100% when all are done
        wm.progress_end()
        context.workspace.status_text_set(None)
        self._job.failed = failed  # a failed bake, like a cancelled one, keeps the previous bake
        area = getattr(context, "area", None)
        if area is not None:
            area.header_text_set(None)
        _meters.pop(self._job, None)
        self._job.finish()
        # FINISHED whenever frames were written, so that the undo step covers them.
        result = {"FINISHED"} if self._job.done else {"CANCELLED"}
        if failed:
            for line in self._job.warnings:
                self.report({"WARNING"}, line)
            self.report({"ERROR"}, f"Radiosity: {self._error} ({self._job.summary})")
            return result
        self._report_end(self._job)
        return result


class RADIOSITY_OT_clear(bpy.types.Operator):
    """Remove the baked colour attributes, the switch modifiers and bake-time copies"""

    bl_idname = "radiosity.clear"
    bl_label = "Clear Radiosity Bake"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from .blender import bake

        n = bake.clear_bake(context.scene)
        self.report({"INFO"}, f"Radiosity: cleared the bake from {n} object(s)")
        return {"FINISHED"}


classes = (RADIOSITY_OT_bake, RADIOSITY_OT_clear)
