//! A source's Gauss nodes over a rectangle of its domain, in fixed arrays: what the corner
//! gather's Gauss sum reads, made without a heap allocation for every sub-rectangle the
//! recursion visits (a [`crate::kernel::samples::Samples`] there was a quarter of the decimated
//! monastery's gather, and its allocations another tenth).

use glam::DVec3;

use crate::basis::{Basis, MAX_LEN};
use crate::geometry::{Patch, Rect};
use crate::quadrature::GaussLegendre;
use crate::visibility::cell_of;

/// Gauss points per axis on a separated source rectangle.
pub(super) const GAUSS_POINTS: usize = 3;

/// Nodes of the rule.
pub(super) const N: usize = GAUSS_POINTS * GAUSS_POINTS;

#[derive(Clone, Debug)]
pub(super) struct GaussNodes {
    pub position: [DVec3; N],
    pub normal: [DVec3; N],
    /// Visibility cell of each node.
    pub cell: [usize; N],
    /// `w_s w_t |R| A(s,t) Gamma_l(s,t)` per node `k` at `k * nb + l`: the node's weight in the
    /// area measure times each basis function.
    pub weighted_basis: [f64; N * MAX_LEN],
}

impl GaussNodes {
    /// The nodes of `rule` (of [`GAUSS_POINTS`] points) over `rect` of `patch`, with `basis` in
    /// the patch's own parameters and `cells` visibility cells per axis.
    pub fn new(patch: &Patch, rect: &Rect, rule: &GaussLegendre, basis: Basis, cells: usize) -> Self {
        debug_assert_eq!(rule.len(), GAUSS_POINTS);
        let nb = basis.len();
        let mut out = GaussNodes {
            position: [DVec3::ZERO; N],
            normal: [DVec3::ZERO; N],
            cell: [0; N],
            weighted_basis: [0.0; N * MAX_LEN],
        };
        let measure = rect.measure();
        let mut k = 0;
        for (u, wu) in rule.iter() {
            for (v, wv) in rule.iter() {
                let (s, t) = rect.map(u, v);
                let av = patch.area_vector(s, t);
                let a = av.length();
                out.position[k] = patch.point(s, t);
                out.normal[k] = if a > 0.0 { av / a } else { DVec3::ZERO };
                out.cell[k] = cell_of(s, t, cells);
                let row = &mut out.weighted_basis[k * nb..(k + 1) * nb];
                basis.eval_into(s, t, row);
                let w = wu * wv * measure * a;
                for g in row.iter_mut() {
                    *g *= w;
                }
                k += 1;
            }
        }
        out
    }
}
