//! The seed's power series of the kernel under translation (Arques, Biri, Michelin 2001, 3.2).
//!
//! When element `b` moves by `p p0` relative to element `a` (unit `p0`), with `r = y - x`:
//! `g(x, y + p p0) = (a + b p + c p^2) / (pi r^4) * sum_n f_n p^n` (eqs. 12-14), where
//! `a = (n_x.r)(-n_y.r)`, `b = (n_x.p0)(-n_y.r) + (n_x.r)(-n_y.p0)`, `c = (n_x.p0)(-n_y.p0)` and
//! `sum f_n p^n = (1 + 2 alpha p / r^2 + beta p^2 / r^2)^-2` (`alpha = p0.r`, `beta = p0.p0`).
//! So `g' = sum_n p^n phi_n` with `phi_n = (a f_n + b f_{n-1} + c f_{n-2}) / (pi r^4)` (eq. 15),
//! and the integrated coefficients `< integral phi_n Gamma_l | Gamma_k >` (eq. 16) are precomputed
//! once per pair and direction: a new frame then costs `sum_n p^n Phi_n` per coefficient.
//!
//! `f_n` is the paper's `xi_n`; we compute it by the recurrence that follows from
//! `w f' = -2 w' f` (`w = 1 + w1 p + w2 p^2`), which [`xi_closed_form`] checks in tests.
//! The series converges while `r > (1 + sqrt 2) p` (eq. 13) for every point pair; the truncation
//! order and the threshold below come from measured errors (see the tests and README).

use glam::DVec3;

use super::samples::Samples;
use crate::basis::Basis;
use crate::geometry::{FrontPlane, Patch};
use crate::visibility::Visibility;

/// Highest power of `p` kept.
pub const SERIES_ORDER: usize = 8;
/// Largest `p / r_min` at which the truncated series is used; beyond it the pair is re-expanded.
/// Measured (tests/series.rs, 2,000 random point pairs and directions, error relative to the exact
/// point kernel): order 8 gives 1.1e-6 at `t = 0.1` and 3.7e-4 at `t = 0.2` (orders 2/4/6: 1.6,
/// 0.13, 5e-3 at `t = 0.2`); the convergence radius is `t = sqrt 2 - 1 = 0.414`. Integrated over
/// patches the error is far smaller: corners within 3e-5 of peak of the exact update on the demo.
pub const SERIES_MAX_T: f64 = 0.2;
/// A frame evaluates the stored series only up to the power whose dropped tail
/// `sum_{n>m} |p|^n max|Phi_n|` (a bound on every coefficient it leaves out) is at most this
/// fraction of the largest term `|p|^n max|Phi_n|`: close to its reference a pair needs few terms
/// (`t = 0.02`: about 5 of the 9), and reading them is the cost of a series frame.
pub const SERIES_TAIL: f64 = 1e-6;

/// Taylor coefficients `f_0..f_{len-1}` of `(1 + w1 p + w2 p^2)^-2`.
pub fn inverse_square_series(w1: f64, w2: f64, f: &mut [f64]) {
    f[0] = 1.0;
    if f.len() > 1 {
        f[1] = -2.0 * w1;
    }
    for n in 1..f.len() - 1 {
        f[n + 1] = -(w1 * (n + 2) as f64 * f[n] + w2 * (n + 3) as f64 * f[n - 1]) / (n + 1) as f64;
    }
}

/// The paper's `xi_n = sum_{q=ceil(n/2)}^{n} (q+1) C(q, n-q) (-4 alpha^2 / (beta r^2))^q (beta / (2 alpha))^n`.
pub fn xi_closed_form(n: usize, alpha: f64, beta: f64, r2: f64) -> f64 {
    let binom =
        |n: usize, k: usize| -> f64 { (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64) };
    (n.div_ceil(2)..=n)
        .map(|q| {
            (q + 1) as f64
                * binom(q, n - q)
                * (-4.0 * alpha * alpha / (beta * r2)).powi(q as i32)
                * (beta / (2.0 * alpha)).powi(n as i32)
        })
        .sum()
}

