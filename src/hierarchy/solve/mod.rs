//! The solve over hierarchical links: Jacobi iteration with push-pull.
//!
//! Each sweep gathers through every link from the sources' current state (eq. 6 blocks between
//! surfaces; between a cluster and anything, the source's intensity towards the receiver over
//! `d^2`, [`super::lobes`]), then pushes what each node gathered down to the leaves (a
//! surface's polynomial restricted to its quadrants by [`TwoScale`]; a cluster's irradiance lobes
//! to its faces, each with its own normal), sets `b = e + rho H` at the leaves, and pulls the
//! result back up (the parent's projection of its children; a cluster's intensity lobes as the
//! sum of its faces'). On a fixed set of leaves with links only between leaves this is the flat
//! system's Jacobi iteration, so it converges to the flat solution of those elements.
//!
//! [`State`] is split by phase, an `impl State` block per file: this file holds the state, its
//! growth with the tree, the pull and the solve's loop of sweeps; `sources.rs` the leaves'
//! sources (emission and the lights' `rho E_d`, [`LeafRays`]); `bound.rs` the hemisphere bound
//! and its furnace ([`State::bound_leaves`]).

mod bound;
mod sources;

pub use sources::LeafRays;

use glam::DVec3;
use rayon::prelude::*;

use super::anderson::Anderson;
use super::coupling::Link;
use super::lobes::{self, Lobes};
use super::packed::{ClusterEntry, LinkChanges, PackedLinks};
use super::push_pull::{Leaves, Nodes, Walk};
use super::tree::{NodeId, Tree};
use super::two_scale::TwoScale;
use crate::budget;
use crate::error::{Error, Result};

/// The radiosity state of every node.
#[derive(Clone)]
pub struct State {
    nb: usize,
    /// `b^k` per surface node (`nodes x nb`): solved at leaves, pulled above.
    pub b: Vec<[f64; 3]>,
    /// `e^k + (rho E_d)^k` at leaves (`nodes x nb`), once `has_sources`.
    pub sources: Vec<[f64; 3]>,
    has_sources: Vec<bool>,
    /// Area-mean radiosity per node.
    pub mean: Vec<[f64; 3]>,
    /// Intensity lobes per cluster and face (W/sr by direction): what it shoots through
    /// cluster links.
    lobes: Vec<Lobes>,
    /// Per node, the factor a leaf's reflectance is taken with: the hemisphere bound
    /// ([`State::bound_leaves`]); empty: 1 everywhere.
    bound: Vec<f64>,
    two_scale: TwoScale,
}

/// Counts of one solve.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SolveStats {
    pub sweeps: usize,
    /// Rows the hemisphere bound's furnace gathered ([`State::bound_leaves`]; all the nodes, or
    /// the receivers whose links changed).
    pub furnace_rows: usize,
    /// Wall seconds of the furnace (the rest of the solve is its sweeps).
    pub furnace_seconds: f64,
    /// Area-weighted change of the leaves' mean radiosity in the last sweep (W).
    pub last_change: f64,
}

impl State {
    pub fn new(tree: &Tree) -> Self {
        let nb = tree.basis.len();
        let n = tree.nodes.len();
        Self {
            nb,
            b: vec![[0.0; 3]; n * nb],
            sources: vec![[0.0; 3]; n * nb],
            has_sources: vec![false; n],
            mean: vec![[0.0; 3]; n],
            lobes: vec![lobes::ZERO; n],
            bound: Vec::new(),
            two_scale: TwoScale::new(tree.basis),
        }
    }

