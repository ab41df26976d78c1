//! Shadow rays kept from frame to frame.
//!
//! A frame's projection of the direct light ([`super::direct::DirectLight::project_keeping`])
//! casts a fixed sequence of shadow rays per element, set by the element's patch, the lights as
//! placed and the outcomes of the rays before (a World stratum whose corners disagree casts more).
//! It records each ray's outcome in that order ([`Outcomes`]). The next frame, where the element
//! did not move, casts the same rays in the same order for every source placed as before, as
//! long as their outcomes are the same; a source placed otherwise (a light that moved) casts its
//! own sections again ([`Probe::with_changed`]). A ray whose segment meets no box a moving
//! object swept between the two frames has the same outcome: every triangle it could meet is
//! where it was.
//! So such a ray's outcome is taken from the record, the others are traced again, and from the
//! first traced ray whose outcome changed on (the sequence may differ from there) every ray is
//! traced until the next section ([`Probe`]): a section is one source's rays at one projection
//! point, whose sequence does not depend on the rays before it. The projection is then the one a
//! fresh frame makes, bit for bit.
//!
//! Why: with a World lighting the scene every element's 6 x 6 projection points cast 81 sky rays
//! and more (Medium), and the projection was recomputed whole each frame. A box moving in the
//! add-on's 851-face Cornell box under a World took 1.1 s a frame in the projection alone.

use glam::DVec3;

use crate::geometry::Aabb;

/// The outcomes of one element's shadow rays (true: the ray passes), in the order cast.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Outcomes {
    bits: Vec<u64>,
    len: usize,
    /// Where each section's rays start.
    starts: Vec<u32>,
}

impl Outcomes {
    fn push(&mut self, passes: bool) {
        if self.len.is_multiple_of(64) {
            self.bits.push(0);
        }
        if passes {
            self.bits[self.len / 64] |= 1 << (self.len % 64);
        }
        self.len += 1;
    }

    fn get(&self, k: usize) -> Option<bool> {
        (k < self.len).then(|| self.bits[k / 64] >> (k % 64) & 1 == 1)
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        8 * self.bits.capacity() + 4 * self.starts.capacity()
    }
}

/// What a keeping of shadow rays did: rays traced, and taken from the last frame's outcomes.
#[derive(Clone, Copy, Debug, Default)]
pub struct KeptRays {
    pub traced: u64,
    /// Taken from the last frame's outcomes.
    pub taken: u64,
    /// Bytes the outcomes kept for the next frame hold (where counted).
    pub bytes: usize,
}

impl KeptRays {
    /// Adds `other`'s counts to these.
    pub fn add(&mut self, other: KeptRays) {
        self.traced += other.traced;
        self.taken += other.taken;
        self.bytes += other.bytes;
    }
}

/// Answers one element's shadow rays: from the last frame's outcomes where it may, by tracing
/// otherwise, recording every outcome for the next frame.
pub(super) struct Probe<'a> {
    last: Option<&'a Outcomes>,
    swept: &'a [Aabb],
    /// The next ray's place in the sequence, and the end of its section's rays there.
    at: usize,
    end: usize,
    /// A traced ray's outcome differed from the record: the rest of the section may differ.
    diverged: bool,
    /// The next section's number.
    section: usize,
    /// Per source (a section's number modulo their count), whether it changed since the record:
    /// its sections are traced whole. Empty: none changed.
    changed: &'a [bool],
    record: Option<Outcomes>,
    /// Rays traced, and taken from the record.
    rays: KeptRays,
}

impl<'a> Probe<'a> {
    /// A probe that traces every ray and records nothing (a point query).
    pub(super) fn tracing() -> Self {
        Self::new(None, &[], false)
    }

    /// A probe taking from `last` (rays meeting none of `swept`), recording if `record`.
    pub(super) fn new(last: Option<&'a Outcomes>, swept: &'a [Aabb], record: bool) -> Self {
        Self {
            last,
            swept,
            at: 0,
            end: usize::MAX,
            diverged: false,
            section: 0,
            changed: &[],
            record: record.then(Outcomes::default),
            rays: KeptRays::default(),
        }
    }

    /// This probe with `changed`, per source in the order each point casts their sections,
    /// whether the source changed since the record (a light that moved): its sections are traced
    /// whole, the others taken as before. Each point casts one section per source, so a section's
    /// source is its number modulo their count.
    pub(super) fn with_changed(mut self, changed: &'a [bool]) -> Self {
        self.changed = changed;
        self
    }

