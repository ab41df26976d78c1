//! Progress a person can read: one fraction per frame that only grows, the time spent, and an
//! estimate of the time left, for the frame and for the bake.
//!
//! The session reports `(fraction, stage)` per stage ("kernel", "kernel update", "solve",
//! "corner gather"), each from 0 to 1, so the raw fraction falls back at every stage change (the
//! 25% steps that went backwards, issue 24). A [`Meter`] maps each stage onto its share of a
//! frame, keeps the largest value seen, and estimates what is left from the time spent: within a
//! frame by the frame's own rate, for the bake by the mean time of the finished frames (or the
//! first frame's estimate while there is none).
//!
//! The shares are learned: a finished frame's stages, timed, become the shares of the next frame
//! of its kind (the kind is the frame's first stage: "kernel" for a frame built from scratch,
//! "kernel update" for an incremental one, "links" on the hierarchy). Fixed shares only hold on
//! the scenes they were guessed on: on the monastery the corner gather is 90% of a frame, not
//! 45%, and the time left was off by 5x until the frame ended. The fixed shares below are the
//! first frame of each kind's.

use std::time::{Duration, Instant};

/// Each stage's share of a frame before one of its kind is timed: where it starts and how much
/// it spans, with a corner gather to come (`gathers`) or without. The kernel dominates a first
/// frame and the gather an updated one; the shares only need to keep the order. "links" and
/// "hierarchy" (its sweeps) are the hierarchy's. Without a gather the links are most of a frame
/// (23 of 24 s on a 30k-triangle model's first frame): at 45% its time left read 2x the truth.
fn share(stage: &str, gathers: bool) -> (f64, f64) {
    match (stage, gathers) {
        ("kernel" | "kernel update" | "links", true) => (0.0, 0.45),
        ("kernel" | "kernel update" | "links", false) => (0.0, 0.9),
        ("solve" | "hierarchy", true) => (0.45, 0.1),
        ("solve" | "hierarchy", false) => (0.9, 0.1),
        ("corner gather", _) => (0.55, 0.45),
        _ => (0.0, 1.0),
    }
}

/// A frame's stages as timed: `(stage, start, span)` as fractions of the frame, in the order
/// they first ran.
type Shares = Vec<(String, f64, f64)>;

/// The progress of a bake of `frames` frames.
pub struct Meter {
    frames: usize,
    done: usize,
    start: Instant,
    frame_start: Instant,
    /// The largest fraction of the current frame reported.
    fraction: f64,
    /// The largest fraction the running stage reported since it started.
    stage_fraction: f64,
    /// The finished frames' total time.
    finished: Duration,
    /// The current frame's stages in the order they first ran, with their time so far, and the
    /// stage running since when.
    stage_times: Vec<(String, Duration)>,
    running: Option<(String, Instant)>,
    /// Per kind of frame (its first stage), the shares of the last one finished.
    learned: Vec<(String, Shares)>,
    /// Whether a frame ends in a corner gather ([`Meter::gathering`]).
    gathers: bool,
}

/// One reading of a [`Meter`].
#[derive(Clone, Debug, PartialEq)]
pub struct Reading {
    /// Of the current frame, in `[0, 1]`, never less than the last reading of the frame.
    pub frame_fraction: f64,
    /// Of the whole bake, in `[0, 1]`.
    pub bake_fraction: f64,
    pub elapsed: Duration,
    /// Left of the current frame and of the bake; `None` until something is known.
    pub frame_left: Option<Duration>,
    pub bake_left: Option<Duration>,
}

impl Meter {
    pub fn new(frames: usize) -> Self {
        let now = Instant::now();
        Self {
            frames: frames.max(1),
            done: 0,
            start: now,
            frame_start: now,
            fraction: 0.0,
            stage_fraction: 0.0,
            finished: Duration::ZERO,
            stage_times: Vec::new(),
            running: None,
            learned: Vec::new(),
            gathers: true,
        }
    }

