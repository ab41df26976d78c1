//! A surface source integrated from the point: its moments `m^l = integral_S g V Gamma_l dA`
//! with shadow rays from the point (the recursion is [`super::exhaustive`]'s or [`super::near`]'s,
//! by the gather's mode), its light `sum_l m^l b_S^l`, and the feet: where the point touches the
//! source, the part of the source next to it counts with `B` gathered at the foot.

use glam::DVec3;

use super::kept::{How, Memo, Slot};
use super::{Counters, Gather, Mode, Received, Receiver};
use crate::basis::MAX_LEN as MAX_NB;
use crate::gather::penumbra::Corners;
use crate::gather::{FACING, FOOT_BALL, NEAR_FACING, PENUMBRA_DEPTH};
use crate::geometry::{Patch, Rect};
use crate::hierarchy::tree::{NodeId, Surface};
use crate::kernel::point::point_kernel;
use crate::quadrature::GaussLegendre;
use crate::solids::Solids;

/// A surface source being integrated from a point: its face and its patch.
#[derive(Clone, Copy)]
pub(super) struct Source<'a> {
    pub face: u32,
    pub patch: &'a Patch,
}

/// Where a point touches a source (a model's corner on the floor it stands on): the foot
/// point's parameters on the source node and the radius around the point that counts with
/// `B` gathered at the foot.
#[derive(Clone, Copy, Debug)]
pub(super) struct Touch {
    s: f64,
    t: f64,
    radius: f64,
}

/// Which shadow rays a Gauss sum casts.
#[derive(Clone, Copy)]
pub(super) enum Rays<'a> {
    /// Tested against these occluder triangles, the ones that may lie between the point and the
    /// rectangle (none: no rays).
    Among(&'a [usize]),
    /// Any-hit through the BVH (a far source, whose shaft query would cost more than its rays).
    Bvh,
}