/// `phi_n(x, y) * pi r^4` for `n = 0..=SERIES_ORDER`: the series of the point kernel along `p0`.
#[inline]
pub fn point_series(x: DVec3, nx: DVec3, y: DVec3, ny: DVec3, p0: DVec3, out: &mut [f64; SERIES_ORDER + 1]) {
    let r = y - x;
    let r2 = r.length_squared();
    let (cx, cy) = (nx.dot(r), -ny.dot(r));
    let (px, py) = (nx.dot(p0), -ny.dot(p0));
    let a = cx * cy;
    let b = px * cy + cx * py;
    let c = px * py;
    let mut f = [0.0; SERIES_ORDER + 1];
    inverse_square_series(2.0 * p0.dot(r) / r2, p0.length_squared() / r2, &mut f);
    let scale = 1.0 / (std::f64::consts::PI * r2 * r2);
    for n in 0..=SERIES_ORDER {
        let mut h = a * f[n];
        if n >= 1 {
            h += b * f[n - 1];
        }
        if n >= 2 {
            h += c * f[n - 2];
        }
        out[n] = h * scale;
    }
}

/// Lower bound of the distance between two patches (their boxes' distance).
pub fn min_distance(a: &Patch, b: &Patch) -> f64 {
    let (ba, bb) = (a.bounds(), b.bounds());
    let gap = (ba.min - bb.max).max(bb.min - ba.max).max(DVec3::ZERO);
    gap.length()
}

/// True when every point of `b` lies strictly in front of every tangent plane of `a`, so that
/// every point pair has a positive cosine at `a` (no half-space discontinuity, Fig. 4).
///
/// For a planar `a`, its plane's test on `b`'s corners (`b` lies in their hull). A bilinear `a`
/// (the Cornell box's left wall, and every patch subdivided from it) is not planar, but its area
/// vectors `X_s x X_t` are bilinear in `(s, t)`, so every normal lies in the cone of its four
/// corners' normals, of half-angle `theta` about the centre normal `n`. For a point pair
/// `v = y - x`, `n_x . v >= (n . v) cos theta - |v| sin theta`, which is positive for all pairs when
/// the gap `min_b n.y - max_a n.x` (over the corners) times `cos theta` exceeds the pairs' largest
/// distance times `sin theta`.
pub fn wholly_in_front(a: &Patch, b: &Patch) -> bool {
    match a.front_plane() {
        Some(plane) => plane.all_in_front(b),
        None => in_front_of_cone(a, b),
    }
}

/// [`wholly_in_front`] for a bilinear `a` that is not planar: the test on its normals' cone.
fn in_front_of_cone(a: &Patch, b: &Patch) -> bool {
    let n = a.centre_normal();
    let mut cos = 1.0f64;
    for (s, t) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
        let v = a.area_vector(s, t);
        let len = v.length();
        if len > 0.0 {
            cos = cos.min(v.dot(n) / len);
        }
    }
    if cos <= 0.0 {
        return false;
    }
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let lowest = b.corners.iter().map(|p| n.dot(*p)).fold(f64::INFINITY, f64::min);
    let highest = a.corners.iter().map(|p| n.dot(*p)).fold(f64::NEG_INFINITY, f64::max);
    let ((ca, ra), (cb, rb)) = (a.bounding_sphere(), b.bounding_sphere());
    let reach = ca.distance(cb) + ra + rb;
    (lowest - highest) * cos > reach * sin + 1e-9 * ra
}

/// Largest `|n . dir|` at which a motion along unit `dir` counts as parallel to a plane of unit
/// normal `n` ([`clip_invariant`]). Over a motion `p`, a sample pair's cosine at the plane moves
/// by at most `p |n . dir|`; the clipped kernel is proportional to that cosine, so a pair that
/// flips within this tolerance changes the kernel by a relative 1e-9 of `p / r`.
const PARALLEL: f64 = 1e-9;

/// True when translating `b` along unit `dir` relative to `a` leaves the sign of both cosines of
/// every point pair as it is, so that the one-sided kernel's clipping is the same at every
/// displacement and the series of the clipped kernel is the clipped series (Fig. 4's
/// discontinuity cannot occur). On each side, either the other patch lies wholly in front
/// ([`wholly_in_front`], which must then be re-checked as the patches move), or the side is planar
/// and the motion parallel to its plane: the cosine at a plane, `n . (y - x)`, does not change
/// when `y - x` moves along the plane. The second case covers a light that slides under a
/// ceiling: its plane cuts the walls' top row, whose parts above it it never lights, wherever it
/// slides.
pub fn clip_invariant(a: &Patch, b: &Patch, dir: DVec3) -> bool {
    clip_invariant_with((a, a.front_plane()), (b, b.front_plane()), dir)
}