    /// Whether the bake's frames end in a corner gather (the default): the stages' shares of a
    /// frame before one is timed depend on it.
    pub fn gathering(mut self, gathers: bool) -> Self {
        self.gathers = gathers;
        self
    }

    /// Records `fraction` of `stage` of the current frame at time `now`.
    pub fn report(&mut self, fraction: f64, stage: &str, now: Instant) -> Reading {
        self.time_stage(Some(stage), now);
        let fraction = fraction.clamp(0.0, 1.0);
        self.stage_fraction = self.stage_fraction.max(fraction);
        let (from, span) = self.share(stage);
        let f = (from + span * fraction).clamp(0.0, 1.0);
        self.fraction = self.fraction.max(f);
        self.reading(now)
    }

    /// The current frame is finished at `now`; the next one starts, and the next of its kind
    /// will be measured by its stages' times.
    pub fn frame_done(&mut self, now: Instant) {
        self.time_stage(None, now);
        if let Some(shares) = self.timed_shares() {
            let kind = self.stage_times[0].0.clone();
            self.learned.retain(|(k, _)| *k != kind);
            self.learned.push((kind, shares));
        }
        self.stage_times.clear();
        self.finished += now.saturating_duration_since(self.frame_start);
        self.done += 1;
        self.frame_start = now;
        self.fraction = 0.0;
    }

    /// Adds the running stage's time up to `now` and starts `next` (none: the frame ended).
    fn time_stage(&mut self, next: Option<&str>, now: Instant) {
        if let Some((stage, since)) = &self.running {
            if next == Some(stage.as_str()) {
                return;
            }
            let spent = now.saturating_duration_since(*since);
            match self.stage_times.iter_mut().find(|(s, _)| s == stage) {
                Some((_, t)) => *t += spent,
                None => self.stage_times.push((stage.clone(), spent)),
            }
        }
        self.running = next.map(|s| (s.to_owned(), now));
        self.stage_fraction = 0.0;
        if let Some(s) = next
            && !self.stage_times.iter().any(|(t, _)| t == s)
        {
            self.stage_times.push((s.to_owned(), Duration::ZERO));
        }
    }

    /// The finished frame's stages as shares of its time (none if it took no measurable time).
    fn timed_shares(&self) -> Option<Shares> {
        let total: f64 = self.stage_times.iter().map(|(_, t)| t.as_secs_f64()).sum();
        if total <= 0.0 {
            return None;
        }
        let mut start = 0.0;
        Some(
            self.stage_times
                .iter()
                .map(|(s, t)| {
                    let span = t.as_secs_f64() / total;
                    start += span;
                    (s.clone(), start - span, span)
                })
                .collect(),
        )
    }

    /// Where `stage` starts in the current frame and what it spans: as in the last finished
    /// frame of this kind, else the fixed guess.
    fn share(&self, stage: &str) -> (f64, f64) {
        let kind = self.stage_times.first().map(|(s, _)| s.as_str()).unwrap_or(stage);
        self.learned
            .iter()
            .find(|(k, _)| k == kind)
            .and_then(|(_, shares)| shares.iter().find(|(s, ..)| s == stage))
            .map_or_else(|| share(stage, self.gathers), |&(_, start, span)| (start, span))
    }

    /// Seconds left of the current frame at `now`, `in_frame` seconds into it: what the running
    /// stage has left at its own rate, plus the stages after it at the frame's rate so far.
    /// The stage's own rate is what makes the estimate hold when the shares are guesses (a
    /// first frame whose gather is 99% of it, guessed at 45%: on the decimated monastery the
    /// frame's rate said 16 s left with 66 s to go, `python3 -m tools.time_left`). A stage that
    /// reported under 5% of itself is too young for a rate: the frame's alone is used.
    fn frame_left(&self, now: Instant, in_frame: f64) -> Option<f64> {
        if self.fraction <= 0.0 {
            return None;
        }
        let by_frame = in_frame * (1.0 - self.fraction) / self.fraction;
        let Some((stage, since)) = &self.running else { return Some(by_frame) };
        let (g, t) = (self.stage_fraction, now.saturating_duration_since(*since).as_secs_f64());
        if g < 0.05 || t <= 0.0 {
            return Some(by_frame);
        }
        let (start, span) = self.share(stage);
        let after = (1.0 - start - span).max(0.0);
        Some(t * (1.0 - g) / g + after * in_frame / self.fraction)
    }

