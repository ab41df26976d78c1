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
pub fn children(tree: &Tree, a: NodeId, b: NodeId, s: NodeId) -> Vec<(NodeId, NodeId)> {
    let c = tree.children(s);
    if a == b {
        let mut out = Vec::with_capacity(c.len() * (c.len() + 1) / 2);
        for (i, &x) in c.iter().enumerate() {
            for &y in &c[i..] {
                out.push((x, y));
            }
        }
        out
    } else {
        let other = if s == a { b } else { a };
        c.iter().map(|&x| (x, other)).collect()
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
    /// [`Error::OutOfMemory`].
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
        touched: impl Fn(NodeId, NodeId) -> bool,
        may_touch: impl Fn(NodeId, NodeId) -> bool,
        neutral: impl Fn(NodeId, NodeId) -> bool,
        links_whole: impl Fn(NodeId, NodeId) -> bool,
    ) -> Option<Redo> {
        let map = self.map.as_mut()?;
        let mut redo = Redo::default();
        let root = tree.root;
        let rules =
            Rules { touched: &touched, may_touch: &may_touch, neutral: &neutral, links_whole: &links_whole };
        let top = visit(map, tree, &rules, (root, root), &mut redo.tops, &mut redo.touched);
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
#[derive(Default)]
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
                Some(&s) => stack.extend(children(tree, a, b, s).into_iter().rev()),
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
    let below: Vec<Subtree> = kids.iter().map(|&p| visit(map, tree, rules, p, tops, touched)).collect();
    let all = below.iter().all(|t| t.all);
    let any = below.iter().any(|t| t.any);
    if any && (all || (rules.links_whole)(a, b)) {
        // Redone whole from here or from above: the tops found below are inside.
        tops.truncate(first_top);
        return Subtree { all: true, any: true };
    }
    for (&(x, y), t) in kids.iter().zip(&below) {
        if t.all && t.any {
            tops.push((x, y));
        }
    }
    Subtree { all, any }
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
            Some(s) => stack.extend(children(tree, x, y, s)),
            None if !(rules.neutral)(x, y) && !(rules.touched)(x, y) => untouched.push((x, y)),
            None => {}
        }
    }
}