impl Gather<'_> {
    /// Adds the surface node `source`'s light at the point and its form factor to `got`.
    /// With `feet = Some(solids)`, a source the point touches ([`Gather::touch`]) takes its part
    /// next to the point from `B` at the foot: nearly all of its form factor comes from there,
    /// in a contact shadow far finer than the source's polynomial ([`crate::gather`]'s feet).
    pub(super) fn surface_source(
        &self,
        rx: &Receiver,
        (source, slot): (NodeId, Slot),
        feet: Option<Option<&Solids>>,
        got: &mut Received,
        memo: &mut Memo,
    ) {
        let tree = self.inputs.tree;
        let node = tree.node(source);
        let s = node.surface().expect("a surface link's ends are surfaces");
        let nb = tree.basis.len();
        let touch = feet.and_then(|_| self.touch(rx, node.radius, s));
        let how = if touch.is_some() { How::NearFoot } else { How::Near };
        // The moments, then the ball's form factor.
        let v = memo.values(slot, source, how, |v| {
            let (m, weight) = v.split_at_mut(nb);
            let ball =
                touch.map(|t| (crate::gather::Ball { radius: t.radius, foot: (t.s, t.t) }, &mut weight[0]));
            let src = Source { face: s.face, patch: &s.patch };
            match self.mode {
                Mode::Exhaustive => self.exhaustive_moments(rx, src, m, ball),
                Mode::Fast => self.near_moments(rx, src, m, ball),
            }
        });
        let (m, weight) = (&v[..nb], v[nb]);
        let b = self.inputs.state.coefficients(source);
        let mut h = [0.0; 3];
        for l in 0..nb {
            for c in 0..3 {
                h[c] += m[l] * b[l][c];
            }
        }
        // Gamma_0 = 1: the l = 0 moment is the form factor.
        got.add(h, m[0] + weight);
        if let (Some(t), Some(solids), true) = (touch, feet, weight > 0.0) {
            Counters::add(&self.counters.feet, 1);
            let (fs, ft) = s.domain.map(t.s, t.t);
            let mut at_foot = memo.foot(source);
            let [foot, _] = self.point((s.face as usize, fs, ft), None, solids, false, &mut at_foot);
            memo.keep_foot(source, at_foot);
            got.add(foot.map(|b| weight * b), 0.0);
        }
    }

    /// Whether the point touches the surface node `s` (bounding radius `radius`): it lies just
    /// in front of `s`'s plane and its foot falls on `s` (as [`crate::gather`] decides it for an
    /// element). Facing `s` from closer than [`NEAR_FACING`] of its radius, the foot is the
    /// point's projection and the ball [`FOOT_BALL`] times the distance; at an angle, the foot is
    /// as far along the point's normal as the point is above `s` (at least a hundredth of its
    /// face's radius), projected, and the ball three times that.
    pub(super) fn touch(&self, rx: &Receiver, radius: f64, s: &Surface) -> Option<Touch> {
        let (normal, centre) = (s.normal, s.patch.point(0.5, 0.5));
        let d = normal.dot(rx.x - centre);
        // The foot on `s`, or on a neighbour of `s` in its face with the ball reaching `s`: the
        // ball's part on each node of the face counts with `B` at the one foot (a corner above
        // the meeting of the face's nodes would otherwise take most of its ball from their
        // polynomials).
        let on =
            |foot: DVec3, radius: f64| {
                let (u, v) = s.patch.locate(foot);
                let unit = 0.0..=1.0;
                if unit.contains(&u) && unit.contains(&v) {
                    return Some(Touch { s: u, t: v, radius });
                }
                let (fs, ft) = s.domain.map(u, v);
                let nearest = s.patch.point(u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
                (unit.contains(&fs) && unit.contains(&ft) && foot.distance(nearest) < radius)
                    .then_some(Touch { s: u, t: v, radius })
            };
        if rx.n.dot(normal) < -FACING {
            return (d > 0.0 && d < NEAR_FACING * radius).then(|| on(rx.x - d * normal, FOOT_BALL * d))?;
        }
        let touching = d > 0.0 && d < 1e-2 * rx.radius;
        let near = d > 0.0 && d < NEAR_FACING * radius;
        if !(touching || near) || rx.n.dot(normal).abs() > 0.9 {
            return None;
        }
        let offset = if touching { 1e-2 * rx.radius } else { d };
        let foot = rx.x + offset * rx.n;
        on(foot - normal.dot(foot - centre) * normal, 3.0 * offset)
    }

    /// The Gauss sum over `rect` of the source into `out`, with one shadow ray per node that
    /// the point faces, cast as `rays` says; returns the sum's `integral g dA` without
    /// visibility (for [`super::near`]'s scaling to the exact form factor).
    ///
    /// An emitter's rectangle in a penumbra is split in four while it spans more than
    /// `2^-PENUMBRA_DEPTH` of the node per axis, as the flat gather splits it
    /// ([`crate::gather`]; tests/penumbra.rs): its nodes' rays disagree, or rays to its corners
    /// disagree with them (a shadow edge across the margin outside the nodes).
    pub(super) fn gauss(
        &self,
        rx: &Receiver,
        src: Source,
        rect: &Rect,
        rule: &GaussLegendre,
        rays: Rays,
        out: &mut [f64],
    ) -> f64 {
        self.gauss_split(rx, src, rect, rule, rays, out, None)
    }

    /// [`Gather::gauss`], with `ball = Some((r, weight))` the seen nodes within `r` of the point
    /// adding their weight to `weight` instead of their moments to `out` (a rectangle across a
    /// foot's ball, [`super::near`]).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn gauss_split(
        &self,
        rx: &Receiver,
        src: Source,
        rect: &Rect,
        rule: &GaussLegendre,
        rays: Rays,
        out: &mut [f64],
        mut ball: Option<(f64, &mut f64)>,
    ) -> f64 {
        let lit = Lit::nodes(rx, src.patch, rect, rule);
        if lit.count == 0 {
            return 0.0;
        }
        let count = lit.count;
        let mut targets = [DVec3::ZERO; N + 4];
        for (t, node) in targets.iter_mut().zip(&lit.nodes[..count]) {
            *t = node.0;
        }
        // The corners in front of the point go with the nodes' rays, for an emitter's
        // rectangle that may still split.
        let check = (rect.s1 - rect.s0).max(rect.t1 - rect.t0) > 1.0 / (1u32 << PENUMBRA_DEPTH) as f64
            && self.inputs.emission[src.face as usize] != [0.0; 3];
        let mut corners = Corners::of((rx.x, rx.n), src.patch, rect, check);
        let all = count + corners.count;
        targets[count..all].copy_from_slice(&corners.points[..corners.count]);
        let mut visible = [true; N + 4];
        if let Some(o) = self.inputs.occluders {
            let (targets, visible) = (&targets[..all], &mut visible[..all]);
            match rays {
                Rays::Among([]) => {}
                Rays::Among(candidates) => {
                    Counters::add(&self.counters.rays, all as u64);
                    o.visibility_among(candidates, rx.x, (rx.face, src.face), targets, visible);
                }
                Rays::Bvh => {
                    Counters::add(&self.counters.rays, all as u64);
                    o.visible_from(rx.x, (rx.face, src.face), targets, visible);
                }
            }
        }
        corners.seen[..corners.count].copy_from_slice(&visible[count..all]);
        let seen = visible[..count].iter().filter(|&&v| v).count();
        if corners.disagree(seen, count) {
            let mut sum = 0.0;
            for q in rect.quadrants() {
                let ball = ball.as_mut().map(|(r, w)| (*r, &mut **w));
                sum += self.gauss_split(rx, src, &q, rule, rays, out, ball);
            }
            return sum;
        }
        let basis = self.inputs.tree.basis;
        let nb = out.len();
        let mut g = [0.0; MAX_NB];
        for (&(y, w, s, t), _) in lit.nodes[..count].iter().zip(&visible).filter(|(_, v)| **v) {
            if let Some((r, weight)) = ball.as_mut()
                && rx.x.distance(y) <= *r
            {
                **weight += w;
                continue;
            }
            basis.eval_into(s, t, &mut g[..nb]);
            for l in 0..nb {
                out[l] += w * g[l];
            }
        }
        lit.unoccluded
    }
}

