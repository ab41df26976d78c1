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
    eps: f64,
}

impl Occluders {
    /// The shaft from `x` to `bounds`: a segment from `x` to a point inside `bounds` can be
    /// blocked only by a triangle it may hold.
    pub fn point_shaft(&self, x: DVec3, bounds: &Aabb) -> PointShaft {
        PointShaft { shaft: Shaft::new(&Aabb { min: x, max: x }, bounds), eps: 1e-9 * self.scale }
    }

    /// Whether occluder triangle `t` (an index of [`Occluders::point_candidates`]' lists) may
    /// lie in `shaft`: a candidate of a source stays one for a part of the source only if so.
    pub fn may_block(&self, shaft: &PointShaft, t: usize) -> bool {
        shaft.shaft.may_contain_triangle(&self.bvh.triangles()[t].v, shaft.eps)
    }

    /// Which segments from `x` (on element `i`) to `targets` (on element `j`) are unobstructed,
    /// into `out`: any-hit rays through the BVH, without gathering the shaft's triangles first
    /// (for a few rays to a far source the shaft query costs more than the rays).
    pub fn visible_from(&self, x: DVec3, (i, j): (u32, u32), targets: &[DVec3], out: &mut [bool]) {
        let (i, j) = self.ids((i, j));
        for (o, &y) in out.iter_mut().zip(targets) {
            *o = !self.bvh.occluded(x, y - x, 1e-9, 1.0 - 1e-9, i, j);
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
            let (i, j) = self.ids((i, j));
            for (o, &y) in out.iter_mut().zip(targets) {
                *o = !self.bvh.occluded(x, y - x, 1e-9, 1.0 - 1e-9, i, j);
            }
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
