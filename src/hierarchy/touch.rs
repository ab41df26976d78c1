//! Which stored pairs a move may have changed ([`super::update`]'s rule), found by a scan of
//! every pair or, with the pair tree kept, by a walk down it (Drettakis and Sillion 1997 find a
//! move's links through their hierarchy of shafts in the same way).
//!
//! A pair `(a, b)` is touched when an end holds a moved face, or when a moved object's swept
//! box meets the shaft between the ends' boxes (their convex hull,
//! [`Shaft::between_may_contain_box`]). The walk enters the subtree of an inner pair only where
//! the same test holds on boxes that bound everything below each end ([`Touch::may_below`]): a
//! shaft between larger boxes holds the shafts between smaller ones inside them, and a node holds
//! a moved face if a node below it does. So it reaches every touched leaf, and its cost grows
//! with the pairs near the move rather than with the scene.

use glam::DVec3;

use super::pair_tree::{self, Splits};
use super::refine::Hierarchy;
use super::tree::{NodeId, Tree};
use crate::geometry::Aabb;
use crate::system::Element;
use crate::visibility::shaft::Shaft;

/// What a frame changes in the tree it inherits.
#[derive(Clone, Debug, Default)]
pub struct Moves {
    /// Per face of the tree: it moved (its patch changed).
    pub faces: Vec<bool>,
    /// The bounds of each moving object's moved faces, old and new places together.
    pub swept: Vec<Aabb>,
}

impl Moves {
    /// Adds `later`'s moves to these (moves over several frames, as one): a face moved if it
    /// moved in either, and a swept box that meets one of these grows it (a moving object's
    /// boxes frame after frame share its place between them), else joins them.
    pub fn add(&mut self, later: &Moves) {
        for (a, &b) in self.faces.iter_mut().zip(&later.faces) {
            *a |= b;
        }
        for &x in &later.swept {
            match self.swept.iter_mut().find(|s| s.overlaps(&x)) {
                Some(s) => *s = s.union(x),
                None => self.swept.push(x),
            }
        }
    }

    /// Per object with moved faces, the box around their old and new patches.
    pub fn swept_bounds(old: &[Element], new: &[Element]) -> Vec<Aabb> {
        let mut out: Vec<(u32, Aabb)> = Vec::new();
        for (a, b) in old.iter().zip(new) {
            if a.patch == b.patch {
                continue;
            }
            let both = a.patch.bounds().union(b.patch.bounds());
            match out.last_mut() {
                Some((o, x)) if *o == b.object => *x = x.union(both),
                _ => out.push((b.object, both)),
            }
        }
        out.into_iter().map(|(_, x)| x).collect()
    }
}

/// What a value computed from a point towards a node reads of the occluders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reach {
    /// Segments from the point to the node, each tested against every triangle (through the
    /// BVH): only triangles that meet the convex hull of the point and the node's box can
    /// change it.
    Hull,
    /// Shaft queries between the point and parts of the node, whose candidate lists (kept or
    /// not by conservative plane tests, and deciding how a part is integrated) hold only
    /// triangles that meet the box around the point and the node.
    Box,
}

/// The touch test of one move on one tree.
pub struct Touch<'a> {
    moves: &'a Moves,
    /// Per node: it holds a moved face.
    holds: Vec<bool>,
    /// Per node: its own box ([`Tree::bounds`]), and a box around its own and every node's
    /// below it (a cluster's sphere need not hold its children's).
    boxes: Vec<Aabb>,
    below: Vec<Aabb>,
    /// A margin of rounding, scaled to the scene, so that a box that only touches a shaft is in.
    eps: f64,
}

impl<'a> Touch<'a> {
    pub fn new(tree: &Tree, moves: &'a Moves) -> Self {
        let holds = tree.nodes_holding(&moves.faces);
        let boxes: Vec<Aabb> = (0..tree.nodes.len() as NodeId).map(|id| tree.bounds(id)).collect();
        let mut below = boxes.clone();
        // Children after their parents in a pre-order, then unions from the leaves up.
        let mut order = Vec::with_capacity(tree.nodes.len());
        let mut stack = vec![tree.root];
        while let Some(id) = stack.pop() {
            order.push(id);
            stack.extend_from_slice(tree.children(id));
        }
        for &id in order.iter().rev() {
            for &c in tree.children(id) {
                below[id as usize] = below[id as usize].union(below[c as usize]);
            }
        }
        let scene_box = moves.swept.iter().fold(below[tree.root as usize], |u, x| u.union(*x));
        let eps = 1e-9 * scene_box.diagonal().length().max(1e-300);
        Self { moves, holds, boxes, below, eps }
    }

