//! One sweep: what every node gathers through its links from the current state
//! ([`State::gather`]; a cluster link's geometry, [`cluster_entry`]), pushed to the leaves and
//! pulled ([`State::push`]), and the Anderson mixer over the sweeps ([`Accelerated`]).

use glam::DVec3;
use rayon::prelude::*;

use super::State;
use crate::budget;
use crate::error::Result;
use crate::hierarchy::anderson::Anderson;
use crate::hierarchy::lobes::{self, Lobes};
use crate::hierarchy::packed::{ClusterEntry, PackedLinks};
use crate::hierarchy::push_pull::NO_SLOPE;
use crate::hierarchy::tree::{NodeId, Tree};

impl State {
    /// What every node receives through its own links from the current state, into `out`
    /// (grown to the tree on the first sweep).
    pub(super) fn gather(&self, tree: &Tree, packed: &PackedLinks, out: &mut Gathered) -> Result<()> {
        let (nb, n) = (self.nb, tree.nodes.len());
        let built = tree.built();
        if out.h.len() != n * nb
            || out.lobes.len() != n
            || out.constant.len() != n
            || out.slopes.len() != built
        {
            let what = "the hierarchy's gathered light";
            *out = Gathered::empty();
            out.h = budget::try_filled(n * nb, [0.0; 3], what)?;
            out.lobes = budget::try_filled(n, lobes::ZERO, what)?;
            out.constant = budget::try_filled(n, [0.0; 3], what)?;
            out.slopes = budget::try_filled(built, [DVec3::ZERO; 3], what)?;
        }
        // Every node's constant coefficient in a row of its own: most links of a model of small
        // triangles are constant links (2.4M of 3.0M on a 30k-triangle model), and reading their
        // sources' `b^0` from a third of `b` (`nb` coefficients apart) was most of a sweep.
        out.constant.par_iter_mut().zip(self.b.par_chunks(nb)).for_each(|(c, b)| *c = b[0]);
        let constant = &out.constant;
        let slopes = slope_rows(&mut out.slopes, n);
        out.h.par_chunks_mut(nb).zip(out.lobes.par_iter_mut()).zip(slopes).enumerate().for_each(
            |(r, ((hr, lr), sr))| {
                hr.fill([0.0; 3]);
                *lr = lobes::ZERO;
                let mut slope = [DVec3::ZERO; 3];
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
                        self.cluster_arrival(e, planar, (&mut h0, &mut slope), lr);
                    }
                }
                for c in 0..3 {
                    hr[0][c] += h0[c];
                }
                if let Some(sr) = sr {
                    *sr = slope;
                }
            },
        );
        Ok(())
    }

    /// Adds what the cluster link `e` brings its receiver (`planar`: one with a plane) from the
    /// source's current state: to the receiver's constant term `h0` and its slope over its plane
    /// (`slope`, per channel: a planar cluster's, [`ClusterEntry::slope`]), or as a lobe to
    /// `lobes`.
    #[inline]
    pub(super) fn cluster_arrival(
        &self,
        e: &ClusterEntry,
        planar: bool,
        (h0, slope): (&mut [f64; 3], &mut [DVec3; 3]),
        lobes: &mut Lobes,
    ) {
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
                let g = DVec3::new(e.slope[0] as f64, e.slope[1] as f64, e.slope[2] as f64);
                for c in 0..3 {
                    h0[c] += arriving[c];
                    slope[c] += arriving[c] * g;
                }
            }
        }
    }

    /// Pushes `gathered` to the leaves, sets `b = e + rho H` there and, with `pull`, pulls
    /// (without, the nodes above the leaves wait for a [`State::refresh`];
    /// [`Walk::push`](crate::hierarchy::push_pull::Walk::push)); returns the leaves'
    /// area-weighted change of mean radiosity.
    pub(super) fn push(&mut self, tree: &Tree, gathered: &Gathered, pull: bool) -> f64 {
        let zero = [[0.0; 3]; crate::basis::MAX_LEN];
        let nb = self.nb;
        self.walk(tree).push(tree.root, (&lobes::ZERO, &NO_SLOPE), &zero[..nb], gathered, 0, pull)
    }
}

/// The cluster link from `s` to `r` with this transmittance as a sweep reads it: the source's
/// intensity towards the receiver (a planar source's mean radiosity times its projected area over
/// pi, else its lobes, [`crate::hierarchy::lobes`]) becomes the irradiance `I cos / d^2` times the
/// transmittance, which `b = e + rho H` takes as it is (eq. 1); a receiver that is not planar
/// gathers it as a lobe from the direction it comes from.
pub(in crate::hierarchy) fn cluster_entry(
    tree: &Tree,
    r: NodeId,
    s: NodeId,
    transmittance: f32,
) -> ClusterEntry {
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
    let slope = match nr.plane_normal {
        Some(n) if nr.is_cluster() && scale > 0.0 => slope_over_plane(tree, r, s, n),
        _ => DVec3::ZERO,
    };
    ClusterEntry {
        source: s,
        w: w.as_vec3().to_array(),
        emit: emit as f32,
        scale: scale as f32,
        slope: slope.as_vec3().to_array(),
    }
}

