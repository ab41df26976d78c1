//! Anderson acceleration of the hierarchical solve's fixed-point iteration.
//!
//! A Jacobi sweep with push-pull is a linear map `x -> g(x) = s + M x` on the leaves'
//! coefficients (`s` the sources, `M = rho H` through the links). Its error shrinks per sweep by
//! the spectral radius of `M`, which in a bright closed room is close to the reflectance, so a
//! fresh frame took 8-15 sweeps. Anderson's method (type II; Walker & Ni 2011, eq. 2.1 and
//! section 3) keeps the last `depth` steps and takes the combination of their images whose
//! residual `f = g(x) - x` is least:
//!
//! ```text
//! gamma    = argmin || f_k - dF gamma ||_W        dF = [f_{i+1} - f_i], i = k-m..k-1
//! x_{k+1}  = g(x_k) - dG gamma                    dG = [g_{i+1} - g_i]
//! ```
//!
//! On a linear map with full depth this is GMRES on `(I - M) x = s` (Walker & Ni, theorem 2.2),
//! so it converges at least as fast as the plain sweeps and usually much faster. The norm `W`
//! weights each leaf by its area, the norm in which the solve's stopping test measures change.
//! The least-squares problem, `depth x depth`, goes through its normal equations, whose products
//! are kept from step to step (a step adds one column's, in the same pass that forms it); the
//! oldest step is dropped whenever they are too ill-conditioned to solve (Walker & Ni's
//! condition control).

use std::collections::VecDeque;

use rayon::prelude::*;

use crate::budget;
use crate::error::Result;

/// A column pair: a residual and an image (or their differences).
type Pair = (Vec<f64>, Vec<f64>);

/// The mixer: the last steps' residual and image differences, in storage reserved up front.
pub struct Anderson {
    depth: usize,
    /// The norm's weight per group of `stride` entries.
    weights: Vec<f64>,
    stride: usize,
    /// The previous step's residual `f` and image `g`.
    last: Option<Pair>,
    /// `(f_{i+1} - f_i, g_{i+1} - g_i)`, oldest first.
    steps: VecDeque<Pair>,
    /// Reserved columns not in use.
    pool: Vec<Pair>,
    /// The weighted products of the steps' residual differences with each other, in `steps`'
    /// order: kept from step to step, so a step computes only its new column's.
    gram: VecDeque<Vec<f64>>,
}

/// Groups of entries a task of the mixer's pass takes; its sums are added block by block, in
/// order, so that the mix is the same for any number of threads.
const BLOCK: usize = 2048;

/// One block's share of the new Gram row and of the right-hand side.
struct BlockSums {
    row: [f64; MAX_DEPTH + 1],
    rhs: [f64; MAX_DEPTH + 1],
}

/// The deepest mixer [`Anderson::new`] makes.
pub const MAX_DEPTH: usize = 16;

impl Anderson {
    /// A mixer over vectors of `weights.len() x stride` entries keeping `depth` steps (at most
    /// [`MAX_DEPTH`]; 0: it leaves every image as it is); [`crate::Error::OutOfMemory`] when its
    /// `2 depth + 2` vectors cannot be had (a caller then sweeps without it).
    pub fn new(depth: usize, weights: Vec<f64>, stride: usize) -> Result<Self> {
        let depth = depth.min(MAX_DEPTH);
        let n = weights.len() * stride;
        let what = "the hierarchical solve's acceleration";
        // Reserved now, so that a large scene learns before its first sweep whether it fits.
        let mut pool = Vec::with_capacity(depth + 1);
        for _ in 0..=depth {
            pool.push((budget::try_filled(n, 0.0, what)?, budget::try_filled(n, 0.0, what)?));
        }
        Ok(Self { depth, weights, stride, last: None, steps: VecDeque::new(), pool, gram: VecDeque::new() })
    }

