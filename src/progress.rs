//! Progress a person can read: one fraction per frame that only grows, the time spent, and an
//! estimate of the time left, for the frame and for the bake.
//!
//! The session reports `(fraction, stage)` per stage ("kernel", "kernel update", "solve",
//! "corner gather"), each from 0 to 1, so the raw fraction falls back at every stage change (the
//! 25% steps that went backwards, issue 24). A [`Meter`] maps each stage onto its share of a
//! frame, keeps the largest value seen, and estimates what is left from the time spent: within a
//! frame by the frame's own rate, for the bake by the mean time of the finished frames (or the
//! first frame's estimate while there is none).

use std::time::{Duration, Instant};

/// Each stage's share of a frame: where it starts and how much it spans. The kernel dominates a
/// first frame and the gather an updated one; the shares only need to keep the order.
fn share(stage: &str) -> (f64, f64) {
    match stage {
        "kernel" | "kernel update" => (0.0, 0.45),
        "solve" => (0.45, 0.1),
        "corner gather" => (0.55, 0.45),
        _ => (0.0, 1.0),
    }
}

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
        }
    }

    /// Records `fraction` of `stage` of the current frame at time `now`.
    pub fn report(&mut self, fraction: f64, stage: &str, now: Instant) -> Reading {
        let (from, span) = share(stage);
        let f = (from + span * fraction.clamp(0.0, 1.0)).clamp(0.0, 1.0);
        self.fraction = self.fraction.max(f);
        self.reading(now)
    }

    /// The current frame is finished at `now`; the next one starts.
    pub fn frame_done(&mut self, now: Instant) {
        self.finished += now.saturating_duration_since(self.frame_start);
        self.done += 1;
        self.frame_start = now;
        self.fraction = 0.0;
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
}