/// [`clip_invariant`] with each patch's [`Patch::front_plane`] given (computed once per element
/// and frame instead of per pair).
pub fn clip_invariant_with(
    (a, plane_a): (&Patch, Option<FrontPlane>),
    (b, plane_b): (&Patch, Option<FrontPlane>),
    dir: DVec3,
) -> bool {
    let side = |x: &Patch, plane: Option<FrontPlane>, other: &Patch| match plane {
        Some(plane) => plane.all_in_front(other) || plane.normal.dot(dir).abs() <= PARALLEL,
        None => in_front_of_cone(x, other),
    };
    side(a, plane_a, b) && side(b, plane_b, a)
}

/// Pairs the series applies to along unit `dir`: the kernel's clipping invariant
/// under the motion ([`clip_invariant`]), and separated enough that the kernel is one Gauss
/// product (near pairs go through the adaptive integrator). Returns `r_min`.
pub fn eligible(a: &Patch, b: &Patch, dir: DVec3) -> Option<f64> {
    if !clip_invariant(a, b, dir) {
        return None;
    }
    let (ca, ra) = a.bounding_sphere();
    let (cb, rb) = b.bounding_sphere();
    if ca.distance(cb) <= super::pair::SEPARATION * (ra + rb) {
        return None;
    }
    let r = min_distance(a, b);
    (r > 0.0).then_some(r)
}

/// A pair's kernel as a polynomial in the displacement along `dir`.
#[derive(Clone, Debug)]
pub struct PairSeries {
    /// Unit direction of `b`'s motion relative to `a`.
    pub dir: DVec3,
    /// Corner 0 of `a` and of `b` at the reference position.
    pub ref_a: DVec3,
    pub ref_b: DVec3,
    /// Lower bound of the distance between the patches at the reference.
    pub r_min: f64,
    /// Shape epochs of `a` and `b` at the reference (a non-translation bumps them).
    pub epochs: (u32, u32),
    /// Gauss points per axis of the single product the terms were integrated with (the pair
    /// separated: [`eligible`]). The series is that quadrature's kernel as a polynomial in `p`,
    /// so it stands for the pair's kernel only while the pair still takes that rule: a pair that
    /// comes nearer than [`super::pair::SEPARATION`] is split adaptively, and one that crosses
    /// [`super::pair::MID`] or [`super::pair::FAR`] changes rule (2e-2 of the peak block entry
    /// apart, seen by `tests/animation_random.rs`).
    pub points: usize,
    /// `Phi_n` for `n = 0..=SERIES_ORDER`, each `[G_ab | G_ba]`, `nb x nb` each.
    pub terms: Vec<f32>,
    /// `max_kl |Phi_n^kl|` for each `n`.
    pub norms: [f32; SERIES_ORDER + 1],
}

impl PairSeries {
    /// The series of `terms` ([`expand`] with `points` Gauss points per axis) about the reference
    /// corners `ref_a`, `ref_b`.
    pub fn new(
        dir: DVec3,
        (ref_a, ref_b): (DVec3, DVec3),
        r_min: f64,
        epochs: (u32, u32),
        points: usize,
        terms: Vec<f32>,
    ) -> Self {
        let len = terms.len() / (SERIES_ORDER + 1);
        let mut norms = [0.0f32; SERIES_ORDER + 1];
        for (norm, t) in norms.iter_mut().zip(terms.chunks_exact(len)) {
            *norm = t.iter().fold(0.0, |m, x| m.max(x.abs()));
        }
        Self { dir, ref_a, ref_b, r_min, epochs, points, terms, norms }
    }

    /// The highest power of `p` evaluation keeps: the smallest `m` whose dropped terms add up to
    /// at most [`SERIES_TAIL`] of the largest term at `p`.
    pub fn order_at(&self, p: f64) -> usize {
        let mut size = [0.0f64; SERIES_ORDER + 1];
        let mut power = 1.0;
        for (s, &norm) in size.iter_mut().zip(&self.norms) {
            *s = norm as f64 * power;
            power *= p.abs();
        }
        let bound = SERIES_TAIL * size.iter().fold(0.0f64, |m, &x| m.max(x));
        let (mut m, mut tail) = (SERIES_ORDER, 0.0);
        while m > 0 && tail + size[m] <= bound {
            tail += size[m];
            m -= 1;
        }
        m
    }

