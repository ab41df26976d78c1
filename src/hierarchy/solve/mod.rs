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
//! and its furnace ([`State::bound_leaves`]); `sweep.rs` one sweep's gather and push
//! ([`State::gather`], [`cluster_entry`]) and the Anderson mixer over the sweeps.

mod bound;
mod sources;
mod sweep;

pub use sources::LeafRays;
pub(crate) use sweep::ANDERSON_DEPTH;
use sweep::{Accelerated, Side};
pub(super) use sweep::{Gathered, cluster_entry};

use super::coupling::Link;
use super::lobes::{self, Lobes};
use super::packed::{LinkChanges, PackedLinks};
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

    /// The intensity lobes node `id` shoots through cluster links (W/sr by direction).
    pub fn lobes(&self, id: NodeId) -> &Lobes {
        &self.lobes[id as usize]
    }

    /// `b` of surface node `id`.
    pub fn coefficients(&self, id: NodeId) -> &[[f64; 3]] {
        &self.b[id as usize * self.nb..(id as usize + 1) * self.nb]
    }
}
