//! A source's moments at a corner point, `integral g(x,y) V(x,y) Gamma_l(y) dA_y` (eq. 1 at one
//! point against each basis function, [`Gather::moments`]): the source split where it is near
//! the point, an emitter's part in a penumbra split while its rays disagree
//! ([`Gather::penumbra`]), each part a Gauss sum ([`Gather::gauss`]) with the corner's rays where
//! its visibility is not read from a link's mask.

use glam::DVec3;

use super::nodes::{GaussNodes, N};
use super::penumbra::Corners;
use super::{
    Among, Ball, FACING, FOOT_BALL, GAUSS_RATIO, Gather, MAX_DEPTH, Mode, NEAR_FACING, PENUMBRA_DEPTH,
    Receiver, Side, Touch, behind_plane,
};
use crate::geometry::{Patch, Rect};
use crate::kernel::point::{point_kernel, point_to_polygon};
use crate::visibility::cell_of;

impl Gather<'_> {
    /// Adds `integral g(x,y) V(x,y) Gamma_l(y) dA_y` over `rect` of source `j` to `out[l]`.
    /// With `ball = Some((r, weight))`, the part of the source within `r` of the corner adds its
    /// `integral g V dA` to `weight` instead (see [`Foot`](super::Foot)).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn moments(
        &self,
        rx: &Receiver,
        j: usize,
        rect: &Rect,
        mode: Mode,
        depth: u32,
        out: &mut [f64],
        ball: Option<(Ball, &mut f64)>,
    ) {
        let Some((sub, centre, radius)) = self.front_part(rx, j, rect) else { return };
        let patch = &self.patches[j];
        let distance = rx.x.distance(centre);
        // A foot's ball: a rectangle wholly inside it adds its seen form factor to `weight`; one
        // across its edge is split while it is coarse against the ball ([`BALL_EDGE`]), then
        // taken as any rectangle with its seen nodes shared out by the side they lie on
        // (`across`); one outside is any rectangle.
        let mut across = None;
        if let Some((ball, weight)) = ball {
            match ball.side(rect, &sub, (distance, radius), depth) {
                Side::Inside => {
                    // Gamma_0 = 1 on the unit square: the l = 0 moment is the plain integral.
                    let mut m = [0.0; crate::basis::MAX_LEN];
                    self.moments(rx, j, rect, mode, depth, &mut m[..out.len()], None);
                    *weight += m[0];
                    return;
                }
                Side::Split => {
                    for q in rect.quadrants() {
                        self.moments(rx, j, &q, mode, depth + 1, out, Some((ball, &mut *weight)));
                    }
                    return;
                }
                Side::Across => across = Some((ball, weight)),
                Side::Outside => {}
            }
        }
        if distance >= GAUSS_RATIO * radius {
            // An emitter's rectangle in the penumbra (its rays disagree) is split further: its
            // direct light is the sharpest term of the corner's `B`, and 3 x 3 rays per
            // rectangle put a corner beside a building up to 10% off (the monastery's ground,
            // docs/validation-real.md; tests/penumbra.rs).
            let refine = self.is_emitter[j] && mode == Mode::Rays && depth < PENUMBRA_DEPTH;
            // The nodes lie inside the rectangle (a ninth of it from its edges): a shadow edge
            // that crosses only that margin is seen by a ray to one of its corners instead. The
            // corners in front of the corner's plane go with the nodes' rays (they lie in the
            // same bounds: the same shaft's candidates, most often none, so no ray at all).
            let mut corners = Corners::of((rx.x, rx.n), patch, rect, refine);
            let mut m = [0.0; crate::basis::MAX_LEN];
            let m = &mut m[..out.len()];
            let mut inside = 0.0;
            let split = across.as_ref().map(|(b, _)| (b.radius, &mut inside));
            let among = Among::Bounds(&sub.bounds());
            let (seen, count) = if depth == 0 {
                self.gauss(rx, j, &self.nodes[j], among, mode, &mut corners, m, split)
            } else {
                let nodes = GaussNodes::new(patch, rect, self.rule, self.sys.basis, self.cells_per_axis);
                self.gauss(rx, j, &nodes, among, mode, &mut corners, m, split)
            };
            let mixed = corners.disagree(seen, count);
            // A penumbra's rectangle across a ball's edge counts on its centre's side.
            let (out, weight) = match across {
                Some((b, weight)) if mixed && distance <= b.radius => {
                    let mut whole = [0.0; crate::basis::MAX_LEN];
                    let whole = &mut whole[..out.len()];
                    self.penumbra_parts(rx, j, rect, depth, &sub, whole);
                    *weight += whole[0];
                    return;
                }
                Some((_, weight)) => (out, Some(weight)),
                None => (out, None),
            };
            if mixed {
                self.penumbra_parts(rx, j, rect, depth, &sub, out);
            } else {
                for (o, x) in out.iter_mut().zip(m.iter()) {
                    *o += x;
                }
                if let Some(weight) = weight {
                    *weight += inside;
                }
            }
            return;
        }
        if depth >= MAX_DEPTH {
            let (s, t) = rect.map(0.5, 0.5);
            let y = patch.point(s, t);
            if !self.visible(rx, j, y, cell_of(s, t, self.cells_per_axis), mode) {
                return;
            }
            let f = point_to_polygon(rx.x, rx.n, &sub.corners, sub.centre_normal());
            if let Some((b, weight)) = across
                && rx.x.distance(y) <= b.radius
            {
                *weight += f;
                return;
            }
            for (l, g) in self.sys.basis.eval(s, t).into_iter().enumerate() {
                out[l] += f * g;
            }
            return;
        }
        for q in rect.quadrants() {
            let across = across.as_mut().map(|(b, w)| (*b, &mut **w));
            self.moments(rx, j, &q, mode, depth + 1, out, across);
        }
    }

    /// An emitter's rectangle whose rays disagree (a penumbra), split in four and each quadrant
    /// taken by [`Gather::penumbra`].
    fn penumbra_parts(&self, rx: &Receiver, j: usize, rect: &Rect, depth: u32, sub: &Patch, out: &mut [f64]) {
        // Every quadrant's shaft lies in this rectangle's: its candidates serve them all.
        // (Queried again here, only for a rectangle in a penumbra: the Gauss sum keeps its list
        // in a thread-local, which no allocation per rectangle needs.)
        let mut candidates = Vec::new();
        if let Some(o) = self.occluders {
            o.point_candidates(rx.x, rx.n, (rx.element, j as u32), &sub.bounds(), &mut candidates);
        }
        for q in rect.quadrants() {
            self.penumbra(rx, j, &q, depth + 1, &candidates, out);
        }
    }

    /// `rect` of source `j` as a patch and its bounding sphere; `None` when the gather is stopped
    /// or the part lies wholly behind the corner's plane (it adds nothing).
    pub(super) fn front_part(&self, rx: &Receiver, j: usize, rect: &Rect) -> Option<(Patch, DVec3, f64)> {
        if self.stop.stopped() {
            return None;
        }
        let sub = self.patches[j].sub_patch(rect);
        let (centre, radius) = sub.bounding_sphere();
        (!behind_plane(rx.x, rx.n, &sub, radius)).then_some((sub, centre, radius))
    }

    /// [`Gather::moments`] of an emitter's rectangle inside a penumbra (with rays, no foot
    /// ball), given the occluders that may block any segment from the corner to it (those of the
    /// rectangle it was split from): split again while its rays disagree, down to
    /// [`PENUMBRA_DEPTH`], each part's rays tested against those occluders alone.
    pub(super) fn penumbra(
        &self,
        rx: &Receiver,
        j: usize,
        rect: &Rect,
        depth: u32,
        candidates: &[usize],
        out: &mut [f64],
    ) {
        let Some((sub, centre, radius)) = self.front_part(rx, j, rect) else { return };
        let patch = &self.patches[j];
        if rx.x.distance(centre) < GAUSS_RATIO * radius {
            // Too near for the Gauss rule: the general recursion takes it.
            return self.moments(rx, j, rect, Mode::Rays, depth, out, None);
        }
        // A list too long to test triangle by triangle (its rays would each walk the BVH) is
        // gathered again for this part's own, narrower shaft.
        let mut narrowed = Vec::new();
        let candidates = match self.occluders {
            Some(o) if candidates.len() > crate::visibility::BRUTE_FORCE_CANDIDATES => {
                o.point_candidates(rx.x, rx.n, (rx.element, j as u32), &sub.bounds(), &mut narrowed);
                &narrowed[..]
            }
            _ => candidates,
        };
        let mut corners = Corners::of((rx.x, rx.n), patch, rect, depth < PENUMBRA_DEPTH);
        let mut m = [0.0; crate::basis::MAX_LEN];
        let m = &mut m[..out.len()];
        let nodes = GaussNodes::new(patch, rect, self.rule, self.sys.basis, self.cells_per_axis);
        let (seen, count) =
            self.gauss(rx, j, &nodes, Among::Candidates(candidates), Mode::Rays, &mut corners, m, None);
        if corners.disagree(seen, count) {
            for q in rect.quadrants() {
                self.penumbra(rx, j, &q, depth + 1, candidates, out);
            }
        } else {
            for (o, x) in out.iter_mut().zip(m.iter()) {
                *o += x;
            }
        }
    }

    /// Whether the corner touches source `j`: it lies just in front of `j`'s plane (within a
    /// hundredth of its element's radius) and its foot, moved that much along the corner's own
    /// normal so that it lies on the open side, falls on `j`.
    pub(super) fn touch(&self, rx: &Receiver, i: usize, j: usize) -> Option<Touch> {
        let pj = &self.patches[j];
        let plane = self.planes[j]?;
        let d = plane.normal.dot(rx.x - plane.centre);
        if rx.n.dot(plane.normal) < -FACING {
            return self.near_facing(rx, j, d);
        }
        // Touching (within a hundredth of the corner's element), or standing closer than
        // NEAR_FACING of the source's radius above it: the foot is as far along the corner's
        // normal as the corner is above the source.
        let touching = d > 0.0 && d < 1e-2 * self.radii[i];
        let near = d > 0.0 && d < NEAR_FACING * self.radii[j];
        let offset = if touching { 1e-2 * self.radii[i] } else { d };
        if !(touching || near) || rx.n.dot(plane.normal).abs() > 0.9 {
            return None;
        }
        let foot = rx.x + offset * rx.n;
        foot_on(pj, foot - plane.normal.dot(foot - plane.centre) * plane.normal, 3.0 * offset)
    }

    /// Whether the corner faces source `j` from closer than [`NEAR_FACING`] of `j`'s radius (the
    /// underside of a model standing on a table, a face folded onto its neighbour): nearly all of
    /// its form factor to `j` then comes from the disc of radius a few `d` under it, where the
    /// shadow it casts on `j` is far finer than `j`'s polynomial. That part counts with `B`
    /// gathered at the foot, the corner's projection on `j` ([`FOOT_BALL`] `d` around the corner).
    pub(super) fn near_facing(&self, rx: &Receiver, j: usize, d: f64) -> Option<Touch> {
        let plane = self.planes[j]?;
        if !(d > 0.0 && d < NEAR_FACING * self.radii[j]) {
            return None;
        }
        foot_on(&self.patches[j], rx.x - d * plane.normal, FOOT_BALL * d)
    }

    /// The Gauss sum over `nodes` of source `j` into `out`, its rays (with `Mode::Rays`) tested
    /// against the occluders `among` gives, as are those to `corners` (their verdicts written
    /// back); how many of the nodes in front of the corner it sees, of how many.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn gauss(
        &self,
        rx: &Receiver,
        j: usize,
        nodes: &GaussNodes,
        among: Among,
        mode: Mode,
        corners: &mut Corners,
        out: &mut [f64],
        mut ball: Option<(f64, &mut f64)>,
    ) -> (usize, usize) {
        // GAUSS_POINTS^2 nodes: fixed arrays, no allocation per moment.
        let mut lit = [(0usize, 0.0f64); N];
        let mut count = 0;
        for k in 0..N {
            let g = point_kernel(rx.x, rx.n, nodes.position[k], nodes.normal[k]);
            if g != 0.0 {
                lit[count] = (k, g);
                count += 1;
            }
        }
        let mut visible = [true; N];
        match (mode, self.occluders) {
            (Mode::Rays, Some(o)) if count > 0 => {
                // The lit nodes, then the corners.
                let mut targets = [DVec3::ZERO; N + 4];
                for a in 0..count {
                    targets[a] = nodes.position[lit[a].0];
                }
                let all = count + corners.count;
                targets[count..all].copy_from_slice(&corners.points[..corners.count]);
                let mut seen = [true; N + 4];
                let (ends, targets, seen_all) = ((rx.element, j as u32), &targets[..all], &mut seen[..all]);
                match among {
                    Among::Bounds(bounds) => o.point_visibility(rx.x, rx.n, ends, bounds, targets, seen_all),
                    Among::Candidates(candidates) => {
                        o.visibility_among(candidates, rx.x, ends, targets, seen_all)
                    }
                }
                visible[..count].copy_from_slice(&seen[..count]);
                corners.seen[..corners.count].copy_from_slice(&seen[count..all]);
            }
            (Mode::Mask(_), _) => {
                for a in 0..count {
                    let k = lit[a].0;
                    visible[a] = self.visible(rx, j, nodes.position[k], nodes.cell[k], mode);
                }
            }
            _ => {}
        }
        let nb = out.len();
        for (&(k, g), _) in lit[..count].iter().zip(&visible).filter(|(_, v)| **v) {
            // (Gamma_0 = 1: a node's l = 0 weight is its area weight.)
            if let Some((r, weight)) = ball.as_mut()
                && rx.x.distance(nodes.position[k]) <= *r
            {
                **weight += g * nodes.weighted_basis[k * nb];
                continue;
            }
            for l in 0..nb {
                out[l] += g * nodes.weighted_basis[k * nb + l];
            }
        }
        (visible[..count].iter().filter(|v| **v).count(), count)
    }

    /// Whether `y` (in visibility cell `cell` of source `j`) is seen from the corner.
    pub(super) fn visible(&self, rx: &Receiver, j: usize, y: DVec3, cell: usize, mode: Mode) -> bool {
        match (mode, self.occluders) {
            (Mode::Open, _) | (_, None) => true,
            (Mode::Rays, Some(o)) => o.segment_visible(rx.x, y, rx.element, j as u32),
            (Mode::Mask(bits), _) => bits >> cell & 1 == 1,
        }
    }
}

/// The touch of a source at `foot` (on its plane) when the foot falls on the source.
fn foot_on(source: &Patch, foot: DVec3, radius: f64) -> Option<Touch> {
    let (s, t) = source.locate(foot);
    ((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t)).then_some(Touch { s, t, radius })
}
