//! Quadrature samples of an element over a rectangle of its parameter domain.

use glam::DVec3;

use crate::basis::Basis;
use crate::geometry::{Patch, Rect};
use crate::quadrature::GaussLegendre;
use crate::visibility::cell_of;

/// `n x n` Gauss samples of an element restricted to a rectangle of its domain.
#[derive(Clone, Debug)]
pub struct Samples {
    pub position: Vec<DVec3>,
    pub normal: Vec<DVec3>,
    /// Quadrature weight in the element's parameter measure (`w_s w_t |R|`).
    pub weight: Vec<f64>,
    /// Weight times the area element `A(s,t)`: the weight in the area measure.
    pub area_weight: Vec<f64>,
    /// `Gamma_k` at each sample, `len x nb`, row-major.
    pub basis: Vec<f64>,
    /// Visibility cell of each sample.
    pub cell: Vec<usize>,
    /// `weight * Gamma_k`, `len x nb`: the outer (receiver) side of a Gauss product.
    pub weighted_basis: Vec<f64>,
    /// `area_weight * Gamma_k`, `len x nb`: the inner (source) side of a Gauss product.
    pub area_weighted_basis: Vec<f64>,
    /// Positions and normals by coordinate (`[x, y, z]`), for loops over samples that vectorise.
    pub(crate) position_soa: [Vec<f64>; 3],
    pub(crate) normal_soa: [Vec<f64>; 3],
}

impl Samples {
    pub fn new(patch: &Patch, rect: &Rect, rule: &GaussLegendre, basis: Basis, vis_cells: usize) -> Self {
        let n = rule.len() * rule.len();
        let nb = basis.len();
        let mut s = Samples {
            position: Vec::with_capacity(n),
            normal: Vec::with_capacity(n),
            weight: Vec::with_capacity(n),
            area_weight: Vec::with_capacity(n),
            basis: vec![0.0; n * nb],
            cell: Vec::with_capacity(n),
            weighted_basis: vec![0.0; n * nb],
            area_weighted_basis: vec![0.0; n * nb],
            position_soa: Default::default(),
            normal_soa: Default::default(),
        };
        let measure = rect.measure();
        let mut k = 0;
        for (u, wu) in rule.iter() {
            for (v, wv) in rule.iter() {
                let (ps, pt) = rect.map(u, v);
                let av = patch.area_vector(ps, pt);
                let a = av.length();
                let w = wu * wv * measure;
                s.position.push(patch.point(ps, pt));
                s.normal.push(if a > 0.0 { av / a } else { DVec3::ZERO });
                s.weight.push(w);
                s.area_weight.push(w * a);
                basis.eval_into(ps, pt, &mut s.basis[k * nb..(k + 1) * nb]);
                s.cell.push(cell_of(ps, pt, vis_cells));
                k += 1;
            }
        }
        for k in 0..n {
            for l in 0..nb {
                s.weighted_basis[k * nb + l] = s.weight[k] * s.basis[k * nb + l];
                s.area_weighted_basis[k * nb + l] = s.area_weight[k] * s.basis[k * nb + l];
            }
        }
        for c in 0..3 {
            s.position_soa[c] = s.position.iter().map(|p| p[c]).collect();
            s.normal_soa[c] = s.normal.iter().map(|p| p[c]).collect();
        }
        s
    }

    pub fn len(&self) -> usize {
        self.position.len()
    }

    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }
}
