//! Replaying the last frame's shots as the first guess of the next frame's Delta solve.
//!
//! Progressive refinement keeps `b = e + K (b - u)` (`u` the unshot part, `K = rho G`): every
//! shot moves energy from `u` into `s = b - u`, the part already sent. A frame's solve makes the
//! shots `sigma = s_after - s_before`, and they deliver `K sigma = b_after - b_before`. Both are
//! known for free once the solve is done, and the next frame, whose kernel is `K' = K + Delta K`,
//! can replay `alpha sigma` by adding
//!
//! ```text
//! b += alpha K' sigma,    u += alpha (K' sigma - sigma),    K' sigma = K sigma + Delta K sigma,
//! ```
//!
//! which keeps the invariant for any `alpha` (exactly, but for the rounding of the solver's f32
//! batch sums): the solution and the error bound of the solve are those without the replay, only
//! the work changes. `Delta K sigma` costs what `Delta K b` costs (the changed pairs only, formed
//! alongside it). Under steady motion the frames' shots resemble each other, so much of the new
//! frame's unshot power cancels: on the moving-light box the power left to shoot halves and the
//! solve takes about 30% fewer shots (README, issue 3).
//!
//! `alpha` minimises the unshot power `sum T |u + alpha c|` (`c = K' sigma - sigma`, `T` the
//! transfers the solver ranks and stops by): a weighted median, within `[-3, 3]`. It is near 1
//! while the motion holds and falls to 0 when it stops, where replaying the last frame would add
//! work.

use crate::solver::Coefficients;

/// The shots of one solve and what they delivered.
#[derive(Clone, Debug)]
pub struct Replay {
    /// `sigma`, per coefficient, RGB: the unshot energy the solve sent.
    sigma: Vec<[f64; 3]>,
    /// `K sigma` with the kernel of that solve: the change of `b` the shots made.
    k_sigma: Vec<[f64; 3]>,
    /// The surface reflectances of that kernel (`K = rho G`); a replay under others would break
    /// the invariant. (Changes of the hemisphere bound are kernel changes, in `Delta K sigma`.)
    reflectance: Vec<[f64; 3]>,
}

impl Replay {
    /// The shots of a solve that took the solution from `before` to `after`.
    pub fn record(before: &Coefficients, after: &Coefficients, reflectance: &[[f64; 3]]) -> Self {
        let per_coefficient = |f: &dyn Fn(usize, usize) -> f64| -> Vec<[f64; 3]> {
            (0..after.b.len()).map(|k| std::array::from_fn(|c| f(k, c))).collect()
        };
        let sent = |x: &Coefficients, k: usize, c: usize| x.b[k][c] - x.unshot[k][c];
        Self {
            sigma: per_coefficient(&|k, c| sent(after, k, c) - sent(before, k, c)),
            k_sigma: per_coefficient(&|k, c| after.b[k][c] - before.b[k][c]),
            reflectance: reflectance.to_vec(),
        }
    }

    /// `sigma`, for forming `Delta K sigma`.
    pub fn sigma(&self) -> &[[f64; 3]] {
        &self.sigma
    }

    /// `K sigma` under the kernel of the solve that made the shots.
    pub fn k_sigma(&self) -> &[[f64; 3]] {
        &self.k_sigma
    }

    /// Whether the replay holds for a kernel with these reflectances.
    pub fn applies_to(&self, reflectance: &[[f64; 3]]) -> bool {
        self.reflectance == reflectance
    }

    /// Replays `alpha sigma` into `x` (module docs), `alpha` chosen to leave the least unshot
    /// power given the solver's `transfers`; returns `alpha`. `delta_k_sigma` is `Delta K sigma`
    /// of this frame's kernel change.
    pub fn apply(&self, x: &mut Coefficients, delta_k_sigma: &[[f64; 3]], transfers: &[f64]) -> f64 {
        assert_eq!(x.b.len(), self.sigma.len(), "replay recorded for another system");
        // c = K' sigma - sigma, per coefficient.
        let c = |k: usize, ch: usize| self.k_sigma[k][ch] + delta_k_sigma[k][ch] - self.sigma[k][ch];
        let term = |t: usize| {
            let (k, ch) = (t / 3, t % 3);
            (x.unshot[k][ch], c(k, ch), transfers[k])
        };
        let alpha = least_power_scale(3 * x.b.len(), term);
        for k in 0..x.b.len() {
            for ch in 0..3 {
                let k_sigma = self.k_sigma[k][ch] + delta_k_sigma[k][ch];
                x.b[k][ch] += alpha * k_sigma;
                x.unshot[k][ch] += alpha * (k_sigma - self.sigma[k][ch]);
            }
        }
        alpha
    }
}

