//! Solving eq. (5), `b_i^k = e_i^k + sum_{j,l} rho_i G_ij^kl b_j^l`, per RGB channel.
//!
//! [`shoot`]: progressive refinement (Cohen et al. 1988, in Galerkin form as in the seed's 3.4):
//! repeatedly shoot the unshot coefficients that would deliver the most power (a batch at a time,
//! in parallel), until what is left would deliver less than a threshold. The animation update
//! uses the same routine on the differences `Delta b` (eq. 9). [`gauss_seidel`]: a direct
//! iteration, the cross-check in tests.

use crate::error::{Error, Result, invalid_scene};
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
/// the function over the unit parameter square, orthonormal basis): the emitted power the
/// tolerance is relative to.
pub fn power(v: &[[f64; 3]], area: f64) -> f64 {
    (0..3).map(|c| v.iter().map(|x| x[c] * x[c]).sum::<f64>().sqrt()).sum::<f64>() * area
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShootStats {
    /// Columns shot: one unshot coefficient `l` of one element sent to all its receivers.
    pub shots: usize,
    /// Power the unshot coefficients left would deliver in one bounce (before reflection).
    pub residual: f64,
    /// Link coefficients read by the shots (f32 each), the memory traffic that bounds a solve.
    pub floats_read: u64,
}

/// Shooters of one batch: every (element, coefficient) whose unshot would deliver at least this
/// fraction of the largest. Shooting them together (Jacobi-style) instead of one at a time
/// (Southwell) keeps the progressive order of magnitude and gives the threads enough work per
/// batch.
const BATCH_FRACTION: f64 = 0.25;

/// Power one unshot coefficient would deliver, `T_j^l sum_c |u_c|` (`T` from
/// [`LinkStore::transfers`]): what shots are ranked by and the sum of which must fall below the
/// stopping threshold.
fn coefficient_power(u: &[f64; 3], transfer: f64) -> f64 {
    (u[0].abs() + u[1].abs() + u[2].abs()) * transfer
}

/// One column shot: element `e` sends its unshot coefficient `l` (value `u`, RGB, in the
/// batch sums' units, [`SumScale`]).
#[derive(Clone, Copy, Debug)]
struct Shot {
    e: ElementId,
    l: u32,
    u: [f32; 3],
}

/// The power of two a solve's f32 batch sums are kept in units of, so that their range follows
/// the unshot values and not the scene's units.
///
/// A solve's values shrink geometrically toward its tolerance. Had the sums been kept in the
/// scene's units, a dim scene (emission 1e-30) or a tolerance of 1e-300 took them into f32's
/// subnormals, where a shot through a coupling above 1/2 rounds back up to the smallest
/// subnormal: the same few values circled between two elements for ever (seen in CI, from the
/// FFI property test). Scaled so that the largest unshot value starts in `[1, 2)`, the sums stay
/// normal down to 2^-126 of it, and a shot below that, which can deliver nothing f32 can hold, is
/// dropped instead of shot (`shoot`). Scaling by a power of two is exact, so solutions in the
/// normal range are bit-identical to unscaled sums.
#[derive(Clone, Copy, Debug)]
struct SumScale {
    /// Scene units -> sum units.
    up: f64,
    /// Sum units -> scene units.
    down: f64,
}

impl SumScale {
    fn of(unshot: &[[f64; 3]]) -> Result<Self> {
        let largest = unshot.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        if !largest.is_finite() {
            return Err(Error::Internal(format!("unshot radiosity {largest} is not finite")));
        }
        // f64 holds 2^+-1000 exactly; a largest value outside that is clamped (and a zero one
        // needs no scale).
        let exponent = if largest > 0.0 { largest.log2().floor().clamp(-1000.0, 1000.0) } else { 0.0 };
        Ok(Self { up: (-exponent).exp2(), down: exponent.exp2() })
    }
}

/// Lanes per channel of a batch's sums per receiver: `nb` rounded up to a whole vector.
///
/// A batch's sums are f32, `[receiver][channel][lane]`, each channel's row a whole vector
/// (16 lanes for `nb = 9`): a receiver takes a shot in one multiply-add per channel on its whole
/// row, with no shuffles. The f64 `[channel][k]` rows before took 18% longer a frame (solve
/// 17.9 -> 14.7 ms median, moving-light box, 5 interleaved runs) and the static solve 20% longer;
/// the time went to the adds and stores of 27 doubles in odd-sized rows, not to reading the links
/// (halving the link bytes had changed nothing). A batch's sums round to f32 (6e-8 relative)
/// once, before they join `b`, which stays f64: the shooting invariant holds to 2e-9 of the peak
/// (`replay` tests) and a frame's solution moves by 5e-9 of the peak.
fn lanes(nb: usize) -> usize {
    match nb {
        1 | 4 | 16 => nb,
        9 => 16,
        nb => unreachable!("{nb} basis functions"),
    }
}

/// How many receivers ahead a shot asks for the link columns it will read. The hardware's own
/// prefetch leaves the first load of each receiver's coefficients the slowest instruction of the
/// loop; 16 ahead (576 bytes) took the Delta solve from 16.3 to 15.1 ms median (5 interleaved
/// runs) and 14.5 to 12.7 ms in `cargo bench --bench solver` (3 alternating runs; 8 and 32
/// ahead gained less).
const PREFETCH_RECEIVERS: usize = 16;

/// A solve whose unshot power grows this many times over its start diverges. With reflectances
/// below 1 and form factors summing to at most 1, a shot delivers less power than it takes
/// (up to the weighting of the higher-order coefficients): growth means the kernel is wrong for
/// the scene, and without this test the solve went on until the values overflowed, then for ever
/// on NaN. Seen only in the FFI property test's random scenes, about 1 solve in 12,000: faces that
/// cross, overlap or share three corners, with visibility off or one visibility sample (surfaces
/// that hide one another then all receive light) or, before validation required more Gauss points
/// than the basis order, with too coarse a rule.
const DIVERGED: f64 = 1e6;

/// Batches with fewer link coefficients than this are shot on one thread: below it, handing
/// out the work costs more than it saves.
const PARALLEL_FLOATS: u64 = 1 << 16;

/// Progressive refinement until the unshot coefficients would deliver less than `stop_power`,
/// shooting in parallel batches. `cancel` is polled between batches. The link store must have
/// its receiver areas ([`LinkStore::set_receiver_areas`]).
///
/// Shooters are single coefficients, not whole elements: a batch takes every coefficient `l`
/// of every element whose unshot would deliver much power, and shooting it reads only column `l`
/// of the element's blocks ([`LinkStore::shooter_column`]). They are ranked, and the stopping
/// test summed, by the power they would deliver, `T_j^l sum_c |u_j^l,c|`, not by the size of the
/// unshot function: a higher-order coefficient (no net flux, a gradient) delivers far less than
/// its norm to all but its near neighbours; ranked by its norm it took a fifth more shots (a third
/// more floats read) in a frame's Delta solve. With reflectances below `rho_max`, what is left
/// unshot changes the solution by at most `rho_max / (1 - rho_max)` times `stop_power` in power.
///
/// Threads split the receivers (element ranges of equal link count), not the shooters, so each
/// writes its own part of `b` and `unshot` directly and the sums do not depend on the threads.
pub fn shoot(
    links: &LinkStore,
    reflectance: &[[f64; 3]],
    x: &mut Coefficients,
    stop_power: f64,
    cancel: &dyn Fn() -> bool,
) -> Result<ShootStats> {
    use rayon::prelude::*;
    let nb = x.nb;
    let n = reflectance.len();
    let transfer = links.transfers();
    assert_eq!(transfer.len(), n * nb, "the link store needs its receiver areas");
    let mut priority: Vec<f64> = (0..n * nb).map(|i| coefficient_power(&x.unshot[i], transfer[i])).collect();
    let mut stats = ShootStats::default();
    let parts = receiver_ranges(links, n, rayon::current_num_threads().max(1));
    let mut shots: Vec<Shot> = Vec::new();
    // The batch sums, their rows starting on cache lines ([`lanes`]).
    let lane = lanes(nb);
    let width = 3 * lane;
    let mut gathered_buf = vec![0.0f32; n * width + 16];
    let offset = gathered_buf.as_ptr().align_offset(64);
    let gathered = &mut gathered_buf[offset..offset + n * width];
    let scale = SumScale::of(&x.unshot)?;
    let start_total: f64 = priority.iter().sum();
    loop {
        let total: f64 = priority.iter().sum();
        let best = priority.iter().copied().fold(0.0, f64::max);
        if total <= stop_power || best <= 0.0 {
            stats.residual = total;
            return Ok(stats);
        }
        if !total.is_finite() || total > DIVERGED * start_total {
            return Err(invalid_scene!(
                "the solution diverges (the unshot power grew {:.1e}-fold in {} shots): the kernel \
                 passes on more light than it receives, as with faces that cross or overlap while \
                 visibility is off or coarse; turn visibility on, raise settings.visibility_samples \
                 and quadrature_order, or mend the mesh",
                total / start_total,
                stats.shots
            ));
        }
        if cancel() {
            return Err(Error::Cancelled);
        }
        // Take the batch's unshot coefficients.
        shots.clear();
        let mut floats = 0;
        for e in 0..n {
            let before = shots.len();
            for l in 0..nb {
                let i = e * nb + l;
                if priority[i] >= BATCH_FRACTION * best && priority[i] > 0.0 {
                    let u = x.unshot[i].map(|v| (v * scale.up) as f32);
                    if u.iter().any(|v| v.abs() >= f32::MIN_POSITIVE) {
                        shots.push(Shot { e: e as ElementId, l: l as u32, u });
                    }
                    x.unshot[i] = [0.0; 3];
                    priority[i] = 0.0;
                }
            }
            floats += ((shots.len() - before) * links.receivers_of(e as ElementId).len() * nb) as u64;
        }
        stats.shots += shots.len();
        stats.floats_read += floats;
        let ranges: &[(usize, usize)] = if floats < PARALLEL_FLOATS { &[(0, n)] } else { &parts };
        // Split the outputs along the receiver ranges.
        let mut work = Vec::with_capacity(ranges.len());
        let (mut b, mut unshot) = (&mut x.b[..], &mut x.unshot[..]);
        let (mut pr, mut gs) = (&mut priority[..], &mut gathered[..]);
        for &(lo, hi) in ranges {
            let m = hi - lo;
            let (b0, b1) = b.split_at_mut(m * nb);
            let (u0, u1) = unshot.split_at_mut(m * nb);
            let (p0, p1) = pr.split_at_mut(m * nb);
            let (g0, g1) = gs.split_at_mut(m * width);
            work.push(Part { lo, hi, b: b0, unshot: u0, priority: p0, gathered: g0 });
            (b, unshot, pr, gs) = (b1, u1, p1, g1);
        }
        let shots = &shots;
        let run = |part: Part| {
            let mut touched = vec![false; part.hi - part.lo];
            shoot_range(links, shots, nb, part.lo, part.hi, part.gathered, &mut touched);
            // rho_i is the same for every shooter, so it multiplies the sum once, here.
            for (r, _) in touched.iter().enumerate().filter(|(_, t)| **t) {
                let e = part.lo + r;
                let g = &mut part.gathered[r * width..(r + 1) * width];
                for k in 0..nb {
                    for c in 0..3 {
                        let d = reflectance[e][c] * (g[c * lane + k] as f64 * scale.down);
                        part.b[r * nb + k][c] += d;
                        part.unshot[r * nb + k][c] += d;
                    }
                }
                g.fill(0.0);
                for l in 0..nb {
                    part.priority[r * nb + l] =
                        coefficient_power(&part.unshot[r * nb + l], transfer[e * nb + l]);
                }
            }
        };
        if work.len() == 1 {
            work.into_iter().for_each(run);
        } else {
            work.into_par_iter().for_each(run);
        }
    }
}

/// One thread's share of a batch: receivers `lo..hi` and their slices of the solution.
struct Part<'a> {
    lo: usize,
    hi: usize,
    b: &'a mut [[f64; 3]],
    unshot: &'a mut [[f64; 3]],
    priority: &'a mut [f64],
    /// `sum_j G_ij u_j` per receiver, `[c][lane]` ([`lanes`]), zero between batches.
    gathered: &'a mut [f32],
}