    /// Takes the step `x -> g` (`g = g(x)`) and overwrites `g` with the next iterate.
    pub fn mix(&mut self, x: &[f64], g: &mut [f64]) {
        debug_assert_eq!(x.len(), g.len());
        debug_assert_eq!(g.len(), self.weights.len() * self.stride);
        if self.depth == 0 {
            return;
        }
        let Some((mut f_last, mut g_last)) = self.last.take() else {
            // The first step: remember it, and take the plain sweep.
            let (mut f, mut gs) = self.pool.pop().expect("the pool holds depth + 1 pairs");
            f.par_iter_mut().zip(gs.par_iter_mut()).zip(x.par_iter().zip(g.par_iter())).for_each(
                |((fi, gi), (&xi, &gx))| {
                    *fi = gx - xi;
                    *gi = gx;
                },
            );
            self.last = Some((f, gs));
            return;
        };
        // The new difference column, in the oldest step's storage once `depth` are kept.
        if self.steps.len() == self.depth {
            self.drop_oldest();
        }
        let (mut df, mut dg) = self.pool.pop().expect("the pool holds depth + 1 pairs");
        // One pass: the new columns, the new residual, and the products the least-squares
        // problem needs of them (the older columns' products with each other are kept). In
        // blocks of groups, in parallel: each block's sums are added in block order.
        let m = self.steps.len();
        let n = self.stride;
        let span = BLOCK * n;
        let olds: Vec<&[f64]> = self.steps.iter().map(|(d, _)| d.as_slice()).collect();
        let blocks: Vec<BlockSums> = df
            .par_chunks_mut(span)
            .zip(dg.par_chunks_mut(span))
            .zip(f_last.par_chunks_mut(span).zip(g_last.par_chunks_mut(span)))
            .zip(x.par_chunks(span).zip(g.par_chunks(span)))
            .zip(self.weights.par_chunks(BLOCK))
            .enumerate()
            .map(|(k, ((((df, dg), (f_last, g_last)), (x, g)), weights))| {
                let olds: Vec<&[f64]> = olds.iter().map(|o| &o[k * span..k * span + df.len()]).collect();
                let mut sums = BlockSums { row: [0.0; MAX_DEPTH + 1], rhs: [0.0; MAX_DEPTH + 1] };
                for (c, &w) in weights.iter().enumerate() {
                    let (mut own, mut own_rhs) = (0.0, 0.0);
                    let mut with = [0.0; MAX_DEPTH];
                    let mut with_rhs = [0.0; MAX_DEPTH];
                    for i in c * n..(c + 1) * n {
                        let f = g[i] - x[i];
                        let d = f - f_last[i];
                        df[i] = d;
                        dg[i] = g[i] - g_last[i];
                        f_last[i] = f;
                        g_last[i] = g[i];
                        own += d * d;
                        own_rhs += d * f;
                        for (j, old) in olds.iter().enumerate() {
                            with[j] += d * old[i];
                            with_rhs[j] += old[i] * f;
                        }
                    }
                    for j in 0..m {
                        sums.row[j] += w * with[j];
                        sums.rhs[j] += w * with_rhs[j];
                    }
                    sums.row[m] += w * own;
                    sums.rhs[m] += w * own_rhs;
                }
                sums
            })
            .collect();
        let mut row = vec![0.0; m + 1];
        let mut rhs = vec![0.0; m + 1];
        for b in &blocks {
            for j in 0..=m {
                row[j] += b.row[j];
                rhs[j] += b.rhs[j];
            }
        }
        for (j, r) in self.gram.iter_mut().enumerate() {
            r.push(row[j]);
        }
        self.gram.push_back(row);
        self.steps.push_back((df, dg));
        let gamma = self.least_squares(rhs);
        let images: Vec<(&[f64], f64)> = self.steps.iter().map(|(_, dg)| dg.as_slice()).zip(gamma).collect();
        g.par_chunks_mut(span).enumerate().for_each(|(k, g)| {
            for &(dg, c) in &images {
                for (gi, &d) in g.iter_mut().zip(&dg[k * span..]) {
                    *gi -= c * d;
                }
            }
        });
        self.last = Some((f_last, g_last));
    }

