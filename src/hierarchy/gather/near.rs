//! A near surface source integrated from the point with rays, cheaply ([`super::Mode::Fast`]).
//!
//! The exhaustive recursion ([`super::exhaustive`]) splits a near source until every part is
//! [`GAUSS_RATIO`] of its radius away, twelve levels deep next to a contact, and casts nine rays
//! into every part against the source's whole candidate list: on a mesh, where every corner
//! stands on the edge of its neighbours, that was 90% of the gather (5 ms and 14,000 rays for
//! each neighbour a corner touches, on the bunny). Here a part keeps only the candidates its own
//! shaft from the point may hold, and
//! - a part with none is unoccluded: it is taken whole by its exact polygon form factor
//!   ([`super::polygon`]), the Gauss nodes only sharing it out over the basis, once the basis
//!   varies little over it (from [`BASIS_DEPTH`] levels down); no rays;
//! - a part with candidates is split for its visibility down to [`VIS_DEPTH`] levels, then
//!   taken by its polygon form factor shared out by its Gauss nodes' rays;
//! - a part [`GAUSS_RATIO`] of its radius away is summed by the Gauss rule as the exhaustive
//!   recursion does, with rays against its own candidates.

use std::ops::Range;

use super::surface::{Rays, Source};
use super::{Counters, FAR_RATIO, GAUSS_RATIO, Gather, Receiver, polygon};
use crate::basis::MAX_LEN as MAX_NB;
use crate::gather::{Ball, Side, behind_plane};
use crate::geometry::{Patch, Rect};

/// An unoccluded part is split until it spans at most `2^-BASIS_DEPTH` of its source's
/// parameters (the basis functions' spread over it, which its Gauss nodes share its form factor
/// out by).
const BASIS_DEPTH: u32 = 3;

/// A part its shaft's triangles may hide is split until it spans `2^-VIS_DEPTH` of its source's
/// parameters: the finest detail of a contact shadow a near source resolves.
const VIS_DEPTH: u32 = 6;

/// Deepest split of a part the point lies next to (a contact) while its shaft holds candidates.
const MAX_DEPTH: u32 = 12;

/// A part far enough for the Gauss rule casts its rays against its holder's candidates when
/// they are at most this many, else through the BVH (narrowing a long list would cost more than
/// the rays); the visibility module's own threshold for a brute-force list.
const SHORT_LIST: usize = 24;

/// Candidate lists longer than this are gathered again from the BVH for a part of the source;
/// shorter ones are narrowed triangle by triangle.
const NARROW_MAX: usize = 64;