/// Splits elements `0..n` into at most `parts` consecutive ranges receiving about the same
/// number of links (the work of a shot is per link).
fn receiver_ranges(links: &LinkStore, n: usize, parts: usize) -> Vec<(usize, usize)> {
    let degree = |e: usize| links.pairs_of(e as ElementId).len() + 1;
    let total: usize = (0..n).map(degree).sum();
    let mut ranges = Vec::with_capacity(parts);
    let (mut lo, mut acc) = (0, 0);
    for e in 0..n {
        acc += degree(e);
        if acc * parts >= total * (ranges.len() + 1) && ranges.len() + 1 < parts {
            ranges.push((lo, e + 1));
            lo = e + 1;
        }
    }
    ranges.push((lo, n));
    ranges
}

crate::simd::multiversion! {
    /// Adds to receivers `lo..hi` (outputs indexed from `lo`) what the batch `shots` (grouped by
    /// element, as taken) sends them before reflection, `sum_l G_ij^{kl} u_l`, into `gathered`
    /// (`[receiver][c][lane]`, [`lanes`]), and marks them `touched`.
    fn shoot_range(
        links: &LinkStore,
        shots: &[Shot],
        nb: usize,
        lo: usize,
        hi: usize,
        gathered: &mut [f32],
        touched: &mut [bool],
    ) {
        match nb {
            1 => shoot_range_nb::<1, 1>(links, shots, lo, hi, gathered, touched),
            4 => shoot_range_nb::<4, 4>(links, shots, lo, hi, gathered, touched),
            9 => shoot_range_nb::<9, 16>(links, shots, lo, hi, gathered, touched),
            16 => shoot_range_nb::<16, 16>(links, shots, lo, hi, gathered, touched),
            nb => unreachable!("{nb} basis functions"),
        }
    }
}