/// Gauss nodes per rectangle, at most.
const N: usize = super::GAUSS_POINTS * super::GAUSS_POINTS;

/// The Gauss nodes of a rectangle that the point faces.
struct Lit {
    /// Position, weight `g w_s w_t |R| A(s,t)`, and parameters `(s, t)`.
    nodes: [(DVec3, f64, f64, f64); N],
    count: usize,
    /// The weights' sum: `integral g dA` without visibility.
    unoccluded: f64,
}

impl Lit {
    fn nodes(rx: &Receiver, patch: &Patch, rect: &Rect, rule: &GaussLegendre) -> Self {
        let measure = rect.measure();
        let mut lit = Lit { nodes: [(DVec3::ZERO, 0.0, 0.0, 0.0); N], count: 0, unoccluded: 0.0 };
        for (u, wu) in rule.iter() {
            for (v, wv) in rule.iter() {
                let (s, t) = rect.map(u, v);
                let av = patch.area_vector(s, t);
                let a = av.length();
                if a <= 0.0 {
                    continue;
                }
                let y = patch.point(s, t);
                let g = point_kernel(rx.x, rx.n, y, av / a);
                if g != 0.0 {
                    let w = g * wu * wv * measure * a;
                    lit.nodes[lit.count] = (y, w, s, t);
                    lit.unoccluded += w;
                    lit.count += 1;
                }
            }
        }
        lit
    }
}