/// [`least_power_scale`] looks in `[-ALPHA_RANGE, ALPHA_RANGE]` (1 under steady motion, -1 when it
/// reverses), first to bins of `ALPHA_STEP`.
const ALPHA_RANGE: f64 = 3.0;
const ALPHA_STEP: f64 = 0.01;

/// The `alpha` in `[-ALPHA_RANGE, ALPHA_RANGE]` minimising `sum w |u + alpha c|` over the terms
/// `term(0..n) = (u, c, w)` (weights `w >= 0`): the sum is `sum w |c| |alpha - (-u / c)|`, so
/// `alpha` is the median of the points `-u / c` (clamped to the range) weighted by `w |c|`. A
/// histogram finds the bin holding the median in one pass over the terms, and a second pass sorts
/// only that bin's points: no copy of all ~30k points of the moving-light box, whose selection took
/// 0.73-0.96 ms a frame against 0.50-0.68 ms now (sorting them, 1.5 ms). Zero when no term depends
/// on `alpha`.
fn least_power_scale(n: usize, term: impl Fn(usize) -> (f64, f64, f64)) -> f64 {
    const BINS: usize = (2.0 * ALPHA_RANGE / ALPHA_STEP) as usize;
    let point = |t: usize| {
        let (u, c, w) = term(t);
        let valid = c != 0.0 && w > 0.0 && u.is_finite() && c.is_finite();
        valid.then(|| ((-u / c).clamp(-ALPHA_RANGE, ALPHA_RANGE), w * c.abs()))
    };
    let bin = |p: f64| (((p + ALPHA_RANGE) / ALPHA_STEP) as usize).min(BINS - 1);
    let mut weight = [0.0f64; BINS];
    for (p, w) in (0..n).filter_map(point) {
        weight[bin(p)] += w;
    }
    let mut rest = weight.iter().sum::<f64>() / 2.0;
    if rest <= 0.0 {
        return 0.0;
    }
    // The bin where the cumulative weight reaches half, and the weight still to reach inside it.
    let Some(median_bin) = weight.iter().position(|&w| {
        let inside = rest <= w;
        if !inside {
            rest -= w;
        }
        inside
    }) else {
        return 0.0;
    };
    let mut inside: Vec<(f64, f64)> =
        (0..n).filter_map(point).filter(|&(p, _)| bin(p) == median_bin).collect();
    inside.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut below = 0.0;
    for &(p, w) in &inside {
        below += w;
        if below >= rest {
            return p;
        }
    }
    inside.last().map_or(0.0, |p| p.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::links::LinkStore;
    use crate::visibility::Visibility;

    /// A link store of `n` elements, `nb` functions each, every pair linked with small
    /// pseudo-random blocks (a contraction), and reflectances.
    fn system(n: usize, nb: usize, seed: u64) -> (LinkStore, Vec<[f64; 3]>) {
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 0.04
        };
        let mut links = LinkStore::new(n, nb);
        for a in 0..n {
            for b in a + 1..n {
                let ab: Vec<f64> = (0..nb * nb).map(|_| next()).collect();
                let ba: Vec<f64> = (0..nb * nb).map(|_| next()).collect();
                links.push(a as u32, b as u32, &ab, &ba, Visibility::Full);
            }
        }
        links.set_receiver_areas(&vec![1.0; n]);
        let rho = (0..n).map(|e| [0.5 + 0.01 * e as f64, 0.6, 0.7]).collect();
        (links, rho)
    }

    /// `K v = rho G v`, through the store.
    fn apply_k(links: &LinkStore, rho: &[[f64; 3]], v: &[[f64; 3]]) -> Vec<[f64; 3]> {
        (0..rho.len())
            .flat_map(|i| {
                let row = crate::solver::gather_row(links, i as u32, v);
                row.into_iter().map(move |g| std::array::from_fn(|c| rho[i][c] * g[c]))
            })
            .collect()
    }

    /// `max |e + K (b - u) - b|`: how far `x` is from the shooting invariant.
    fn invariant_error(links: &LinkStore, rho: &[[f64; 3]], e: &[[f64; 3]], x: &Coefficients) -> f64 {
        let sent: Vec<[f64; 3]> =
            x.b.iter().zip(&x.unshot).map(|(b, u)| std::array::from_fn(|c| b[c] - u[c])).collect();
        let k_sent = apply_k(links, rho, &sent);
        (0..x.b.len())
            .flat_map(|k| (0..3).map(move |c| (k, c)))
            .map(|(k, c)| (e[k][c] + k_sent[k][c] - x.b[k][c]).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn replay_keeps_the_invariant_and_solves_to_the_same_answer() {
        let (n, nb) = (12, 4);
        let (links, rho) = system(n, nb, 7);
        let mut e = vec![[0.0; 3]; n * nb];
        e[0] = [1.0, 2.0, 3.0];
        e[5 * nb] = [0.5, 0.5, 0.5];
        let mut x = Coefficients::from_emission(&e, nb);
        let stop = 1e-10;
        let before = x.clone();
        crate::solver::shoot(&links, &rho, &mut x, stop, &|| false).unwrap();
        let replay = Replay::record(&before, &x, &rho);
        // The solver sums each batch's shots in f32: the invariant holds to that rounding.
        let peak = x.b.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(invariant_error(&links, &rho, &e, &x) < 1e-7 * peak);

        // Next "frame": the emission changes by Delta e (Delta K = 0 here), then the replay.
        let e2: Vec<[f64; 3]> = e.iter().map(|v| v.map(|x| 1.1 * x)).collect();
        let mut y = x.clone();
        for k in 0..n * nb {
            for c in 0..3 {
                y.b[k][c] += e2[k][c] - e[k][c];
                y.unshot[k][c] += e2[k][c] - e[k][c];
            }
        }
        let unshot_power = |x: &Coefficients| -> f64 {
            x.unshot
                .iter()
                .zip(links.transfers())
                .map(|(u, t)| t * u.iter().map(|v| v.abs()).sum::<f64>())
                .sum()
        };
        let power_before = unshot_power(&y);
        let zero = vec![[0.0; 3]; n * nb];
        let alpha = replay.apply(&mut y, &zero, links.transfers());
        // The emission grew by 10% along the same pattern: replaying the last solve's shots (a
        // solve from emission) 0.1 times cancels the new unshot power almost entirely.
        assert!((alpha - 0.1).abs() < 0.02, "alpha {alpha}");
        assert!(unshot_power(&y) < 0.05 * power_before, "{} vs {power_before}", unshot_power(&y));
        assert!(invariant_error(&links, &rho, &e2, &y) < 1e-7 * peak);
        crate::solver::shoot(&links, &rho, &mut y, stop, &|| false).unwrap();
        let reference = crate::solver::gauss_seidel(&links, &rho, &e2, 1e-14);
        for (a, b) in y.b.iter().zip(&reference) {
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() < 1e-7 * peak, "{} vs {}", a[c], b[c]);
            }
        }
    }

    #[test]
    fn least_power_scale_is_the_minimiser() {
        let mut state = 3u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let terms: Vec<(f64, f64, f64)> = (0..200).map(|_| (next(), next(), next() + 0.5)).collect();
        let cost = |alpha: f64| terms.iter().map(|&(u, c, w)| w * (u + alpha * c).abs()).sum::<f64>();
        let alpha = least_power_scale(terms.len(), |t| terms[t]);
        for k in -300..=300 {
            let other = k as f64 / 100.0;
            assert!(
                cost(alpha) <= cost(other) + 1e-12,
                "alpha {alpha}: {} > {} at {other}",
                cost(alpha),
                cost(other)
            );
        }
        assert_eq!(least_power_scale(1, |_| (1.0, 0.0, 1.0)), 0.0);
        assert_eq!(least_power_scale(1, |_| (1.0, -2.0, 1.0)), 0.5);
        // Beyond the range: its end.
        assert_eq!(least_power_scale(1, |_| (10.0, -1.0, 1.0)), ALPHA_RANGE);
    }
}