    /// The progress at `now`: the frame's fraction as last reported, the times moving on.
    pub fn reading(&self, now: Instant) -> Reading {
        let in_frame = now.saturating_duration_since(self.frame_start).as_secs_f64();
        let frame_left = self.frame_left(now, in_frame);
        // A finished frame's mean is the better guess for the frames to come (the first frame,
        // which builds every link, is slower than the updated ones).
        let per_frame = if self.done > 0 {
            Some(self.finished.as_secs_f64() / self.done as f64)
        } else {
            frame_left.map(|left| in_frame + left)
        };
        let rest = (self.frames - self.done).saturating_sub(1) as f64;
        let bake_left = match (frame_left, per_frame) {
            (Some(f), Some(p)) => Some(f + rest * p),
            (None, Some(p)) => Some((1.0 + rest) * p),
            _ => None,
        };
        Reading {
            frame_fraction: self.fraction,
            bake_fraction: ((self.done as f64 + self.fraction) / self.frames as f64).min(1.0),
            elapsed: now.saturating_duration_since(self.start),
            frame_left: frame_left.map(Duration::from_secs_f64),
            bake_left: bake_left.map(Duration::from_secs_f64),
        }
    }
}

/// Progress lines for a terminal, fed by a bake's callbacks and by a heartbeat: the running
/// frame's line at most every `interval` when fed, and again from [`Lines::line`] without a
/// report when the library was silent for `interval` (one slow link or corner of a 125k-face
/// scene), so a terminal waits about `interval` at most. The CLI calls it from the session's
/// callback and from a thread every 0.1 s.
pub struct Lines {
    pub meter: Meter,
    interval: Duration,
    last: Instant,
    /// The frame and stage reporting ("frame 12 (3/40): corner gather"); `None` between frames.
    running: Option<String>,
}

impl Lines {
    pub fn new(frames: usize, interval: Duration) -> Self {
        let meter = Meter::new(frames);
        let last = meter.start;
        Lines { meter, interval, last, running: None }
    }

    /// Whether the bake's frames end in a corner gather ([`Meter::gathering`]).
    pub fn gathering(mut self, gathers: bool) -> Self {
        self.meter = self.meter.gathering(gathers);
        self
    }

    /// The line to print at `now`, if `interval` passed since the last one and a frame runs;
    /// `running`, when given, names the frame and stage reporting now.
    pub fn line(&mut self, now: Instant, running: Option<String>) -> Option<String> {
        if running.is_some() {
            self.running = running;
        }
        let what = self.running.as_ref()?;
        if now.saturating_duration_since(self.last) < self.interval {
            return None;
        }
        self.last = now;
        let r = self.meter.reading(now);
        let left = |d: Option<Duration>| d.map_or("?".to_string(), human);
        Some(format!(
            "{what}, frame {:.0}%, {} left; bake {:.0}%, {} spent, {} left",
            100.0 * r.frame_fraction,
            left(r.frame_left),
            100.0 * r.bake_fraction,
            human(r.elapsed),
            left(r.bake_left),
        ))
    }

    /// The running frame ended at `now`: no line until the next one reports.
    pub fn frame_done(&mut self, now: Instant) {
        self.meter.frame_done(now);
        self.running = None;
    }
}

