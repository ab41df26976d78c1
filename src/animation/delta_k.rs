//! `Delta K (b - u)` and `Delta K sigma` (eq. 9): the change of the stored kernel taken on the part
//! already shot and on the replay's `sigma`, from the pairs the store took this frame and from the
//! rows whose hemisphere bound moved.

use rayon::prelude::*;

use crate::hemisphere;
use crate::links::ReplacedBlocks;
use crate::scene::Scene;
use crate::solver::{self, Coefficients};
use crate::system::{Element, System};

use super::apply::Written;

/// A pair's kernel change for `Delta K (b - u)`: `new = [G_ij | G_ji]`, `old` the two blocks
/// replaced (zero for a new pair).
struct KernelChange<'a> {
    i: u32,
    j: u32,
    new: &'a [f32],
    old: [&'a [f32]; 2],
}

/// How many changes ahead `Delta K (b - u)` prefetches blocks.
const PREFETCH_CHANGES: usize = 4;

/// `b - u` of `solution`, the part already shot (module docs), written over `sent` (a buffer).
pub(super) fn shot_part(solution: &Coefficients, mut sent: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
    sent.clear();
    sent.extend(solution.b.iter().zip(&solution.unshot).map(|(b, u)| std::array::from_fn(|c| b[c] - u[c])));
    sent
}

/// The kernel's changes taken on the two vectors `x`, `b - u` and `sigma` (zero without a replay),
/// added to `out`, `Delta b` and `Delta K sigma`.
pub(super) struct DeltaK<'a> {
    pub(super) x: [&'a [[f64; 3]]; 2],
    pub(super) out: [&'a mut [[f64; 3]]; 2],
}

impl DeltaK<'_> {
    /// Adds `Delta K (b - u)` with the previous frame's b and u (the part already shot: module
    /// docs), and `Delta K sigma`, for both receivers of each pair in `written` (eq. 9), under the
    /// system's reflectances; `replaced` holds the blocks its rewrites replaced. Returns per
    /// receiver `r` the range `first[r]..first[r + 1]` of its changes (empty: none).
    ///
    /// Summed per receiver in parallel: the changes are listed by receiver (a counting sort), so
    /// each task owns its rows of Delta b and sums them in change order, whatever the threads (a
    /// fold over changes allocated and summed a whole Delta b per run, slower than one thread).
    pub(super) fn add_pair_changes(
        &mut self,
        sys: &System,
        written: &Written,
        replaced: &ReplacedBlocks,
    ) -> Vec<u32> {
        let nb = sys.basis.len();
        let n = self.out[0].len() / nb;
        let n2 = nb * nb;
        let Written { rewrites, fresh } = written;
        let zeros = vec![0.0f32; n2];
        let changes: Vec<KernelChange> = rewrites
            .iter()
            .enumerate()
            .map(|(k, &(p, i, new))| KernelChange {
                i,
                j: sys.links.other(p, i),
                new,
                old: [replaced.get(k, 0), replaced.get(k, 1)],
            })
            .chain(fresh.iter().map(|&(i, j, new)| KernelChange { i, j, new, old: [&zeros, &zeros] }))
            .collect();
        // Per receiver, `first[r]..first[r + 1]` of `received`: (change, half), half 0 being
        // `G_ij` for receiver `i`, half 1 `G_ji` for `j`.
        let mut first = vec![0u32; n + 1];
        for c in &changes {
            first[c.i as usize + 1] += 1;
            first[c.j as usize + 1] += 1;
        }
        for e in 0..n {
            first[e + 1] += first[e];
        }
        let mut fill = first.clone();
        let mut received = vec![(0u32, 0u8); 2 * changes.len()];
        for (k, c) in changes.iter().enumerate() {
            for (half, r) in [(0u8, c.i), (1, c.j)] {
                received[fill[r as usize] as usize] = (k as u32, half);
                fill[r as usize] += 1;
            }
        }
        // What receiver `r` gets from entry `(k, half)`: the source and the new and old block.
        let blocks_of = |(k, half): (u32, u8)| {
            let c = &changes[k as usize];
            let source = if half == 0 { c.j } else { c.i };
            (source, &c.new[half as usize * n2..][..n2], c.old[half as usize])
        };
        let [sent, sigma] = self.x;
        let [delta_b, delta_k_sigma] = &mut self.out;
        let outputs = delta_b.par_chunks_mut(nb).zip(delta_k_sigma.par_chunks_mut(nb));
        outputs.enumerate().for_each(|(r, (out_b, out_sigma))| {
            let mine = &received[first[r] as usize..first[r + 1] as usize];
            for (x, &entry) in mine.iter().enumerate() {
                // The blocks lie wherever their pairs were computed: ask for them ahead
                // (measured: apply 8.4 -> 7.1 ms median on the moving-light box).
                if let Some(&ahead) = mine.get(x + PREFETCH_CHANGES) {
                    let (_, new, old) = blocks_of(ahead);
                    crate::simd::prefetch(new);
                    crate::simd::prefetch(old);
                }
                let (source, new, old) = blocks_of(entry);
                let s = source as usize * nb..(source as usize + 1) * nb;
                let rho = sys.reflectance[r];
                delta_kb([&mut *out_b, &mut *out_sigma], rho, [&sent[s.clone()], &sigma[s]], new, old);
            }
        });
        first
    }

    /// Adds the changes of the hemisphere bound of the receivers with changes (`first`, from
    /// [`Self::add_pair_changes`]), and sets the system's bound to them; `elements` are the new
    /// frame's, their surface reflectance that of `next`.
    ///
    /// The hemisphere bound follows the changed rows (crate::hemisphere): a receiver whose
    /// bounded reflectance goes from rho' to rho'' changes the kernel by (rho'' - rho') G_new,
    /// taken on (b - u) and on sigma like the block changes. Whole rows: the billiard changes
    /// ~630 of its 1,189 bounds a frame, which two serial gather_row each took 0.57 s of a 0.65 s
    /// apply (0.013 s before the bound). Both vectors in one pass; many rows (an eighth of the
    /// elements or more) by streaming the store once (solver::gather_rows, equal up to rounding),
    /// few rows each on its own in parallel (gather_row_pair). Which bounds changed is O(1) per
    /// receiver: the store keeps each row's sum through its writes (LinkStore::row_sum); summing
    /// every changed receiver's whole row here cost the moving-light box, whose light changes
    /// every row, 7.6 ms of a 22.4 ms apply (medians).
    pub(super) fn add_bound_changes(
        &mut self,
        sys: &mut System,
        first: &[u32],
        elements: &[Element],
        next: &Scene,
    ) {
        let n = first.len() - 1;
        let nb = sys.basis.len();
        let [sent, sigma] = self.x;
        let [delta_b, delta_k_sigma] = &mut self.out;
        let sys_ref = &*sys;
        let bounds: Vec<(usize, [f64; 3])> = (0..n)
            .into_par_iter()
            .filter(|&r| first[r] < first[r + 1])
            .filter_map(|r| {
                let rho = elements[r].reflectance(next);
                let bounded = hemisphere::bounded_reflectance(&sys_ref.links, r as u32, rho);
                (bounded != sys_ref.reflectance[r]).then_some((r, bounded))
            })
            .collect();
        let gathered: Vec<[Vec<[f64; 3]>; 2]> = if bounds.len() * 8 >= n {
            let rows: Vec<u32> = bounds.iter().map(|&(r, _)| r as u32).collect();
            solver::gather_rows(&sys_ref.links, &rows, [sent, sigma])
        } else {
            bounds
                .par_iter()
                .map(|&(r, _)| solver::gather_row_pair(&sys_ref.links, r as u32, [sent, sigma]))
                .collect()
        };
        for (&(r, bounded), [on_sent, on_sigma]) in bounds.iter().zip(&gathered) {
            let change: [f64; 3] = std::array::from_fn(|c| bounded[c] - sys_ref.reflectance[r][c]);
            for k in 0..nb {
                for c in 0..3 {
                    delta_b[r * nb + k][c] += change[c] * on_sent[k][c];
                    delta_k_sigma[r * nb + k][c] += change[c] * on_sigma[k][c];
                }
            }
        }
        for (r, bounded) in bounds {
            sys.reflectance[r] = bounded;
        }
    }
}

