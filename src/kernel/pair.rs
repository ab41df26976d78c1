//! Kernel coefficients of one pair of elements, both directions at once (eq. 6).
//!
//! `G_ij^kl = integral Gamma_k(s,t) integral g(x,y) VIS A_j(u,v) Gamma_l(u,v) du dv ds dt`, so that
//! `K_ij^kl = rho_i G_ij^kl`. The point kernel `g` is symmetric, so each evaluation feeds both
//! `G_ij` and `G_ji` (issue 2, item 3: the symmetry halves the work).
//!
//! Near-singular pairs (shared edges or corners, patches close relative to their size) are split
//! adaptively: a pair of sub-rectangles is integrated by Gauss when their bounding spheres are
//! separated by `SEPARATION` times the sum of their radii; otherwise the larger one is split into
//! quadrants, down to `MAX_DEPTH`, where the inner integral becomes the analytic point-to-polygon
//! form factor (Lambert's contour formula), which carries the `1/r^2` singularity exactly.

use glam::DVec3;

use crate::basis::Basis;
use crate::geometry::{Patch, Rect};
use crate::quadrature::GaussLegendre;
use crate::visibility::Visibility;

use super::point::point_to_polygon;
use super::samples::Samples;

/// Bounding spheres farther apart than this many radii-sums are integrated directly.
pub const SEPARATION: f64 = 1.5;
/// Deepest split of a near pair before the analytic inner integral takes over.
const MAX_DEPTH: usize = 3;

/// Pairs separated by more than this many radii-sums use [`PairContext::far_points`] per axis.
pub const FAR: f64 = 6.0;
/// Pairs separated by more than this (and at most [`FAR`]) use [`PairContext::mid_points`].
pub const MID: f64 = 3.0;

/// What pair integration needs to know besides the two elements.
pub struct PairContext<'a> {
    pub basis: Basis,
    /// The rule for near pairs and sub-pairs (`quadrature_order` points per axis).
    pub rule: &'a GaussLegendre,
    /// Visibility samples per axis (`m`); cells are `m x m`.
    pub vis_axis: usize,
    /// Use fewer points for separated pairs ([`PairContext::points_for`]).
    pub adaptive: bool,
}

impl PairContext<'_> {
    /// Points per axis for well-separated pairs: the kernel is smooth there (its nearest
    /// singularity is `FAR` radii away), so `order + 1` points, which still resolve every basis
    /// function, integrate `Gamma_k` times a cubic kernel exactly. Never more than the near rule.
    pub fn far_points(&self) -> usize {
        (self.basis.order() + 1).max(2).min(self.rule.len())
    }

    pub fn mid_points(&self) -> usize {
        (self.basis.order() + 1).max(3).min(self.rule.len())
    }

    /// Points per axis for a pair whose bounding spheres are `ratio` radii-sums apart.
    pub fn points_for(&self, ratio: f64) -> usize {
        if !self.adaptive {
            self.rule.len()
        } else if ratio > FAR {
            self.far_points()
        } else if ratio > MID {
            self.mid_points()
        } else {
            self.rule.len()
        }
    }
}

/// The two coefficient blocks of a pair, `nb x nb` each, row = receiver function `k`.
#[derive(Clone, Debug, PartialEq)]
pub struct PairCoefficients {
    /// `G_ij`: receiver `i`, source `j`.
    pub ij: Vec<f64>,
    /// `G_ji`: receiver `j`, source `i`.
    pub ji: Vec<f64>,
}

impl PairCoefficients {
    pub fn zeros(nb: usize) -> Self {
        Self { ij: vec![0.0; nb * nb], ji: vec![0.0; nb * nb] }
    }
}

/// Integrates the pair `(i, j)`. `whole(e, n)` gives element `e`'s samples over its full domain
/// with `n` points per axis (cached by the caller: most pairs need nothing else).
pub fn integrate_pair<'s>(
    ctx: &PairContext,
    pi: &Patch,
    pj: &Patch,
    whole: impl Fn(bool, usize) -> &'s Samples,
    vis: &Visibility,
) -> PairCoefficients {
    let mut out = PairCoefficients::zeros(ctx.basis.len());
    let spheres = (pi.bounding_sphere(), pj.bounding_sphere());
    integrate_pair_into(ctx, pi, pj, spheres, whole, vis, &mut out.ij, &mut out.ji);
    out
}

