//! Two-scale relations of the Legendre basis: a parent element's polynomial restricted to one of
//! its quadrants, and the parent's projection of its four children (push and pull).
//!
//! With the parameter-space orthonormal basis of [`crate::basis`], a polynomial of degree `n` per
//! axis restricted to the quadrant `q` is again such a polynomial in the quadrant's own `(s', t')`.
//! Its coefficients are `c_q = P_q c` with
//!
//! `P_q[k][l] = integral_[0,1]^2 Gamma_k(s',t') Gamma_l(map_q(s',t')) ds' dt'
//!            = 4 integral_q Gamma_k^q Gamma_l ds dt`,
//!
//! which is exact. The parent's projection of a function given by its four children is
//! `c[l] = integral Gamma_l B ds dt = (1/4) sum_q sum_k P_q[k][l] c_q[k]`, i.e.
//! `c = (1/4) sum_q P_q^T c_q`: exact for polynomials of the basis, and the L2 projection
//! otherwise. The tensor basis makes `P_q` the Kronecker product of two 1-D matrices, one per
//! half of each axis.

use crate::basis::{Basis, MAX_ORDER, legendre_1d};
use crate::quadrature::GaussLegendre;

/// `P_q` for the four quadrants of [`crate::geometry::Rect::quadrants`], `nb x nb` each, row-major
/// (row = the child's function `k`, column = the parent's function `l`).
#[derive(Clone, Debug)]
pub struct TwoScale {
    nb: usize,
    p: [Vec<f64>; 4],
}

/// Which half of each axis the quadrants of [`crate::geometry::Rect::quadrants`] take, `(s, t)`.
const HALVES: [(usize, usize); 4] = [(0, 0), (1, 0), (1, 1), (0, 1)];

impl TwoScale {
    pub fn new(basis: Basis) -> Self {
        let n = basis.order() + 1;
        // `half[h][a][c] = integral_0^1 L_a(u) L_c((u + h) / 2) du`, exact with n Gauss points
        // (the integrand has degree <= 2 order).
        let rule = GaussLegendre::new(MAX_ORDER + 1);
        let mut half = [[[0.0; MAX_ORDER + 1]; MAX_ORDER + 1]; 2];
        for (h, m) in half.iter_mut().enumerate() {
            for (u, w) in rule.iter() {
                let child = legendre_1d(u);
                let parent = legendre_1d(0.5 * (u + h as f64));
                for a in 0..n {
                    for c in 0..n {
                        m[a][c] += w * child[a] * parent[c];
                    }
                }
            }
        }
        let nb = n * n;
        let p = HALVES.map(|(hs, ht)| {
            let mut m = vec![0.0; nb * nb];
            for a in 0..n {
                for b in 0..n {
                    for c in 0..n {
                        for d in 0..n {
                            m[(a * n + b) * nb + c * n + d] = half[hs][a][c] * half[ht][b][d];
                        }
                    }
                }
            }
            m
        });
        Self { nb, p }
    }

    pub fn nb(&self) -> usize {
        self.nb
    }

    /// `P_q` of quadrant `q`, `nb x nb` row-major.
    pub fn matrix(&self, q: usize) -> &[f64] {
        &self.p[q]
    }

    /// Push: the parent's polynomial `parent` restricted to quadrant `q`, added to `child`.
    pub fn push_add(&self, q: usize, parent: &[[f64; 3]], child: &mut [[f64; 3]]) {
        let m = &self.p[q];
        for k in 0..self.nb {
            let row = &m[k * self.nb..(k + 1) * self.nb];
            for (l, &w) in row.iter().enumerate() {
                if w != 0.0 {
                    for c in 0..3 {
                        child[k][c] += w * parent[l][c];
                    }
                }
            }
        }
    }

