//! The refinement oracle: its verdict on one pair of nodes (link it as it stands, split an end,
//! or skip it), how much of an accepted link to compute, how a computed pair is filed, and how
//! near a kept pair comes to being split (its load). The rules are those [`super`] describes.

use crate::hierarchy::coupling::{self, Weight};
use crate::hierarchy::tree::{Kind, NodeId, Tree};

/// What the oracle needs to know.
pub struct Oracle {
    /// Largest power a link may carry unrefined (W).
    pub threshold: f64,
    /// Surfaces are not split below this area, nor deeper than `max_depth` below their face.
    pub min_area: f64,
    pub max_depth: u32,
    /// Whether links may end at clusters (off: every link is between two surfaces, for tests).
    pub clusters: bool,
    /// Cluster links need their bounding spheres this many radii-sums apart
    /// ([`crate::hierarchy::HierarchySettings::cluster_separation`]).
    pub cluster_separation: f64,
    /// Surface links that carry at most [`coupling::LIGHT_SHARE`] of the threshold are made
    /// light ([`crate::hierarchy::HierarchySettings::light_links`]).
    pub light_links: bool,
}

/// Partially visible links, and pairs whose sampled rays were all blocked, are split while they
/// can carry more than this share of the threshold.
const PARTIAL_SHARE: f64 = 0.25;

/// How a computed pair is filed ([`Oracle::filing`]).
pub(super) enum Filing {
    /// A shadow boundary crosses the pair (some rays pass), or may (none does: a few rays cannot
    /// show that the pair is wholly hidden), and the pair may carry enough to matter.
    SplitForShadows,
    /// Kept as computed, with this load ([`Oracle::load`], [`Oracle::blocked_load`]).
    Load(f32),
}

/// The decision for one pair.
pub(super) enum Verdict {
    Skip,
    Link,
    Split(NodeId),
}

impl Oracle {
    /// The oracle would link the pair `(a, b)` as it stands with `radiosity` per node: what an
    /// update asks of a pair above links a move touched before it refines it again coarser
    /// ([`crate::hierarchy::pair_tree::Splits::coarsest_touched`]).
    pub fn links_whole(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId) -> bool {
        a != b && matches!(self.decide(tree, radiosity, a, b, self.threshold), Verdict::Link)
    }

    /// How near the link between `a` and `b` (`light`: a light link) comes at `radiosity` to
    /// failing the test that made it: the largest of its power over the threshold (none when
    /// neither end can split: that link stands whatever it carries) and, for a light link, its
    /// power over a light link's limit. Each is linear in either end's brightness, so the test
    /// can fail later only where this times the growth of an end's brightness exceeds 1.
    /// Rounded up a little, so that the `f32` never understates it.
    pub fn load(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId, light: bool) -> f32 {
        let bar = self.threshold;
        let split = if self.splittable(tree, a) || self.splittable(tree, b) {
            self.pair_carried(tree, radiosity, a, b) / bar
        } else {
            0.0
        };
        let heavy =
            if light { self.pair_power(tree, radiosity, a, b) / (coupling::LIGHT_SHARE * bar) } else { 0.0 };
        let load = split.max(heavy) * (1.0 + 1e-6);
        if load.is_finite() { load as f32 } else { f32::INFINITY }
    }

    /// What [`Oracle::load`] is for a link, for a pair none of whose rays passed: how near it
    /// comes at `radiosity` to [`Oracle::may_carry_much`], which splits it.
    pub fn blocked_load(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId) -> f32 {
        if !(self.splittable(tree, a) || self.splittable(tree, b)) {
            return 0.0;
        }
        let load = self.pair_power(tree, radiosity, a, b) / (PARTIAL_SHARE * self.threshold) * (1.0 + 1e-6);
        if load.is_finite() { load as f32 } else { f32::INFINITY }
    }

