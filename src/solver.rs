//! Solving eq. (5), `b_i^k = e_i^k + sum_{j,l} rho_i G_ij^kl b_j^l`, per RGB channel.
//!
//! [`shoot`]: progressive refinement (Cohen et al. 1988, in Galerkin form as in the seed's 3.4):
//! repeatedly shoot the element whose unshot coefficient vector carries the most power, until
//! the unshot power is below a threshold. The animation update uses the same routine on the
//! differences `Delta b` (eq. 9). [`gauss_seidel`]: a direct iteration, the cross-check in tests.

use crate::error::{Error, Result};
use crate::links::{ElementId, LinkStore};

/// Radiosity coefficients and their unshot part, `[element * nb + k]`, RGB.
#[derive(Clone, Debug, PartialEq)]
pub struct Coefficients {
    pub nb: usize,
    pub b: Vec<[f64; 3]>,
    pub unshot: Vec<[f64; 3]>,
}

impl Coefficients {
    pub fn zeros(n_elements: usize, nb: usize) -> Self {
        Self { nb, b: vec![[0.0; 3]; n_elements * nb], unshot: vec![[0.0; 3]; n_elements * nb] }
    }

    /// Starts a solve from emission coefficients: `b = unshot = e`.
    pub fn from_emission(e: &[[f64; 3]], nb: usize) -> Self {
        Self { nb, b: e.to_vec(), unshot: e.to_vec() }
    }

    pub fn element(&self, e: usize) -> &[[f64; 3]] {
        &self.b[e * self.nb..(e + 1) * self.nb]
    }
}

/// Power-like size of an element's coefficient vector: `area * sum_c ||v_c||_2` (the L2 norm of
/// the function over the unit parameter square, orthonormal basis), used to pick shooters.
pub fn power(v: &[[f64; 3]], area: f64) -> f64 {
    (0..3).map(|c| v.iter().map(|x| x[c] * x[c]).sum::<f64>().sqrt()).sum::<f64>() * area
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShootStats {
    pub shots: usize,
    /// Unshot power left, relative to the reference.
    pub residual: f64,
}

/// Progressive refinement until the unshot power is below `stop_power`. `cancel` is polled every
/// few hundred shots.
pub fn shoot(
    links: &LinkStore,
    reflectance: &[[f64; 3]],
    area: &[f64],
    x: &mut Coefficients,
    stop_power: f64,
    cancel: &dyn Fn() -> bool,
) -> Result<ShootStats> {
    let nb = x.nb;
    let n = area.len();
    let mut priority: Vec<f64> = (0..n).map(|e| power(&x.unshot[e * nb..(e + 1) * nb], area[e])).collect();
    let mut shots = 0;
    let mut shooter = vec![[0.0f64; 3]; nb];
    loop {
        let (mut best, mut best_p, mut total) = (0, -1.0, 0.0);
        for (e, &p) in priority.iter().enumerate() {
            total += p;
            if p > best_p {
                best = e;
                best_p = p;
            }
        }
        if total <= stop_power || best_p <= 0.0 {
            return Ok(ShootStats { shots, residual: total });
        }
        if shots % 256 == 0 && cancel() {
            return Err(Error::Cancelled);
        }
        let j = best as ElementId;
        shooter.copy_from_slice(&x.unshot[best * nb..(best + 1) * nb]);
        x.unshot[best * nb..(best + 1) * nb].fill([0.0; 3]);
        priority[best] = 0.0;
        for &p in links.pairs_of(j) {
            let i = links.other(p, j) as usize;
            let g = links.block(p, i as ElementId);
            let rho = reflectance[i];
            let mut changed = false;
            for k in 0..nb {
                let row = &g[k * nb..(k + 1) * nb];
                let mut acc = [0.0; 3];
                for l in 0..nb {
                    let gkl = row[l] as f64;
                    acc[0] += gkl * shooter[l][0];
                    acc[1] += gkl * shooter[l][1];
                    acc[2] += gkl * shooter[l][2];
                }
                for c in 0..3 {
                    let d = rho[c] * acc[c];
                    if d != 0.0 {
                        x.b[i * nb + k][c] += d;
                        x.unshot[i * nb + k][c] += d;
                        changed = true;
                    }
                }
            }
            if changed {
                priority[i] = power(&x.unshot[i * nb..(i + 1) * nb], area[i]);
            }
        }
        shots += 1;
    }
}

/// Gauss-Seidel on eq. (5) until no coefficient moves by more than `tol` (absolute); returns `b`.
pub fn gauss_seidel(links: &LinkStore, reflectance: &[[f64; 3]], e: &[[f64; 3]], tol: f64) -> Vec<[f64; 3]> {
    let nb = links.nb();
    let n = reflectance.len();
    let mut b = e.to_vec();
    for _ in 0..10_000 {
        let mut delta: f64 = 0.0;
        for i in 0..n {
            let mut acc = vec![[0.0; 3]; nb];
            for &p in links.pairs_of(i as ElementId) {
                let j = links.other(p, i as ElementId) as usize;
                let g = links.block(p, i as ElementId);
                for k in 0..nb {
                    for l in 0..nb {
                        for c in 0..3 {
                            acc[k][c] += g[k * nb + l] as f64 * b[j * nb + l][c];
                        }
                    }
                }
            }
            for k in 0..nb {
                for c in 0..3 {
                    let v = e[i * nb + k][c] + reflectance[i][c] * acc[k][c];
                    delta = delta.max((v - b[i * nb + k][c]).abs());
                    b[i * nb + k][c] = v;
                }
            }
        }
        if delta <= tol {
            break;
        }
    }
    b
}