    /// Takes in nodes the tree gained since: each new surface starts from its parent's polynomial
    /// restricted to it, so a refined state is the state it refines.
    /// [`crate::Error::OutOfMemory`] when the larger state cannot be had (the state is then as
    /// it was).
    pub fn grow(&mut self, tree: &Tree) -> Result<()> {
        let (nb, old) = (self.nb, self.mean.len());
        let n = tree.nodes.len();
        if n == old {
            return Ok(());
        }
        let what = "the hierarchy's solution";
        budget::try_reserve_exact(&mut self.b, (n - old) * nb, what)?;
        budget::try_reserve_exact(&mut self.sources, (n - old) * nb, what)?;
        budget::try_reserve_exact(&mut self.has_sources, n - old, what)?;
        budget::try_reserve_exact(&mut self.mean, n - old, what)?;
        budget::try_reserve_exact(&mut self.lobes, n - old, what)?;
        self.b.resize(n * nb, [0.0; 3]);
        self.sources.resize(n * nb, [0.0; 3]);
        self.has_sources.resize(n, false);
        self.mean.resize(n, [0.0; 3]);
        self.lobes.resize(n, lobes::ZERO);
        // Children are appended after their parent, so parents are complete when met.
        for id in 0..old {
            let Some(s) = tree.nodes[id].surface() else { continue };
            let Some(children) = s.children else { continue };
            for (q, &c) in children.iter().enumerate() {
                let c = c as usize;
                if c < old {
                    continue;
                }
                self.push_from(id, q, c);
            }
        }
        for id in old..n {
            let Some(s) = tree.nodes[id].surface() else { continue };
            let Some(children) = s.children else { continue };
            for (q, &c) in children.iter().enumerate() {
                self.push_from(id, q, c as usize);
            }
        }
        Ok(())
    }

    fn push_from(&mut self, parent: usize, q: usize, child: usize) {
        let nb = self.nb;
        let p: Vec<[f64; 3]> = self.b[parent * nb..(parent + 1) * nb].to_vec();
        let c = &mut self.b[child * nb..(child + 1) * nb];
        c.iter_mut().for_each(|x| *x = [0.0; 3]);
        self.two_scale.push_add(q, &p, c);
        self.mean[child] = self.mean[parent];
    }

    /// Pulls the leaves' current `b` up the tree (means, cluster lobes) without solving: after
    /// faces moved, so that the next sweep shoots from their new normals and areas. A later
    /// frame's solve starts here, from the last frame's solution.
    pub fn refresh(&mut self, tree: &Tree) {
        self.walk(tree).pull(tree.root, 0);
    }

    /// A walk over the tree that writes this state's nodes ([`push_pull`](super::push_pull)).
    fn walk<'a>(&'a mut self, tree: &'a Tree) -> Walk<'a> {
        Walk {
            tree,
            nodes: Nodes::new(&mut self.b, &mut self.mean, &mut self.lobes, self.nb),
            sources: &self.sources,
            leaves: Leaves::Solve { bound: &self.bound },
            two_scale: &self.two_scale,
            nb: self.nb,
        }
    }

    /// Sets every leaf to its sources and pulls: the state before any light has bounced.
    pub fn start_from_sources(&mut self, tree: &Tree) {
        let nb = self.nb;
        let mut leaves = Vec::new();
        tree.leaves_below(tree.root, &mut leaves);
        for id in leaves {
            let i = id as usize;
            let src: Vec<[f64; 3]> = self.sources[i * nb..(i + 1) * nb].to_vec();
            self.b[i * nb..(i + 1) * nb].copy_from_slice(&src);
        }
        self.refresh(tree);
    }

    /// Jacobi sweeps, each mixed with the last `hs.anderson_depth` ([`super::anderson`]), until
    /// the leaves' area-weighted change falls below `stop` (W), at most `hs.max_sweeps`.
    pub fn solve(
        &mut self,
        tree: &Tree,
        links: &[Link],
        stop: f64,
        hs: &super::HierarchySettings,
        cancel: &(dyn Fn() -> bool + Sync),
    ) -> Result<SolveStats> {
        let geometry = |r, s, t| cluster_entry(tree, r, s, t);
        let mut packed =
            PackedLinks::new(tree.nodes.len(), links, self.nb, &mut LinkChanges::default(), &geometry)?;
        self.solve_packed(tree, &mut packed, stop, hs, cancel)
    }