    /// The two oracles decide alike but for their thresholds (which
    /// [`Hierarchy::decided_at`](super::Hierarchy::decided_at) is relative to).
    pub fn same_rules(&self, other: &Oracle) -> bool {
        let rules = |o: &Oracle| (o.min_area, o.max_depth, o.clusters, o.cluster_separation, o.light_links);
        rules(self) == rules(other)
    }

    pub(super) fn splittable(&self, tree: &Tree, id: NodeId) -> bool {
        match &tree.node(id).kind {
            Kind::Cluster { .. } => true,
            Kind::Surface(s) => s.depth < self.max_depth && tree.node(id).area > 4.0 * self.min_area,
        }
    }

    /// The error an unrefined link from `q` into `p` may make, with `radiosity[q]` the current
    /// estimate of `q`'s mean radiosity (largest channel): the power it carries,
    /// `rho_p B_q A_p F`, with `F` the form factor of a facing disc of `q`'s area at the centres'
    /// distance, `A_q cos_p cos_q / (pi d^2 + A_q)` (at most 1, finite at contact; the cosines
    /// bounded over the spheres), times how far a polynomial of the basis order can be off over
    /// the pair, `min(1, ((r_p + r_q) / d)^(order + 1))`.
    fn carried(&self, tree: &Tree, radiosity: &[f64], p: NodeId, q: NodeId) -> f64 {
        self.carried_as(tree, radiosity, p, q, true)
    }

    /// [`Oracle::carried`], the smoothness factor left out unless `smooth`: across a shadow
    /// boundary the transfer is not smooth, and a link's error is up to all it carries.
    fn carried_as(&self, tree: &Tree, radiosity: &[f64], p: NodeId, q: NodeId, smooth: bool) -> f64 {
        let (np, nq) = (tree.node(p), tree.node(q));
        let b = radiosity[q as usize];
        if b <= 0.0 || np.rho_max <= 0.0 {
            return 0.0;
        }
        let v = nq.centre - np.centre;
        let d = v.length().max(1e-300);
        let reach = np.radius + nq.radius;
        let sin = (reach / d).min(1.0);
        let cos_bound = |id: NodeId, towards: glam::DVec3| match &tree.node(id).kind {
            Kind::Surface(s) => (s.normal.dot(towards) / d + sin).clamp(0.0, 1.0),
            Kind::Cluster { .. } => 1.0,
        };
        let (cp, cq) = (cos_bound(p, v), cos_bound(q, -v));
        let f = nq.area * cp * cq / (std::f64::consts::PI * d * d + nq.area);
        // A cluster's transfer from the centres is off by the spread of `1/r^2` over the pair,
        // `~ ((r_p + r_q) / d)^2`; a surface pair's polynomials by the kernel's next order.
        let power = if np.is_cluster() || nq.is_cluster() { 2 } else { tree.basis.order() as i32 + 1 };
        let smoothness = if smooth { sin.powi(power) } else { 1.0 };
        np.rho_max * b * np.area * f * smoothness
    }

    fn pair_carried(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId) -> f64 {
        self.carried(tree, radiosity, a, b).max(self.carried(tree, radiosity, b, a))
    }

    /// The power a pair carries at most, without the smoothness factor (a partly visible pair).
    fn pair_power(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId) -> f64 {
        self.carried_as(tree, radiosity, a, b, false).max(self.carried_as(tree, radiosity, b, a, false))
    }

    /// How much of the accepted link between `a` and `b` to compute: light when both are
    /// surfaces and all it can carry is a small share of the threshold.
    pub(super) fn weight(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId) -> Weight {
        let surfaces = !tree.node(a).is_cluster() && !tree.node(b).is_cluster();
        if self.light_links
            && surfaces
            && self.pair_power(tree, radiosity, a, b) <= coupling::LIGHT_SHARE * self.threshold
        {
            Weight::Light
        } else {
            Weight::Full
        }
    }

