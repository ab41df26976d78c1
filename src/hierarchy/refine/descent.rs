//! The refinement's work stack decided in parallel: a pair taken off it with, depth first, the
//! pairs its splits make ([`Descent`]), and the share of the work each pair stands for, which
//! the progress reports ([`PairSpace`]).

use super::oracle::{Oracle, Verdict};
use super::{NODES, same_face};
use crate::budget;
use crate::error::Result;
use crate::hierarchy::coupling::Weight;
use crate::hierarchy::tree::{Kind, Node, NodeId, Tree};

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
pub(super) struct PairSpace {
    /// Faces below each cluster present when the refinement starts (the nodes it adds are
    /// surfaces).
    faces: Vec<f64>,
}

impl PairSpace {
    pub(super) fn new(tree: &Tree) -> Self {
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
    pub(super) fn links(&self, tree: &Tree, a: NodeId, b: NodeId) -> f64 {
        let (x, y) = (tree.node(a), tree.node(b));
        let faces = |id: NodeId, node: &Node| match node.kind {
            Kind::Surface(_) => 1.0,
            Kind::Cluster { .. } => self.faces.get(id as usize).map_or(1.0, |&n| n.max(1.0)),
        };
        let (na, nb) = (faces(a, x), faces(b, y));
        if a == b {
            return na * (2.0 * na).log2().sqrt().sqrt();
        }
        // A surface sees only what lies before its plane: of the other node's sphere, this
        // share (the oracle skips a pair wholly behind, or of one face: a decision, no link).
        let before = |s: &Node, o: &Node| match &s.kind {
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
    pub(super) fn divide(
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
pub(super) struct Deciding<'a> {
    pub(super) tree: &'a Tree,
    pub(super) oracle: &'a Oracle,
    pub(super) space: &'a PairSpace,
    pub(super) radiosity: &'a [f64],
    pub(super) stores_idle: bool,
}

/// A decision for the serial loop of [`Hierarchy::refine_pairs`](super::Hierarchy::refine_pairs)
/// to file, in order.
pub(super) enum Decided {
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
pub(super) struct Descent {
    pub(super) decided: Vec<Decided>,
    /// The work's share settled by the decisions (skipped pairs, and splits that made no pairs).
    pub(super) settled: f64,
    /// The pairs left [`Decided::Open`].
    pub(super) open: usize,
}

/// The most decisions one [`Descent`] makes: enough that a descent's filing is a copy, few
/// enough that the top of the refinement (one pair, the root's with itself) spreads over the
/// threads within a few rounds.
const DESCENT: usize = 64;

impl Descent {
    pub(super) fn of(d: &Deciding, pair: (NodeId, NodeId), share: f64) -> Self {
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

/// What a pair the oracle skips costs (a decision) in links computed ([`PairSpace::links`]): a
/// decision took about a twentieth of a link's time on the monastery's parts.
const SKIPPED: f64 = 0.05;