/// [`integrate_pair`] with the elements' bounding spheres given, accumulating into `ij` and `ji`
/// (`nb x nb` each, zeroed by the caller).
#[allow(clippy::too_many_arguments)]
pub(crate) fn integrate_pair_into<'s>(
    ctx: &PairContext,
    pi: &Patch,
    pj: &Patch,
    ((ci, ri), (cj, rj)): ((DVec3, f64), (DVec3, f64)),
    whole: impl Fn(bool, usize) -> &'s Samples,
    vis: &Visibility,
    ij: &mut [f64],
    ji: &mut [f64],
) {
    let ratio = ci.distance(cj) / (ri + rj);
    if ratio > SEPARATION {
        let n = ctx.points_for(ratio);
        gauss_leaf(ctx, whole(false, n), whole(true, n), vis, ij, ji);
    } else {
        let mut cache_i = SubSamples::new(pi);
        let mut cache_j = SubSamples::new(pj);
        let mut out = (ij, ji);
        split(ctx, &mut cache_i, &Rect::UNIT, &mut cache_j, &Rect::UNIT, vis, 0, &mut out);
    }
}

/// The samples of one element's sub-rectangles met while splitting a near pair, made once each:
/// the quadtree nodes down to [`MAX_DEPTH`] (1 + 4 + 16 + 64 of them).
struct SubSamples<'p> {
    patch: &'p Patch,
    slots: Vec<Option<Samples>>,
    /// Rectangles that are not quadtree nodes (never met today), made on demand.
    other: Option<Samples>,
}

impl<'p> SubSamples<'p> {
    fn new(patch: &'p Patch) -> Self {
        Self { patch, slots: Vec::new(), other: None }
    }

    /// Slot of a quadtree node: level `L` (side `2^-L`), then `s0 2^L`, `t0 2^L`.
    fn slot(r: &Rect) -> Option<usize> {
        let mut base = 0;
        for level in 0..=MAX_DEPTH as i32 {
            let n = 1usize << level;
            let side = 0.5f64.powi(level);
            if r.s1 - r.s0 == side && r.t1 - r.t0 == side {
                let (a, b) = (r.s0 * n as f64, r.t0 * n as f64);
                if a.fract() != 0.0 || b.fract() != 0.0 || a < 0.0 || b < 0.0 {
                    return None;
                }
                let (a, b) = (a as usize, b as usize);
                return (a < n && b < n).then_some(base + a * n + b);
            }
            base += n * n;
        }
        None
    }