/// [`shoot_range`] with `NB` basis functions and `L` lanes per channel ([`lanes`]).
#[inline(always)]
fn shoot_range_nb<const NB: usize, const L: usize>(
    links: &LinkStore,
    shots: &[Shot],
    lo: usize,
    hi: usize,
    gathered: &mut [f32],
    touched: &mut [bool],
) {
    let (gathered, _) = gathered.as_chunks_mut::<L>();
    let (gathered, _) = gathered.as_chunks_mut::<3>();
    for group in shots.chunk_by(|x, y| x.e == y.e) {
        let e = group[0].e;
        let receivers = links.receivers_of(e);
        // The group's columns, each `[receiver][k]`.
        let cols: [&[[f32; NB]]; NB] = std::array::from_fn(|m| match group.get(m) {
            Some(s) => links.shooter_column(e, s.l as usize).as_chunks::<NB>().0,
            None => &[],
        });
        let cols = &cols[..group.len()];
        // The group's unshot values, as the sums are kept.
        let us: [[f32; 3]; NB] = std::array::from_fn(|m| group.get(m).map_or([0.0; 3], |s| s.u));
        for (r, &i) in receivers.iter().enumerate() {
            let i = i as usize;
            if i < lo || i >= hi {
                continue;
            }
            // acc[c][k] += sum_l G[k][l] u[l][c] over the group's l, one vector per channel.
            let acc = &mut gathered[i - lo];
            for (col, u) in cols.iter().zip(&us) {
                if let Some(ahead) = col.get(r + PREFETCH_RECEIVERS) {
                    crate::simd::prefetch(&ahead[..1]);
                }
                let g: [f32; L] = std::array::from_fn(|k| if k < NB { col[r][k] } else { 0.0 });
                for c in 0..3 {
                    for k in 0..L {
                        acc[c][k] += g[k] * u[c];
                    }
                }
            }
            touched[i - lo] = true;
        }
    }
}