    /// [`State::solve`] on links packed already (whose furnace rows the hemisphere bound keeps,
    /// [`PackedLinks::furnace`]).
    pub fn solve_packed(
        &mut self,
        tree: &Tree,
        packed: &mut PackedLinks,
        stop: f64,
        hs: &super::HierarchySettings,
        cancel: &(dyn Fn() -> bool + Sync),
    ) -> Result<SolveStats> {
        let mut leaves = Vec::new();
        tree.leaves_below(tree.root, &mut leaves);
        let t = std::time::Instant::now();
        let furnace_rows = self.bound_leaves(tree, &leaves, packed, hs.check_furnace)?;
        let furnace_seconds = t.elapsed().as_secs_f64();
        let mut stats = SolveStats { furnace_rows, furnace_seconds, ..Default::default() };
        let packed = &*packed;
        // One buffer for every sweep's gathered light: made anew each sweep (190 MB on the full
        // monastery), its pages' first touches were a twentieth of an updated frame.
        let mut gathered = Gathered::empty();
        let first = self.source_power(tree).max(1e-300);
        // Without room for the mixer's columns the plain sweeps still converge, only slower.
        let depth = hs.anderson_depth;
        let mut accelerated =
            (depth > 0).then(|| Accelerated::new(tree, &leaves, self.nb, depth).ok()).flatten();
        for sweep in 0..hs.max_sweeps {
            if cancel() {
                return Err(Error::Cancelled);
            }
            if let Some(a) = accelerated.as_mut() {
                a.read(&self.b, &leaves, self.nb, Side::Before);
            }
            self.gather(tree, packed, &mut gathered)?;
            // With the mixer, which changes the leaves before anything reads the nodes above,
            // the sweep pushes only, and the pull follows the mixing.
            let mixing = accelerated.is_some();
            let change = self.push(tree, &gathered, !mixing);
            stats.sweeps = sweep + 1;
            stats.last_change = change;
            if !change.is_finite() || change > 1e6 * first {
                return Err(Error::Internal("the hierarchical solution diverges".into()));
            }
            // Stopping on the sweep's own result keeps the state one plain sweep of itself.
            if change <= stop {
                if mixing {
                    self.refresh(tree);
                }
                break;
            }
            if let Some(a) = accelerated.as_mut() {
                a.read(&self.b, &leaves, self.nb, Side::After);
                a.mix_into(&mut self.b, self.nb);
                self.refresh(tree);
            }
        }
        Ok(stats)
    }

    /// What every node receives through its own links from the current state, into `out`
    /// (grown to the tree on the first sweep).
    fn gather(&self, tree: &Tree, packed: &PackedLinks, out: &mut Gathered) -> Result<()> {
        let (nb, n) = (self.nb, tree.nodes.len());
        if out.h.len() != n * nb || out.lobes.len() != n || out.constant.len() != n {
            let what = "the hierarchy's gathered light";
            *out = Gathered { h: Vec::new(), lobes: Vec::new(), constant: Vec::new() };
            out.h = budget::try_filled(n * nb, [0.0; 3], what)?;
            out.lobes = budget::try_filled(n, lobes::ZERO, what)?;
            out.constant = budget::try_filled(n, [0.0; 3], what)?;
        }
        // Every node's constant coefficient in a row of its own: most links of a model of small
        // triangles are constant links (2.4M of 3.0M on a 30k-triangle model), and reading their
        // sources' `b^0` from a third of `b` (`nb` coefficients apart) was most of a sweep.
        out.constant.par_iter_mut().zip(self.b.par_chunks(nb)).for_each(|(c, b)| *c = b[0]);
        let constant = &out.constant;
        out.h.par_chunks_mut(nb).zip(out.lobes.par_iter_mut()).enumerate().for_each(|(r, (hr, lr))| {
            hr.fill([0.0; 3]);
            *lr = lobes::ZERO;
            // What arrives in the constant term, summed apart from `hr` (which the compiler
            // cannot keep in registers across the loop: a store and a load per entry).
            let mut h0 = [0.0f64; 3];
            let planar = tree.nodes[r].plane_normal.is_some();
            // The packings in turn: the links packed whole, then those made since.
            for blocks in packed.parts() {
                // Surface links: their blocks in this receiver's run of the packed copy, read in
                // order (the per-link boxes are scattered over the heap, and reading them was most
                // of a sweep's time).
                let (sources, run) = blocks.of(r);
                for (&s, block) in sources.iter().zip(run.chunks_exact(nb * nb)) {
                    let bs = &self.b[s as usize * nb..(s as usize + 1) * nb];
                    for (k, row) in block.chunks_exact(nb).enumerate() {
                        let mut sum = [0.0f64; 3];
                        for (&g, b) in row.iter().zip(bs) {
                            let g = g as f64;
                            sum[0] += g * b[0];
                            sum[1] += g * b[1];
                            sum[2] += g * b[2];
                        }
                        for c in 0..3 {
                            hr[k][c] += sum[c];
                        }
                    }
                }
                // Constant links: the receiver's constant term from the source's.
                for &(s, g) in blocks.constants_of(r) {
                    let b0 = &constant[s as usize];
                    let g = g as f64;
                    for c in 0..3 {
                        h0[c] += g * b0[c];
                    }
                }
                // Cluster links (their geometry worked out when packed, [`cluster_entry`]); a
                // planar receiver holds its (constant) irradiance in `H^0`, which the push hands
                // to its faces unchanged.
                for e in blocks.clusters_of(r) {
                    self.cluster_arrival(e, planar, &mut h0, lr);
                }
            }
            for c in 0..3 {
                hr[0][c] += h0[c];
            }
        });
        Ok(())
    }