    /// The pair may carry more than [`PARTIAL_SHARE`] of the threshold and can be split: a
    /// shadow boundary across it is worth following down. So is one none of whose sampled rays
    /// passed: a light link's few segments, or a mask's cells, all blocked do not show that the
    /// whole pair is hidden, and a hidden pair's light is dropped from the solve whole, so that
    /// error is one-signed and adds up over the scene.
    pub(super) fn may_carry_much(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId) -> bool {
        self.pair_power(tree, radiosity, a, b) > PARTIAL_SHARE * self.threshold
            && (self.splittable(tree, a) || self.splittable(tree, b))
    }

    /// How [`Hierarchy::take_computed`](super::Hierarchy::take_computed) files the computed pair
    /// `(a, b)`, worked out beside the computation (in parallel; the filing's own reads were a
    /// tenth of the link phase's serial part on the full monastery): split further when a
    /// shadow boundary crosses it, or may, and it may carry much; else kept with its load (a
    /// link's, a hidden pair's; unused for a pair that exchanges nothing). The two ends and
    /// their estimates are what a split elsewhere leaves as they are, so this is what the
    /// filing read itself.
    pub(super) fn filing(
        &self,
        tree: &Tree,
        radiosity: &[f64],
        a: NodeId,
        b: NodeId,
        c: &coupling::Computed,
    ) -> Filing {
        if (c.partial || c.blocked) && self.may_carry_much(tree, radiosity, a, b) {
            return Filing::SplitForShadows;
        }
        Filing::Load(match &c.coupling {
            Some(coupling) => {
                let light = matches!(coupling, coupling::Coupling::Constants { .. });
                self.load(tree, radiosity, a, b, light)
            }
            None if c.blocked => self.blocked_load(tree, radiosity, a, b),
            None => 0.0,
        })
    }

    pub(super) fn decide(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId, bar: f64) -> Verdict {
        let (na, nb) = (tree.node(a), tree.node(b));
        if let (Some(sa), Some(sb)) = (na.surface(), nb.surface())
            && sa.face == sb.face
        {
            return Verdict::Skip;
        }
        // A surface exchanges nothing with what lies wholly behind its plane.
        let behind = |s: NodeId, o: NodeId| {
            tree.node(s).surface().is_some_and(|x| {
                x.normal.dot(tree.node(o).centre - x.patch.point(0.5, 0.5)) < -tree.node(o).radius
            })
        };
        if behind(a, b) || behind(b, a) {
            return Verdict::Skip;
        }
        // A surface split ahead for a contact is linked through its parts only.
        for x in [a, b] {
            if tree.opened(x) {
                return Verdict::Split(x);
            }
        }
        let separated = na.centre.distance(nb.centre) > self.cluster_separation * (na.radius + nb.radius);
        let clustered = na.is_cluster() || nb.is_cluster();
        let carried = self.pair_carried(tree, radiosity, a, b);
        let small = carried <= bar && (self.clusters || !clustered);
        // A cluster link needs its spheres apart for its centres' transfer to hold. (Letting
        // negligible links join clusters closer than that, with the transfer bounded by
        // `1/max(d, r_p + r_q)^2`, made the decimated monastery 20x faster and 32% too dark:
        // many small links, each underestimated. With the sampled kernel ratio of
        // `coupling::transmittance` the mean holds at 1.5 radii-sums, but not the closed box's
        // balance: docs/method.md, "How near a cluster may link".)
        if small && (separated || !clustered) {
            return Verdict::Link;
        }
        if small {
            // Light enough, only too near for a cluster's transfer: open the cluster (the
            // larger, when both are), not the surface, whose polynomial carries this well.
            return Verdict::Split(match (na.is_cluster(), nb.is_cluster()) {
                (true, true) if nb.radius > na.radius => b,
                (true, _) => a,
                _ => b,
            });
        }
        let (ca, cb) = (self.splittable(tree, a), self.splittable(tree, b));
        match (ca, cb) {
            (false, false) => Verdict::Link,
            (true, false) => Verdict::Split(a),
            (false, true) => Verdict::Split(b),
            (true, true) => Verdict::Split(if na.radius >= nb.radius { a } else { b }),
        }
    }
}
