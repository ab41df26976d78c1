//! Solving eq. (5), `b_i^k = e_i^k + sum_{j,l} rho_i G_ij^kl b_j^l`, per RGB channel.
//!
//! [`shoot`]: progressive refinement (Cohen et al. 1988, in Galerkin form as in the seed's 3.4):
//! repeatedly shoot the elements whose unshot coefficient vectors carry the most power (a batch
//! at a time, in parallel), until the unshot power is below a threshold. The animation update
//! uses the same routine on the differences `Delta b` (eq. 9). [`gauss_seidel`]: a direct
//! iteration, the cross-check in tests.

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

/// Shooters of one batch: every element whose unshot power is at least this fraction of the
/// largest. Shooting them together (Jacobi-style) instead of one at a time (Southwell) keeps the
/// progressive order of magnitude and gives the threads enough work per batch.
const BATCH_FRACTION: f64 = 0.25;

/// Progressive refinement until the unshot power is below `stop_power`, shooting in parallel
/// batches. `cancel` is polled between batches.
pub fn shoot(
    links: &LinkStore,
    reflectance: &[[f64; 3]],
    area: &[f64],
    x: &mut Coefficients,
    stop_power: f64,
    cancel: &dyn Fn() -> bool,
) -> Result<ShootStats> {
    use rayon::prelude::*;
    let nb = x.nb;
    let n = area.len();
    let mut priority: Vec<f64> = (0..n).map(|e| power(&x.unshot[e * nb..(e + 1) * nb], area[e])).collect();
    let mut shots = 0;
    let threads = rayon::current_num_threads().max(1);
    loop {
        let total: f64 = priority.iter().sum();
        let best = priority.iter().copied().fold(0.0, f64::max);
        if total <= stop_power || best <= 0.0 {
            return Ok(ShootStats { shots, residual: total });
        }
        if cancel() {
            return Err(Error::Cancelled);
        }
        // Take the batch's unshot coefficients.
        let mut shooters: Vec<(usize, Vec<[f64; 3]>)> = Vec::new();
        for e in 0..n {
            if priority[e] >= BATCH_FRACTION * best && priority[e] > 0.0 {
                shooters.push((e, x.unshot[e * nb..(e + 1) * nb].to_vec()));
                x.unshot[e * nb..(e + 1) * nb].fill([0.0; 3]);
                priority[e] = 0.0;
            }
        }
        shots += shooters.len();
        // Each chunk of shooters accumulates into its own buffer; buffers are summed.
        let chunk = shooters.len().div_ceil(2 * threads).max(1);
        let delta = shooters
            .par_chunks(chunk)
            .map(|batch| {
                let mut buf = vec![[0.0f64; 3]; n * nb];
                for (j, u) in batch {
                    shoot_one(links, reflectance, *j as ElementId, u, nb, &mut buf);
                }
                buf
            })
            .reduce_with(|mut a, b| {
                for (x, y) in a.iter_mut().zip(&b) {
                    for c in 0..3 {
                        x[c] += y[c];
                    }
                }
                a
            })
            .unwrap_or_default();
        for e in 0..n {
            let d = &delta[e * nb..(e + 1) * nb];
            if d.iter().all(|v| *v == [0.0; 3]) {
                continue;
            }
            for k in 0..nb {
                for c in 0..3 {
                    x.b[e * nb + k][c] += d[k][c];
                    x.unshot[e * nb + k][c] += d[k][c];
                }
            }
            priority[e] = power(&x.unshot[e * nb..(e + 1) * nb], area[e]);
        }
    }
}

/// Adds what element `j` with unshot coefficients `u` gives every receiver, `rho_i G_ij u`, to `out`.
fn shoot_one(
    links: &LinkStore,
    reflectance: &[[f64; 3]],
    j: ElementId,
    u: &[[f64; 3]],
    nb: usize,
    out: &mut [[f64; 3]],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has AVX-512F (checked above).
            unsafe { shoot_one_avx512(links, reflectance, j, u, nb, out) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked above).
            unsafe { shoot_one_avx2(links, reflectance, j, u, nb, out) };
            return;
        }
    }
    shoot_one_body(links, reflectance, j, u, nb, out);
}

/// [`shoot_one`] compiled for AVX-512 (wider conversions and products), same operations.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f")]
fn shoot_one_avx512(
    links: &LinkStore,
    reflectance: &[[f64; 3]],
    j: ElementId,
    u: &[[f64; 3]],
    nb: usize,
    out: &mut [[f64; 3]],
) {
    shoot_one_body(links, reflectance, j, u, nb, out);
}

/// [`shoot_one`] compiled for AVX2, same operations.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn shoot_one_avx2(
    links: &LinkStore,
    reflectance: &[[f64; 3]],
    j: ElementId,
    u: &[[f64; 3]],
    nb: usize,
    out: &mut [[f64; 3]],
) {
    shoot_one_body(links, reflectance, j, u, nb, out);
}

#[inline(always)]
fn shoot_one_body(
    links: &LinkStore,
    reflectance: &[[f64; 3]],
    j: ElementId,
    u: &[[f64; 3]],
    nb: usize,
    out: &mut [[f64; 3]],
) {
    match nb {
        1 => shoot_one_nb::<1>(links, reflectance, j, u, out),
        4 => shoot_one_nb::<4>(links, reflectance, j, u, out),
        9 => shoot_one_nb::<9>(links, reflectance, j, u, out),
        16 => shoot_one_nb::<16>(links, reflectance, j, u, out),
        nb => unreachable!("{nb} basis functions"),
    }
}

/// Blocks this many receivers ahead are prefetched: they are scattered over the whole store.
const PREFETCH_AHEAD: usize = 4;

#[inline(always)]
fn prefetch(block: &[f32]) {
    #[cfg(target_arch = "x86_64")]
    for line in block.chunks(16) {
        // SAFETY: prefetching is a hint; the address is that of a live slice element.
        unsafe {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(line.as_ptr().cast())
        };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = block;
}

/// [`shoot_one`] with `NB` basis functions; the same operations in the same order.
#[inline(always)]
fn shoot_one_nb<const NB: usize>(
    links: &LinkStore,
    reflectance: &[[f64; 3]],
    j: ElementId,
    u: &[[f64; 3]],
    out: &mut [[f64; 3]],
) {
    let u: &[[f64; 3]; NB] = u.try_into().expect("nb coefficients");
    let (out, _) = out.as_chunks_mut::<NB>();
    let receivers = links.receivers_of(j);
    for (r, n) in receivers.iter().enumerate() {
        if let Some(ahead) = receivers.get(r + PREFETCH_AHEAD) {
            prefetch(links.block_at(ahead.block));
        }
        let (g, _) = links.block_at(n.block).as_chunks::<NB>();
        let i = n.receiver as usize;
        let rho = reflectance[i];
        let o = &mut out[i];
        // acc[c][k] = sum_l G[k][l] u[l][c], l ascending as a dot product would; vectorised
        // over k (one column of G at a time).
        let mut acc = [[0.0f64; NB]; 3];
        for l in 0..NB {
            let col: [f64; NB] = std::array::from_fn(|k| g[k][l] as f64);
            for c in 0..3 {
                let ul = u[l][c];
                for k in 0..NB {
                    acc[c][k] += col[k] * ul;
                }
            }
        }
        for k in 0..NB {
            for c in 0..3 {
                o[k][c] += rho[c] * acc[c][k];
            }
        }
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
