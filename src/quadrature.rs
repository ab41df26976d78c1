//! Gauss-Legendre quadrature on `[0,1]`.
//!
//! Nodes by Newton iteration on `P_n` (Golub-Welsch is not needed at these sizes); `n` points
//! integrate polynomials of degree `2n-1` exactly.

/// `n` Gauss-Legendre nodes and weights mapped to `[0,1]` (weights sum to 1).
#[derive(Clone, Debug)]
pub struct GaussLegendre {
    nodes: Vec<f64>,
    weights: Vec<f64>,
}

impl GaussLegendre {
    pub fn new(n: usize) -> Self {
        assert!(n >= 1, "a quadrature rule needs at least one point");
        let mut nodes = vec![0.0; n];
        let mut weights = vec![0.0; n];
        for i in 0..n.div_ceil(2) {
            // Chebyshev-like initial guess for the i-th root of P_n on [-1,1], descending.
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (p, d) = legendre_and_derivative(n, x);
                dp = d;
                let dx = p / d;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            let (_, d) = legendre_and_derivative(n, x);
            dp = if d != 0.0 { d } else { dp };
            let w = 2.0 / ((1.0 - x * x) * dp * dp);
            // Map [-1,1] -> [0,1]: node (1+x)/2, weight w/2.
            nodes[i] = (1.0 - x) / 2.0;
            nodes[n - 1 - i] = (1.0 + x) / 2.0;
            weights[i] = w / 2.0;
            weights[n - 1 - i] = w / 2.0;
        }
        Self { nodes, weights }
    }

    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    pub fn nodes(&self) -> &[f64] {
        &self.nodes
    }

    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// `(node, weight)` pairs in increasing node order.
    pub fn iter(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.nodes.iter().copied().zip(self.weights.iter().copied())
    }
}

/// `P_n(x)` and `P_n'(x)` by Bonnet's recursion.
fn legendre_and_derivative(n: usize, x: f64) -> (f64, f64) {
    let mut p0 = 1.0;
    let mut p1 = x;
    if n == 0 {
        return (1.0, 0.0);
    }
    for k in 2..=n {
        let k = k as f64;
        let p2 = ((2.0 * k - 1.0) * x * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
    }
    let d = n as f64 * (x * p1 - p0) / (x * x - 1.0);
    (p1, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integrates_polynomials_of_degree_2n_minus_1_exactly() {
        for n in 1..=12 {
            let q = GaussLegendre::new(n);
            for deg in 0..2 * n {
                let got: f64 = q.iter().map(|(x, w)| w * x.powi(deg as i32)).sum();
                let want = 1.0 / (deg as f64 + 1.0);
                assert!((got - want).abs() < 1e-14, "n={n} degree {deg}: {got} vs {want}");
            }
        }
    }

    #[test]
    fn nodes_are_sorted_and_inside() {
        let q = GaussLegendre::new(7);
        assert!(q.nodes().windows(2).all(|w| w[0] < w[1]));
        assert!(q.nodes().iter().all(|&x| x > 0.0 && x < 1.0));
        assert!((q.nodes()[3] - 0.5).abs() < 1e-15);
    }
}
