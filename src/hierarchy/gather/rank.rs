//! Which of a point's sources get rays from the point, and how many ([`super::Mode::Fast`]).
//!
//! Every source is first valued without rays: the light it would bring to the point unoccluded
//! (a near surface by its exact polygon form factor shared out by its Gauss nodes, a far one by
//! the Gauss rule, a cluster by its intensity lobes), ranked by its form factor times its mean
//! radiosity (a cluster by that light). Then from the brightest down:
//! - while what the rest could bring unoccluded is more than [`ESTIMATED_SHARE`] of the point's
//!   light (theirs plus the lights' direct), and always for a source the point touches, each
//!   source is cast from the point in full: a near one by [`super::near`], feet and all, a far
//!   one as the exhaustive gather takes it whole ([`super::far`]);
//! - past that, a surface takes one Gauss sum with a ray per node through the BVH, without
//!   splitting (a near one's scaled to its exact polygon form factor); once what is left brings
//!   no light at all, a surface takes one ray to its centre, for its form factor; a cluster
//!   takes its intensity times its link's transmittance where the link's rays all arrived or
//!   were all blocked, and the point's own where they were mixed ([`Gather::dim_cluster`]).
//!
//! The rays go where the light is: on a mesh most of a corner's hundreds of sources are dim
//! neighbours, and each of them was a shaft query and up to twelve levels of splitting in the
//! exhaustive gather.
//!
//! The tail keeps a ray per Gauss node: its share is of the sources' unoccluded light, and where
//! most of that is hidden (a corner inside a room) the tail's visibility is much of what the
//! corner receives. Measured on the decimated monastery (fast against exhaustive 0.95% RMS): the
//! tail unoccluded 13.9%, from its links as the solve took it (the receiving node's `H`
//! polynomial of each link read at the corner, no rays) 9.1%, one ray to each source's centre
//! 1.60%, one ray for the last 1% of the ranked light 1.40%. On a 10k-face crop of the monastery its sources take under two rays each,
//! and one a source saved 5.5% of the rays (docs/benchmarks.md, "The hierarchy's corner gather
//! at scale").

use super::kept::{How, Memo, Slot};
use super::polygon;
use super::sources::Linked;
use super::surface::{Rays, Source};
use super::{Counters, Gather, Received, Receiver};
use crate::basis::MAX_LEN as MAX_NB;
use crate::gather::behind_plane;
use crate::geometry::Rect;
use crate::hierarchy::tree::NodeId;
use crate::solids::Solids;

/// The share of a point's light (its sources' unoccluded, ranked as [`Ranked::weight`], and the
/// lights' direct) that the sources taken coarsely may bring at most.
const ESTIMATED_SHARE: f64 = 0.1;

/// A source of a point valued without rays.
pub(super) struct Ranked {
    linked: Linked,
    /// Its place among the point's kept values.
    slot: Slot,
    /// A surface near the point ([`super::NEAR_RATIO`]): cast by [`super::near`].
    near: bool,
    /// A near surface the point touches: always cast (with its foot).
    touched: bool,
    /// The ranking: the form factor times the mean radiosity, summed over the channels (a
    /// cluster's unoccluded light).
    weight: f64,
    /// A cluster's unoccluded light `H` at the point.
    cluster_light: [f64; 3],
    /// A surface's unoccluded form factor.
    form_factor: f64,
}