/// `sum_j G_ij^{kl} v_j^l` for receiver `i`, per `k` (before reflection): one row of eq. (5)'s
/// sum, read through the store pair by pair (for checks, not speed).
pub fn gather_row(links: &LinkStore, i: ElementId, v: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let nb = links.nb();
    let mut acc = vec![[0.0; 3]; nb];
    for &p in links.pairs_of(i) {
        let j = links.other(p, i) as usize;
        for l in 0..nb {
            let g = links.column(p, i, l);
            for k in 0..nb {
                for c in 0..3 {
                    acc[k][c] += g[k] as f64 * v[j * nb + l][c];
                }
            }
        }
    }
    acc
}

/// [`gather_row`] on two vectors at once, each sum exactly as [`gather_row`] forms it (the same
/// products, added in the same order: pair, then `l`), so the results are bit for bit its own.
/// One pass over the row's blocks serves both vectors (the row, scattered over its shooters'
/// columns, is what costs: the animation's hemisphere bound gathers `b - u` and `sigma` on each
/// receiver whose bound changed, 630 of the billiard's 1,189 per frame).
pub fn gather_row_pair(links: &LinkStore, i: ElementId, v: [&[[f64; 3]]; 2]) -> [Vec<[f64; 3]>; 2] {
    match links.nb() {
        1 => gather_row_pair_nb::<1>(links, i, v),
        4 => gather_row_pair_nb::<4>(links, i, v),
        9 => gather_row_pair_nb::<9>(links, i, v),
        16 => gather_row_pair_nb::<16>(links, i, v),
        nb => unreachable!("{nb} basis functions"),
    }
}

/// How many pairs ahead [`gather_row_pair`] asks for a row's blocks.
const PREFETCH_ROW_PAIRS: usize = 4;