    /// Adds what the cluster link `e` brings its receiver (`planar`: one with a plane) from the
    /// source's current state: to the receiver's constant term `h0`, or as a lobe to `lobes`.
    #[inline]
    fn cluster_arrival(&self, e: &ClusterEntry, planar: bool, h0: &mut [f64; 3], lobes: &mut Lobes) {
        // (Zero: a link taken out, `PackedLinks`, or facing away.)
        if e.scale == 0.0 {
            return;
        }
        let s = e.source as usize;
        // (The direction only for lobes, and its harmonics once for both ends: a planar source's
        // or receiver's cosine is in the entry.)
        let lobe_source = e.emit < 0.0;
        let y = (lobe_source || !planar)
            .then(|| lobes::harmonics(DVec3::new(e.w[0] as f64, e.w[1] as f64, e.w[2] as f64)));
        let intensity = match &y {
            Some(y) if lobe_source => lobes::eval_at(&self.lobes[s], y),
            _ => self.mean[s].map(|m| m * e.emit as f64),
        };
        let scale = e.scale as f64;
        let arriving = intensity.map(|i| i * scale);
        match &y {
            Some(y) if !planar => lobes::add_lobe_at(lobes, &lobes::opposite(y), arriving),
            _ => {
                for c in 0..3 {
                    h0[c] += arriving[c];
                }
            }
        }
    }

    /// Pushes `gathered` to the leaves, sets `b = e + rho H` there and, with `pull`, pulls
    /// (without, the nodes above the leaves wait for a [`State::refresh`]; [`Walk::push`]);
    /// returns the leaves' area-weighted change of mean radiosity.
    fn push(&mut self, tree: &Tree, gathered: &Gathered, pull: bool) -> f64 {
        let zero = [[0.0; 3]; crate::basis::MAX_LEN];
        let nb = self.nb;
        self.walk(tree).push(tree.root, &lobes::ZERO, &zero[..nb], gathered, 0, pull)
    }

    /// The intensity lobes node `id` shoots through cluster links (W/sr by direction).
    pub fn lobes(&self, id: NodeId) -> &Lobes {
        &self.lobes[id as usize]
    }

    /// `b` of surface node `id`.
    pub fn coefficients(&self, id: NodeId) -> &[[f64; 3]] {
        &self.b[id as usize * self.nb..(id as usize + 1) * self.nb]
    }
}

/// The cluster link from `s` to `r` with this transmittance as a sweep reads it: the source's
/// intensity towards the receiver (a planar source's mean radiosity times its projected area over
/// pi, else its lobes, [`super::lobes`]) becomes the irradiance `I cos / d^2` times the
/// transmittance, which `b = e + rho H` takes as it is (eq. 1); a receiver that is not planar
/// gathers it as a lobe from the direction it comes from.
pub(super) fn cluster_entry(tree: &Tree, r: NodeId, s: NodeId, transmittance: f32) -> ClusterEntry {
    let (nr, ns) = (&tree.nodes[r as usize], &tree.nodes[s as usize]);
    let v = nr.centre - ns.centre;
    let d2 = v.length_squared();
    if d2 <= 0.0 {
        return ClusterEntry::none(s);
    }
    let w = v / d2.sqrt();
    let emit = match ns.plane_normal {
        Some(n) => ns.area * n.dot(w).max(0.0) / std::f64::consts::PI,
        None => -1.0,
    };
    let cos = nr.plane_normal.map_or(1.0, |n| (-n.dot(w)).max(0.0));
    let scale = transmittance as f64 / d2 * cos;
    ClusterEntry { source: s, w: w.as_vec3().to_array(), emit: emit as f32, scale: scale as f32 }
}

