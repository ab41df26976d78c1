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
/// it spans. The kernel dominates a first frame and the gather an updated one; the shares only
/// need to keep the order. "links" and "hierarchy" (its sweeps) are the hierarchy's.
fn share(stage: &str) -> (f64, f64) {
    match stage {
        "kernel" | "kernel update" | "links" => (0.0, 0.45),
        "solve" | "hierarchy" => (0.45, 0.1),
        "corner gather" => (0.55, 0.45),
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
    /// The finished frames' total time.
    finished: Duration,
    /// The current frame's stages in the order they first ran, with their time so far, and the
    /// stage running since when.
    stage_times: Vec<(String, Duration)>,
    running: Option<(String, Instant)>,
    /// Per kind of frame (its first stage), the shares of the last one finished.
    learned: Vec<(String, Shares)>,
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
            finished: Duration::ZERO,
            stage_times: Vec::new(),
            running: None,
            learned: Vec::new(),
        }
    }

    /// Records `fraction` of `stage` of the current frame at time `now`.
    pub fn report(&mut self, fraction: f64, stage: &str, now: Instant) -> Reading {
        self.time_stage(Some(stage), now);
        let (from, span) = self.share(stage);
        let f = (from + span * fraction.clamp(0.0, 1.0)).clamp(0.0, 1.0);
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
            .map_or_else(|| share(stage), |&(_, start, span)| (start, span))
    }

    fn reading(&self, now: Instant) -> Reading {
        let in_frame = now.saturating_duration_since(self.frame_start).as_secs_f64();
        let frame_left = (self.fraction > 0.0).then(|| in_frame * (1.0 - self.fraction) / self.fraction);
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