fn gather_row_pair_nb<const NB: usize>(
    links: &LinkStore,
    i: ElementId,
    [v, w]: [&[[f64; 3]]; 2],
) -> [Vec<[f64; 3]>; 2] {
    let mut acc = [[[0.0f64; 3]; NB]; 2];
    let pairs = links.pairs_of(i);
    for (x, &p) in pairs.iter().enumerate() {
        if let Some(&ahead) = pairs.get(x + PREFETCH_ROW_PAIRS) {
            let (shooter, slot) = links.slot(ahead, i);
            for l in 0..NB {
                crate::simd::prefetch(&links.shooter_column(shooter as ElementId, l)[slot * NB..][..NB]);
            }
        }
        let (j, slot) = links.slot(p, i);
        let (vj, wj) = (&v[j * NB..][..NB], &w[j * NB..][..NB]);
        for l in 0..NB {
            let g = &links.shooter_column(j as ElementId, l)[slot * NB..][..NB];
            for k in 0..NB {
                let g = g[k] as f64;
                for c in 0..3 {
                    acc[0][k][c] += g * vj[l][c];
                    acc[1][k][c] += g * wj[l][c];
                }
            }
        }
    }
    acc.map(|a| a.to_vec())
}

/// Shooter ranges [`gather_rows`] splits the store into, summed in range order: a fixed number,
/// so that its sums do not depend on the thread count.
const GATHER_CHUNKS: usize = 8;

/// [`gather_row_pair`] for many receivers `rows` at once: the store streamed shooter by shooter
/// (its layout, as a shot reads it), each shooter's columns read once for every row. A receiver's
/// sum then runs in shooter order instead of its pairs' order, so it equals
/// [`gather_row_pair`]'s up to rounding (billiard, 8 frames: within 2.8e-18 of the peak). Reading
/// the whole store pays when the rows are many: the billiard's ~630 of 1,189 hemisphere bounds a
/// frame, pair by pair, were memory stalls on a scattered read (one column slice per `l`).
pub fn gather_rows(links: &LinkStore, rows: &[ElementId], v: [&[[f64; 3]]; 2]) -> Vec<[Vec<[f64; 3]>; 2]> {
    use rayon::prelude::*;
    let nb = links.nb();
    let n = v[0].len() / nb;
    let mut pos = vec![u32::MAX; n];
    for (q, &i) in rows.iter().enumerate() {
        pos[i as usize] = q as u32;
    }
    // Per row: `[vector][c][k]`.
    let width = 2 * 3 * nb;
    let step = n.div_ceil(GATHER_CHUNKS).max(1);
    let starts: Vec<usize> = (0..n).step_by(step).collect();
    let parts: Vec<Vec<f64>> = starts
        .into_par_iter()
        .map(|lo| {
            let mut acc = vec![0.0; rows.len() * width];
            gather_shooters(links, lo, (lo + step).min(n), &pos, v[0], v[1], &mut acc);
            acc
        })
        .collect();
    let mut total = vec![0.0; rows.len() * width];
    for part in &parts {
        for (t, x) in total.iter_mut().zip(part) {
            *t += x;
        }
    }
    total
        .chunks_exact(width)
        .map(|a| {
            std::array::from_fn(|h| {
                (0..nb).map(|k| std::array::from_fn(|c| a[(h * 3 + c) * nb + k])).collect()
            })
        })
        .collect()
}

crate::simd::multiversion! {
    /// Adds what shooters `lo..hi` send the rows marked in `pos` (their index, `u32::MAX`
    /// elsewhere) from `v` and `w` into `acc` (`[row][vector][c][k]`), for [`gather_rows`].
    fn gather_shooters(
        links: &LinkStore,
        lo: usize,
        hi: usize,
        pos: &[u32],
        v: &[[f64; 3]],
        w: &[[f64; 3]],
        acc: &mut [f64],
    ) {
        match links.nb() {
            1 => gather_shooters_nb::<1>(links, lo..hi, pos, [v, w], acc),
            4 => gather_shooters_nb::<4>(links, lo..hi, pos, [v, w], acc),
            9 => gather_shooters_nb::<9>(links, lo..hi, pos, [v, w], acc),
            16 => gather_shooters_nb::<16>(links, lo..hi, pos, [v, w], acc),
            nb => unreachable!("{nb} basis functions"),
        }
    }
}

