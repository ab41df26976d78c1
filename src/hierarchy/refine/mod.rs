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
//!
//! By job: `oracle.rs` the verdict on one pair ([`Oracle`]), `descent.rs` the work stack decided
//! in parallel and each pair's share of the progress, `passes.rs` the passes over the stored pairs
//! and taking pairs out of them; here the [`Hierarchy`] that holds the links and builds them
//! ([`Hierarchy::link_all`], [`Hierarchy::link_pairs`], [`Hierarchy::relink`]).

mod descent;
mod oracle;
mod passes;

use rayon::prelude::*;

pub use super::coupling::Link;
use super::coupling::{self, LinkContext, Weight};
use super::packed::{LinkChanges, PackedLinks};
use super::pair_tree::Splits;
use super::tree::{Kind, NodeId, Tree};
use crate::budget;
use crate::error::Result;
use descent::{Decided, Deciding, Descent, PairSpace};
pub use oracle::Oracle;
use oracle::{Filing, Verdict};
pub use passes::take_out;
use passes::{failing, indices_where};

/// What [`budget`]'s errors name.
const LINKS: &str = "the hierarchy's links";
const NODES: &str = "the hierarchy's nodes";

/// Hears the share of a batch of links computed (0 to 1); `false` cancels the refinement.
pub type LinkProgress<'a> = &'a (dyn Fn(f64) -> bool + Sync);

/// Links computed between two progress reports: a few hundred ms on two cores for the costliest
/// (near, partly visible) pairs, far less than a sweep for the usual ones.
const LINK_CHUNK: usize = 4096;

/// Accepted pairs decided before they are computed: a bound on the refinement's own memory.
const BATCH: usize = 1 << 20;

/// Pairs taken off the work stack and decided at once, in parallel.
const DECIDE_CHUNK: usize = 1 << 14;

/// Whether `a` and `b` are parts of one face.
fn same_face(tree: &Tree, a: NodeId, b: NodeId) -> bool {
    matches!((tree.node(a).surface(), tree.node(b).surface()), (Some(x), Some(y)) if x.face == y.face)
}

/// A relink after which no node grew more than this many times brighter than its pairs were
/// decided at reads only their loads ([`Hierarchy::relink`]).
const QUICK_GROWTH: f64 = 2.0;

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
