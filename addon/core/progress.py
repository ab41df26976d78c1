"""Progress a person can read, for the add-on: the Python twin of ``src/progress.rs``.

The library reports ``(fraction, stage)`` per stage ("kernel", "kernel update", "solve",
"corner gather"), each from 0 to 1, so the raw fraction falls back at every stage change. A
``Meter`` maps each stage onto its share of a frame (the same shares as the CLI's), keeps the
largest value seen in the frame, and estimates the time left: within a frame by the frame's own
rate, for the bake by the finished frames' mean (the first frame's estimate while none is done).
The shares are learned as the library's are: a finished frame's stages, timed, are the shares of
the next frame of its kind (its first stage), so a frame whose gather is 90% of it (the
monastery's) is not reported half done when its gather starts.

``Lines`` turns the events of a bake into the lines the headless script prints: one every
``interval`` seconds inside a frame (repeated by a heartbeat thread while the library is
silent), one per finished frame, each with the time spent and left, and a closing summary.
Both are called from the library's worker threads (one call at a time, but not the main thread):
a lock guards the state, and nothing here touches bpy.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from dataclasses import dataclass


def share(stage: str, gathers: bool = True) -> tuple[float, float]:
    """Where ``stage`` starts in a frame and how much of it it spans before a frame of its kind
    was timed, with a corner gather to come or without (``src/progress.rs``); "links" and
    "hierarchy" are the hierarchy's stages."""
    if stage in ("kernel", "kernel update", "links"):
        return 0.0, 0.45 if gathers else 0.9
    if stage in ("solve", "hierarchy"):
        return (0.45, 0.1) if gathers else (0.9, 0.1)
    if stage == "corner gather":
        return 0.55, 0.45
    return 0.0, 1.0


def job_gathers(job) -> bool:
    """Whether ``job``'s frames end in a corner gather (its settings' Sharp Corners; True when
    it does not say)."""
    return bool(getattr(getattr(job, "settings", None), "corner_gather", True))


@dataclass
class Reading:
    frame_fraction: float      # of the current frame, never less than the frame's last reading
    bake_fraction: float       # of the whole bake
    elapsed: float             # seconds since the meter started
    frame_left: float | None   # seconds; None until something is known
    bake_left: float | None