thread_local! {
    /// The candidate lists of a recursion's levels, one after the other, and a query's result.
    static LISTS: std::cell::RefCell<(Vec<usize>, Vec<usize>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// One near source's recursion.
struct Walk<'g, 'a> {
    gather: &'g Gather<'a>,
    rx: &'g Receiver,
    src: Source<'g>,
    /// The candidate lists of the open levels (each part's a range of it).
    lists: &'g mut Vec<usize>,
    /// A BVH query's result before it joins `lists`.
    query: &'g mut Vec<usize>,
}

impl Gather<'_> {
    /// The moments of the whole near source `src` into `out`; with `ball = Some((r, weight))`
    /// the part within `r` of the point adds its form factor to `weight` instead (the feet,
    /// [`super::surface`]).
    pub(super) fn near_moments(
        &self,
        rx: &Receiver,
        src: Source,
        out: &mut [f64],
        ball: Option<(Ball, &mut f64)>,
    ) {
        LISTS.with_borrow_mut(|(lists, query)| {
            lists.clear();
            if let Some(o) = self.inputs.occluders {
                o.point_candidates(rx.x, rx.n, (rx.face, src.face), &src.patch.bounds(), lists);
                Counters::add(&self.counters.shafts, 1);
            }
            let all = 0..lists.len();
            let mut walk = Walk { gather: self, rx, src, lists, query };
            walk.rect(&Rect::UNIT, 0, all, out, ball);
        });
    }
}

impl Walk<'_, '_> {
    /// Adds the moments of `rect` of the source to `out`, given the candidates `candidates` (a
    /// range of `lists`) of a part holding it.
    fn rect(
        &mut self,
        rect: &Rect,
        depth: u32,
        candidates: Range<usize>,
        out: &mut [f64],
        ball: Option<(Ball, &mut f64)>,
    ) {
        let g = self.gather;
        if g.stop.stopped() {
            return;
        }
        let sub = self.src.patch.sub_patch(rect);
        let (centre, radius) = sub.bounding_sphere();
        if behind_plane(self.rx.x, self.rx.n, &sub, radius) {
            return;
        }
        let distance = self.rx.x.distance(centre);
        // A foot's ball: a part wholly inside it adds its seen form factor to `weight`; one across
        // its edge is split while it is coarse against the ball, then taken as any part with its
        // seen nodes shared out by the side they lie on (`across`); one outside is any part.
        let mut across = None;
        if let Some((ball, weight)) = ball {
            match ball.side(rect, &sub, (distance, radius), depth) {
                Side::Inside => {
                    let mut m = [0.0; MAX_NB];
                    self.rect(rect, depth, candidates, &mut m[..out.len()], None);
                    *weight += m[0];
                    return;
                }
                Side::Split => {
                    for q in rect.quadrants() {
                        self.rect(&q, depth + 1, candidates.clone(), out, Some((ball, &mut *weight)));
                    }
                    return;
                }
                Side::Across => across = Some((ball, weight)),
                Side::Outside => {}
            }
        }
        if distance >= GAUSS_RATIO * radius {
            // Far enough for the Gauss rule: its rays against the holder's candidates when they
            // are few, else through the BVH (narrowing the list would cost more than the rays).
            let rule = if distance >= FAR_RATIO * radius { &g.far_rule } else { &g.rule };
            let rays =
                if candidates.len() <= SHORT_LIST { Rays::Among(&self.lists[candidates]) } else { Rays::Bvh };
            g.gauss_split(self.rx, self.src, rect, rule, rays, out, across.map(|(b, w)| (b.radius, w)));
            return;
        }
        let (own, pushed) = self.narrow(&sub, candidates);
        // Deep enough for its visibility, unless the point lies within its bounding sphere (then
        // split on while its shaft holds candidates, to `MAX_DEPTH` at most).
        let settled = depth >= VIS_DEPTH && distance >= radius;
        if own.is_empty() && depth >= BASIS_DEPTH || settled || depth >= MAX_DEPTH {
            let mut m = [0.0; MAX_NB];
            self.polygon(rect, &sub, Rays::Among(&self.lists[own.clone()]), &mut m[..out.len()], across);
            for (o, m) in out.iter_mut().zip(m) {
                *o += m;
            }
        } else {
            for q in rect.quadrants() {
                let across = across.as_mut().map(|(b, w)| (*b, &mut **w));
                self.rect(&q, depth + 1, own.clone(), out, across);
            }
        }
        if pushed {
            self.lists.truncate(own.start);
        }
    }

    /// The candidates of the part `sub` out of its parent's `candidates`: a range of `lists`,
    /// and whether it was pushed onto them (to be dropped after the part).
    fn narrow(&mut self, sub: &Patch, candidates: Range<usize>) -> (Range<usize>, bool) {
        let Some(o) = self.gather.inputs.occluders else { return (candidates, false) };
        if candidates.is_empty() {
            return (candidates, false);
        }
        let start = self.lists.len();
        if candidates.len() > NARROW_MAX {
            let (rx, face) = (self.rx, self.src.face);
            o.point_candidates(rx.x, rx.n, (rx.face, face), &sub.bounds(), self.query);
            Counters::add(&self.gather.counters.shafts, 1);
            self.lists.extend_from_slice(self.query);
        } else {
            let shaft = o.point_shaft(self.rx.x, &sub.bounds());
            for k in candidates {
                let t = self.lists[k];
                if o.may_block(&shaft, t) {
                    self.lists.push(t);
                }
            }
        }
        (start..self.lists.len(), true)
    }

    /// Writes the moments of `rect` (`sub` of the source) taken as a polygon to `out`: its exact
    /// form factor from the point, shared out over the basis (and the `rays`) by its Gauss
    /// nodes' kernel.
    fn polygon(&self, rect: &Rect, sub: &Patch, rays: Rays, out: &mut [f64], ball: Option<(Ball, &mut f64)>) {
        let (g, rx) = (self.gather, self.rx);
        let f = polygon::form_factor(rx.x, rx.n, &sub.corners, sub.centre_normal());
        if f <= 0.0 {
            return;
        }
        let mut inside = 0.0;
        let split = ball.as_ref().map(|(b, _)| (b.radius, &mut inside));
        let unoccluded = g.gauss_split(rx, self.src, rect, &g.rule, rays, out, split);
        // (With no node in front the part is a sliver at the point's horizon: taken as seen.)
        super::rank::scale_to(out, unoccluded, f);
        if let Some((_, weight)) = ball
            && unoccluded > 0.0
        {
            *weight += inside * f / unoccluded;
        }
    }
}
