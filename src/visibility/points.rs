//! Visibility from a point, for the corner gathers: single segments and packets of them, the
//! triangles that may block the segments from a point to a source, and those segments' verdicts;
//! for the gather through the hierarchy (`hierarchy::gather`), narrowing a candidate list to the
//! shaft of a part of a source, and rays straight through the BVH where no candidate list is
//! worth gathering.

use glam::DVec3;

use super::batch::{CANDIDATES, CAST};
use super::link::shaft_candidates;
use super::shaft::Shaft;
use super::{BRUTE_FORCE_CANDIDATES, Occluders, bvh};
use crate::geometry::Aabb;

/// The shaft from a point to a box, to narrow a candidate list with
/// ([`Occluders::may_block`]).
pub struct PointShaft {
    shaft: Shaft,
    /// The point and the box the shaft joins (for [`Occluders::crosses`]).
    x: DVec3,
    bounds: Aabb,
    eps: f64,
}

impl Occluders {
    /// The shaft from `x` to `bounds`: a segment from `x` to a point inside `bounds` can be
    /// blocked only by a triangle it may hold.
    pub fn point_shaft(&self, x: DVec3, bounds: &Aabb) -> PointShaft {
        PointShaft {
            shaft: Shaft::new(&Aabb { min: x, max: x }, bounds),
            x,
            bounds: *bounds,
            eps: 1e-9 * self.scale,
        }
    }

    /// Whether occluder triangle `t` (an index of [`Occluders::point_candidates`]' lists) may
    /// lie in `shaft`: a candidate of a source stays one for a part of the source only if so.
    pub fn may_block(&self, shaft: &PointShaft, t: usize) -> bool {
        self.crosses(t, shaft.x, &shaft.bounds)
            && shaft.shaft.may_contain_triangle(&self.bvh.triangles()[t].v, shaft.eps)
    }

    /// Whether a segment from `x` to a point of `bounds` may cross occluder triangle `t`'s
    /// plane between its ends: not when `x` lies in that plane (within the occluders' `1e-9` of
    /// the scene: a segment leaving a point of the plane meets it only there, where a traced
    /// ray could still count a hit past its `t_min`, the shadow acne of a copy of the point's
    /// face), nor when `bounds` lies wholly on `x`'s side of it (the walls standing on a
    /// neighbour's far edge, which every shaft from a corner touches).
    fn crosses(&self, t: usize, x: DVec3, bounds: &Aabb) -> bool {
        let (n, d) = self.triangle_planes[t];
        let eps = 1e-9 * self.scale;
        let from = n.dot(x) - d;
        if from.abs() <= eps {
            return false;
        }
        let (c, h) = (bounds.centre(), 0.5 * bounds.diagonal());
        let (mid, spread) = (n.dot(c) - d, n.abs().dot(h));
        if from > 0.0 { mid - spread < -eps } else { mid + spread > eps }
    }

    /// Which segments from `x` (on element `i`) to `targets` (on element `j`) are unobstructed,
    /// into `out`: any-hit rays through the BVH, without gathering the shaft's triangles first
    /// (for a few rays to a far source the shaft query costs more than the rays).
    pub fn visible_from(&self, x: DVec3, (i, j): (u32, u32), targets: &[DVec3], out: &mut [bool]) {
        let (i, j) = self.ids((i, j));
        // The segments leave one point for one source: coherent, traced as packets.
        let origins = [x; bvh::PACKET];
        let mut dirs = [DVec3::ZERO; bvh::PACKET];
        let mut blocked = [false; bvh::PACKET];
        for (out, targets) in out.chunks_mut(bvh::PACKET).zip(targets.chunks(bvh::PACKET)) {
            let n = targets.len();
            for (d, &y) in dirs.iter_mut().zip(targets) {
                *d = y - x;
            }
            blocked[..n].fill(false);
            self.bvh.occluded_packet(&origins[..n], &dirs[..n], 1e-9, 1.0 - 1e-9, i, j, &mut blocked[..n]);
            for (o, b) in out.iter_mut().zip(&blocked[..n]) {
                *o = !b;
            }
        }
    }
}

impl Occluders {
    /// Whether the segment from `a` (on element `i`) to `b` (on element `j`) is unobstructed by
    /// any other element: one ray, for point queries such as the corner gather.
    pub fn segment_visible(&self, a: DVec3, b: DVec3, i: u32, j: u32) -> bool {
        let (i, j) = self.ids((i, j));
        !self.bvh.occluded(a, b - a, 1e-9, 1.0 - 1e-9, i, j)
    }