class Meter:
    """The progress of a bake of ``frames`` frames (times in seconds of ``time.perf_counter``)."""

    def __init__(self, frames: int, now: float | None = None, gathers: bool = True):
        now = time.perf_counter() if now is None else now
        self.gathers = gathers   # whether a frame ends in a corner gather (the first frame's shares)
        self.frames = max(int(frames), 1)
        self.done = 0
        self.start = self.frame_start = now
        self.fraction = 0.0
        self.stage_fraction = 0.0   # the largest fraction the running stage reported since it started
        self.finished = 0.0   # the finished frames' total time
        self.stage_times: dict[str, float] = {}   # this frame's stages, in the order they ran
        self.running: tuple[str, float] | None = None
        self.learned: dict[str, dict[str, tuple[float, float]]] = {}   # kind -> stage -> share

    def report(self, fraction: float, stage: str, now: float) -> Reading:
        self._time_stage(stage, now)
        fraction = min(max(fraction, 0.0), 1.0)
        self.stage_fraction = max(self.stage_fraction, fraction)
        start, span = self._share(stage)
        f = min(max(start + span * fraction, 0.0), 1.0)
        self.fraction = max(self.fraction, f)
        return self.reading(now)

    def frame_done(self, now: float) -> None:
        self._time_stage(None, now)
        total = sum(self.stage_times.values())
        if total > 0:
            shares, start = {}, 0.0
            for stage, seconds in self.stage_times.items():
                shares[stage] = (start, seconds / total)
                start += seconds / total
            self.learned[next(iter(self.stage_times))] = shares
        self.stage_times = {}
        self.finished += max(now - self.frame_start, 0.0)
        self.done += 1
        self.frame_start = now
        self.fraction = 0.0

    def _time_stage(self, stage: str | None, now: float) -> None:
        """Adds the running stage's time up to ``now`` and starts ``stage`` (None: frame ended)."""
        if self.running is not None:
            if self.running[0] == stage:
                return
            name, since = self.running
            self.stage_times[name] = self.stage_times.get(name, 0.0) + max(now - since, 0.0)
        self.running = None if stage is None else (stage, now)
        self.stage_fraction = 0.0
        if stage is not None:
            self.stage_times.setdefault(stage, 0.0)

    def _share(self, stage: str) -> tuple[float, float]:
        kind = next(iter(self.stage_times), stage)
        return self.learned.get(kind, {}).get(stage) or share(stage, self.gathers)

    def _frame_left(self, now: float, in_frame: float) -> float | None:
        """Seconds left of the frame: the running stage's rest at its own rate plus the stages
        after it at the frame's rate (``src/progress.rs``, ``Meter::frame_left``: the stage's
        rate holds where the shares are guesses); the frame's rate alone for a stage under 5%."""
        if self.fraction <= 0:
            return None
        by_frame = in_frame * (1.0 - self.fraction) / self.fraction
        if self.running is None:
            return by_frame
        stage, since = self.running
        g, t = self.stage_fraction, max(now - since, 0.0)
        if g < 0.05 or t <= 0:
            return by_frame
        start, span = self._share(stage)
        return t * (1.0 - g) / g + max(1.0 - start - span, 0.0) * in_frame / self.fraction

    def reading(self, now: float) -> Reading:
        in_frame = max(now - self.frame_start, 0.0)
        frame_left = self._frame_left(now, in_frame)
        if self.done:
            per_frame = self.finished / self.done
        else:
            per_frame = None if frame_left is None else in_frame + frame_left
        rest = max(self.frames - self.done - 1, 0)
        if per_frame is None:
            bake_left = None
        elif frame_left is None:
            bake_left = (1 + rest) * per_frame if self.done < self.frames else 0.0
        else:
            bake_left = frame_left + rest * per_frame
        return Reading(
            frame_fraction=self.fraction,
            bake_fraction=min((self.done + self.fraction) / self.frames, 1.0),
            elapsed=max(now - self.start, 0.0),
            frame_left=frame_left,
            bake_left=bake_left,
        )


def human(seconds: float | None) -> str:
    """``1 h 02 m``, ``3 m 07 s``, ``12.3 s``; ``?`` for unknown."""
    if seconds is None:
        return "?"
    s = max(seconds, 0.0)
    if s >= 3600:
        return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} m"
    if s >= 60:
        return f"{int(s // 60)} m {int(s % 60):02d} s"
    return f"{s:.1f} s"


def status_text(frame, index: int, total: int, stage: str, r: Reading) -> str:
    """The status bar / header line of a bake in the UI."""
    return (f"Radiosity: frame {frame} ({index}/{total}): {stage or 'preparing'}, "
            f"frame {100 * r.frame_fraction:.0f}%, {human(r.frame_left)} left | "
            f"bake {100 * r.bake_fraction:.0f}%, {human(r.elapsed)} spent, "
            f"{human(r.bake_left)} left | Esc: cancel")