crate::simd::multiversion! {
    /// `out[v] += rho (G_new - G_old) x[v]` for one receiver (its `nb` coefficients, reflectance
    /// `rho`) and the coefficients `x[v]` of one source, for the two vectors `b - u` and `sigma`
    /// at once: the blocks are read once, and the six channels of the two vectors make one vector
    /// register (a multiply per block entry instead of six).
    fn delta_kb(out: [&mut [[f64; 3]]; 2], rho: [f64; 3], x: [&[[f64; 3]]; 2], new: &[f32], old: &[f32]) {
        match x[0].len() {
            1 => delta_kb_nb::<1>(out, rho, x, new, old),
            4 => delta_kb_nb::<4>(out, rho, x, new, old),
            9 => delta_kb_nb::<9>(out, rho, x, new, old),
            16 => delta_kb_nb::<16>(out, rho, x, new, old),
            nb => unreachable!("{nb} basis functions"),
        }
    }
}

/// [`delta_kb`] with `NB` basis functions.
#[inline(always)]
fn delta_kb_nb<const NB: usize>(
    [out_b, out_sigma]: [&mut [[f64; 3]]; 2],
    rho: [f64; 3],
    x: [&[[f64; 3]]; 2],
    new: &[f32],
    old: &[f32],
) {
    // Per source function l: b's three channels, sigma's three, two lanes of padding.
    let xs: [[f64; 8]; NB] = std::array::from_fn(|l| {
        let (b, s) = (x[0][l], x[1][l]);
        [b[0], b[1], b[2], s[0], s[1], s[2], 0.0, 0.0]
    });
    let rows = new.as_chunks::<NB>().0.iter().zip(old.as_chunks::<NB>().0);
    for ((ob, os), (new, old)) in out_b.iter_mut().zip(out_sigma.iter_mut()).zip(rows) {
        let mut acc = [0.0f64; 8];
        for (xl, (&g1, &g0)) in xs.iter().zip(new.iter().zip(old)) {
            let d = g1 as f64 - g0 as f64;
            for v in 0..8 {
                acc[v] += d * xl[v];
            }
        }
        for c in 0..3 {
            ob[c] += rho[c] * acc[c];
            os[c] += rho[c] * acc[3 + c];
        }
    }
}