    /// [`Occluders::segment_visible`] for up to [`bvh::PACKET`] segments at once, traced together:
    /// `visible[k]` for the segment `ends[k]`, from a point on element `elements[k].0` to one on
    /// `elements[k].1`.
    pub fn segments_visible(&self, ends: &[(DVec3, DVec3)], elements: &[(u32, u32)], visible: &mut [bool]) {
        let n = ends.len();
        let (mut origins, mut dirs) = ([DVec3::ZERO; bvh::PACKET], [DVec3::ZERO; bvh::PACKET]);
        for (k, &(a, b)) in ends.iter().enumerate() {
            (origins[k], dirs[k]) = (a, b - a);
        }
        let mut blocked = [false; bvh::PACKET];
        let mut skips = [(0, 0); bvh::PACKET];
        for (s, &e) in skips.iter_mut().zip(elements) {
            *s = self.ids(e);
        }
        self.bvh.occluded_each(&origins[..n], &dirs[..n], (1e-9, 1.0 - 1e-9), &skips[..n], &mut blocked[..n]);
        for (v, b) in visible.iter_mut().zip(&blocked[..n]) {
            *v = !b;
        }
    }

    /// Which segments from the point `x` (on element `i`, front normal `n`) to `targets` (points
    /// of element `j`, inside `bounds`, in front of `x`'s tangent plane and, when `j` is planar,
    /// with `x` in front of `j`'s plane) are unobstructed, written to `out` (as long as
    /// `targets`). Triangles are first gathered from the shaft between `x` and `bounds` (usually
    /// none: no rays at all); short lists are tested directly, long ones through the BVH.
    ///
    /// Triangles wholly behind either plane are dropped, as [`Occluders::link_visibility`] drops
    /// them: a segment from a point in front of a plane to a point on it stays in front of it.
    /// On `j`'s side this drops the source's coplanar neighbours (the other elements of a
    /// subdivided light, which every shaft to one of them touches) and whatever lies behind the
    /// source, so a corner's rays to a light are cast only where something stands between.
    pub fn point_visibility(
        &self,
        x: DVec3,
        n: DVec3,
        (i, j): (u32, u32),
        bounds: &crate::geometry::Aabb,
        targets: &[DVec3],
        out: &mut [bool],
    ) {
        CANDIDATES.with_borrow_mut(|candidates| {
            self.point_candidates(x, n, (i, j), bounds, candidates);
            self.visibility_among(candidates, x, (i, j), targets, out);
        });
    }

    /// The occluder triangles that may block a segment from the point `x` (on element `i`, front
    /// normal `n`) to a point of element `j` inside `bounds`, into `out`: those
    /// [`Occluders::point_visibility`] tests. They are candidates for every part of `j` inside
    /// `bounds` too, so a point gathering a source it splits finds them once.
    pub fn point_candidates(
        &self,
        x: DVec3,
        n: DVec3,
        (i, j): (u32, u32),
        bounds: &crate::geometry::Aabb,
        out: &mut Vec<usize>,
    ) {
        let shaft = Shaft::new(&crate::geometry::Aabb { min: x, max: x }, bounds);
        // Segments leave `x` to its front and end on `j`: triangles wholly behind `x`'s tangent
        // plane, or behind `j`'s plane, cannot block.
        let (own, source) = ((n, n.dot(x)), self.culling_planes[j as usize]);
        let both = [own, source.unwrap_or(own)];
        let planes = &both[..1 + source.is_some() as usize];
        shaft_candidates(self, &shaft, planes, self.ids((i, j)), out);
        out.retain(|&t| self.crosses(t, x, bounds));
    }

    /// Which segments from `x` (on element `i`) to `targets` (on element `j`) are unobstructed,
    /// into `out`, given the triangles that may block them ([`Occluders::point_candidates`] for
    /// bounds holding the targets): short lists tested directly, long ones through the BVH.
    pub fn visibility_among(
        &self,
        candidates: &[usize],
        x: DVec3,
        (i, j): (u32, u32),
        targets: &[DVec3],
        out: &mut [bool],
    ) {
        if candidates.is_empty() {
            out.fill(true);
        } else if candidates.len() <= BRUTE_FORCE_CANDIDATES {
            CAST.with_borrow_mut(|(tris, from)| {
                tris.gather_into(&self.edges, candidates);
                tris.terms_from(x, from);
                for (o, &y) in out.iter_mut().zip(targets) {
                    *o = !tris.any_hit(from, y - x, 1e-9, 1.0 - 1e-9);
                }
            });
        } else {
            self.visible_from(x, (i, j), targets, out);
        }
    }

