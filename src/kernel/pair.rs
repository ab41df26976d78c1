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

use crate::basis::Basis;
use crate::geometry::{Patch, Rect};
use crate::quadrature::GaussLegendre;
use crate::visibility::Visibility;

use super::point::{point_kernel, point_to_polygon};
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

    pub fn is_zero(&self) -> bool {
        self.ij.iter().chain(&self.ji).all(|&x| x == 0.0)
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
    let (ci, ri) = pi.bounding_sphere();
    let (cj, rj) = pj.bounding_sphere();
    let ratio = ci.distance(cj) / (ri + rj);
    if ratio > SEPARATION {
        let n = ctx.points_for(ratio);
        gauss_leaf(ctx, whole(false, n), whole(true, n), vis, &mut out);
    } else {
        split(ctx, pi, &Rect::UNIT, pj, &Rect::UNIT, vis, 0, &mut out);
    }
    out
}

#[allow(clippy::too_many_arguments)]
fn split(
    ctx: &PairContext,
    pi: &Patch,
    rect_i: &Rect,
    pj: &Patch,
    rect_j: &Rect,
    vis: &Visibility,
    depth: usize,
    out: &mut PairCoefficients,
) {
    let sub_i = pi.sub_patch(rect_i);
    let sub_j = pj.sub_patch(rect_j);
    let (ci, ri) = sub_i.bounding_sphere();
    let (cj, rj) = sub_j.bounding_sphere();
    let cells = ctx.vis_axis;
    if ci.distance(cj) > SEPARATION * (ri + rj) {
        let si = Samples::new(pi, rect_i, ctx.rule, ctx.basis, cells);
        let sj = Samples::new(pj, rect_j, ctx.rule, ctx.basis, cells);
        gauss_leaf(ctx, &si, &sj, vis, out);
        return;
    }
    if depth >= MAX_DEPTH {
        analytic_leaf(ctx, pi, rect_i, pj, rect_j, vis, out);
        return;
    }
    // Split the larger side; split both when they are of a size, so the recursion stays balanced.
    let split_i = ri >= 0.5 * rj;
    let split_j = rj >= 0.5 * ri;
    let parts_i: Vec<Rect> = if split_i { rect_i.quadrants().to_vec() } else { vec![*rect_i] };
    let parts_j: Vec<Rect> = if split_j { rect_j.quadrants().to_vec() } else { vec![*rect_j] };
    for a in &parts_i {
        for b in &parts_j {
            split(ctx, pi, a, pj, b, vis, depth + 1, out);
        }
    }
}

/// Tensor Gauss over both sub-domains, as two small matrix products per direction:
/// `G_ij += Phi_i^T (M diag(wA_j) Phi_j)` and `G_ji += Phi_j^T (M^T diag(wA_i) Phi_i)`,
/// with `M_ab = g(x_a, y_b) VIS_ab w_a w_b / (w_a w_b)` folded into the weights below.
fn gauss_leaf(ctx: &PairContext, si: &Samples, sj: &Samples, vis: &Visibility, out: &mut PairCoefficients) {
    let nb = ctx.basis.len();
    let cells = ctx.vis_axis * ctx.vis_axis;
    let (na, nbp) = (si.len(), sj.len());
    // T1[a][l] = sum_b g_ab V_ab wA_b Gamma_l(b);  T2[b][k] = sum_a g_ab V_ab wA_a Gamma_k(a).
    let mut t1 = vec![0.0; na * nb];
    let mut t2 = vec![0.0; nbp * nb];
    for a in 0..na {
        for b in 0..nbp {
            let mut g = point_kernel(si.position[a], si.normal[a], sj.position[b], sj.normal[b]);
            if g == 0.0 {
                continue;
            }
            g *= vis.at(si.cell[a], sj.cell[b], cells);
            if g == 0.0 {
                continue;
            }
            let gj = g * sj.area_weight[b];
            let gi = g * si.area_weight[a];
            let phi_a = &si.basis[a * nb..(a + 1) * nb];
            let phi_b = &sj.basis[b * nb..(b + 1) * nb];
            let row1 = &mut t1[a * nb..(a + 1) * nb];
            for l in 0..nb {
                row1[l] += gj * phi_b[l];
            }
            let row2 = &mut t2[b * nb..(b + 1) * nb];
            for k in 0..nb {
                row2[k] += gi * phi_a[k];
            }
        }
    }
    for a in 0..na {
        let phi_a = &si.basis[a * nb..(a + 1) * nb];
        let w = si.weight[a];
        for k in 0..nb {
            let f = w * phi_a[k];
            if f == 0.0 {
                continue;
            }
            for l in 0..nb {
                out.ij[k * nb + l] += f * t1[a * nb + l];
            }
        }
    }
    for b in 0..nbp {
        let phi_b = &sj.basis[b * nb..(b + 1) * nb];
        let w = sj.weight[b];
        for l in 0..nb {
            let f = w * phi_b[l];
            if f == 0.0 {
                continue;
            }
            for k in 0..nb {
                out.ji[l * nb + k] += f * t2[b * nb + k];
            }
        }
    }
}

/// Deepest level of a near pair: Gauss over one side, the exact form factor to the other side's
/// polygon as the inner integral, the inner basis function taken at the polygon's centre. Done
/// both ways round so each direction keeps the exact singular part.
#[allow(clippy::too_many_arguments)]
fn analytic_leaf(
    ctx: &PairContext,
    pi: &Patch,
    rect_i: &Rect,
    pj: &Patch,
    rect_j: &Rect,
    vis: &Visibility,
    out: &mut PairCoefficients,
) {
    let nb = ctx.basis.len();
    let m = ctx.vis_axis;
    let one_way =
        |recv: &Patch, rect_r: &Rect, src: &Patch, rect_s: &Rect, block: &mut [f64], transpose_vis: bool| {
            let samples = Samples::new(recv, rect_r, ctx.rule, ctx.basis, m);
            let poly = src.sub_patch(rect_s);
            let poly_normal = poly.centre_normal();
            let (cs, ct) = rect_s.map(0.5, 0.5);
            let phi_src = ctx.basis.eval(cs, ct);
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
        };
    // G_ij: receiver i's samples, inner integral F(x_a -> S_j) = integral g A_j du dv over rect_j.
    one_way(pi, rect_i, pj, rect_j, &mut out.ij, false);
    one_way(pj, rect_j, pi, rect_i, &mut out.ji, true);
}
