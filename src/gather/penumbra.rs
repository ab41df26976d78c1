//! The penumbra check both corner gathers make on an emitter's rectangle (the flat
//! [`super::Gather::moments`] and the hierarchy's `gather::surface`): whether its Gauss nodes'
//! shadow rays, and rays to its corners, disagree, so that it is split further (down to
//! [`super::PENUMBRA_DEPTH`] levels; tests/penumbra.rs).

use glam::DVec3;

use crate::geometry::{Patch, Rect};

/// The corners of an emitter's rectangle that a penumbra check casts rays to (those in front of
/// the receiving point's plane), and whether each is seen: the nodes lie inside the rectangle (a
/// ninth of it from its edges), and a shadow edge that crosses only that margin is seen by a ray
/// to one of its corners instead.
pub(crate) struct Corners {
    /// Whether the rectangle may be split for a penumbra at all.
    check: bool,
    pub points: [DVec3; 4],
    pub count: usize,
    /// Set by the caller's rays (all seen until then).
    pub seen: [bool; 4],
}

impl Corners {
    /// The corners of `rect` of `patch` in front of the point `x` (normal `n`); none unless
    /// `check`.
    pub fn of((x, n): (DVec3, DVec3), patch: &Patch, rect: &Rect, check: bool) -> Self {
        let mut corners = Corners { check, points: [DVec3::ZERO; 4], count: 0, seen: [true; 4] };
        if check {
            for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                let (s, t) = rect.map(u, v);
                let y = patch.point(s, t);
                if n.dot(y - x) > 0.0 {
                    corners.points[corners.count] = y;
                    corners.count += 1;
                }
            }
        }
        corners
    }

    /// Whether the rectangle is in a penumbra: of its `count` lit Gauss nodes `seen` are seen, and
    /// some but not all, or its corners disagree with them. Never where it is not to be checked.
    pub fn disagree(&self, seen: usize, count: usize) -> bool {
        let lit = seen == count;
        self.check
            && count > 0
            && ((seen > 0 && seen < count) || self.seen[..self.count].iter().any(|&c| c != lit))
    }
}