    /// Whether some occluder triangle, not of element `i`, has bounds within `r` of the point `x`
    /// and reaches in front of its tangent plane (normal `n`) by more than `r / 100`: something
    /// may hide `x` from close by. (The margin keeps the neighbours on a gently curved or
    /// twisted surface, such as the Cornell box's left wall, from counting.)
    pub fn any_near(&self, x: DVec3, n: DVec3, r: f64, i: u32) -> bool {
        let query = crate::geometry::Aabb { min: x - DVec3::splat(r), max: x + DVec3::splat(r) };
        let eps = 1e-2 * r;
        let i = self.id(i as usize);
        let mut found = false;
        self.bvh.for_each_overlapping(&query, |t| {
            let tri = &self.bvh.triangles()[t];
            found |= tri.element != i && tri.v.iter().any(|v| n.dot(*v - x) > eps);
        });
        found
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use crate::geometry::{Aabb, Patch};
    use crate::visibility::Occluders;

    /// The bilinear patch through four corners.
    fn quad(c: [[f64; 3]; 4]) -> Patch {
        Patch::from_corners(&c.map(DVec3::from_array))
    }

    /// A point on a face that a copy of it covers (the decimated monastery has many), the copy
    /// tilted a little about a line through the point and the point a rounding error behind
    /// it, sees a source in front: the copy's plane holds the point, so no segment from it
    /// crosses the copy. Traced, a segment meets the copy's plane a few 1e-9 of its length
    /// out, past the rays' `t_min`: the point read black (shadow acne; on a 5k-face crop of the
    /// monastery a fast-gathered corner 0.17 instead of 0.67). The tangent plane's test does not
    /// drop the copy: it reaches in front of it.
    #[test]
    fn a_copy_of_the_receiving_face_through_the_point_hides_nothing() {
        let receiver = quad([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]]);
        // The copy, tilted by 4e-6 about the line x = 0, z = 0.5.
        let d = 2e-6;
        let copy = quad([[-d, 0.0, 0.0], [-d, 1.0, 0.0], [d, 1.0, 1.0], [d, 0.0, 1.0]]);
        let source = quad([[1.0, 0.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 0.0], [1.0, 0.0, 0.0]]);
        // (A wall behind them, so that neither is on the scene's hull, which occludes nothing.)
        let wall = quad([[-2.0, 0.0, 0.0], [-2.0, 1.0, 0.0], [-2.0, 1.0, 1.0], [-2.0, 0.0, 1.0]]);
        let occluders = Occluders::new(&[receiver, copy, source, wall], 2);
        let targets: Vec<DVec3> = [(0.1, 0.1), (0.9, 0.2), (0.5, 0.5), (0.2, 0.9), (0.95, 0.95)]
            .map(|(s, t)| source.point(s, t))
            .into();
        // 2e-9 behind the copy: inside the occluders' tolerance (1e-9 of the scene's diagonal, 3.5).
        for y in [0.5, 0.01, 0.7] {
            let x = DVec3::new(-2e-9, y, 0.5);
            let mut seen = vec![false; targets.len()];
            occluders.point_visibility(x, DVec3::X, (0, 2), &source.bounds(), &targets, &mut seen);
            assert!(seen.iter().all(|&v| v), "from {x}: {seen:?}");
        }
        // Behind the copy by more than the tolerance, the point is hidden by it.
        let x = DVec3::new(-1e-3, 0.5, 0.5);
        let mut seen = vec![true; targets.len()];
        occluders.point_visibility(x, DVec3::X, (0, 2), &source.bounds(), &targets, &mut seen);
        assert!(seen.iter().all(|&v| !v), "{seen:?}");
    }

    /// A triangle the source's box lies wholly on the point's side of cannot block: a wall
    /// standing on the source's far edge, the point on the source's side of it.
    #[test]
    fn a_wall_beyond_the_source_is_no_candidate() {
        let floor = quad([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]);
        // A wall in the plane y = 1 over the floor's edge, and the receiving point on a post
        // facing +x inside the room, a little above the floor.
        let wall = quad([[0.0, 1.0, 0.0], [0.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 0.0]]);
        let post = quad([[0.0, 0.2, 0.0], [0.0, 0.8, 0.0], [0.0, 0.8, 0.5], [0.0, 0.2, 0.5]]);
        let occluders = Occluders::new(&[post, floor, wall], 2);
        let x = DVec3::new(0.0, 0.5, 0.25);
        let mut candidates = Vec::new();
        occluders.point_candidates(x, DVec3::X, (0, 1), &floor.bounds(), &mut candidates);
        assert!(candidates.is_empty(), "{candidates:?}");
        // Past the wall, the same wall is a candidate for a box that reaches beyond it.
        let beyond = Aabb { min: DVec3::new(0.0, 0.0, 0.0), max: DVec3::new(1.0, 1.5, 0.0) };
        occluders.point_candidates(x, DVec3::X, (0, 1), &beyond, &mut candidates);
        assert!(!candidates.is_empty());
    }
}