impl Gather<'_> {
    /// The source `linked` of the point valued, `None` when it can bring nothing.
    pub(super) fn rank(&self, rx: &Receiver, linked: Linked, feet: bool, memo: &mut Memo) -> Option<Ranked> {
        let tree = self.inputs.tree;
        let node = tree.node(linked.source);
        let Some(s) = node.surface() else {
            let (_, slot) = memo.listed(linked.source, || [0.0; 2]);
            let light = self.cluster_light(rx, linked.source);
            let weight = light.iter().sum();
            return (weight > 0.0).then_some(Ranked {
                linked,
                slot,
                near: false,
                touched: false,
                weight,
                cluster_light: light,
                form_factor: 0.0,
            });
        };
        // The unoccluded form factor, and what the source is to the point: behind its plane
        // (-1), else near (1) and touched (2) added.
        let ([form_factor, what], slot) = memo.listed(linked.source, || {
            if behind_plane(rx.x, rx.n, &s.patch, node.radius) {
                return [0.0, -1.0];
            }
            let near = self.is_near(rx, linked.source);
            // A source the point touches takes its part next to the point from the foot,
            // however dark its own polynomial (a sliver the solve barely lights).
            let touched = near && feet && self.touch(rx, node.radius, s).is_some();
            let m = self.whole(rx, linked.source, near, Rays::Among(&[]));
            [m[0], f64::from(u8::from(near) + 2 * u8::from(touched))]
        });
        if what < 0.0 {
            return None;
        }
        let (near, touched) = (what % 2.0 == 1.0, what >= 2.0);
        // The ranking by the form factor times the mean radiosity: the moments' light can come
        // out negative where the nodes share a near source's form factor out badly.
        let weight = form_factor * self.inputs.state.mean[linked.source as usize].iter().sum::<f64>();
        (weight > 0.0 || form_factor > 0.0 || touched).then_some(Ranked {
            linked,
            slot,
            near,
            touched,
            weight,
            cluster_light: [0.0; 3],
            form_factor,
        })
    }

    /// The surface node `source`'s moments at the point by one Gauss sum with `rays`, and
    /// `near` the point, scaled to the exact polygon form factor (next to the point the Gauss
    /// nodes miss most of the kernel; they only share it out): unoccluded for the ranking, with
    /// rays through the BVH for a coarse cast.
    fn whole(&self, rx: &Receiver, source: NodeId, near: bool, rays: Rays) -> [f64; MAX_NB] {
        let tree = self.inputs.tree;
        let s = tree.node(source).surface().expect("a surface");
        let nb = tree.basis.len();
        let mut m = [0.0; MAX_NB];
        let src = Source { face: s.face, patch: &s.patch };
        let rule = if near { &self.rule } else { &self.far_rule };
        let sum = self.gauss(rx, src, &Rect::UNIT, rule, rays, &mut m[..nb]);
        if near {
            let f = polygon::form_factor(rx.x, rx.n, &s.patch.corners, s.normal);
            scale_to(&mut m[..nb], sum, f);
        }
        m
    }

    /// Adds the surface source `source`'s light at the point to `got` by one Gauss sum with rays
    /// through the BVH, scaled to the exact form factor when `near`.
    fn coarse_cast(
        &self,
        rx: &Receiver,
        (source, slot): (NodeId, Slot),
        near: bool,
        got: &mut Received,
        memo: &mut Memo,
    ) {
        let nb = self.inputs.tree.basis.len();
        let how = if near { How::CoarseNear } else { How::Coarse };
        let m = memo
            .values(slot, source, how, |m| m.copy_from_slice(&self.whole(rx, source, near, Rays::Bvh)[..nb]));
        got.add(self.light(source, &m[..nb]), m[0]);
    }

    /// Adds the sources' light to `got` (see the module's comment): cast from the point in full
    /// for the brightest ones until the rest could bring at most [`ESTIMATED_SHARE`] of the
    /// point's light (theirs unoccluded plus `direct`, summed over the channels), the rest
    /// coarsely.
    pub(super) fn settle(
        &self,
        rx: &Receiver,
        ranked: &[Ranked],
        direct: f64,
        feet: Option<Option<&Solids>>,
        got: &mut Received,
        memo: &mut Memo,
    ) {
        let tree = self.inputs.tree;
        let mut rest: f64 = ranked.iter().map(|r| r.weight).sum();
        let bar = ESTIMATED_SHARE * (direct + rest);
        // The brightest first, ties in the order listed: sorted by key, not moving the sources
        // (sorting them was 8% of an updated frame's gather on the moving-light box).
        let mut order = ORDER.take();
        order.clear();
        order.extend(ranked.iter().enumerate().map(|(k, r)| (r.weight, k as u32)));
        order.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        for &(_, k) in &order {
            let r = &ranked[k as usize];
            let source = r.linked.source;
            // (Without visibility there are no rays to save: every source is integrated.)
            if r.touched || rest > bar || self.inputs.occluders.is_none() {
                if r.near {
                    Counters::add(&self.counters.near, 1);
                    self.surface_source(rx, (source, r.slot), feet, got, memo);
                } else {
                    Counters::add(&self.counters.far_cast, 1);
                    self.far_cast(rx, (source, r.slot), got, memo);
                }
                if self.stop.stopped() {
                    return;
                }
            } else if tree.node(source).is_cluster() {
                Counters::add(&self.counters.coarse, 1);
                got.add(self.dim_cluster(rx, (r.linked, r.slot), r.cluster_light, memo), 0.0);
            } else if rest <= 0.0 {
                // Nothing left brings light: one ray for the form factor (the hemisphere bound).
                Counters::add(&self.counters.coarse, 1);
                let s = tree.node(source).surface().expect("a surface");
                let mut seen = [true];
                if let Some(o) = self.inputs.occluders {
                    Counters::add(&self.counters.rays, 1);
                    o.visible_from(rx.x, (rx.face, s.face), &[s.patch.point(0.5, 0.5)], &mut seen);
                }
                if seen[0] {
                    let m = self.whole(rx, source, r.near, Rays::Among(&[]));
                    got.add(self.light(source, &m[..tree.basis.len()]), r.form_factor);
                }
            } else {
                Counters::add(&self.counters.coarse, 1);
                self.coarse_cast(rx, (source, r.slot), r.near, got, memo);
            }
            rest -= r.weight;
        }
        ORDER.set(order);
    }
}

thread_local! {
    /// [`Gather::settle`]'s order of the sources, kept for the thread's next point.
    static ORDER: std::cell::Cell<Vec<(f64, u32)>> = const { std::cell::Cell::new(Vec::new()) };
}

/// Moments `m` of a Gauss sum whose unoccluded `integral g dA` came to `sum`, scaled to the exact
/// form factor `f`; when no node counted (all behind the point's plane while part of the polygon
/// is in front), `f` on the constant alone.
pub(super) fn scale_to(m: &mut [f64], sum: f64, f: f64) {
    if sum > 0.0 {
        m.iter_mut().for_each(|m| *m *= f / sum);
    } else {
        m.fill(0.0);
        m[0] = f;
    }
}