/// `1 h 02 m`, `3 m 07 s`, `12.3 s`.
pub fn human(d: Duration) -> String {
    let s = d.as_secs_f64();
    if s >= 3600.0 {
        format!("{} h {:02} m", (s / 3600.0) as u64, ((s % 3600.0) / 60.0) as u64)
    } else if s >= 60.0 {
        format!("{} m {:02} s", (s / 60.0) as u64, (s % 60.0) as u64)
    } else {
        format!("{s:.1} s")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_heartbeat_repeats_the_line_while_the_library_is_silent() {
        let mut lines = Lines::new(2, Duration::from_secs(1));
        let t0 = lines.meter.start;
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        lines.meter.report(0.5, "corner gather", at(0.0));
        let gather = Some("frame 7 (1/2): corner gather".to_string());
        assert_eq!(lines.line(at(0.5), gather), None, "less than the interval since the start");
        // Silent from here: the heartbeat's calls give a line a second, the time moving on.
        // At 2 s the gather, the last stage, is half done after 2 s of it: 2 s left, and the
        // next frame is expected to take 4 s.
        assert_eq!(
            lines.line(at(2.0), None).as_deref(),
            Some("frame 7 (1/2): corner gather, frame 78%, 2.0 s left; bake 39%, 2.0 s spent, 6.0 s left")
        );
        assert_eq!(lines.line(at(2.5), None), None);
        assert!(lines.line(at(5.0), None).unwrap().contains("5.0 s spent"));
        lines.frame_done(at(5.0));
        assert_eq!(lines.line(at(9.0), None), None, "no frame runs: nothing to repeat");
    }

    /// Without a corner gather a first frame is nearly all links: half of them done is most of
    /// the frame, and the time left is about the time spent (at 45%, 2.1x as much).
    #[test]
    fn a_frame_without_a_gather_is_mostly_its_links() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let mut m = Meter::new(1).gathering(false);
        m.report(0.0, "links", at(0.0));
        let r = m.report(0.5, "links", at(10.0));
        assert!((r.frame_fraction - 0.45).abs() < 1e-12, "{}", r.frame_fraction);
        let want = 10.0 + 0.1 * 10.0 / 0.45;
        assert!((r.frame_left.unwrap().as_secs_f64() - want).abs() < 1e-3, "{:?}", r.frame_left);
        let r = m.report(0.5, "hierarchy", at(11.0));
        assert!((r.frame_fraction - 0.95).abs() < 1e-12, "{}", r.frame_fraction);
        // With a gather to come the same links are under a quarter of the frame.
        let mut m = Meter::new(1);
        assert!((m.report(0.5, "links", at(10.0)).frame_fraction - 0.225).abs() < 1e-12);
    }

    /// The running stage's own rate: a gather guessed at 45% of the frame that is all of it.
    #[test]
    fn the_time_left_follows_the_running_stage_at_its_own_rate() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let mut m = Meter::new(1);
        m.report(1.0, "kernel", at(1.0));
        m.report(0.0, "corner gather", at(2.0));
        // 10 s into the gather, 25% of it: 30 s left (the frame's rate, 12 s for 66%, says 6 s).
        let r = m.report(0.25, "corner gather", at(12.0));
        assert!((r.frame_left.unwrap().as_secs_f64() - 30.0).abs() < 1e-9, "{:?}", r.frame_left);
        // A stage before others: its own rest plus the later stages' shares at the frame's rate.
        // (The meter's frame starts when it is made, a moment after t0.)
        let mut m = Meter::new(1);
        m.report(0.0, "kernel", at(0.0));
        let r = m.report(0.5, "kernel", at(4.0));
        let want = 4.0 + 0.55 * 4.0 / (0.45 * 0.5);
        assert!((r.frame_left.unwrap().as_secs_f64() - want).abs() < 1e-3, "{:?}", r.frame_left);
        // Under 5% of a stage: the frame's rate alone.
        let r = m.report(0.01, "corner gather", at(5.0));
        let f = 0.55 + 0.45 * 0.01;
        assert!((r.frame_left.unwrap().as_secs_f64() - 5.0 * (1.0 - f) / f).abs() < 1e-3);
    }

    #[test]
    fn the_fraction_never_falls_back_across_stages() {
        let t = Instant::now();
        let mut m = Meter::new(2);
        let mut last = 0.0;
        for (f, stage) in [
            (0.5, "kernel"),
            (1.0, "kernel"),
            (1.0, "solve"),
            (0.0, "corner gather"),
            (0.7, "corner gather"),
            (0.2, "solve"),
        ] {
            let r = m.report(f, stage, t);
            assert!(r.frame_fraction >= last, "{stage} {f}: {} < {last}", r.frame_fraction);
            last = r.frame_fraction;
        }
        assert!((m.report(0.7, "corner gather", t).bake_fraction - (0.55 + 0.45 * 0.7) / 2.0).abs() < 1e-12);
    }

    #[test]
    fn time_left_follows_the_rate_then_the_finished_frames() {
        let t0 = Instant::now();
        let mut m = Meter::new(3);
        assert_eq!(m.report(0.0, "kernel", t0).bake_left, None);
        // The gather starts 11 s into the first frame, 55% of it by the shares: the frame has
        // 11 x 45/55 s left, and each of the two frames after it is expected to take as long.
        let r = m.report(0.0, "corner gather", t0 + Duration::from_secs(11));
        assert!((r.frame_fraction - 0.55).abs() < 1e-12);
        let left = r.frame_left.unwrap().as_secs_f64();
        assert!((left - 11.0 * 0.45 / 0.55).abs() < 1e-6, "{left}");
        let bake = r.bake_left.unwrap().as_secs_f64();
        assert!((bake - (left + 2.0 * (11.0 + left))).abs() < 1e-6, "{bake}");
        // The first frame took 20 s: the other two are expected at that mean.
        m.frame_done(t0 + Duration::from_secs(20));
        let r = m.report(0.0, "kernel update", t0 + Duration::from_secs(20));
        assert_eq!(r.frame_left, None);
        assert!((r.bake_left.unwrap().as_secs_f64() - 40.0).abs() < 1e-6);
        assert_eq!(human(Duration::from_secs(3725)), "1 h 02 m");
        assert_eq!(human(Duration::from_secs(187)), "3 m 07 s");
    }

    /// A frame whose gather took 90% of it (the monastery's) makes the next frame of its kind
    /// map the gather onto 90%: its time left is right from the gather's start, where the
    /// fixed shares put the gather at 45% and said the frame was half done.
    #[test]
    fn the_next_frame_of_a_kind_is_measured_by_the_last_ones_stages() {
        let t0 = Instant::now();
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let mut m = Meter::new(3);
        m.report(0.0, "kernel", at(0.0));
        m.report(1.0, "kernel", at(1.0));
        m.report(0.0, "solve", at(1.0));
        m.report(0.0, "corner gather", at(2.0));
        m.frame_done(at(20.0));
        // The second frame, of the same kind: kernel 5%, solve 5%, gather 90% of 20 s.
        m.report(0.0, "kernel", at(20.0));
        let r = m.report(0.0, "corner gather", at(22.0));
        assert!((r.frame_fraction - 0.1).abs() < 1e-12, "{}", r.frame_fraction);
        assert!((r.frame_left.unwrap().as_secs_f64() - 18.0).abs() < 1e-6);
        let r = m.report(0.5, "corner gather", at(31.0));
        assert!((r.frame_fraction - 0.55).abs() < 1e-12, "{}", r.frame_fraction);
        // A frame of another kind (an incremental one) starts from the fixed shares.
        m.frame_done(at(40.0));
        let r = m.report(0.5, "kernel update", at(41.0));
        assert!((r.frame_fraction - 0.5 * 0.45).abs() < 1e-12, "{}", r.frame_fraction);
        let r = m.report(0.0, "corner gather", at(42.0));
        assert!((r.frame_fraction - 0.55).abs() < 1e-12, "{}", r.frame_fraction);
    }
}
