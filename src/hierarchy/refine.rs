//! The refinement oracle and the link hierarchy it builds (Hanrahan, Salzman and Aupperle 1991,
//! BF refinement; Smits, Arvo and Greenberg 1994 for clusters).
//!
//! A pair of nodes is linked as it stands when the energy it can carry is small, `rho_p B_q A_p
//! min(1, F_pq^upper)` in either direction below the threshold (`accuracy` x the emitted power),
//! with `F^upper = A_q cos_p^upper cos_q^upper / (pi d_min^2)` from the bounding spheres; otherwise
//! the larger node that can split is split and its children are paired with the other. A cluster
//! link also needs its two spheres apart (its transfer uses the centres' distance), and a link
//! through which some rays pass and some do not (a shadow boundary) is split further while it can
//! carry more than a quarter of the threshold; so is a pair none of whose rays passes (a few
//! rays cannot show that a pair carrying that much is wholly hidden). After each solve the links
//! and the hidden pairs are tested again with the new radiosities (brightness decides where
//! refinement pays), and split where they fail.

use rayon::prelude::*;

pub use super::coupling::Link;
use super::coupling::{self, LinkContext, Weight};
use crate::budget;
use crate::error::Result;

/// What [`budget`]'s errors name.
const LINKS: &str = "the hierarchy's links";
const NODES: &str = "the hierarchy's nodes";
use super::packed::{LinkChanges, PackedLinks};
use super::pair_tree::Splits;
use super::tree::{Kind, NodeId, Tree};

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
    /// ([`super::HierarchySettings::cluster_separation`]).
    pub cluster_separation: f64,
    /// Surface links that carry at most [`coupling::LIGHT_SHARE`] of the threshold are made
    /// light ([`super::HierarchySettings::light_links`]).
    pub light_links: bool,
}

/// Hears the share of a batch of links computed (0 to 1); `false` cancels the refinement.
pub type LinkProgress<'a> = &'a (dyn Fn(f64) -> bool + Sync);

/// Links computed between two progress reports: a few hundred ms on two cores for the costliest
/// (near, partly visible) pairs, far less than a sweep for the usual ones.
const LINK_CHUNK: usize = 4096;

/// Accepted pairs decided before they are computed: a bound on the refinement's own memory.
const BATCH: usize = 1 << 20;

/// Pairs taken off the work stack and decided at once, in parallel.
const DECIDE_CHUNK: usize = 1 << 14;

/// How much work a pair of nodes stands for: the refinement's progress is the share of its
/// work's estimated links settled (linked, blocked or idle). A pair's estimate only divides its
/// parent's share among the pairs a split makes of it ([`PairSpace::divide`]), so the shares add
/// up to the work's total: the progress grows and ends at 1 whatever the estimates are, and
/// better estimates only make it more even in time.
///
/// The links are what the time goes into, and they grow about linearly in the faces, not as
/// their pairs: a cluster's own pair of `n` faces is taken to make `n (log2 2n)^(1/4)` of them; a
/// pair of two nodes one link when far, up to `n_a + n_b` (each end's faces that lie before the
/// other's plane, when it is a surface) when their spheres touch, falling as the sixth power of
/// their radii-sum over their distance; a pair the oracle will skip (one face, or wholly behind
/// a surface) a decision, [`SKIPPED`]. (The powers were fitted on the monastery's parts.)
/// Counted in pairs of faces, the high, far pairs between a cluster's children, half the pairs of
/// faces and one link each, moved the progress as much as all the links below them: the
/// 30k-triangle monastery's first link round said 47% at a tenth of its time and 80% at half;
/// now 11-12% and 55-58% (docs/benchmarks.md, "Progress: the time left"; tests/link_progress.rs).
/// Only the progress: the stack's order, the verdicts and the links are as they were.
struct PairSpace {
    /// Faces below each cluster present when the refinement starts (the nodes it adds are
    /// surfaces).
    faces: Vec<f64>,
}

impl PairSpace {
    fn new(tree: &Tree) -> Self {
        let mut faces = vec![0.0; tree.nodes.len()];
        // Children come before their parents in the node list: clusters are appended above
        // their members, quadrants after their face.
        for (id, node) in tree.nodes.iter().enumerate() {
            faces[id] = match &node.kind {
                Kind::Cluster { children } => children.iter().map(|&c| faces[c as usize]).sum(),
                Kind::Surface(_) => 1.0,
            };
        }
        Self { faces }
    }

    /// The links the pair `(a, b)` is expected to make (the node's own when `a == b`).
    fn links(&self, tree: &Tree, a: NodeId, b: NodeId) -> f64 {
        let (x, y) = (tree.node(a), tree.node(b));
        let faces = |id: NodeId, node: &super::tree::Node| match node.kind {
            Kind::Surface(_) => 1.0,
            Kind::Cluster { .. } => self.faces.get(id as usize).map_or(1.0, |&n| n.max(1.0)),
        };
        let (na, nb) = (faces(a, x), faces(b, y));
        if a == b {
            return na * (2.0 * na).log2().sqrt().sqrt();
        }
        // A surface sees only what lies before its plane: of the other node's sphere, this
        // share (the oracle skips a pair wholly behind, or of one face: a decision, no link).
        let before = |s: &super::tree::Node, o: &super::tree::Node| match &s.kind {
            Kind::Surface(f) if o.radius > 0.0 => {
                ((f.normal.dot(o.centre - s.centre) + o.radius) / (2.0 * o.radius)).clamp(0.0, 1.0)
            }
            _ => 1.0,
        };
        let (fa, fb) = (before(y, x), before(x, y));
        let one_face = matches!((x.surface(), y.surface()), (Some(p), Some(q)) if p.face == q.face);
        if one_face || fa == 0.0 || fb == 0.0 {
            return SKIPPED;
        }
        // (Two surfaces, the most of the pairs: one link or a split's few.)
        if na * nb <= 1.0 {
            return 1.0;
        }
        let reach = x.radius + y.radius;
        let d2 = x.centre.distance_squared(y.centre);
        let near = if d2 > reach * reach { (reach * reach / d2).powi(3) } else { 1.0 };
        (1.0 + (na * fa + nb * fb) * near).min(na * nb)
    }