    /// Displacement of `b` relative to `a` since the reference, from their current corner 0.
    pub fn displacement(&self, a_now: DVec3, b_now: DVec3) -> DVec3 {
        (b_now - self.ref_b) - (a_now - self.ref_a)
    }

    /// `sum_n p^n Phi_n` (eq. 16 plus the reference kernel) into `[G_ab | G_ba]` (`2 nb^2`,
    /// overwritten), up to `n = `[`PairSeries::order_at`]`(p)`, which it returns.
    pub fn eval_into(&self, p: f64, out: &mut [f64]) -> usize {
        let len = out.len();
        debug_assert_eq!(self.terms.len(), (SERIES_ORDER + 1) * len);
        let kept = self.terms_at(p);
        // Horner in p over the terms kept, highest first.
        out.fill(0.0);
        for t in kept.chunks_exact(len).rev() {
            for (o, &x) in out.iter_mut().zip(t) {
                *o = *o * p + x as f64;
            }
        }
        kept.len() / len - 1
    }

    /// The terms an evaluation at `p` reads: `Phi_0` to `Phi_m`, `m = `[`PairSeries::order_at`]`(p)`.
    pub fn terms_at(&self, p: f64) -> &[f32] {
        let len = self.terms.len() / (SERIES_ORDER + 1);
        &self.terms[..(self.order_at(p) + 1) * len]
    }
}