    fn get(&mut self, ctx: &PairContext, r: &Rect) -> &Samples {
        let make = || Samples::new(self.patch, r, ctx.rule, ctx.basis, ctx.vis_axis);
        match Self::slot(r) {
            Some(k) => {
                if self.slots.is_empty() {
                    self.slots.resize_with(85, || None);
                }
                if self.slots[k].is_none() {
                    self.slots[k] = Some(make());
                }
                self.slots[k].as_ref().unwrap()
            }
            None => self.other.insert(make()),
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn split(
    ctx: &PairContext,
    cache_i: &mut SubSamples,
    rect_i: &Rect,
    cache_j: &mut SubSamples,
    rect_j: &Rect,
    vis: &Visibility,
    depth: usize,
    out: &mut (&mut [f64], &mut [f64]),
) {
    let sub_i = cache_i.patch.sub_patch(rect_i);
    let sub_j = cache_j.patch.sub_patch(rect_j);
    let (ci, ri) = sub_i.bounding_sphere();
    let (cj, rj) = sub_j.bounding_sphere();
    if ci.distance(cj) > SEPARATION * (ri + rj) {
        let si = cache_i.get(ctx, rect_i);
        let sj = cache_j.get(ctx, rect_j);
        gauss_leaf(ctx, si, sj, vis, out.0, out.1);
        return;
    }
    if depth >= MAX_DEPTH {
        analytic_leaf(ctx, cache_i, rect_i, cache_j, rect_j, vis, out);
        return;
    }
    // Split the larger side; split both when they are of a size, so the recursion stays balanced.
    let split_i = ri >= 0.5 * rj;
    let split_j = rj >= 0.5 * ri;
    let (quad_i, quad_j) = (rect_i.quadrants(), rect_j.quadrants());
    let parts_i: &[Rect] = if split_i { &quad_i } else { std::slice::from_ref(rect_i) };
    let parts_j: &[Rect] = if split_j { &quad_j } else { std::slice::from_ref(rect_j) };
    for a in parts_i {
        for b in parts_j {
            split(ctx, cache_i, a, cache_j, b, vis, depth + 1, out);
        }
    }
}

/// Products `na x nbp` up to this use a stack buffer for `M` in [`gauss_leaf`].
const STACK_PRODUCT: usize = 256;

crate::simd::multiversion! {
    /// Tensor Gauss over both sub-domains, as two small matrix products per direction:
    /// `G_ij += Phi_i^T diag(w_i) M diag(wA_j) Phi_j` and `G_ji += Phi_j^T diag(w_j) M^T diag(wA_i) Phi_i`
    /// with `M_ab = g(x_a, y_b) VIS_ab`.
    fn gauss_leaf(
        ctx: &PairContext,
        si: &Samples,
        sj: &Samples,
        vis: &Visibility,
        ij: &mut [f64],
        ji: &mut [f64],
    ) {
        let cells = ctx.vis_axis * ctx.vis_axis;
        let (na, nbp) = (si.len(), sj.len());
        let mut stack = [0.0f64; STACK_PRODUCT];
        let mut heap = Vec::new();
        let m = if na * nbp <= STACK_PRODUCT {
            &mut stack[..na * nbp]
        } else {
            heap.resize(na * nbp, 0.0);
            &mut heap[..]
        };
        kernel_matrix(si, sj, vis, cells, m);
        project_any(ctx.basis.len(), si, sj, m, ij, ji);
    }
}

/// [`project`] for `nb` basis functions (1, 4, 9 or 16), inlined into the caller's vector width.
#[inline(always)]
pub(crate) fn project_any(nb: usize, si: &Samples, sj: &Samples, m: &[f64], ij: &mut [f64], ji: &mut [f64]) {
    match nb {
        1 => project::<1>(si, sj, m, ij, ji),
        4 => project::<4>(si, sj, m, ij, ji),
        9 => project::<9>(si, sj, m, ij, ji),
        16 => project::<16>(si, sj, m, ij, ji),
        nb => unreachable!("{nb} basis functions"),
    }
}

/// `M_ab = g(x_a, y_b) VIS_ab`, row-major `na x nbp`: the point kernel (`point::point_kernel`, the
/// same operations) over structure-of-arrays samples, so the loop vectorises.
#[inline(always)]
fn kernel_matrix(si: &Samples, sj: &Samples, vis: &Visibility, cells: usize, m: &mut [f64]) {
    let nbp = sj.len();
    let [yx, yy, yz] = &sj.position_soa;
    let [mx, my, mz] = &sj.normal_soa;
    let (yx, yy, yz, mx, my, mz) = (&yx[..nbp], &yy[..nbp], &yz[..nbp], &mx[..nbp], &my[..nbp], &mz[..nbp]);
    for (a, row) in m.chunks_exact_mut(nbp).enumerate() {
        let x = si.position[a];
        let nx = si.normal[a];
        for b in 0..nbp {
            let (dx, dy, dz) = (yx[b] - x.x, yy[b] - x.y, yz[b] - x.z);
            let cx = nx.x * dx + nx.y * dy + nx.z * dz;
            let cy = -(mx[b] * dx + my[b] * dy + mz[b] * dz);
            let r2 = dx * dx + dy * dy + dz * dz;
            let g = cx * cy / (std::f64::consts::PI * r2 * r2);
            row[b] = if cx <= 0.0 || cy <= 0.0 { 0.0 } else { g };
        }
        if let Visibility::Partial(_) | Visibility::Blocked = vis {
            let ca = si.cell[a];
            for b in 0..nbp {
                row[b] *= vis.at(ca, sj.cell[b], cells);
            }
        }
    }
}

/// `G_ij += P_i^T (M Q_j)` and `G_ji += P_j^T (M^T Q_i)` with `P = diag(w) Phi`, `Q = diag(wA) Phi`,
/// one row of `M Q_j` (one column of `M^T Q_i`) at a time, in registers.
#[inline(always)]
fn project<const NB: usize>(si: &Samples, sj: &Samples, m: &[f64], ij: &mut [f64], ji: &mut [f64]) {
    let (na, nbp) = (si.len(), sj.len());
    let (pi_w, _) = si.weighted_basis.as_chunks::<NB>();
    let (qi, _) = si.area_weighted_basis.as_chunks::<NB>();
    let (pj_w, _) = sj.weighted_basis.as_chunks::<NB>();
    let (qj, _) = sj.area_weighted_basis.as_chunks::<NB>();
    let (ij, _) = ij.as_chunks_mut::<NB>();
    let (ji, _) = ji.as_chunks_mut::<NB>();
    let (qi, qj, pi_w, pj_w) = (&qi[..na], &qj[..nbp], &pi_w[..na], &pj_w[..nbp]);
    for (a, row) in m.chunks_exact(nbp).enumerate() {
        let mut t = [0.0f64; NB];
        for (g, qb) in row.iter().zip(qj) {
            for l in 0..NB {
                t[l] += g * qb[l];
            }
        }
        let pa = &pi_w[a];
        for k in 0..NB {
            let f = pa[k];
            for l in 0..NB {
                ij[k][l] += f * t[l];
            }
        }
    }
    for b in 0..nbp {
        let mut t = [0.0f64; NB];
        for (g, qa) in m[b..].iter().step_by(nbp).zip(qi) {
            for k in 0..NB {
                t[k] += g * qa[k];
            }
        }
        let pb = &pj_w[b];
        for l in 0..NB {
            let f = pb[l];
            for k in 0..NB {
                ji[l][k] += f * t[k];
            }
        }
    }
}

/// Deepest level of a near pair: Gauss over one side, the exact form factor to the other side's
/// polygon as the inner integral, the inner basis function taken at the polygon's centre. Done
/// both ways round so each direction keeps the exact singular part.
fn analytic_leaf(
    ctx: &PairContext,
    cache_i: &mut SubSamples,
    rect_i: &Rect,
    cache_j: &mut SubSamples,
    rect_j: &Rect,
    vis: &Visibility,
    out: &mut (&mut [f64], &mut [f64]),
) {
    // G_ij: receiver i's samples, inner integral F(x_a -> S_j) = integral g A_j du dv over rect_j.
    let (pi, pj) = (cache_i.patch, cache_j.patch);
    analytic_one_way(ctx, cache_i.get(ctx, rect_i), (pj, rect_j), vis, out.0, false);
    analytic_one_way(ctx, cache_j.get(ctx, rect_j), (pi, rect_i), vis, out.1, true);
}

/// One direction of [`analytic_leaf`]: the receiver's `samples` against the polygon of `rect_s`
/// of `src`, the source's basis at the rectangle's centre, into `block` (`transpose_vis`: the
/// source is the visibility's first element).
fn analytic_one_way(
    ctx: &PairContext,
    samples: &Samples,
    (src, rect_s): (&Patch, &Rect),
    vis: &Visibility,
    block: &mut [f64],
    transpose_vis: bool,
) {
    let nb = ctx.basis.len();
    let m = ctx.vis_axis;
    let poly = src.sub_patch(rect_s);
    let poly_normal = poly.centre_normal();
    let (cs, ct) = rect_s.map(0.5, 0.5);
    let mut phi_src = [0.0; 16];
    ctx.basis.eval_into(cs, ct, &mut phi_src[..nb]);
    let src_cell = crate::visibility::cell_of(cs, ct, m);
    let mut corners = poly.corners.to_vec();
    corners.dedup();
    for a in 0..samples.len() {
        let f = point_to_polygon(samples.position[a], samples.normal[a], &corners, poly_normal);
        if f == 0.0 {
            continue;
        }
        let v = if transpose_vis {
            vis.at(src_cell, samples.cell[a], m * m)
        } else {
            vis.at(samples.cell[a], src_cell, m * m)
        };
        let w = samples.weight[a] * f * v;
        let phi_a = &samples.basis[a * nb..(a + 1) * nb];
        for k in 0..nb {
            for l in 0..nb {
                block[k * nb + l] += w * phi_a[k] * phi_src[l];
            }
        }
    }
}

/// A near pair integrated coarsely: the receivers' `rule` points against each quadrant of the
/// source's polygon analytically (Lambert's contour formula, exact for a constant source and no
/// occlusion), the source's basis taken at each quadrant's centre, no splitting. (At the whole
/// polygon's centre the source's linear functions vanish, and a near link dropped the share of
/// its source's gradient: the Cornell box's floor of error on the hierarchy, 1.34% -> 1.20% at
/// accuracy 1e-4, docs/benchmarks.md.) The hierarchy's choice for
/// near links, which its oracle keeps to those carrying little (it refines the elements where
/// they would carry more); `ij` and `ji` are accumulated into.
pub fn integrate_near_coarse(
    ctx: &PairContext,
    pi: &Patch,
    pj: &Patch,
    vis: &Visibility,
    ij: &mut [f64],
    ji: &mut [f64],
) {
    let (mut cache_i, mut cache_j) = (SubSamples::new(pi), SubSamples::new(pj));
    // Each source in quadrants: the basis at each quadrant's centre keeps the source's
    // first-order moments, which the basis at the whole polygon's centre (where they vanish)
    // dropped.
    let si = cache_i.get(ctx, &Rect::UNIT);
    for q in Rect::UNIT.quadrants() {
        analytic_one_way(ctx, si, (pj, &q), vis, ij, false);
    }
    let sj = cache_j.get(ctx, &Rect::UNIT);
    for q in Rect::UNIT.quadrants() {
        analytic_one_way(ctx, sj, (pi, &q), vis, ji, true);
    }
}
