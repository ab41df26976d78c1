//! The pair tree: which pairs of nodes the refinement split, and at which end (issue 21).
//!
//! Refinement starts from the root paired with itself and replaces a pair by its children
//! ([`children`]): a cluster paired with itself by every pair of its children, any other pair
//! `(a, b)` split at end `s` by each child `c` of `s` paired with the other end, `(c, other)`.
//! The links, the blocked and the idle pairs are the leaves of that tree, with the pairs that
//! exchange nothing by construction (a node with itself, two parts of one face), which are not
//! stored. [`Splits`] records the inner pairs and the end each was split at.
//!
//! What it is for: coarsening. An update re-links the pairs a move touched; refined again from
//! where they stood, they can only get finer, and over an animation the links of whatever a
//! moving object passed near pile up (the demo animation's 3,382 links grew to 5,562 in 32
//! frames, against 3,583 for a fresh build of the last frame). With the inner pairs known, an
//! update finds the largest subtrees all of whose stored leaves a move touched, or that hold a
//! touched leaf and that the oracle would now link whole ([`Splits::coarsest_touched`]), and
//! refines them again from their top, where the oracle may accept a coarser link (Drettakis and
//! Sillion 1997 re-refine and coarsen the links a move crosses in the same way). The second rule
//! recomputes some untouched pairs with the touched ones (a shadow's links outside the swept
//! shafts, where the shadow left); without it the demo animation kept 4,285 links at frame 32
//! instead of 3,999, with no measurable difference in time per frame (0.035-0.059 against
//! 0.046-0.047 s, two runs each, alternated).
//!
//! The record costs about 20 bytes per inner pair (0.7 inner pairs per stored pair on the
//! decimated monastery: 629k for 910k links, blocked and idle pairs), so it is kept
//! only for animations ([`super::HierarchySettings::keep_pair_tree`]).

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

use rayon::prelude::*;

use super::tree::{NodeId, Tree};
use crate::budget;
use crate::error::Result;

/// A pair as one key: `a` in the high half.
pub fn key(a: NodeId, b: NodeId) -> u64 {
    ((a as u64) << 32) | b as u64
}

/// Hashes a pair key with murmur3's finaliser: the std hasher is several times slower for the
/// tens of millions of pairs a large model splits, and a bare multiply leaves the low bits (the
/// bucket) to depend on `b` alone.
#[derive(Default, Clone, Copy)]
pub struct PairHasher(u64);