/// The relative slope `grad H / H` over the plane of the planar cluster `r` (normal `n`), at its
/// centroid, of the light the source `s` sends it as a point at its centre: a planar source's
/// `cos_s cos_r / r^2` is `(n_s . r)(-n . r) / |r|^4` (`r` from the source to the point), another's
/// intensity taken as constant over the receiver's small angle, `(-n . r) / |r|^3`. The receiver's
/// cosine varies along its normal only, so in its plane `grad ln H = n_s / (n_s . r) - k r / |r|^2`
/// projected, `k` 4 or 3. A cluster link's total over the receiver is right (its kernel ratio,
/// [`crate::hierarchy::coupling`]) but its faces took it evenly, the nearer too dark and the
/// farther too bright by the spread of `1 / r^2` over the cluster: first order in its size over
/// the distance, where the total is second. The slope, pushed to each child at its own centroid,
/// leaves that to second order as well. Capped so that `H` changes by at most a half across the
/// receiver's bounding sphere (grazing sources, where the linear model fails first).
fn slope_over_plane(tree: &Tree, r: NodeId, s: NodeId, n: DVec3) -> DVec3 {
    let (nr, ns) = (&tree.nodes[r as usize], &tree.nodes[s as usize]);
    let v = tree.centroid(r) - ns.centre;
    let d2 = v.length_squared();
    if d2 <= 0.0 || n.dot(v) >= 0.0 {
        return DVec3::ZERO;
    }
    let mut g = match ns.plane_normal {
        Some(m) if m.dot(v) > 0.0 => m / m.dot(v) - 4.0 * v / d2,
        Some(_) => return DVec3::ZERO,
        None => -3.0 * v / d2,
    };
    g -= g.dot(n) * n;
    let cap = 0.5 / nr.radius.max(1e-300);
    let length = g.length();
    if length > cap { g * (cap / length) } else { g }
}

/// How many steps the solve's Anderson mixer keeps by default. On the animation bench's three scenes
/// (fresh frames' sweeps, room / billiard / box) plain Jacobi took 26.2 / 19.1 / 14.9; depth 1
/// 17.1 / 12.0 / 12.0, 2 16.1 / 11.5 / 10.0, 3 13.8 / 10.4 / 9.0, 4 12.1 / 10.0 / 9.0, 8 11.3 /
/// 9.7 / 9.0: 4 is within a sweep of 8 at half the columns.
pub(crate) const ANDERSON_DEPTH: usize = 4;

/// Which copy of the leaves [`Accelerated::read`] fills.
#[derive(Clone, Copy)]
pub(super) enum Side {
    Before,
    After,
}

/// The leaves' coefficients before and after a sweep, and the mixer that takes the next iterate
/// from them ([`crate::hierarchy::anderson`]).
pub(super) struct Accelerated {
    before: Vec<f64>,
    after: Vec<f64>,
    mixer: Anderson,
    /// Per node, its place among the leaves ([`NOT_A_LEAF`] for the others): the mixed leaves
    /// are written back node by node, in parallel.
    slot: Vec<u32>,
}

const NOT_A_LEAF: u32 = u32::MAX;

impl Accelerated {
    pub(super) fn new(tree: &Tree, leaves: &[NodeId], nb: usize, depth: usize) -> Result<Self> {
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

    pub(super) fn read(&mut self, b: &[[f64; 3]], leaves: &[NodeId], nb: usize, side: Side) {
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
    pub(super) fn mix_into(&mut self, b: &mut [[f64; 3]], nb: usize) {
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
pub(in crate::hierarchy) struct Gathered {
    /// `H^k` per surface node (`nodes x nb`; empty: nothing).
    pub h: Vec<[f64; 3]>,
    /// Irradiance lobes per cluster (empty: nothing).
    pub lobes: Vec<Lobes>,
    /// Per node of the cluster build ([`Tree::built`]), the slope over its plane of what a
    /// planar cluster gathered (`grad H` per channel; zero for the others): the push hands each
    /// child the constant at its own centroid.
    pub slopes: Vec<[DVec3; 3]>,
    /// Per node, its `b^0`, read by the constant links.
    pub(super) constant: Vec<[f64; 3]>,
}

impl Gathered {
    pub(in crate::hierarchy) fn empty() -> Self {
        Self { h: Vec::new(), lobes: Vec::new(), constant: Vec::new(), slopes: Vec::new() }
    }
}

/// Per node `0..n`, its row of `slopes` (the cluster build's nodes) or `None` (a node below a
/// face), for zipping with the other rows of a gather.
pub(super) fn slope_rows(
    slopes: &mut [[DVec3; 3]],
    n: usize,
) -> impl IndexedParallelIterator<Item = Option<&mut [DVec3; 3]>> {
    let built = slopes.len();
    slopes.par_iter_mut().map(Some).chain((built..n).into_par_iter().map(|_| None))
}