    /// Starts the next section: one source's rays at one point, cast alike whatever the rays
    /// before it found. Taking from the record starts again at the section's first ray.
    pub(super) fn section(&mut self) {
        if let Some(record) = &mut self.record {
            record.starts.push(record.len as u32);
        }
        let changed = !self.changed.is_empty() && self.changed[self.section % self.changed.len()];
        match self.last.and_then(|o| Some((o, *o.starts.get(self.section)?))).filter(|_| !changed) {
            Some((o, start)) => {
                let end = o.starts.get(self.section + 1).map_or(o.len, |&e| e as usize);
                (self.at, self.end, self.diverged) = (start as usize, end, false);
            }
            None => self.diverged = true,
        }
        self.section += 1;
    }

    /// Whether the segment from `x` to `y` passes: `trace()` it, or take the recorded outcome.
    pub(super) fn passes(&mut self, x: DVec3, y: DVec3, trace: impl FnOnce() -> bool) -> bool {
        // (A section cast as recorded never reads past its end; the bound makes that local.)
        let recorded =
            if self.diverged || self.at >= self.end { None } else { self.last.and_then(|o| o.get(self.at)) };
        self.at += 1;
        let passes = match recorded {
            Some(r) if !self.swept.iter().any(|b| b.meets_segment(x, y)) => {
                self.rays.taken += 1;
                r
            }
            _ => {
                self.rays.traced += 1;
                let p = trace();
                if recorded.is_some_and(|r| r != p) {
                    self.diverged = true;
                }
                p
            }
        };
        if let Some(record) = &mut self.record {
            record.push(passes);
        }
        passes
    }

    /// The outcomes recorded (none if not recording), and the rays traced and taken.
    pub(super) fn finish(self) -> (Outcomes, KeptRays) {
        (self.record.unwrap_or_default(), self.rays)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outcomes_read_back_as_pushed() {
        let mut o = Outcomes::default();
        let pattern: Vec<bool> = (0..200).map(|k| (k * 7 + k / 3) % 5 < 2).collect();
        for &p in &pattern {
            o.push(p);
        }
        assert!(pattern.iter().enumerate().all(|(k, &p)| o.get(k) == Some(p)));
        assert_eq!(o.get(200), None);
    }

    /// A ray through a swept box is traced again; once a traced outcome differs from the record,
    /// every later ray is traced (its sequence may differ).
    #[test]
    fn a_changed_outcome_ends_the_taking() {
        let mut last = Outcomes::default();
        for p in [true, true, false, true] {
            last.push(p);
        }
        let swept = [Aabb { min: DVec3::new(0.4, -1.0, -1.0), max: DVec3::new(0.6, 1.0, 1.0) }];
        last.starts.push(0);
        let mut probe = Probe::new(Some(&last), &swept, true);
        probe.section();
        let (x, across, beside) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        // Beside the box: the record's outcome, whatever the trace would say.
        assert!(probe.passes(x, beside, || false));
        // Through it: traced; the same outcome, so the taking goes on.
        assert!(probe.passes(x, across, || true));
        assert!(!probe.passes(x, beside, || true));
        // Through it, another outcome: from here on every ray is traced.
        assert!(!probe.passes(x, across, || false));
        assert!(probe.passes(x, beside, || true));
        assert_eq!((probe.rays.taken, probe.rays.traced), (2, 3));
        let (record, _) = probe.finish();
        assert_eq!(
            (0..5).map(|k| record.get(k).unwrap()).collect::<Vec<_>>(),
            [true, true, false, false, true]
        );
    }

    /// A changed outcome ends the taking only until the next section, whose rays are taken from
    /// its own start in the record.
    #[test]
    fn a_section_starts_the_taking_again() {
        let mut last = Outcomes::default();
        // Two sections: [true, false] and [false, true].
        last.starts.push(0);
        last.push(true);
        last.push(false);
        last.starts.push(2);
        last.push(false);
        last.push(true);
        let swept = [Aabb { min: DVec3::new(0.4, -1.0, -1.0), max: DVec3::new(0.6, 1.0, 1.0) }];
        let mut probe = Probe::new(Some(&last), &swept, true);
        let (x, across, beside) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        probe.section();
        // Through the box, changed, and one ray more than before (the sequence differed).
        assert!(!probe.passes(x, across, || false));
        assert!(probe.passes(x, beside, || true));
        assert!(probe.passes(x, beside, || true));
        probe.section();
        assert!(!probe.passes(x, beside, || true));
        assert!(probe.passes(x, beside, || false));
        assert_eq!((probe.rays.traced, probe.rays.taken), (3, 2));
        let (record, _) = probe.finish();
        assert_eq!(record.starts, [0, 3]);
    }
}