    /// Divides the share `of` of the pair `parent` among the pairs `new` a split made of it, by
    /// their expected links: equally when the parent is two surfaces (its parts are alike, about
    /// a link each, and their nodes need not be read). Returns the share settled: all of it
    /// when the split made no pairs.
    fn divide(
        &self,
        tree: &Tree,
        of: f64,
        pair: (NodeId, NodeId),
        new: &[(NodeId, NodeId)],
        shares: &mut Vec<f64>,
    ) -> Result<f64> {
        budget::try_reserve(shares, new.len(), NODES)?;
        Ok(self.divide_in(tree, of, pair, new, shares))
    }

    /// [`PairSpace::divide`] without asking the budget for room (a [`Descent`]'s own short
    /// list, a few shares).
    fn divide_in(
        &self,
        tree: &Tree,
        of: f64,
        (a, b): (NodeId, NodeId),
        new: &[(NodeId, NodeId)],
        shares: &mut Vec<f64>,
    ) -> f64 {
        if new.is_empty() {
            return of;
        }
        let start = shares.len();
        if !tree.node(a).is_cluster() && !tree.node(b).is_cluster() {
            shares.resize(start + new.len(), of / new.len() as f64);
            return 0.0;
        }
        shares.extend(new.iter().map(|&(a, b)| self.links(tree, a, b)));
        let sum: f64 = shares[start..].iter().sum();
        if sum > 0.0 && sum.is_finite() {
            shares[start..].iter_mut().for_each(|x| *x *= of / sum);
        } else {
            shares[start..].iter_mut().for_each(|x| *x = of / new.len() as f64);
        }
        0.0
    }
}

/// What [`Descent::of`] reads: the tree and the estimates as they stand when a chunk of the
/// work stack is decided.
struct Deciding<'a> {
    tree: &'a Tree,
    oracle: &'a Oracle,
    space: &'a PairSpace,
    radiosity: &'a [f64],
    stores_idle: bool,
}

/// A decision for the serial loop of [`Hierarchy::refine_pairs`] to file, in order.
enum Decided {
    /// The pair `(a, b)` was split at `s`, whose children exist (the pair tree's record).
    Split(NodeId, NodeId, NodeId),
    /// The pair carries nothing and is kept as idle.
    Idle(NodeId, NodeId),
    /// The pair is to be linked as it stands, with its share of the work.
    Link(NodeId, NodeId, Weight, f64),
    /// The pair is to be split at the surface leaf `s`: new nodes, which the serial loop makes.
    SplitLeaf(NodeId, NodeId, NodeId, f64),
    /// The pair is left on the work stack, undecided, with its share.
    Open(NodeId, NodeId, f64),
}

/// One pair taken off the work stack, decided with the pairs its splits make, depth first,
/// while they need no new node (the split end is a cluster or a surface split already), at
/// most [`DESCENT`] decisions. Before, every pair a split made went back on the stack and was
/// decided in a later round, its split filed by the serial loop: on a 30k-triangle crop of the
/// monastery over 16M splits of a cluster, whose filing (the progress estimates of the pairs
/// made, [`PairSpace::links`], reading both nodes) was most of the link phase's serial part.
/// Each pair is decided as it would be alone (a verdict reads the two nodes and their
/// estimates, which a split elsewhere does not change), and the whole is the same for every
/// thread count. (Not the links of when each split went back on the stack: the surfaces'
/// quadtree nodes are made in another order, and their ids seed a cluster link's rays.)
struct Descent {
    decided: Vec<Decided>,
    /// The work's share settled by the decisions (skipped pairs, and splits that made no pairs).
    settled: f64,
    /// The pairs left [`Decided::Open`].
    open: usize,
}

/// The most decisions one [`Descent`] makes: enough that a descent's filing is a copy, few
/// enough that the top of the refinement (one pair, the root's with itself) spreads over the
/// threads within a few rounds.
const DESCENT: usize = 64;

impl Descent {
    fn of(d: &Deciding, pair: (NodeId, NodeId), share: f64) -> Self {
        let (tree, bar) = (d.tree, d.oracle.threshold);
        let mut out = Descent { decided: Vec::new(), settled: 0.0, open: 0 };
        // The pairs still to decide and their shares, a stack as the work is: the same order.
        let (mut stack, mut shares) = (vec![pair], vec![share]);
        let mut decisions = 0;
        while let Some((a, b)) = stack.pop() {
            let share = shares.pop().expect("a share per pair");
            if decisions == DESCENT {
                // The rest back on the work stack, bottom first, so that it pops as here.
                stack.push((a, b));
                shares.push(share);
                out.open = stack.len();
                for (&(a, b), &share) in stack.iter().zip(&shares) {
                    out.decided.push(Decided::Open(a, b, share));
                }
                break;
            }
            decisions += 1;
            let pushed = stack.len();
            if a == b {
                // A cluster's light among its own parts; a surface does not light itself (its
                // parts are one face: nothing to record).
                if tree.node(a).is_cluster() {
                    out.decided.push(Decided::Split(a, a, a));
                }
                let children = tree.children(a);
                for (i, &x) in children.iter().enumerate() {
                    stack.extend(children[i..].iter().map(|&y| (x, y)));
                }
                out.settled += d.space.divide_in(tree, share, (a, b), &stack[pushed..], &mut shares);
                continue;
            }
            match d.oracle.decide(tree, d.radiosity, a, b, bar) {
                Verdict::Skip => {
                    out.settled += share;
                    if d.stores_idle && !same_face(tree, a, b) {
                        out.decided.push(Decided::Idle(a, b));
                    }
                }
                Verdict::Link => {
                    let weight = d.oracle.weight(tree, d.radiosity, a, b);
                    out.decided.push(Decided::Link(a, b, weight, share));
                }
                Verdict::Split(s) if tree.children(s).is_empty() => {
                    out.decided.push(Decided::SplitLeaf(a, b, s, share));
                }
                Verdict::Split(s) => {
                    out.decided.push(Decided::Split(a, b, s));
                    let other = if s == a { b } else { a };
                    stack.extend(tree.children(s).iter().map(|&c| (c, other)));
                    out.settled += d.space.divide_in(tree, share, (a, b), &stack[pushed..], &mut shares);
                }
            }
        }
        out
    }
}