class Lines:
    """Progress lines of a bake for a terminal, from the bake's listener events.

    Inside a frame, a line at most every ``interval`` seconds (the library calls back every few
    milliseconds); after each frame, ``Radiosity: frame F done (i/n) in T s; bake P%, S spent,
    about L left``; ``summary()`` gives the closing line. The library may be silent for longer
    than ``interval`` (one slow link or corner on a 125k-face scene): inside ``heartbeat()``, a
    thread repeats the frame's line (its time spent and left moving on) when none came for
    ``interval``, so a terminal never waits more than about ``interval`` for a line. A bake in
    several jobs (the headless checkpoints) announces each with ``expect``, which keeps ``i/n``
    counting across them.
    """

    def __init__(self, frames: int, interval: float = 1.0, out=None, clock=time.perf_counter):
        self.clock = clock
        self.meter = Meter(frames, clock())
        self.interval = interval
        self.out = out
        self.last_line = self.meter.start
        self.lock = threading.Lock()
        self.frame_seconds: list[float] = []
        self.job = None
        self.beyond = 0
        self.kept = None   # frames the first job kept from an earlier bake
        self._job_seen = True
        self.running = None   # (frame, stage) of the frame in progress, for the heartbeat

    def expect(self, job, beyond: int = 0) -> None:
        """The events to come are ``job``'s, and ``beyond`` frames follow it in later jobs. The
        job's own count is known once it started, so the total is set at its first event."""
        with self.lock:
            self.job, self.beyond = job, beyond
            self._job_seen = False

    def job_ended(self) -> None:
        """The expected job returned (its counts count even when it solved nothing)."""
        with self.lock:
            self._see_job()
            self.running = None

    def _see_job(self) -> None:
        if not self._job_seen:
            self._job_seen = True
            self.meter.frames = max(self.meter.done + int(self.job.total) + self.beyond, 1)
            self.meter.gathers = job_gathers(self.job)
            if self.kept is None:
                self.kept = int(self.job.kept)

    def listen(self, event: dict) -> None:
        """A listener of ``addon.blender.bake``: never cancels, never raises."""
        with self.lock:
            now = self.clock()
            m = self.meter
            self._see_job()
            if event.get("kind") == "progress":
                m.report(float(event["fraction"]), str(event["stage"]), now)
                self.running = (event["frame"], str(event["stage"]))
                if now - self.last_line >= self.interval:
                    self._frame_line(now)
            elif event.get("kind") == "frame":
                m.frame_done(now)
                self.running = None
                self.frame_seconds.append(float(event["seconds"]))
                r = m.reading(now)
                self.last_line = now
                self._print(f"Radiosity: frame {event['frame']} done ({m.done}/{m.frames}) in "
                            f"{event['seconds']:.2f} s; bake {100 * r.bake_fraction:.0f}%, "
                            f"{human(r.elapsed)} spent, about {human(r.bake_left)} left")
        return None

    def tick(self) -> None:
        """The heartbeat: the running frame's line again if none was printed for ``interval``."""
        with self.lock:
            now = self.clock()
            if self.running is not None and now - self.last_line >= max(self.interval, 0.1):
                self._frame_line(now)

    @contextlib.contextmanager
    def heartbeat(self, period: float | None = None):
        """Calls ``tick`` from a daemon thread every ``period`` seconds (a tenth of ``interval``
        by default, at least 0.1 s) while the block runs."""
        stop = threading.Event()
        period = max(self.interval / 10 if period is None else period, 0.1)

        def beat():
            while not stop.wait(period):
                self.tick()

        thread = threading.Thread(target=beat, name="radiosity-progress", daemon=True)
        thread.start()
        try:
            yield self
        finally:
            stop.set()
            thread.join()

    def _frame_line(self, now: float) -> None:
        """The line of the frame in progress (the lock held)."""
        m = self.meter
        frame, stage = self.running
        r = m.reading(now)
        self.last_line = now
        self._print(f"Radiosity: frame {frame} ({m.done + 1}/{m.frames}): "
                    f"{stage}, frame {100 * r.frame_fraction:.0f}%, "
                    f"{human(r.frame_left)} left; bake {100 * r.bake_fraction:.0f}%, "
                    f"{human(r.elapsed)} spent, about {human(r.bake_left)} left")

    def summary(self) -> str:
        with self.lock:
            kept = self.kept or 0
            n = len(self.frame_seconds)
            elapsed = self.clock() - self.meter.start
            mean = f", {sum(self.frame_seconds) / n:.2f} s a frame" if n else ""
            more = f"; {kept} frame(s) kept from before" if kept else ""
            return (f"Radiosity: summary: solved {n} of {self.meter.frames} frame(s) in "
                    f"{human(elapsed)}{mean}{more}")

    def _print(self, line: str) -> None:
        try:
            print(line, file=self.out or sys.stdout, flush=True)
        except (OSError, ValueError):
            pass  # a closed terminal must not cancel the bake