    /// Forgets the oldest step and its products.
    fn drop_oldest(&mut self) {
        let oldest = self.steps.pop_front().expect("a step to drop");
        self.pool.push(oldest);
        self.gram.pop_front();
        for r in self.gram.iter_mut() {
            r.remove(0);
        }
    }

    /// `gamma` over the kept steps (`rhs`: each step's product with the newest residual), after
    /// dropping the oldest until the problem is well-conditioned.
    fn least_squares(&mut self, mut rhs: Vec<f64>) -> Vec<f64> {
        loop {
            let m = self.steps.len();
            let mut a: Vec<f64> = self.gram.iter().flatten().copied().collect();
            let mut b = rhs.clone();
            if let Some(gamma) = cholesky_solve(&mut a, &mut b, m) {
                return gamma;
            }
            // Nearly dependent steps: drop the oldest and try again (none left: a plain sweep).
            self.drop_oldest();
            rhs.remove(0);
        }
    }
}

/// Solves the symmetric positive definite `a x = rhs` (`m x m`, row-major) in place; `None` when
/// a pivot falls below `1e-12` of its diagonal entry (nearly dependent columns).
fn cholesky_solve(a: &mut [f64], rhs: &mut [f64], m: usize) -> Option<Vec<f64>> {
    for j in 0..m {
        let diag = a[j * m + j];
        let mut d = diag;
        for k in 0..j {
            d -= a[j * m + k] * a[j * m + k];
        }
        // NaN fails this too.
        if d.is_nan() || d <= 1e-12 * diag {
            return None;
        }
        let d = d.sqrt();
        a[j * m + j] = d;
        for i in j + 1..m {
            let mut v = a[i * m + j];
            for k in 0..j {
                v -= a[i * m + k] * a[j * m + k];
            }
            a[i * m + j] = v / d;
        }
    }
    // L y = rhs, then L^T x = y.
    for i in 0..m {
        let mut v = rhs[i];
        for k in 0..i {
            v -= a[i * m + k] * rhs[k];
        }
        rhs[i] = v / a[i * m + i];
    }
    for i in (0..m).rev() {
        let mut v = rhs[i];
        for k in i + 1..m {
            v -= a[k * m + i] * rhs[k];
        }
        rhs[i] = v / a[i * m + i];
    }
    Some(rhs.to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `x = s + M x` for a 3 x 3 contraction with spectral radius ~0.9: the plain iteration
    /// needs ~150 steps to 1e-7; the mixer, a few more than the dimension.
    #[test]
    fn a_linear_contraction_converges_in_a_few_steps() {
        let m = [[0.5, 0.3, 0.05], [0.2, 0.4, 0.3], [0.1, 0.35, 0.45]];
        let s = [1.0, 0.5, 0.25];
        let g = |x: &[f64]| -> Vec<f64> {
            (0..3).map(|i| s[i] + (0..3).map(|j| m[i][j] * x[j]).sum::<f64>()).collect()
        };
        // The exact solution by the plain iteration run long.
        let mut exact = vec![0.0; 3];
        for _ in 0..2000 {
            exact = g(&exact);
        }
        let mut mixer = Anderson::new(3, vec![1.0, 2.0, 0.5], 1).unwrap();
        let mut x = vec![0.0; 3];
        let mut steps = 0;
        while (0..3).map(|i| (x[i] - exact[i]).abs()).fold(0.0, f64::max) > 1e-7 {
            let mut next = g(&x);
            mixer.mix(&x, &mut next);
            x = next;
            steps += 1;
            assert!(steps < 10, "{steps} steps, x {x:?} against {exact:?}");
        }
        let mut plain = vec![0.0; 3];
        let mut plain_steps = 0;
        while (0..3).map(|i| (plain[i] - exact[i]).abs()).fold(0.0, f64::max) > 1e-7 {
            plain = g(&plain);
            plain_steps += 1;
        }
        assert!(plain_steps > 5 * steps, "plain {plain_steps}, mixed {steps}");
    }

    /// Over many blocks of groups (the pass's parallel blocks, a last one partly filled), each
    /// mixed iterate is the one Anderson's formula gives computed directly (the history's
    /// differences, the weighted normal equations, `x = g - dG gamma`): an entry or weight taken
    /// from the wrong block, or a block's sums added twice, would move it.
    #[test]
    fn many_blocks_mix_as_one() {
        let (groups, stride, depth) = (3 * BLOCK + 17, 2, 3);
        let n = groups * stride;
        let s: Vec<f64> = (0..n).map(|i| 1.0 + (i % 7) as f64 * 0.1).collect();
        // A contraction that couples entries blocks apart.
        let g = |x: &[f64]| -> Vec<f64> {
            (0..n).map(|i| s[i] + 0.5 * x[i] + 0.4 * x[(i * 7919 + 13) % n]).collect()
        };
        let weights: Vec<f64> = (0..groups).map(|c| 1.0 + (c % 5) as f64).collect();
        let dot = |u: &[f64], v: &[f64]| (0..n).map(|i| weights[i / stride] * u[i] * v[i]).sum::<f64>();
        let mut mixer = Anderson::new(depth, weights.clone(), stride).unwrap();
        let (mut x, mut fs, mut gs) = (vec![0.0; n], Vec::<Vec<f64>>::new(), Vec::<Vec<f64>>::new());
        for step in 0..8 {
            let gx = g(&x);
            let f: Vec<f64> = (0..n).map(|i| gx[i] - x[i]).collect();
            fs.push(f);
            gs.push(gx.clone());
            // Directly: the last `depth` differences of residuals and images.
            let k = fs.len() - 1;
            let m = k.min(depth);
            let diff =
                |v: &[Vec<f64>], j: usize| -> Vec<f64> { (0..n).map(|i| v[j + 1][i] - v[j][i]).collect() };
            let df: Vec<Vec<f64>> = (k - m..k).map(|j| diff(&fs, j)).collect();
            let dg: Vec<Vec<f64>> = (k - m..k).map(|j| diff(&gs, j)).collect();
            let mut a: Vec<f64> = (0..m * m).map(|e| dot(&df[e / m], &df[e % m])).collect();
            let mut rhs: Vec<f64> = (0..m).map(|j| dot(&df[j], &fs[k])).collect();
            let gamma = cholesky_solve(&mut a, &mut rhs, m).expect("well conditioned");
            let want: Vec<f64> =
                (0..n).map(|i| gx[i] - (0..m).map(|j| gamma[j] * dg[j][i]).sum::<f64>()).collect();
            let mut got = gx;
            mixer.mix(&x, &mut got);
            let scale = want.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            let off = got.iter().zip(&want).fold(0.0f64, |a, (u, v)| a.max((u - v).abs()));
            assert!(off <= 1e-9 * scale, "step {step}: {off} off the direct formula (scale {scale})");
            x = got;
        }
    }

    #[test]
    fn dependent_steps_are_dropped_not_divided_by() {
        // g(x) = x + 1 on every entry: each step's residual is the same, so dF = 0.
        let mut mixer = Anderson::new(2, vec![1.0; 2], 2).unwrap();
        let mut x = vec![0.0; 4];
        for _ in 0..4 {
            let mut next: Vec<f64> = x.iter().map(|v| v + 1.0).collect();
            mixer.mix(&x, &mut next);
            assert!(next.iter().all(|v| v.is_finite()));
            x = next;
        }
        assert_eq!(x, vec![4.0; 4]);
    }

    #[test]
    fn depth_zero_is_the_plain_iteration() {
        let mut mixer = Anderson::new(0, vec![1.0], 1).unwrap();
        let mut next = vec![0.5];
        mixer.mix(&[0.0], &mut next);
        mixer.mix(&[0.5], &mut next);
        assert_eq!(next, vec![0.5]);
    }
}