/// Whether `a` and `b` are parts of one face.
fn same_face(tree: &Tree, a: NodeId, b: NodeId) -> bool {
    matches!((tree.node(a).surface(), tree.node(b).surface()), (Some(x), Some(y)) if x.face == y.face)
}

/// What a pair the oracle skips costs (a decision) in links computed ([`PairSpace::links`]): a
/// decision took about a twentieth of a link's time on the monastery's parts.
const SKIPPED: f64 = 0.05;

/// A relink after which no node grew more than this many times brighter than its pairs were
/// decided at reads only their loads ([`Hierarchy::relink`]).
const QUICK_GROWTH: f64 = 2.0;

/// Partially visible links, and pairs whose sampled rays were all blocked, are split while they
/// can carry more than this share of the threshold.
const PARTIAL_SHARE: f64 = 0.25;

/// How a computed pair is filed ([`Oracle::filing`]).
enum Filing {
    /// A shadow boundary crosses the pair (some rays pass), or may (none does: a few rays cannot
    /// show that the pair is wholly hidden), and the pair may carry enough to matter.
    SplitForShadows,
    /// Kept as computed, with this load ([`Oracle::load`], [`Oracle::blocked_load`]).
    Load(f32),
}

/// The decision for one pair.
enum Verdict {
    Skip,
    Link,
    Split(NodeId),
}

impl Oracle {
    /// The oracle would link the pair `(a, b)` as it stands with `radiosity` per node: what an
    /// update asks of a pair above links a move touched before it refines it again coarser
    /// ([`super::pair_tree::Splits::coarsest_touched`]).
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

    /// The two oracles decide alike but for their thresholds (which [`Hierarchy::decided_at`]
    /// is relative to).
    pub fn same_rules(&self, other: &Oracle) -> bool {
        let rules = |o: &Oracle| (o.min_area, o.max_depth, o.clusters, o.cluster_separation, o.light_links);
        rules(self) == rules(other)
    }