    /// The boxes the moves swept (their faces' old and new places).
    pub fn swept(&self) -> &[Aabb] {
        &self.moves.swept
    }

    /// Per node: it holds a moved face.
    pub fn holds(&self) -> &[bool] {
        &self.holds
    }

    /// Nothing between the point `x` and the node `id` can have changed for what `reach` reads:
    /// no face at or below `id` moved, and no swept box meets the region around `x` and
    /// everything below `id` that `reach` says. For [`crate::hierarchy::gather`]'s kept values;
    /// `false` for a node made after this test.
    pub fn spares(&self, x: DVec3, id: NodeId, reach: Reach) -> bool {
        let Some(&below) = self.below.get(id as usize) else { return false };
        if !self.unmoved(id) {
            return false;
        }
        let point = Aabb { min: x, max: x };
        match reach {
            Reach::Box => {
                let reach = below.grow(x).inflated(self.eps);
                !self.moves.swept.iter().any(|s| s.overlaps(&reach))
            }
            Reach::Hull => {
                !self.moves.swept.iter().any(|s| Shaft::between_may_contain_box(&point, &below, s, self.eps))
            }
        }
    }

    /// No face at or below `id` moved (`false` for a node made after this test).
    pub fn unmoved(&self, id: NodeId) -> bool {
        self.holds.get(id as usize).is_some_and(|&h| !h)
    }

    /// The pair `(a, b)` may have changed ([the module's rule](self)).
    pub fn pair(&self, a: NodeId, b: NodeId) -> bool {
        self.test(&self.boxes, a, b)
    }

    /// Some pair below `(a, b)` (itself included) may have changed.
    pub fn may_below(&self, a: NodeId, b: NodeId) -> bool {
        self.test(&self.below, a, b)
    }

    fn test(&self, boxes: &[Aabb], a: NodeId, b: NodeId) -> bool {
        let (a, b) = (a as usize, b as usize);
        self.holds[a]
            || self.holds[b]
            || self
                .moves
                .swept
                .iter()
                .any(|x| Shaft::between_may_contain_box(&boxes[a], &boxes[b], x, self.eps))
    }
}

/// The pairs (links, blocked, and `idle`: [`Hierarchy::idle_pairs`]) `touch` says may have
/// changed, by a scan of them all.
pub fn by_scan(hierarchy: &Hierarchy, idle: &[(NodeId, NodeId)], touch: &Touch) -> Vec<(NodeId, NodeId)> {
    let links = hierarchy.links.iter().map(|l| (l.a, l.b));
    let others = hierarchy.blocked.iter().chain(idle).copied();
    links.chain(others).filter(|&(a, b)| touch.pair(a, b)).collect()
}

/// The same pairs by a walk down the pair tree, in its order; `None` when it is not kept.
pub fn by_walk(hierarchy: &Hierarchy, touch: &Touch) -> Option<Vec<(NodeId, NodeId)>> {
    let splits: &Splits = &hierarchy.splits;
    if !splits.is_kept() {
        return None;
    }
    let tree = &hierarchy.tree;
    let (mut out, mut stack) = (Vec::new(), vec![(tree.root, tree.root)]);
    while let Some((a, b)) = stack.pop() {
        if !touch.may_below(a, b) {
            continue;
        }
        match splits.split_of(a, b) {
            Some(s) => stack.extend_from_slice(&pair_tree::children(tree, a, b, s)),
            None if !neutral(tree, a, b) && touch.pair(a, b) => out.push((a, b)),
            None => {}
        }
    }
    Some(out)
}

/// A pair that exchanges nothing by construction and is never stored: a node with itself, two
/// parts of one face.
pub fn neutral(tree: &Tree, a: NodeId, b: NodeId) -> bool {
    a == b
        || matches!((tree.node(a).surface(), tree.node(b).surface()), (Some(x), Some(y)) if x.face == y.face)
}