#[inline(always)]
fn gather_shooters_nb<const NB: usize>(
    links: &LinkStore,
    shooters: std::ops::Range<usize>,
    pos: &[u32],
    [v, w]: [&[[f64; 3]]; 2],
    acc: &mut [f64],
) {
    let (acc, _) = acc.as_chunks_mut::<NB>();
    for j in shooters {
        let cols: [&[[f32; NB]]; NB] =
            std::array::from_fn(|l| links.shooter_column(j as ElementId, l).as_chunks::<NB>().0);
        let (vj, wj) = (&v[j * NB..][..NB], &w[j * NB..][..NB]);
        for (r, &i) in links.receivers_of(j as ElementId).iter().enumerate() {
            let q = pos[i as usize];
            if q == u32::MAX {
                continue;
            }
            let a = &mut acc[q as usize * 6..][..6];
            for l in 0..NB {
                let g: [f64; NB] = std::array::from_fn(|k| cols[l][r][k] as f64);
                for c in 0..3 {
                    for k in 0..NB {
                        a[c][k] += g[k] * vj[l][c];
                        a[3 + c][k] += g[k] * wj[l][c];
                    }
                }
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
            let acc = gather_row(links, i as ElementId, &b);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::visibility::Visibility;

    /// Two elements, one basis function, coupled both ways by `g` (`G_ab = G_ba = g`).
    fn facing_pair(g: f64) -> LinkStore {
        let mut links = LinkStore::new(2, 1);
        links.push(0, 1, &[g], &[g], Visibility::Full);
        links.set_receiver_areas(&[1.0, 1.0]);
        links
    }

    /// Solves with emission `e` on element 0 down to `stop`, failing (not hanging) after 10,000
    /// batches.
    fn solve(links: &LinkStore, rho: f64, e: f64, stop: f64) -> Result<Coefficients> {
        let mut x = Coefficients::from_emission(&[[e; 3], [0.0; 3]], 1);
        let batches = std::cell::Cell::new(0);
        let cancel = || {
            batches.set(batches.get() + 1);
            batches.get() > 10_000
        };
        shoot(links, &[[rho; 3]; 2], &mut x, stop, &cancel)?;
        Ok(x)
    }

    #[test]
    fn dim_scenes_and_tiny_tolerances_converge_to_the_closed_form() {
        // A coupling above 1/2 is what trapped unscaled f32 sums: from the smallest subnormal,
        // 0.9 * 0.9 of it rounds back up to it, and the solve went on for ever.
        let (g, rho) = (0.9, 0.9);
        let links = facing_pair(g);
        // b_0 = e / (1 - (rho g)^2), b_1 = rho g b_0.
        let closed_form = |e: f64| {
            let b0 = e / (1.0 - (rho * g) * (rho * g));
            [b0, rho * g * b0]
        };
        for (e, stop) in [(1.0, 1e-12), (1e-30, 1e-300), (1.0, 1e-300), (1e30, 1e-10)] {
            let x = solve(&links, rho, e, stop).unwrap_or_else(|err| panic!("e {e}, stop {stop}: {err}"));
            let want = closed_form(e);
            for (b, w) in x.b.iter().zip(want) {
                // f32 sums: 6e-8 relative per batch.
                assert!((b[0] - w).abs() < 1e-6 * w, "e {e}, stop {stop}: {} vs {w}", b[0]);
            }
        }
    }

    #[test]
    fn a_diverging_kernel_is_an_error_not_a_hang() {
        // rho g = 1.35 > 1: each bounce brings back more than was sent.
        let links = facing_pair(1.5);
        match solve(&links, 0.9, 1.0, 1e-6) {
            Err(Error::InvalidScene(m)) => assert!(m.contains("diverges"), "{m}"),
            other => panic!("{other:?}"),
        }
        // Just below 1 converges, however slowly.
        assert!(solve(&facing_pair(1.1), 0.9, 1.0, 1e-6).is_ok());
    }

    #[test]
    fn solutions_scale_with_the_emission_exactly() {
        // The sums are kept in units of a power of two that follows the values, so a scene 2^-100
        // as bright solves to exactly 2^-100 times the solution, shot for shot.
        let links = facing_pair(0.7);
        let bright = solve(&links, 0.8, 1.5, 1e-9).unwrap();
        let dim = solve(&links, 0.8, 1.5 * 2f64.powi(-100), 1e-9 * 2f64.powi(-100)).unwrap();
        for (a, b) in bright.b.iter().zip(&dim.b) {
            assert_eq!(a.map(|v| v * 2f64.powi(-100)), *b);
        }
    }
}
