//! Orthonormal tensor Legendre basis on the unit square (Zatz 1993, section 3; seed eq. 3).
//!
//! `Gamma_ab(s,t) = sqrt((2a+1)(2b+1)) P_a(2s-1) P_b(2t-1)`, orthonormal for the *parameter-space*
//! inner product `<f|g> = integral_[0,1]^2 f g ds dt`, which is the one eq. (4) projects with.
//! Functions are numbered `k = a * (order+1) + b`, so `k = 0` is the constant function 1.

/// Highest polynomial degree per axis that the library supports.
pub const MAX_ORDER: usize = 3;

/// The most functions a basis has, `(MAX_ORDER+1)^2`: the size of a stack buffer for one
/// element's coefficients.
pub const MAX_LEN: usize = (MAX_ORDER + 1) * (MAX_ORDER + 1);

/// A basis of polynomial degree `order` per axis: `(order+1)^2` functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Basis {
    order: usize,
}

impl Basis {
    /// Panics if `order > MAX_ORDER`; scene validation rejects such settings first.
    pub fn new(order: usize) -> Self {
        assert!(order <= MAX_ORDER, "basis order {order} > {MAX_ORDER}");
        Self { order }
    }

    pub fn order(self) -> usize {
        self.order
    }

    /// Number of basis functions, `(order+1)^2`.
    pub fn len(self) -> usize {
        (self.order + 1) * (self.order + 1)
    }

    pub fn is_empty(self) -> bool {
        false
    }

    /// Writes `Gamma_k(s,t)` for every `k` into `out[..self.len()]`.
    pub fn eval_into(self, s: f64, t: f64, out: &mut [f64]) {
        let n = self.order + 1;
        let ps = legendre_1d(s);
        let pt = legendre_1d(t);
        for a in 0..n {
            for b in 0..n {
                out[a * n + b] = ps[a] * pt[b];
            }
        }
    }

    /// `Gamma_k(s,t)` for every `k`.
    pub fn eval(self, s: f64, t: f64) -> Vec<f64> {
        let mut out = vec![0.0; self.len()];
        self.eval_into(s, t, &mut out);
        out
    }
}

/// Shifted orthonormal Legendre polynomials on `[0,1]`, degrees 0..=3:
/// 1, sqrt3 (2u-1), sqrt5 (6u^2-6u+1), sqrt7 (20u^3-30u^2+12u-1).
pub fn legendre_1d(u: f64) -> [f64; MAX_ORDER + 1] {
    let x = 2.0 * u - 1.0;
    // Bonnet's recursion on [-1,1], then the orthonormal scale sqrt(2a+1).
    let p0 = 1.0;
    let p1 = x;
    let p2 = (3.0 * x * p1 - p0) / 2.0;
    let p3 = (5.0 * x * p2 - 2.0 * p1) / 3.0;
    [p0, 3f64.sqrt() * p1, 5f64.sqrt() * p2, 7f64.sqrt() * p3]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quadrature::GaussLegendre;

    #[test]
    fn orthonormal_at_every_order() {
        let q = GaussLegendre::new(8);
        for order in 0..=MAX_ORDER {
            let basis = Basis::new(order);
            let n = basis.len();
            let mut gram = vec![0.0; n * n];
            for (s, ws) in q.iter() {
                for (t, wt) in q.iter() {
                    let g = basis.eval(s, t);
                    for k in 0..n {
                        for l in 0..n {
                            gram[k * n + l] += ws * wt * g[k] * g[l];
                        }
                    }
                }
            }
            for k in 0..n {
                for l in 0..n {
                    let want = if k == l { 1.0 } else { 0.0 };
                    assert!((gram[k * n + l] - want).abs() < 1e-12, "order {order} <{k}|{l}>");
                }
            }
        }
    }

    #[test]
    fn closed_forms_match_references() {
        let u: f64 = 0.3;
        let p = legendre_1d(u);
        assert!((p[2] - 5f64.sqrt() * (6.0 * u * u - 6.0 * u + 1.0)).abs() < 1e-14);
        let cubic = 20.0 * u.powi(3) - 30.0 * u * u + 12.0 * u - 1.0;
        assert!((p[3] - 7f64.sqrt() * cubic).abs() < 1e-14);
    }
}