impl Hasher for PairHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }

    fn write_u64(&mut self, x: u64) {
        let mut h = self.0 ^ x;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^= h >> 33;
        self.0 = h;
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

pub type PairMap<V> = HashMap<u64, V, BuildHasherDefault<PairHasher>>;
pub type PairSet = HashSet<u64, BuildHasherDefault<PairHasher>>;

/// The inner pairs of the pair tree and the end each was split at; or nothing, when not kept.
#[derive(Clone, Default)]
pub struct Splits {
    map: Option<PairMap<NodeId>>,
}

/// The children of pair `(a, b)` split at `s`, in the order the refinement makes them.
pub fn children(tree: &Tree, a: NodeId, b: NodeId, s: NodeId) -> PairChildren {
    let c = tree.children(s);
    let mut out = PairChildren { pairs: [(0, 0); MAX_PAIR_CHILDREN], len: 0 };
    let mut push = |p| {
        out.pairs[out.len] = p;
        out.len += 1;
    };
    if a == b {
        for (i, &x) in c.iter().enumerate() {
            for &y in &c[i..] {
                push((x, y));
            }
        }
    } else {
        let other = if s == a { b } else { a };
        c.iter().for_each(|&x| push((x, other)));
    }
    out
}

/// A pair's children: at most a surface's four quadrants paired among themselves.
const MAX_PAIR_CHILDREN: usize = 10;

/// [`children`]'s pairs, kept on the stack: the walks down the pair tree visit tens of
/// thousands of pairs a frame, and a vector for each pair's children was most of an updated
/// frame's walk on the moving-light box.
#[derive(Clone, Copy)]
pub struct PairChildren {
    pairs: [(NodeId, NodeId); MAX_PAIR_CHILDREN],
    len: usize,
}

impl std::ops::Deref for PairChildren {
    type Target = [(NodeId, NodeId)];
    fn deref(&self) -> &Self::Target {
        &self.pairs[..self.len]
    }
}

/// What a subtree's stored leaves are: all touched (or exchanging nothing), and any touched.
#[derive(Clone, Copy)]
struct Subtree {
    all: bool,
    any: bool,
}

impl Splits {
    /// A record that keeps every split.
    pub fn kept() -> Self {
        Self { map: Some(PairMap::default()) }
    }

    /// No record: updates refine touched pairs from where they stood and never coarsen.
    pub fn off() -> Self {
        Self { map: None }
    }

    pub fn is_kept(&self) -> bool {
        self.map.is_some()
    }

    /// Inner pairs recorded.
    pub fn len(&self) -> usize {
        self.map.as_ref().map_or(0, |m| m.len())
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes the record holds (its table's slots).
    pub fn bytes(&self) -> usize {
        self.map.as_ref().map_or(0, |m| m.capacity() * (std::mem::size_of::<(u64, NodeId)>() + 1))
    }

    /// Records that pair `(a, b)` was split at `s`. A table that cannot grow is
    /// [`Error::OutOfMemory`](crate::Error::OutOfMemory).
    pub fn record(&mut self, a: NodeId, b: NodeId, s: NodeId) -> Result<()> {
        if let Some(m) = self.map.as_mut() {
            if m.len() == m.capacity() {
                let more = m.len().max(1024);
                m.try_reserve(more).map_err(|_| {
                    budget::out_of_memory("the hierarchy's pair tree", (m.len() + more) as u64 * 24)
                })?;
            }
            m.insert(key(a, b), s);
        }
        Ok(())
    }

    /// The end pair `(a, b)` was split at, `None` for a leaf (or when nothing is kept).
    pub fn split_of(&self, a: NodeId, b: NodeId) -> Option<NodeId> {
        self.map.as_ref()?.get(&key(a, b)).copied()
    }

    /// Where an update refines again from ([the module's comment](self)), each recorded split
    /// at or below them forgotten: the tops of the largest subtrees that are *redone*, that is
    /// all of whose stored leaves are `touched` (at least one), or which hold a touched leaf
    /// and which the oracle would now link whole (`links_whole`: a shadow the move took away is
    /// linked coarse again), or whose children are all redone. Pairs that exchange nothing by
    /// construction (`neutral`: a node with itself, two parts of one face) count as touched.
    /// Also returns the touched leaves (what [`super::touch::by_walk`] finds, found on the same
    /// walk) and the stored leaves below the tops that are not touched, which the update must
    /// take out of the stores too. The walk skips the subtrees where `may_touch` says no leaf is
    /// touched ([`super::touch::Touch::may_below`]), so that its cost follows the move. `None`
    /// when nothing is kept.
    pub fn coarsest_touched(
        &mut self,
        tree: &Tree,
        touched: impl Fn(NodeId, NodeId) -> bool + Sync,
        may_touch: impl Fn(NodeId, NodeId) -> bool + Sync,
        neutral: impl Fn(NodeId, NodeId) -> bool + Sync,
        links_whole: impl Fn(NodeId, NodeId) -> bool + Sync,
    ) -> Option<Redo> {
        self.coarsest_touched_at(tree, touched, may_touch, neutral, links_whole, PARALLEL_LEVELS)
    }

    /// [`Splits::coarsest_touched`] with the children of the first `parallel_levels` levels'
    /// pairs walked in parallel.
    fn coarsest_touched_at(
        &mut self,
        tree: &Tree,
        touched: impl Fn(NodeId, NodeId) -> bool + Sync,
        may_touch: impl Fn(NodeId, NodeId) -> bool + Sync,
        neutral: impl Fn(NodeId, NodeId) -> bool + Sync,
        links_whole: impl Fn(NodeId, NodeId) -> bool + Sync,
        parallel_levels: u32,
    ) -> Option<Redo> {
        let map = self.map.as_mut()?;
        let mut redo = Redo::default();
        let root = tree.root;
        let rules =
            Rules { touched: &touched, may_touch: &may_touch, neutral: &neutral, links_whole: &links_whole };
        let found = visit_parallel(map, tree, &rules, (root, root), parallel_levels);
        let top = found.subtree;
        (redo.tops, redo.touched) = (found.tops, found.touched);
        if top.all && top.any {
            redo.tops.clear();
            redo.tops.push((root, root));
        }
        for &(a, b) in &redo.tops {
            forget_below(map, tree, a, b, &rules, &mut redo.untouched);
        }
        Some(redo)
    }
}

/// What an update refines again ([`Splits::coarsest_touched`]).
#[derive(Debug, Default, PartialEq)]
pub struct Redo {
    /// The pairs to refine from.
    pub tops: Vec<(NodeId, NodeId)>,
    /// Stored pairs below them that the move did not touch, redone with them.
    pub untouched: Vec<(NodeId, NodeId)>,
    /// The stored pairs the move touched.
    pub touched: Vec<(NodeId, NodeId)>,
}

/// The tests [`visit`] applies.
struct Rules<'a, T, M, N, W> {
    touched: &'a T,
    may_touch: &'a M,
    neutral: &'a N,
    links_whole: &'a W,
}

impl Splits {
    /// The leaves of the recorded tree below the root's pair with itself, in the refinement's
    /// order, the pairs that exchange nothing by construction (`neutral`) left out: with every
    /// split recorded, the links, blocked and idle pairs, each once. `None` when nothing is kept.
    pub fn leaves(
        &self,
        tree: &Tree,
        neutral: impl Fn(NodeId, NodeId) -> bool,
    ) -> Option<Vec<(NodeId, NodeId)>> {
        let map = self.map.as_ref()?;
        let (mut out, mut stack) = (Vec::new(), vec![(tree.root, tree.root)]);
        while let Some((a, b)) = stack.pop() {
            match map.get(&key(a, b)) {
                Some(&s) => stack.extend(children(tree, a, b, s).iter().rev()),
                None if !neutral(a, b) => out.push((a, b)),
                None => {}
            }
        }
        Some(out)
    }
}

/// The pair `p`'s subtree: whether it is redone whole (`all`) and holds a touched leaf (`any`).
/// The tops inside a pair not redone whole go to `tops`, the touched leaves to `touched`.
fn visit<T, M, N, W>(
    map: &PairMap<NodeId>,
    tree: &Tree,
    rules: &Rules<T, M, N, W>,
    (a, b): (NodeId, NodeId),
    tops: &mut Vec<(NodeId, NodeId)>,
    touched: &mut Vec<(NodeId, NodeId)>,
) -> Subtree
where
    T: Fn(NodeId, NodeId) -> bool,
    M: Fn(NodeId, NodeId) -> bool,
    N: Fn(NodeId, NodeId) -> bool,
    W: Fn(NodeId, NodeId) -> bool,
{
    // No touched leaf below: as a subtree with an untouched one (it may hold none, but its
    // parent then only redoes less).
    if !(rules.may_touch)(a, b) {
        return Subtree { all: false, any: false };
    }
    let Some(&s) = map.get(&key(a, b)) else {
        return if (rules.neutral)(a, b) {
            Subtree { all: true, any: false }
        } else if (rules.touched)(a, b) {
            touched.push((a, b));
            Subtree { all: true, any: true }
        } else {
            Subtree { all: false, any: false }
        };
    };
    let kids = children(tree, a, b, s);
    let first_top = tops.len();
    let mut below = [Subtree { all: false, any: false }; MAX_PAIR_CHILDREN];
    for (t, &p) in below.iter_mut().zip(kids.iter()) {
        *t = visit(map, tree, rules, p, tops, touched);
    }
    inner(rules, (a, b), &kids, &below[..kids.len()], tops, first_top)
}

/// An inner pair `(a, b)`'s subtree from its children's (`kids`, `below`), the tops its
/// children's walks found at `tops[first_top..]`: dropped when it is redone whole, followed by
/// the children redone whole when it is not.
fn inner<T, M, N, W>(
    rules: &Rules<T, M, N, W>,
    (a, b): (NodeId, NodeId),
    kids: &[(NodeId, NodeId)],
    below: &[Subtree],
    tops: &mut Vec<(NodeId, NodeId)>,
    first_top: usize,
) -> Subtree
where
    W: Fn(NodeId, NodeId) -> bool,
{
    let all = below.iter().all(|t| t.all);
    let any = below.iter().any(|t| t.any);
    if any && (all || (rules.links_whole)(a, b)) {
        // Redone whole from here or from above: the tops found below are inside.
        tops.truncate(first_top);
        return Subtree { all: true, any: true };
    }
    for (&(x, y), t) in kids.iter().zip(below) {
        if t.all && t.any {
            tops.push((x, y));
        }
    }
    Subtree { all, any }
}

/// Levels of the pair tree whose pairs' children [`visit_parallel`] walks in parallel (a pair
/// has two to ten children: far more tasks than the cores, each subtree below walked in turn).
/// The walk, one hash lookup and a shaft test or two per pair visited, was 0.29-0.41 s of an
/// updated frame of the full monastery (4.3-4.8 s, a build with timers).
const PARALLEL_LEVELS: u32 = 10;

/// What [`visit`] finds below a pair: its subtree, and the tops and touched leaves it writes.
struct Found {
    subtree: Subtree,
    tops: Vec<(NodeId, NodeId)>,
    touched: Vec<(NodeId, NodeId)>,
}

/// [`visit`] with the children of the pairs of the first `levels` levels walked in parallel,
/// each child's lists then joined in the children's order: the same tops and touched leaves, in
/// the same order, as the walk in turn (the order of the pairs refined again, and so of the
/// links made from them).
fn visit_parallel<T, M, N, W>(
    map: &PairMap<NodeId>,
    tree: &Tree,
    rules: &Rules<T, M, N, W>,
    (a, b): (NodeId, NodeId),
    levels: u32,
) -> Found
where
    T: Fn(NodeId, NodeId) -> bool + Sync,
    M: Fn(NodeId, NodeId) -> bool + Sync,
    N: Fn(NodeId, NodeId) -> bool + Sync,
    W: Fn(NodeId, NodeId) -> bool + Sync,
{
    let split = map.get(&key(a, b)).copied();
    let Some(s) = split.filter(|_| levels > 0 && (rules.may_touch)(a, b)) else {
        let (mut tops, mut touched) = (Vec::new(), Vec::new());
        let subtree = visit(map, tree, rules, (a, b), &mut tops, &mut touched);
        return Found { subtree, tops, touched };
    };
    let kids = children(tree, a, b, s);
    let found: Vec<Found> =
        kids.par_iter().map(|&p| visit_parallel(map, tree, rules, p, levels - 1)).collect();
    let below: Vec<Subtree> = found.iter().map(|f| f.subtree).collect();
    let mut tops = Vec::with_capacity(found.iter().map(|f| f.tops.len()).sum());
    let mut touched = Vec::with_capacity(found.iter().map(|f| f.touched.len()).sum());
    for f in found {
        tops.extend(f.tops);
        touched.extend(f.touched);
    }
    let subtree = inner(rules, (a, b), &kids, &below, &mut tops, 0);
    Found { subtree, tops, touched }
}

/// Forgets the records of `(a, b)` and of every inner pair below it; its stored leaves that are
/// not touched go to `untouched`.
fn forget_below<T, M, N, W>(
    map: &mut PairMap<NodeId>,
    tree: &Tree,
    a: NodeId,
    b: NodeId,
    rules: &Rules<T, M, N, W>,
    untouched: &mut Vec<(NodeId, NodeId)>,
) where
    T: Fn(NodeId, NodeId) -> bool,
    N: Fn(NodeId, NodeId) -> bool,
{
    let mut stack = vec![(a, b)];
    while let Some((x, y)) = stack.pop() {
        match map.remove(&key(x, y)) {
            Some(s) => stack.extend_from_slice(&children(tree, x, y, s)),
            None if !(rules.neutral)(x, y) && !(rules.touched)(x, y) => untouched.push((x, y)),
            None => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Aabb;
    use crate::hierarchy::touch::{Moves, Touch, neutral};
    use crate::hierarchy::update::update_frame;
    use crate::hierarchy::{HierarchySettings, solve_frame};
    use crate::system::no_progress;

    /// The update's walk with its first levels in parallel finds the same tops, touched and
    /// untouched pairs, in the same order, and forgets the same records as the walk in turn, for
    /// random moves over the moving-light box's pair tree after an update (a rule that links
    /// some inner pairs whole, so that subtrees' tops are dropped as well as kept).
    #[test]
    fn the_parallel_walk_is_the_walk_in_turn() {
        let scene = crate::scenes::cornell_box_moving_light(4, 8, crate::scene::Settings::default());
        let hs = HierarchySettings { keep_pair_tree: true, ..Default::default() };
        let mut first = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
        let h = update_frame(&mut first, &scene, 2.0, &hs, &no_progress).unwrap();
        let tree = &h.hierarchy.tree;
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (scene_box, mut redone) = (tree.bounds(tree.root), 0);
        for case in 0..60 {
            let faces: Vec<bool> = (0..tree.faces.len()).map(|_| next() < 0.01 * (case % 3) as f64).collect();
            let c = scene_box.min + scene_box.diagonal() * glam::DVec3::new(next(), next(), next());
            let half = scene_box.diagonal() * (0.02 + 0.3 * next());
            let moves = Moves { faces, swept: vec![Aabb { min: c - half, max: c + half }] };
            let touch = Touch::new(tree, &moves);
            let walk = |levels: u32| {
                let mut splits = h.hierarchy.splits.clone();
                let redo = splits
                    .coarsest_touched_at(
                        tree,
                        |a, b| touch.pair(a, b),
                        |a, b| touch.may_below(a, b),
                        |a, b| neutral(tree, a, b),
                        |a, b| (a ^ b) % 5 == 0,
                        levels,
                    )
                    .unwrap();
                (redo, splits.len())
            };
            let (in_turn, parallel) = (walk(0), walk(PARALLEL_LEVELS));
            assert_eq!(in_turn, parallel, "case {case}");
            redone += usize::from(!in_turn.0.tops.is_empty());
        }
        assert!(redone > 20, "only {redone} of 60 moves redid a subtree");
    }
}