/// How many steps the solve's Anderson mixer keeps by default. On the animation bench's three scenes
/// (fresh frames' sweeps, room / billiard / box) plain Jacobi took 26.2 / 19.1 / 14.9; depth 1
/// 17.1 / 12.0 / 12.0, 2 16.1 / 11.5 / 10.0, 3 13.8 / 10.4 / 9.0, 4 12.1 / 10.0 / 9.0, 8 11.3 /
/// 9.7 / 9.0: 4 is within a sweep of 8 at half the columns.
pub(crate) const ANDERSON_DEPTH: usize = 4;

/// Which copy of the leaves [`Accelerated::read`] fills.
#[derive(Clone, Copy)]
enum Side {
    Before,
    After,
}

/// The leaves' coefficients before and after a sweep, and the mixer that takes the next iterate
/// from them ([`super::anderson`]).
struct Accelerated {
    before: Vec<f64>,
    after: Vec<f64>,
    mixer: Anderson,
    /// Per node, its place among the leaves ([`NOT_A_LEAF`] for the others): the mixed leaves
    /// are written back node by node, in parallel.
    slot: Vec<u32>,
}

const NOT_A_LEAF: u32 = u32::MAX;

impl Accelerated {
    fn new(tree: &Tree, leaves: &[NodeId], nb: usize, depth: usize) -> Result<Self> {
        let what = "the hierarchical solve's acceleration";
        let n = leaves.len() * nb * 3;
        let weights = leaves.iter().map(|&id| tree.nodes[id as usize].area).collect();
        let mut slot = budget::try_filled(tree.nodes.len(), NOT_A_LEAF, what)?;
        for (k, &id) in leaves.iter().enumerate() {
            slot[id as usize] = k as u32;
        }
        Ok(Self {
            before: budget::try_filled(n, 0.0, what)?,
            after: budget::try_filled(n, 0.0, what)?,
            mixer: Anderson::new(depth, weights, nb * 3)?,
            slot,
        })
    }

    fn read(&mut self, b: &[[f64; 3]], leaves: &[NodeId], nb: usize, side: Side) {
        let out = match side {
            Side::Before => &mut self.before,
            Side::After => &mut self.after,
        };
        out.par_chunks_exact_mut(nb * 3).zip(leaves).for_each(|(chunk, &id)| {
            let i = id as usize;
            for (dst, src) in chunk.chunks_exact_mut(3).zip(&b[i * nb..(i + 1) * nb]) {
                dst.copy_from_slice(src);
            }
        });
    }

    /// Mixes the last sweep and writes the next iterate to the leaves (the tree above them is
    /// then stale until a pull).
    fn mix_into(&mut self, b: &mut [[f64; 3]], nb: usize) {
        self.mixer.mix(&self.before, &mut self.after);
        let after = &self.after;
        b.par_chunks_exact_mut(nb).zip(&self.slot).for_each(|(b, &k)| {
            if k != NOT_A_LEAF {
                let k = k as usize;
                for (dst, src) in b.iter_mut().zip(after[k * nb * 3..(k + 1) * nb * 3].chunks_exact(3)) {
                    dst.copy_from_slice(src);
                }
            }
        });
    }
}

/// What one gather sweep delivered per node.
pub(super) struct Gathered {
    /// `H^k` per surface node (`nodes x nb`; empty: nothing).
    pub h: Vec<[f64; 3]>,
    /// Irradiance lobes per cluster (empty: nothing).
    pub lobes: Vec<Lobes>,
    /// Per node, its `b^0`, read by the constant links.
    constant: Vec<[f64; 3]>,
}

impl Gathered {
    pub(super) fn empty() -> Self {
        Self { h: Vec::new(), lobes: Vec::new(), constant: Vec::new() }
    }
}
