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
    /// The replay's `K sigma` (crate::replay), under the kernel before this frame's changes.
    pub(super) k_sigma: Option<&'a [[f64; 3]]>,
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
    /// taken on (b - u) and on sigma like the block changes. Which bounds changed is O(1) per
    /// receiver: the store keeps each row's sum through its writes (LinkStore::row_sum).
    ///
    /// The rows' products `G_new (b - u)` and `G_new sigma` come from what the solution already
    /// holds ([`Self::row_products`]), not from the store: in a closed scene every row's sum is 1 up to
    /// quadrature error, so a moving light moves about half the bounds every frame, and reading
    /// their rows through the store took 22-31 ms of the moving-light box's 33-47 ms kernel update
    /// (the add-on's live preview, 2026-12-07). Rows that cannot be taken that way are gathered.
    pub(super) fn add_bound_changes(
        &mut self,
        sys: &mut System,
        first: &[u32],
        elements: &[Element],
        next: &Scene,
    ) {
        let n = first.len() - 1;
        let nb = sys.basis.len();
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
        let products = self.row_products(sys_ref, &bounds);
        let [delta_b, delta_k_sigma] = &mut self.out;
        for (&(r, bounded), [on_sent, on_sigma]) in bounds.iter().zip(&products) {
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

    /// Per receiver `r` of `bounds`, its row of the new kernel's `G` taken on `b - u` and on
    /// `sigma`, both before reflection.
    ///
    /// Progressive shooting keeps `b = s + K (b - u)` (`s` the sources, emission and direct light;
    /// `K = rho' G`, rho' the bounded reflectance it shot with; crate::replay), and the replay's
    /// `K sigma` is the change of `b` its shots made under the same kernel. The pairs' changes
    /// this frame added `rho' (G_new - G_old)` on both vectors to `out` already. So per channel
    /// with `rho' > 0`:
    ///
    /// ```text
    /// G_new (b - u) = (b - s + Delta b) / rho',    G_new sigma = (K sigma + Delta K sigma) / rho',
    /// ```
    ///
    /// O(1) per row, equal to a gather through the store up to the solver's rounding (its batch
    /// sums are `f32`; the test `bound_rows_from_the_solution_equal_the_stores_rows`). A row with
    /// a channel whose bound changes from `rho' = 0` (a material keyed up from black) is gathered
    /// through the store: many rows (an eighth of the elements or more) by streaming it once
    /// (solver::gather_rows, equal up to rounding), few each on its own (gather_row_pair).
    fn row_products(&self, sys: &System, bounds: &[(usize, [f64; 3])]) -> Vec<[Vec<[f64; 3]>; 2]> {
        let nb = sys.basis.len();
        let n = sys.solution.b.len() / nb;
        let [delta_b, delta_k_sigma] = &self.out;
        let from_solution = |&(r, bounded): &(usize, [f64; 3])| -> Option<[Vec<[f64; 3]>; 2]> {
            let rho = sys.reflectance[r];
            if (0..3).any(|c| rho[c] <= 0.0 && bounded[c] != rho[c]) {
                return None;
            }
            let per = |f: &dyn Fn(usize, usize) -> f64| -> Vec<[f64; 3]> {
                (r * nb..(r + 1) * nb)
                    .map(|k| std::array::from_fn(|c| if rho[c] > 0.0 { f(k, c) / rho[c] } else { 0.0 }))
                    .collect()
            };
            let source = |k: usize, c: usize| sys.emission[k][c] + sys.direct.get(k).map_or(0.0, |d| d[c]);
            let on_sent = per(&|k, c| sys.solution.b[k][c] - source(k, c) + delta_b[k][c]);
            let on_sigma = per(&|k, c| self.k_sigma.map_or(0.0, |ks| ks[k][c]) + delta_k_sigma[k][c]);
            Some([on_sent, on_sigma])
        };
        let mut products: Vec<Option<[Vec<[f64; 3]>; 2]>> = bounds.par_iter().map(from_solution).collect();
        let rest: Vec<usize> = (0..bounds.len()).filter(|&q| products[q].is_none()).collect();
        let gathered: Vec<[Vec<[f64; 3]>; 2]> = if rest.len() * 8 >= n {
            let rows: Vec<u32> = rest.iter().map(|&q| bounds[q].0 as u32).collect();
            solver::gather_rows(&sys.links, &rows, self.x)
        } else {
            rest.par_iter()
                .map(|&q| solver::gather_row_pair(&sys.links, bounds[q].0 as u32, self.x))
                .collect()
        };
        for (q, g) in rest.into_iter().zip(gathered) {
            products[q] = Some(g);
        }
        let products: Vec<_> = products.into_iter().map(|p| p.expect("every row taken")).collect();
        #[cfg(test)]
        tests::check_against_the_store(sys, self.x, bounds, &products);
        products
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

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use super::*;
    use crate::animation::{AnimationState, Outcome, advance};
    use crate::scene::Settings;
    use crate::system::no_progress;

    thread_local! {
        /// Set by a test: the worst departure of the bound rows taken from the solution from the
        /// same rows gathered through the store, of the frame's largest gathered entry, and how
        /// many rows were compared (`None`: not checked).
        static CHECKED: Cell<Option<(f64, usize)>> = const { Cell::new(None) };
    }

    /// With [`CHECKED`] set, gathers every row of `bounds` through the store and records how far
    /// `products` are from them.
    pub(super) fn check_against_the_store(
        sys: &System,
        x: [&[[f64; 3]]; 2],
        bounds: &[(usize, [f64; 3])],
        products: &[[Vec<[f64; 3]>; 2]],
    ) {
        let Some((worst, rows)) = CHECKED.get() else { return };
        let gathered: Vec<_> =
            bounds.iter().map(|&(r, _)| solver::gather_row_pair(&sys.links, r as u32, x)).collect();
        let entries = |rows: &[[Vec<[f64; 3]>; 2]], v: usize| -> Vec<f64> {
            rows.iter().flat_map(|row| row[v].iter().flatten().copied().collect::<Vec<_>>()).collect()
        };
        let mut frame_worst: f64 = 0.0;
        for v in 0..2 {
            let (ours, theirs) = (entries(products, v), entries(&gathered, v));
            let peak = theirs.iter().fold(0.0f64, |m, g| m.max(g.abs()));
            if peak > 0.0 {
                let apart = ours.iter().zip(&theirs).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                frame_worst = frame_worst.max(apart / peak);
            }
        }
        CHECKED.set(Some((worst.max(frame_worst), rows + bounds.len())));
    }

    /// The moving light changes every row's form-factor sum in a closed box, and about half the
    /// rows are bounded (their sum over 1 by quadrature error): the rows' products taken from the
    /// solution's invariant are the store's, on `b - u` and on the replay's `sigma`, frame after
    /// frame.
    #[test]
    fn bound_rows_from_the_solution_equal_the_stores_rows() {
        let settings = Settings { basis_order: 2, corner_gather: false, ..Settings::default() };
        let scene = crate::scenes::cornell_box_moving_light(8, 8, settings);
        let mut sys = System::build(&scene, 1.0, &no_progress).unwrap();
        sys.solve(scene.settings.tolerance, &|| false).unwrap();
        let mut state = AnimationState::new(sys.elements.len(), true);
        CHECKED.set(Some((0.0, 0)));
        for f in 2..=8 {
            let outcome = advance(&mut sys, &mut state, &scene, f as f64, &no_progress).unwrap();
            assert!(matches!(outcome, Outcome::Updated(_)), "frame {f} needed a rebuild");
        }
        let (worst, rows) = CHECKED.take().unwrap();
        assert!(rows >= 50, "only {rows} bound rows moved over 7 frames");
        assert!(worst < 1e-5, "the rows taken from the solution are {worst:e} of the peak from the store's");
    }
}