crate::simd::multiversion! {
    /// Integrates `phi_n` against the basis for `n = 0..=SERIES_ORDER` (eq. 16), both directions,
    /// with the same Gauss samples as the exact kernel, so the `n = 0` term is the exact kernel:
    /// per term, the exact kernel's two matrix products ([`super::pair::project_any`]) over the
    /// matrix `phi_n(x_a, y_b) VIS_ab`: about 6.5 us a pair at order 2, ten far-pair quadratures
    /// (as one loop over terms inside the products it took 28 us).
    pub fn expand(
        basis: Basis,
        vis_axis: usize,
        sa: &Samples,
        sb: &Samples,
        vis: &Visibility,
        dir: DVec3,
    ) -> Vec<f32> {
        const N: usize = SERIES_ORDER + 1;
        let nb = basis.len();
        let n2 = nb * nb;
        let cells = vis_axis * vis_axis;
        let (na, nbp) = (sa.len(), sb.len());
        // `[n][a][b]`: phi_n(x_a, y_b) VIS_ab.
        let mut m = vec![0.0; N * na * nbp];
        let mut phi = [0.0; N];
        for a in 0..na {
            for b in 0..nbp {
                let v = vis.at(sa.cell[a], sb.cell[b], cells);
                if v == 0.0 {
                    continue;
                }
                // The exact kernel's one-sided clip ([`super::pair`]'s kernel matrix), fixed over
                // the motion ([`clip_invariant`]): a pair clipped here is clipped at every `p`.
                let r = sb.position[b] - sa.position[a];
                if sa.normal[a].dot(r) <= 0.0 || sb.normal[b].dot(r) >= 0.0 {
                    continue;
                }
                point_series(sa.position[a], sa.normal[a], sb.position[b], sb.normal[b], dir, &mut phi);
                for (n, &f) in phi.iter().enumerate() {
                    m[(n * na + a) * nbp + b] = f * v;
                }
            }
        }
        let mut terms = vec![0.0f64; N * 2 * n2];
        for (term, m) in terms.chunks_exact_mut(2 * n2).zip(m.chunks_exact(na * nbp)) {
            let (ab, ba) = term.split_at_mut(n2);
            super::pair::project_any(nb, sa, sb, m, ab, ba);
        }
        terms.into_iter().map(|x| x as f32).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A series of `len` coefficients per term whose terms shrink like `decay^n`, with signs and
    /// sizes varying inside each term.
    fn synthetic(len: usize, decay: f64) -> PairSeries {
        let terms = (0..=SERIES_ORDER)
            .flat_map(|n| (0..len).map(move |k| (((k * 7 + n * 3) % 11) as f64 - 5.0) * decay.powi(n as i32)))
            .map(|x| x as f32)
            .collect();
        PairSeries::new(DVec3::X, (DVec3::ZERO, DVec3::Y), 1.0, (0, 0), 4, terms)
    }

    /// All `SERIES_ORDER + 1` terms, Horner.
    fn full_eval(ser: &PairSeries, p: f64, len: usize) -> Vec<f64> {
        let mut out = vec![0.0; len];
        for t in ser.terms.chunks_exact(len).rev() {
            for (o, &x) in out.iter_mut().zip(t) {
                *o = *o * p + x as f64;
            }
        }
        out
    }

    /// `wholly_in_front` never says yes when some point pair has a non-positive cosine at `a`
    /// (checked on 12 x 12 points of each patch, `a` twisted out of its plane by up to a third of
    /// its size), and says yes for most pairs that are in front everywhere.
    #[test]
    fn wholly_in_front_is_sound_for_twisted_patches_and_not_vacuous() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut said_yes, mut in_front, mut missed) = (0, 0, 0);
        for _ in 0..3000 {
            let twist = 0.3 * rnd();
            let a = Patch {
                corners: [
                    DVec3::new(-0.5, -0.5, 0.0),
                    DVec3::new(0.5, -0.5, twist * (rnd() - 0.5)),
                    DVec3::new(0.5, 0.5, twist * (rnd() - 0.5)),
                    DVec3::new(-0.5, 0.5, twist * (rnd() - 0.5)),
                ],
            };
            let centre = DVec3::new(4.0 * rnd() - 2.0, 4.0 * rnd() - 2.0, 3.0 * rnd() - 0.3);
            let (u, v) = (DVec3::new(rnd(), rnd(), rnd()) - 0.5, DVec3::new(rnd(), rnd(), rnd()) - 0.5);
            let b = Patch { corners: [centre - u - v, centre + u - v, centre + u + v, centre - u + v] };
            let grid = |patch: &Patch| {
                (0..12)
                    .flat_map(move |i| {
                        (0..12).map(move |j| ((i as f64 + 0.5) / 12.0, (j as f64 + 0.5) / 12.0))
                    })
                    .map(|(s, t)| (patch.point(s, t), patch.area_vector(s, t).normalize()))
                    .collect::<Vec<_>>()
            };
            let (ga, gb) = (grid(&a), grid(&b));
            let everywhere = ga.iter().all(|(x, n)| gb.iter().all(|(y, _)| n.dot(*y - *x) > 0.0))
                && a.corners
                    .iter()
                    .all(|x| b.corners.iter().all(|y| ga.iter().all(|(_, n)| n.dot(*y - *x) > 0.0)));
            let yes = wholly_in_front(&a, &b);
            assert!(!yes || everywhere, "wholly_in_front said yes for {a:?} and {b:?}");
            said_yes += yes as usize;
            in_front += everywhere as usize;
            missed += (everywhere && !yes) as usize;
        }
        assert!(said_yes > 300, "only {said_yes} of 3000 pairs in front");
        assert!(missed * 4 < in_front, "{missed} of {in_front} pairs in front were refused");
    }

    #[test]
    fn truncation_keeps_the_dropped_tail_below_its_bound_and_uses_more_terms_further_out() {
        let len = 2 * 9 * 9;
        let ser = synthetic(len, 4.0);
        let mut out = vec![0.0; len];
        let mut last = 0;
        for p in [0.0, 1e-4, 1e-3, 0.005, 0.02, 0.05, -0.05, 0.1] {
            let m = ser.eval_into(p, &mut out);
            assert_eq!(m, ser.order_at(p));
            assert!(m >= last, "order falls from {last} to {m} at p = {p}");
            last = m;
            let largest =
                (0..=SERIES_ORDER).map(|n| ser.norms[n] as f64 * p.abs().powi(n as i32)).fold(0.0, f64::max);
            let worst =
                out.iter().zip(full_eval(&ser, p, len)).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(
                worst <= SERIES_TAIL * largest * (1.0 + 1e-9),
                "p = {p}: dropped {worst}, bound {}",
                SERIES_TAIL * largest
            );
        }
        assert_eq!(ser.order_at(0.0), 0, "the reference needs Phi_0 only");
        assert!(ser.order_at(0.005) < SERIES_ORDER, "a small step reads fewer terms");
        assert_eq!(ser.order_at(0.1), SERIES_ORDER, "at t = 0.4 per unit decay every term counts");
    }
}