    fn splittable(&self, tree: &Tree, id: NodeId) -> bool {
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
    fn weight(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId) -> Weight {
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
    fn may_carry_much(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId) -> bool {
        self.pair_power(tree, radiosity, a, b) > PARTIAL_SHARE * self.threshold
            && (self.splittable(tree, a) || self.splittable(tree, b))
    }

    /// How [`Hierarchy::take_computed`] files the computed pair `(a, b)`, worked out beside
    /// the computation (in parallel; the filing's own reads were a tenth of the link phase's
    /// serial part on the full monastery): split further when a shadow boundary crosses it, or
    /// may, and it may carry much; else kept with its load (a link's, a hidden pair's; unused
    /// for a pair that exchanges nothing). The two ends and their estimates are what a split
    /// elsewhere leaves as they are, so this is what the filing read itself.
    fn filing(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId, c: &coupling::Computed) -> Filing {
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

    fn decide(&self, tree: &Tree, radiosity: &[f64], a: NodeId, b: NodeId, bar: f64) -> Verdict {
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

/// The indices of `list`'s entries that `gone` says go, ascending (found in parallel).
fn indices_where<T: Sync>(list: &[T], gone: impl Fn(&T) -> bool + Sync) -> Vec<usize> {
    // In pieces, each a plain loop, as [`failing`]'s (by entry, a parallel iterator's
    // `filter_map`: the verdicts 15% slower on the 30k-triangle part's stores).
    list.par_chunks(PASS_CHUNK)
        .enumerate()
        .flat_map_iter(|(k, piece)| {
            let first = k * PASS_CHUNK;
            piece.iter().enumerate().filter(|(_, x)| gone(x)).map(move |(j, _)| first + j).collect::<Vec<_>>()
        })
        .collect()
}

/// Takes the entries at `gone` (ascending indices) out of `list`, keeping the others in order,
/// and hands each to `removed` first. The runs kept between them move down whole, a `memmove`
/// each: `Vec::retain` moved them entry by entry, 1.6x slower on 15M links and 1.8x on 43M
/// hidden pairs with one in 300 taken out (`cargo bench --bench stores`), and an update of the
/// full monastery compacts each store once or twice.
pub fn take_out<T>(list: &mut Vec<T>, gone: &[usize], mut removed: impl FnMut(&T)) {
    let Some(&first) = gone.first() else { return };
    let len = list.len();
    assert!(
        gone.windows(2).all(|w| w[0] < w[1]) && gone[gone.len() - 1] < len,
        "indices ascending, in range"
    );
    for &i in gone {
        removed(&list[i]);
    }
    // SAFETY: the length is cut to `first` before anything moves, so a panicking drop leaks
    // the rest instead of dropping an entry twice. Entry `gone[k]` is dropped before the run
    // after it moves down by `k + 1` onto `write`, which stays below `gone[k]`: no entry is
    // read after it was dropped or overwritten, and `ptr::copy` allows the runs to overlap.
    unsafe {
        list.set_len(first);
        let base = list.as_mut_ptr();
        let mut write = first;
        for (k, &i) in gone.iter().enumerate() {
            std::ptr::drop_in_place(base.add(i));
            let next = gone.get(k + 1).copied().unwrap_or(len);
            let run = next - i - 1;
            std::ptr::copy(base.add(i + 1), base.add(write), run);
            write += run;
        }
        list.set_len(write);
    }
}

/// Stored pairs a pass over a store takes in one piece of work ([`failing`], [`indices_where`]).
const PASS_CHUNK: usize = 4096;

/// The indices, ascending, of the pairs whose load is above `skip_at_most` and which `fails`
/// says fail (`fails(index, load)`, which may rewrite the load). In parallel pieces of
/// [`PASS_CHUNK`] loads, each first compared with `skip_at_most` all together (a loop the
/// compiler vectorises), a piece with none above it left whole: a quick relink finds a few
/// hundred loads above its bar among tens of millions. (The pass by pair, a parallel iterator's
/// `filter_map`, took 0.09 s for the full monastery's 43.5M hidden pairs' loads; the same loop
/// by pieces, 0.02-0.03 s, measured apart on as many loads.) A NaN load is above any bar.
fn failing(
    loads: &mut [f32],
    skip_at_most: f64,
    fails: impl Fn(usize, &mut f32) -> bool + Sync,
) -> Vec<usize> {
    loads
        .par_chunks_mut(PASS_CHUNK)
        .enumerate()
        .flat_map_iter(|(k, piece)| {
            let mut out = Vec::new();
            let above = |l: f32| l as f64 > skip_at_most || l.is_nan();
            if piece.iter().fold(false, |any, &l| any | above(l)) {
                let first = k * PASS_CHUNK;
                for (j, load) in piece.iter_mut().enumerate() {
                    if above(*load) && fails(first + j, load) {
                        out.push(first + j);
                    }
                }
            }
            out
        })
        .collect()
}

/// Links of a tree and the oracle that made them.
pub struct Hierarchy {
    pub tree: Tree,
    pub links: Vec<Link>,
    /// Per link, in `links`' order, how near it came to being split when it was decided
    /// ([`Oracle::load`]): with the growth of its ends' brightness since, what
    /// [`Hierarchy::relink`] needs to know whether to test it again. Apart from the links, so
    /// that a relink after which no node grew much reads 4 bytes a link, not the link.
    pub link_load: Vec<f32>,
    /// Pairs the oracle accepted whose sampled rays were all blocked ([`coupling::Computed`]):
    /// no link for the solve, sources the corner gather tries with its own rays.
    pub blocked: Vec<(NodeId, NodeId)>,
    /// Per blocked pair, in `blocked`'s order, what [`Hierarchy::link_load`] is to a link
    /// ([`Oracle::blocked_load`]); shorter than `blocked`: unknown, tested.
    pub blocked_load: Vec<f32>,
    /// Pairs of different faces that exchange nothing as they stand: one behind the other's
    /// plane, facing away, or no sample between them arriving. Kept so that a later frame in
    /// which they move can link them ([`super::update`]): with `links` and `blocked` they
    /// partition every pair of leaves of different faces ([`Hierarchy::idle_pairs`]). Stored
    /// only without the pair tree: with it, they are its leaves that are neither links nor
    /// blocked, and an update finds them there ([`super::touch::by_walk`]). (Stored, the full
    /// monastery's 53M idle pairs took 0.4 GB, and taking a move's out of them a tenth of an
    /// updated frame.) Nor for a scene in which nothing moves ([`super::HierarchySettings::moves`]).
    pub idle: Vec<(NodeId, NodeId)>,
    /// Whether `idle` is filled: neither with the pair tree kept nor in a still scene.
    pub stores_idle: bool,
    pub oracle: Oracle,
    /// The inner pairs of the refinement and where each was split, when kept for an animation's
    /// coarsening ([`super::pair_tree`]).
    pub splits: Splits,
    /// Per node, a brightness (radiosity estimate over the oracle's threshold) no higher than
    /// the one at which each link and blocked pair at the node was last decided;
    /// `NEG_INFINITY` (or no entry): unknown. [`Hierarchy::relink`] tests again only pairs with
    /// an end now brighter than this: the rest of a verdict is the pair's geometry, which only
    /// a move changes (and a move's pairs are linked again, [`super::update`]), and every test
    /// that splits a pair grows with either end's brightness ([`Oracle::carried_as`] is linear
    /// in it). Tested whole, the relink rounds were a third of an updated frame of the full
    /// monastery.
    pub decided_at: Vec<f64>,
    /// What changed in `links` since the solve last packed them, and that packing, kept from
    /// solve to solve and frame to frame ([`super::packed`]). Every change to `links` is
    /// recorded in `changes`.
    pub changes: LinkChanges,
    pub packed: Option<PackedLinks>,
    /// The casts of the cluster links this frame computed, for the next frame to take where a
    /// move cannot have changed them ([`coupling::Reuse`]); filled only while linking with a
    /// [`coupling::LinkContext::reuse`] (an animation's updated frames).
    pub casts: coupling::Casts,
}

/// Counts of one refinement.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RefineStats {
    pub links: usize,
    pub split_for_shadows: usize,
    pub relinked: usize,
    /// Links and blocked pairs [`Hierarchy::relink`] tested again (the others could not fail:
    /// [`Hierarchy::decided_at`]).
    pub tested: usize,
    /// The relink read only the pairs' loads: no node had grown more than [`QUICK_GROWTH`]
    /// times brighter.
    pub quick: bool,
    /// Wall seconds spent computing the accepted pairs' couplings (quadrature and visibility),
    /// apart from deciding and filing them: what the seed's series could replace at most.
    pub compute_seconds: f64,
    /// Cluster links whose cast was the last frame's ([`coupling::Reuse`]).
    pub reused_casts: usize,
}

impl Hierarchy {
    /// `moves`: something may move in a later frame ([`super::HierarchySettings::moves`]), so
    /// that the idle pairs must be known ([`Hierarchy::stores_idle`]).
    pub fn new(tree: Tree, oracle: Oracle, splits: Splits, moves: bool) -> Self {
        let (links, link_load, blocked, blocked_load) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let idle = Vec::new();
        let (changes, packed) = (LinkChanges::default(), None);
        Self {
            tree,
            links,
            link_load,
            blocked,
            blocked_load,
            stores_idle: moves && !splits.is_kept(),
            idle,
            oracle,
            splits,
            decided_at: Vec::new(),
            changes,
            packed,
            casts: coupling::Casts::default(),
        }
    }

    /// Records that every pair at every node was just decided at `radiosity` (or, for a node
    /// not `all`, that its new pairs were: it keeps the lower of its record and this), and that
    /// the nodes from `new_from` on are new, all their pairs decided now.
    fn note_decided(&mut self, radiosity: &[f64], new_from: usize, all: bool) {
        let bar = self.oracle.threshold;
        if !(bar > 0.0 && bar.is_finite()) {
            self.decided_at.clear();
            return;
        }
        let now = |i: usize| radiosity.get(i).map_or(f64::NEG_INFINITY, |&r| r / bar);
        let n = self.tree.nodes.len();
        self.decided_at.resize(new_from.min(n), f64::NEG_INFINITY);
        for (i, v) in self.decided_at.iter_mut().enumerate() {
            *v = if all { now(i) } else { v.min(now(i)) };
        }
        self.decided_at.extend((self.decided_at.len()..n).map(now));
    }

    /// Per node, how many times brighter it is now, at `radiosity`, than its pairs were decided
    /// at ([`Hierarchy::decided_at`]); infinite where that is unknown or was dark.
    fn growth(&self, radiosity: &[f64]) -> Vec<f64> {
        let bar = self.oracle.threshold;
        (0..self.tree.nodes.len())
            .map(|i| match (self.decided_at.get(i), radiosity.get(i)) {
                (_, Some(&r)) if r <= 0.0 => 0.0,
                (Some(&v), Some(&r)) if v > 0.0 => r / bar / v,
                _ => f64::INFINITY,
            })
            .collect()
    }

    /// Refines the node pairs of `work` into links, as [`Hierarchy::link_all`] refines the
    /// root's: what a later frame does with the pairs a move touched ([`super::update`]).
    pub fn link_pairs(
        &mut self,
        ctx: &LinkContext,
        radiosity: &mut Vec<f64>,
        work: Vec<(NodeId, NodeId)>,
        progress: LinkProgress,
    ) -> Result<RefineStats> {
        let mut stats = RefineStats::default();
        let before = self.tree.nodes.len();
        self.refine_pairs(ctx, radiosity, work, &mut stats, progress)?;
        self.note_decided(radiosity, before, false);
        stats.links = self.links.len();
        Ok(stats)
    }

    /// Takes out of the links, the blocked and the idle pairs every pair `touched` says a change
    /// may have altered, and returns them (as pairs, to be linked again), links first, each
    /// store in its order. The verdicts are taken in parallel: the stores hold tens of millions
    /// of pairs on a large model, and an update takes out a few thousand of them.
    pub fn take_touched(&mut self, touched: impl Fn(NodeId, NodeId) -> bool + Sync) -> Vec<(NodeId, NodeId)> {
        let mut out = Vec::new();
        let gone = indices_where(&self.links, |l| touched(l.a, l.b));
        self.take_links(&gone, |l| out.push((l.a, l.b)));
        let gone = indices_where(&self.blocked, |&(a, b)| touched(a, b));
        self.take_blocked(&gone, |&p| out.push(p));
        let gone = indices_where(&self.idle, |&(a, b)| touched(a, b));
        take_out(&mut self.idle, &gone, |&p| out.push(p));
        out
    }

    /// Takes the links at `gone` (ascending indices) out with their loads, each handed to
    /// `removed` first, and records it in [`Hierarchy::changes`].
    fn take_links(&mut self, gone: &[usize], removed: impl FnMut(&Link)) {
        self.changes.removing(&self.links, gone);
        take_out(&mut self.link_load, gone, |_| {});
        take_out(&mut self.links, gone, removed);
    }

    /// Takes the hidden pairs at `gone` (ascending indices) out with their loads (unknown ones
    /// made infinite first: [`Hierarchy::blocked_load`] may be shorter), each handed to
    /// `removed` first.
    fn take_blocked(&mut self, gone: &[usize], removed: impl FnMut(&(NodeId, NodeId))) {
        self.blocked_load.resize(self.blocked.len(), f32::INFINITY);
        take_out(&mut self.blocked_load, gone, |_| {});
        take_out(&mut self.blocked, gone, removed);
    }

    /// The idle pairs ([`Hierarchy::idle`]): as stored, or with the pair tree kept, its leaves
    /// that are neither links nor blocked; none for a still scene's hierarchy, which keeps
    /// neither.
    pub fn idle_pairs(&self) -> Vec<(NodeId, NodeId)> {
        use super::pair_tree::{PairSet, key};
        let Some(leaves) = self.splits.leaves(&self.tree, |a, b| super::touch::neutral(&self.tree, a, b))
        else {
            return self.idle.clone();
        };
        let stored: PairSet = self
            .links
            .iter()
            .map(|l| key(l.a, l.b))
            .chain(self.blocked.iter().map(|&(a, b)| key(a, b)))
            .collect();
        leaves.into_iter().filter(|&(a, b)| !stored.contains(&key(a, b))).collect()
    }

    /// Builds the links from the root's interaction with itself, `radiosity` per node (it grows
    /// with the tree: new nodes take their parent's).
    /// [`Error::OutOfMemory`](crate::Error::OutOfMemory) when the links or nodes cannot be
    /// had.
    pub fn link_all(
        &mut self,
        ctx: &LinkContext,
        radiosity: &mut Vec<f64>,
        progress: LinkProgress,
    ) -> Result<RefineStats> {
        let root = self.tree.root;
        let mut stats = RefineStats::default();
        self.refine_pairs(ctx, radiosity, vec![(root, root)], &mut stats, progress)?;
        self.note_decided(radiosity, 0, true);
        stats.links = self.links.len();
        Ok(stats)
    }

    /// Tests every link again with the current `radiosity` and refines those that now carry too
    /// much (Hanrahan's re-refinement after a solve).
    pub fn relink(
        &mut self,
        ctx: &LinkContext,
        radiosity: &mut Vec<f64>,
        progress: LinkProgress,
    ) -> Result<RefineStats> {
        let mut stats = RefineStats::default();
        let bar = self.oracle.threshold;
        let mut work = Vec::new();
        // Only a pair with an end brighter than when it was decided can fail now, and a link
        // only if its load grew past 1 (`Oracle::load`: linear in each end's brightness).
        let growth = self.growth(radiosity);
        let nodes_before = self.tree.nodes.len();
        // The most any node grew, when every growth is known. A pair whose load is at most
        // `1 / most` cannot fail, and nearly all are such: on the 30k-triangle monastery a few
        // hundred of its 6.2M pairs have a load above 0.9, and the last relink of an updated
        // frame finds no node grown 1.2 times. So when no node grew more than `QUICK_GROWTH`
        // times, the pass reads only the loads (4 bytes a pair, apart from the links), and
        // leaves the untested ones as they were (see `note_decided` below).
        let most = growth.iter().try_fold(0.0f64, |m, &g| g.is_finite().then_some(m.max(g)));
        let quick = most.filter(|&m| m <= QUICK_GROWTH);
        let quick_bar = quick.map_or(f64::NEG_INFINITY, |m| 1.0 / m);
        // The nodes grown brighter, a bit each: a pair with a known load of at most 1 and neither
        // end brighter passes as it is, and most pairs are such (a bit set a sixty-fourth of the
        // growths' size, looked at instead of both ends' growths).
        let mut brighter = vec![0u64; growth.len().div_ceil(64)];
        for (i, &g) in growth.iter().enumerate() {
            // (NaN counts as brighter.)
            if g > 1.0 || g.is_nan() {
                brighter[i / 64] |= 1 << (i % 64);
            }
        }
        let bright = |a: NodeId| brighter[a as usize / 64] >> (a % 64) & 1 != 0;
        let settled = |a: NodeId, b: NodeId, load: f32| load <= 1.0 && !bright(a) && !bright(b);
        let grown = |a: NodeId, b: NodeId| growth[a as usize].max(growth[b as usize]);
        // Whether the pair (a, b) may fail now and is tested; if not, a full pass brings its load
        // to the brightness now (scaled by its ends' growth: a bound still). (A NaN, an unknown
        // end's growth times no load, is tested.) A quick pass has left the pairs whose load is
        // at most `quick_bar` before reading their ends.
        let may_fail = |a: NodeId, b: NodeId, load: &mut f32| {
            if settled(a, b, *load) {
                return false;
            }
            let growth = grown(a, b);
            let bound = *load as f64 * growth;
            if bound <= 1.0 {
                if growth > 1.0 && quick.is_none() {
                    *load = (bound * (1.0 + 1e-6)) as f32;
                }
                return false;
            }
            true
        };
        let tree = &self.tree;
        let oracle = &self.oracle;
        // The same test that made each link, with the new brightness (in parallel: the tree and
        // the estimates are only read); a light link that may now carry more than a light link
        // may is computed again in full. A full pass brings every kept link's load to the
        // brightness now, which `decided_at` records below: scaled by its ends' growth where
        // untested (a bound still), computed again where tested. A link whose ends both grew no
        // brighter keeps its load as it was, a bound still: most links are untested, and writing
        // every one of them (15M on the full monastery) was most of a relink pass. A quick pass
        // writes only the loads it computed again.
        let tested = std::sync::atomic::AtomicUsize::new(0);
        // The links that fail, by index: most relinks have none.
        let links = &self.links;
        let failed_links = failing(&mut self.link_load, quick_bar, |i, load| {
            let l = &links[i];
            if !may_fail(l.a, l.b, load) {
                return false;
            }
            tested.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let light = matches!(l.coupling, coupling::Coupling::Constants { .. });
            let kept = matches!(oracle.decide(tree, radiosity, l.a, l.b, bar), Verdict::Link)
                && !(light && oracle.weight(tree, radiosity, l.a, l.b) == Weight::Full);
            if kept {
                *load = oracle.load(tree, radiosity, l.a, l.b, light);
            }
            !kept
        });
        // Hidden pairs decided while their ends were dark (a first round knows only the
        // emitters' light) are split now if they may carry enough: kept whole, each would drop
        // all its light from the solve, always the same way (the Cornell box's faces came out
        // 1-5% too dark).
        // (Their loads as the links' above; an unknown load is infinite, and tested.)
        self.blocked_load.resize(self.blocked.len(), f32::INFINITY);
        let blocked = &self.blocked;
        let failed_blocked = failing(&mut self.blocked_load, quick_bar, |i, load| {
            let (a, b) = blocked[i];
            if !may_fail(a, b, load) {
                return false;
            }
            tested.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let kept = !oracle.may_carry_much(tree, radiosity, a, b);
            if kept {
                *load = oracle.blocked_load(tree, radiosity, a, b);
            }
            !kept
        });
        // (Both stores tested before either is changed: the tests read the tree.)
        self.take_links(&failed_links, |l| work.push((l.a, l.b)));
        self.take_blocked(&failed_blocked, |&p| work.push(p));
        stats.relinked = work.len();
        stats.tested = tested.into_inner();
        stats.quick = quick.is_some();
        self.refine_pairs(ctx, radiosity, work, &mut stats, progress)?;
        // A full pass brought every load to the brightness now; a quick one left the untested
        // loads at what their ends were decided at, so each node keeps the lower of that and
        // now (a growth from there bounds the growth from either: the bounds stay bounds).
        self.note_decided(radiosity, nodes_before, quick.is_none());
        stats.links = self.links.len();
        Ok(stats)
    }

    /// Refines `work` into links: decide (splitting nodes) one pair at a time, compute the
    /// accepted links in parallel, and send partially visible ones that carry enough back.
    /// Decisions are made in batches of at most [`BATCH`] accepted pairs, each computed before
    /// the next is decided (a first frame of the full monastery accepts about 100M pairs).
    /// `progress` hears the share of `work`'s estimated links settled so far (linked, blocked or
    /// idle: [`PairSpace`]), and may cancel between chunks of computed links.
    fn refine_pairs(
        &mut self,
        ctx: &LinkContext,
        radiosity: &mut Vec<f64>,
        mut work: Vec<(NodeId, NodeId)>,
        stats: &mut RefineStats,
        progress: LinkProgress,
    ) -> Result<()> {
        let space = PairSpace::new(&self.tree);
        // Per pair on `work`, and per accepted pair, its share of the work ([`PairSpace`]).
        let mut shares: Vec<f64> = Vec::new();
        budget::try_reserve(&mut shares, work.len(), LINKS)?;
        shares.extend(work.iter().map(|&(a, b)| space.links(&self.tree, a, b)));
        let total: f64 = shares.iter().sum();
        let (mut settled, mut reported) = (0.0, 0.0f64);
        let mut accepted = Vec::new();
        let mut accepted_shares = Vec::new();
        let mut part = Vec::new();
        while !work.is_empty() {
            accepted.clear();
            accepted_shares.clear();
            while accepted.len() < BATCH && !work.is_empty() {
                // The top of the stack decided in parallel, each pair by a descent (the tree and
                // the estimates are only read), then filed in order (a surface leaf's split adds
                // nodes): the same verdicts as one at a time, the same for every thread count.
                let top = work.split_off(work.len().saturating_sub(DECIDE_CHUNK));
                let top_shares = shares.split_off(shares.len() - top.len());
                let deciding = Deciding {
                    tree: &self.tree,
                    oracle: &self.oracle,
                    space: &space,
                    radiosity,
                    stores_idle: self.stores_idle,
                };
                let descents: Vec<Descent> = top
                    .par_iter()
                    .zip(&top_shares)
                    .map(|(&pair, &share)| Descent::of(&deciding, pair, share))
                    .collect();
                for descent in descents.into_iter().rev() {
                    settled += descent.settled;
                    budget::try_reserve(&mut work, descent.open, NODES)?;
                    budget::try_reserve(&mut shares, descent.open, NODES)?;
                    for decided in descent.decided {
                        match decided {
                            Decided::Split(a, b, s) => self.splits.record(a, b, s)?,
                            Decided::Idle(a, b) => {
                                budget::try_reserve(&mut self.idle, 1, LINKS)?;
                                self.idle.push((a, b));
                            }
                            Decided::Link(a, b, weight, share) => {
                                accepted.push((a, b, weight));
                                accepted_shares.push(share);
                            }
                            Decided::Open(a, b, share) => {
                                work.push((a, b));
                                shares.push(share);
                            }
                            Decided::SplitLeaf(a, b, s, share) => {
                                let pushed = work.len();
                                self.split_pair((a, b), s, radiosity, &mut work)?;
                                settled +=
                                    space.divide(&self.tree, share, (a, b), &work[pushed..], &mut shares)?;
                            }
                        }
                    }
                }
            }
            // In chunks, so that the batch reports its progress and can be cancelled, and so
            // that what a chunk computed becomes links before the next is computed. The batch's
            // share is reported as its chunks are computed, evenly (each chunk is as many links
            // to compute): the pairs' own shares follow the subtrees the refinement descended,
            // so that in the order the descents file them the first half of a batch's pairs
            // held 69% of its share on the decimated monastery, and the report ran ahead. Never
            // less than a report before it: a pair split for its shadows passes its share on.
            let (from, batch): (f64, f64) = (settled, accepted_shares.iter().sum());
            for (k, (chunk, chunk_shares)) in
                accepted.chunks(LINK_CHUNK).zip(accepted_shares.chunks(LINK_CHUNK)).enumerate()
            {
                let computed = (k * LINK_CHUNK) as f64 / accepted.len() as f64;
                reported = reported.max(((from + batch * computed) / total).min(1.0));
                if !progress(reported) {
                    return Err(crate::Error::Cancelled);
                }
                let (tree, oracle, seen): (_, _, &[f64]) = (&self.tree, &self.oracle, radiosity);
                let t = std::time::Instant::now();
                chunk
                    .par_iter()
                    .map(|&(a, b, weight)| {
                        let (c, cast) = coupling::compute_cast(ctx, tree, a, b, weight);
                        let filing = oracle.filing(tree, seen, a, b, &c);
                        (c, filing, cast)
                    })
                    .collect_into_vec(&mut part);
                stats.compute_seconds += t.elapsed().as_secs_f64();
                if ctx.reuse.is_some() {
                    self.record_casts(chunk, &mut part, stats)?;
                }
                // Reserved first: the allocator's refusal of the large vectors is an error (a
                // full link's own blocks are small allocations).
                budget::try_reserve(&mut self.links, part.len(), LINKS)?;
                budget::try_reserve(&mut self.link_load, part.len(), LINKS)?;
                if self.stores_idle {
                    budget::try_reserve(&mut self.idle, part.len(), LINKS)?;
                }
                budget::try_reserve(&mut self.blocked, part.len(), LINKS)?;
                budget::try_reserve(&mut self.blocked_load, part.len(), LINKS)?;
                for ((&(a, b, _), (c, filing, _)), &share) in
                    chunk.iter().zip(part.drain(..)).zip(chunk_shares)
                {
                    let pushed = work.len();
                    if self.take_computed(a, b, c, filing, radiosity, &mut work, stats)? {
                        settled += share;
                    } else {
                        settled += space.divide(&self.tree, share, (a, b), &work[pushed..], &mut shares)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Keeps the casts of a chunk's cluster links in [`Hierarchy::casts`] (taking them out of
    /// `part`).
    fn record_casts(
        &mut self,
        chunk: &[(NodeId, NodeId, coupling::Weight)],
        part: &mut [(coupling::Computed, Filing, Option<coupling::Casting>)],
        stats: &mut RefineStats,
    ) -> Result<()> {
        let casts = &mut self.casts;
        casts.try_reserve(part.iter().filter(|p| p.2.is_some()).count())?;
        for (&(a, b, _), (_, _, cast)) in chunk.iter().zip(part.iter_mut()) {
            if let Some(c) = cast.take() {
                stats.reused_casts += usize::from(c.reused);
                casts.insert(a, b, c.cast);
            }
        }
        Ok(())
    }

    /// Files the computed link between `a` and `b` as `filing` says ([`Oracle::filing`]): a
    /// link, a blocked or an idle pair (`true`: the pair is settled), or, when a shadow boundary
    /// crosses (or may cross) a pair that carries enough, its larger node split onto `work`
    /// (`false`).
    #[allow(clippy::too_many_arguments)]
    fn take_computed(
        &mut self,
        a: NodeId,
        b: NodeId,
        c: coupling::Computed,
        filing: Filing,
        radiosity: &mut Vec<f64>,
        work: &mut Vec<(NodeId, NodeId)>,
        stats: &mut RefineStats,
    ) -> Result<bool> {
        let load = match filing {
            Filing::SplitForShadows => {
                stats.split_for_shadows += 1;
                let s = self.larger_splittable(a, b);
                self.split_pair((a, b), s, radiosity, work)?;
                return Ok(false);
            }
            Filing::Load(load) => load,
        };
        match c.coupling {
            Some(coupling) => {
                self.link_load.push(load);
                self.links.push(Link { a, b, coupling });
            }
            None if c.blocked => {
                // (Unknown loads before this one stay unknown.)
                self.blocked_load.resize(self.blocked.len(), f32::INFINITY);
                self.blocked_load.push(load);
                self.blocked.push((a, b));
            }
            None if self.stores_idle && !same_face(&self.tree, a, b) => self.idle.push((a, b)),
            None => {}
        }
        Ok(true)
    }

    /// Replaces the pair `(a, b)` by each child of its end `s` (split now if it is a surface
    /// leaf) paired with the other end, onto `work` ([`super::pair_tree::children`]'s order); new nodes
    /// start from their parent's radiosity estimate.
    fn split_pair(
        &mut self,
        (a, b): (NodeId, NodeId),
        s: NodeId,
        radiosity: &mut Vec<f64>,
        work: &mut Vec<(NodeId, NodeId)>,
    ) -> Result<()> {
        let other = if s == a { b } else { a };
        self.splits.record(a, b, s)?;
        let children = match self.tree.node(s).kind {
            Kind::Cluster { children } => children.to_vec(),
            Kind::Surface(_) => {
                budget::try_reserve(&mut self.tree.nodes, 4, NODES)?;
                budget::try_reserve(radiosity, 4, NODES)?;
                let c = self.tree.split(s);
                let r = radiosity[s as usize];
                radiosity.resize(self.tree.nodes.len(), r);
                c.to_vec()
            }
        };
        budget::try_reserve(work, children.len(), NODES)?;
        work.extend(children.into_iter().map(|c| (c, other)));
        Ok(())
    }

    fn larger_splittable(&self, a: NodeId, b: NodeId) -> NodeId {
        let (ca, cb) = (self.oracle.splittable(&self.tree, a), self.oracle.splittable(&self.tree, b));
        match (ca, cb) {
            (true, false) => a,
            (false, true) => b,
            _ => {
                if self.tree.node(a).radius >= self.tree.node(b).radius {
                    a
                } else {
                    b
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::rc::Rc;

    /// `take_out` leaves what `Vec::retain` leaves, in order, hands it the entries taken, and
    /// drops each taken entry once and no kept one (counted through `Rc`s), for random patterns:
    /// none, all, runs at either end, scattered.
    #[test]
    fn taking_out_by_index_keeps_what_retain_keeps() {
        let mut state = 0x853C_49E6_748F_EA9Bu64;
        let mut next = move |n: usize| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 33) as usize) % n.max(1)
        };
        for round in 0..200 {
            let len = next(60);
            let tokens: Vec<Rc<usize>> = (0..len).map(Rc::new).collect();
            let share = [0, 1, 2, 10][round % 4];
            let gone: Vec<usize> = (0..len)
                .filter(|&i| match share {
                    0 => false,
                    1 => true,
                    2 => i < len / 3 || i + 2 >= len,
                    _ => next(10) < 3,
                })
                .collect();
            let mut list: Vec<Rc<usize>> = tokens.to_vec();
            let mut want = list.clone();
            let mut k = 0..;
            want.retain(|_| !gone.contains(&k.next().unwrap()));
            let mut handed = Vec::new();
            take_out(&mut list, &gone, |x| handed.push(**x));
            assert_eq!(handed, gone, "round {round}");
            assert_eq!(
                list.iter().map(|x| **x).collect::<Vec<_>>(),
                want.iter().map(|x| **x).collect::<Vec<_>>()
            );
            drop(want);
            for (i, t) in tokens.iter().enumerate() {
                // The test's own handle, and the list's for a kept entry.
                let held = if gone.contains(&i) { 1 } else { 2 };
                assert_eq!(Rc::strong_count(t), held, "round {round}, entry {i}");
            }
        }
    }

    /// `failing` finds, in order, the pairs a plain loop over every load finds (a load above the
    /// bar, NaN included, that the test fails), leaves the loads below the bar unread, and keeps
    /// what the test writes to a load; `indices_where` is a plain filter's indices. Over several
    /// pieces, the last one partly filled, with lone loads above the bar in otherwise quiet
    /// pieces, and with no bar (a full pass) as well.
    #[test]
    fn the_passes_by_pieces_find_what_a_plain_loop_finds() {
        let mut rng = super::coupling::SplitMix(0x2545_F491_4F6C_DD1D);
        let mut next = move || rng.next();
        let len = 3 * PASS_CHUNK + 123;
        let mut loads: Vec<f32> = (0..len)
            .map(|_| match next() {
                r if r < 0.001 => f32::NAN,
                r if r < 0.01 => 1.5 * r as f32 * 100.0,
                r => 0.5 * r as f32,
            })
            .collect();
        // A quiet piece with one load above the bar, and a last piece whose only one is a NaN.
        loads[2 * PASS_CHUNK..].iter_mut().for_each(|l| *l = 0.1);
        (loads[2 * PASS_CHUNK + 9], loads[3 * PASS_CHUNK + 6]) = (0.9, f32::NAN);
        for bar in [0.6, f64::NEG_INFINITY] {
            // Fails every third index, and halves the load of every pair it is asked about.
            let fails = |i: usize, load: &mut f32| {
                *load *= 0.5;
                i.is_multiple_of(3)
            };
            let mut plain = loads.clone();
            let mut want = Vec::new();
            for (i, load) in plain.iter_mut().enumerate() {
                if (*load as f64 > bar || load.is_nan()) && fails(i, load) {
                    want.push(i);
                }
            }
            let mut pieces = loads.clone();
            let seen = std::sync::atomic::AtomicUsize::new(0);
            let got = failing(&mut pieces, bar, |i, load| {
                assert!(loads[i] as f64 > bar || loads[i].is_nan(), "load {i} below the bar was tested");
                seen.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                fails(i, load)
            });
            assert_eq!(got, want, "bar {bar}");
            assert!(want.len() > 3 && seen.into_inner() > want.len(), "too few tested");
            let same = |x: &f32, y: &f32| x.to_bits() == y.to_bits();
            assert!(plain.iter().zip(&pieces).all(|(x, y)| same(x, y)), "bar {bar}: the loads differ");
        }
        let want: Vec<usize> = (0..len).filter(|&i| loads[i] > 0.3).collect();
        assert_eq!(indices_where(&loads, |&l| l > 0.3), want);
    }
}