    /// Pull: the parent's projection `(1/4) sum_q P_q^T c_q` of its four children, written to
    /// `parent`.
    pub fn pull(&self, children: [&[[f64; 3]]; 4], parent: &mut [[f64; 3]]) {
        parent.iter_mut().for_each(|x| *x = [0.0; 3]);
        for (q, child) in children.iter().enumerate() {
            let m = &self.p[q];
            for k in 0..self.nb {
                for l in 0..self.nb {
                    let w = 0.25 * m[k * self.nb + l];
                    if w != 0.0 {
                        for c in 0..3 {
                            parent[l][c] += w * child[k][c];
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Rect;

    /// A deterministic pseudo-random polynomial's coefficients.
    fn coefficients(nb: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..nb).map(|_| [next(), next(), next()]).collect()
    }

    fn eval(basis: Basis, c: &[[f64; 3]], s: f64, t: f64) -> [f64; 3] {
        let g = basis.eval(s, t);
        let mut out = [0.0; 3];
        for (k, gk) in g.iter().enumerate() {
            for ch in 0..3 {
                out[ch] += gk * c[k][ch];
            }
        }
        out
    }

    #[test]
    fn push_restricts_the_parent_polynomial_exactly() {
        for order in 0..=MAX_ORDER {
            let basis = Basis::new(order);
            let ts = TwoScale::new(basis);
            let parent = coefficients(basis.len(), order as u64 + 1);
            for (q, rect) in Rect::UNIT.quadrants().iter().enumerate() {
                let mut child = vec![[0.0; 3]; basis.len()];
                ts.push_add(q, &parent, &mut child);
                for &(s, t) in &[(0.1, 0.2), (0.5, 0.5), (0.9, 0.33), (0.0, 1.0)] {
                    let (ps, pt) = rect.map(s, t);
                    let (a, b) = (eval(basis, &child, s, t), eval(basis, &parent, ps, pt));
                    for ch in 0..3 {
                        assert!((a[ch] - b[ch]).abs() < 1e-12, "order {order} q {q} at ({s},{t})");
                    }
                }
            }
        }
    }

    #[test]
    fn pull_of_push_is_the_identity() {
        for order in 0..=MAX_ORDER {
            let basis = Basis::new(order);
            let ts = TwoScale::new(basis);
            let parent = coefficients(basis.len(), 7 + order as u64);
            let children: Vec<Vec<[f64; 3]>> = (0..4)
                .map(|q| {
                    let mut c = vec![[0.0; 3]; basis.len()];
                    ts.push_add(q, &parent, &mut c);
                    c
                })
                .collect();
            let mut back = vec![[0.0; 3]; basis.len()];
            ts.pull([&children[0], &children[1], &children[2], &children[3]], &mut back);
            for k in 0..basis.len() {
                for ch in 0..3 {
                    assert!((back[k][ch] - parent[k][ch]).abs() < 1e-12, "order {order} k {k}");
                }
            }
        }
    }

    /// Pull is the parent's L2 projection of whatever the children hold: against Gauss
    /// quadrature of the piecewise polynomial over the parent.
    #[test]
    fn pull_is_the_projection_of_independent_children() {
        let rule = GaussLegendre::new(6);
        for order in 0..=MAX_ORDER {
            let basis = Basis::new(order);
            let ts = TwoScale::new(basis);
            let children: Vec<Vec<[f64; 3]>> = (0..4).map(|q| coefficients(basis.len(), 40 + q)).collect();
            let mut pulled = vec![[0.0; 3]; basis.len()];
            ts.pull([&children[0], &children[1], &children[2], &children[3]], &mut pulled);
            let mut want = vec![[0.0; 3]; basis.len()];
            for (q, rect) in Rect::UNIT.quadrants().iter().enumerate() {
                for (u, wu) in rule.iter() {
                    for (v, wv) in rule.iter() {
                        let f = eval(basis, &children[q], u, v);
                        let (s, t) = rect.map(u, v);
                        let g = basis.eval(s, t);
                        for l in 0..basis.len() {
                            for ch in 0..3 {
                                want[l][ch] += 0.25 * wu * wv * g[l] * f[ch];
                            }
                        }
                    }
                }
            }
            for l in 0..basis.len() {
                for ch in 0..3 {
                    assert!((pulled[l][ch] - want[l][ch]).abs() < 1e-12, "order {order} l {l}");
                }
            }
            // The constant coefficient is the parameter-space mean: the children's means averaged.
            let mean: f64 = children.iter().map(|c| c[0][0]).sum::<f64>() / 4.0;
            assert!((pulled[0][0] - mean).abs() < 1e-12);
        }
    }
}
