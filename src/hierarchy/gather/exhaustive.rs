//! The exhaustive integration of a surface source from the point ([`super::Mode::Exhaustive`]):
//! the source's shaft triangles found once, then the source split until each part is
//! [`GAUSS_RATIO`] of its radius away and summed by the Gauss rule with a ray per node; a part
//! still too near at [`MAX_DEPTH`] is taken as a polygon with one ray. The reference
//! [`super::near`] is tested against.

use super::surface::{Rays, Source};
use super::{Counters, FAR_RATIO, GAUSS_RATIO, Gather, Receiver};
use crate::basis::MAX_LEN as MAX_NB;
use crate::gather::{Ball, Side, behind_plane};
use crate::geometry::Rect;
use crate::kernel::point::point_to_polygon;

/// Deepest split of a source rectangle; there its form factor is taken analytically.
const MAX_DEPTH: u32 = 12;

impl Gather<'_> {
    /// The moments of the whole source `src` into `out` (see [`Gather::exhaustive_rect`]).
    pub(super) fn exhaustive_moments(
        &self,
        rx: &Receiver,
        src: Source,
        out: &mut [f64],
        ball: Option<(Ball, &mut f64)>,
    ) {
        // The triangles that may block the point's rays to any part of the source, found once.
        let mut candidates = Vec::new();
        if let Some(o) = self.inputs.occluders {
            o.point_candidates(rx.x, rx.n, (rx.face, src.face), &src.patch.bounds(), &mut candidates);
            Counters::add(&self.counters.shafts, 1);
        }
        self.exhaustive_rect(rx, src, &candidates, &Rect::UNIT, 0, out, ball);
    }

    /// Adds `integral g(x,y) V(x,y) Gamma_l(y) dA_y` over `rect` of the source (`Gamma_l` over
    /// the node's own parameters) to `out[l]`, with rays tested against `candidates`.
    /// With `ball = Some((r, weight))`, the part within `r` of the point adds its
    /// `integral g V dA` to `weight` instead.
    #[allow(clippy::too_many_arguments)]
    fn exhaustive_rect(
        &self,
        rx: &Receiver,
        src: Source,
        candidates: &[usize],
        rect: &Rect,
        depth: u32,
        out: &mut [f64],
        ball: Option<(Ball, &mut f64)>,
    ) {
        if self.stop.stopped() {
            return;
        }
        let patch = src.patch;
        let sub = patch.sub_patch(rect);
        let (centre, radius) = sub.bounding_sphere();
        if behind_plane(rx.x, rx.n, &sub, radius) {
            return;
        }
        let distance = rx.x.distance(centre);
        // A foot's ball, as [`super::near`] takes it.
        let mut across = None;
        if let Some((ball, weight)) = ball {
            match ball.side(rect, &sub, (distance, radius), depth) {
                Side::Inside => {
                    let mut m = [0.0; MAX_NB];
                    self.exhaustive_rect(rx, src, candidates, rect, depth, &mut m[..out.len()], None);
                    *weight += m[0];
                    return;
                }
                Side::Split => {
                    for q in rect.quadrants() {
                        let ball = Some((ball, &mut *weight));
                        self.exhaustive_rect(rx, src, candidates, &q, depth + 1, out, ball);
                    }
                    return;
                }
                Side::Across => across = Some((ball, weight)),
                Side::Outside => {}
            }
        }
        let basis = self.inputs.tree.basis;
        if distance >= GAUSS_RATIO * radius {
            let rule = if distance >= FAR_RATIO * radius { &self.far_rule } else { &self.rule };
            self.gauss_split(
                rx,
                src,
                rect,
                rule,
                Rays::Among(candidates),
                out,
                across.map(|(b, w)| (b.radius, w)),
            );
            return;
        }
        if depth >= MAX_DEPTH {
            let (s, t) = rect.map(0.5, 0.5);
            let y = patch.point(s, t);
            if let Some(o) = self.inputs.occluders {
                let mut seen = [true];
                Counters::add(&self.counters.rays, !candidates.is_empty() as u64);
                o.visibility_among(candidates, rx.x, (rx.face, src.face), &[y], &mut seen);
                if !seen[0] {
                    return;
                }
            }
            let f = point_to_polygon(rx.x, rx.n, &sub.corners, sub.centre_normal());
            if let Some((b, weight)) = across
                && rx.x.distance(y) <= b.radius
            {
                *weight += f;
                return;
            }
            let mut g = [0.0; MAX_NB];
            basis.eval_into(s, t, &mut g[..out.len()]);
            for (o, g) in out.iter_mut().zip(g) {
                *o += f * g;
            }
            return;
        }
        for q in rect.quadrants() {
            let across = across.as_mut().map(|(b, w)| (*b, &mut **w));
            self.exhaustive_rect(rx, src, candidates, &q, depth + 1, out, across);
        }
    }
}
