//! Box-box shafts (Haines and Wallace 1991, "Shaft culling for efficient ray-cast radiosity"):
//! the union box of two boxes, cut by planes through the edges where one box sticks out and the
//! other defines the union. Anything outside the shaft cannot block a segment between the boxes.

use glam::DVec3;

use crate::geometry::Aabb;

/// At most one plane per pair of faces on different axes: 3 axis pairs x 2 x 2 sides.
const MAX_PLANES: usize = 12;

#[derive(Clone, Debug)]
pub struct Shaft {
    pub bounds: Aabb,
    /// Planes `n . p > d` is outside, the first `count` of them (no heap: one shaft per link).
    planes: [(DVec3, f64); MAX_PLANES],
    /// `|n|` per plane, for the box test.
    abs_normals: [DVec3; MAX_PLANES],
    count: usize,
}

impl Shaft {
    pub fn new(a: &Aabb, b: &Aabb) -> Self {
        let bounds = a.union(*b);
        let mut planes = [(DVec3::ZERO, 0.0); MAX_PLANES];
        let mut abs_normals = [DVec3::ZERO; MAX_PLANES];
        let mut count = 0;
        for_each_plane(a, b, |n, d| {
            planes[count] = (n, d);
            abs_normals[count] = n.abs();
            count += 1;
            true
        });
        Shaft { bounds, planes, abs_normals, count }
    }

    /// `Shaft::new(a, b).may_contain_box(x, eps)`, the same decision, without building the
    /// shaft: planes are formed one at a time and the first that leaves `x` outside ends the
    /// test (most boxes tested against many shafts, such as a moving object's swept bounds
    /// against every pair's shaft, are outside).
    pub fn between_may_contain_box(a: &Aabb, b: &Aabb, x: &Aabb, eps: f64) -> bool {
        if !x.overlaps(&a.union(*b)) {
            return false;
        }
        let (c, h) = (x.centre(), x.diagonal() * 0.5);
        let mut inside = true;
        for_each_plane(a, b, |n, d| {
            // (`!(x > y)`, not `x <= y`: a NaN keeps the box in, as in `may_contain_overlapping_box`)
            let outside = n.dot(c) - n.abs().dot(h) > d + eps;
            inside = !outside;
            inside
        });
        inside
    }

    fn planes(&self) -> &[(DVec3, f64)] {
        &self.planes[..self.count]
    }

    /// False only if the triangle lies wholly outside the shaft (a conservative test).
    pub fn may_contain_triangle(&self, v: &[DVec3; 3], eps: f64) -> bool {
        self.may_contain_points(v, eps)
    }

    /// False only if the convex hull of `v` lies wholly outside the shaft (a conservative test).
    pub fn may_contain_points(&self, v: &[DVec3], eps: f64) -> bool {
        for axis in 0..3 {
            if v.iter().all(|p| p[axis] < self.bounds.min[axis] - eps)
                || v.iter().all(|p| p[axis] > self.bounds.max[axis] + eps)
            {
                return false;
            }
        }
        !self.planes().iter().any(|(n, d)| v.iter().all(|p| n.dot(*p) > d + eps))
    }

    /// False only if the box lies wholly outside the shaft: outside the union box, or wholly on
    /// the outer side of a plane (tested at the box's corner nearest the shaft, `n.c - |n|.h`).
    pub fn may_contain_box(&self, b: &Aabb, eps: f64) -> bool {
        if !b.overlaps(&self.bounds) {
            return false;
        }
        self.may_contain_overlapping_box(b, eps)
    }

    /// [`Shaft::may_contain_box`] for a box already known to overlap [`Shaft::bounds`].
    #[inline]
    pub fn may_contain_overlapping_box(&self, b: &Aabb, eps: f64) -> bool {
        let c = b.centre();
        let h = b.diagonal() * 0.5;
        let (planes, abs) = (&self.planes[..self.count], &self.abs_normals[..self.count]);
        !planes.iter().zip(abs).any(|((n, d), a)| n.dot(c) - a.dot(h) > d + eps)
    }
}

/// Calls `f(n, d)` for each plane of the shaft between `a` and `b` (`n . p > d` is outside,
/// `|n| = 1`) until `f` returns false. Side 0 is the min face, side 1 the max face: for each
/// pair of faces on different axes where A alone defines one and B alone the other, a plane
/// joins A's and B's edges there.
#[inline]
fn for_each_plane(a: &Aabb, b: &Aabb, mut f: impl FnMut(DVec3, f64) -> bool) {
    for u in 0..3 {
        for v in (u + 1)..3 {
            for su in 0..2 {
                for sv in 0..2 {
                    let (ea_u, eb_u) = (face(a, u, su), face(b, u, su));
                    let (ea_v, eb_v) = (face(a, v, sv), face(b, v, sv));
                    let a_u = beyond(ea_u, eb_u, su);
                    let b_u = beyond(eb_u, ea_u, su);
                    let a_v = beyond(ea_v, eb_v, sv);
                    let b_v = beyond(eb_v, ea_v, sv);
                    if !((a_u && b_v) || (b_u && a_v)) {
                        continue;
                    }
                    // Corner edges of A and B on these two faces, in the (u, v) plane.
                    let pa = (ea_u, ea_v);
                    let pb = (eb_u, eb_v);
                    // Outward direction of this corner of the union box.
                    let out = (if su == 1 { 1.0 } else { -1.0 }, if sv == 1 { 1.0 } else { -1.0 });
                    let line = (pb.0 - pa.0, pb.1 - pa.1);
                    let mut n2 = (line.1, -line.0);
                    if n2.0 * out.0 + n2.1 * out.1 < 0.0 {
                        n2 = (-n2.0, -n2.1);
                    }
                    let mut n = DVec3::ZERO;
                    n[u] = n2.0;
                    n[v] = n2.1;
                    let len = n.length();
                    if len == 0.0 {
                        continue;
                    }
                    let n = n / len;
                    let mut p = DVec3::ZERO;
                    p[u] = pa.0;
                    p[v] = pa.1;
                    if !f(n, n.dot(p)) {
                        return;
                    }
                }
            }
        }
    }
}

fn face(b: &Aabb, axis: usize, side: usize) -> f64 {
    if side == 0 { b.min[axis] } else { b.max[axis] }
}

/// True if face coordinate `x` lies strictly beyond `y` on that side (so it defines the union).
fn beyond(x: f64, y: f64, side: usize) -> bool {
    if side == 0 { x < y } else { x > y }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_points_between_boxes_are_inside_and_far_points_outside() {
        let a = Aabb { min: DVec3::new(0.0, 0.0, 0.0), max: DVec3::new(1.0, 1.0, 0.0) };
        let b = Aabb { min: DVec3::new(3.0, 2.0, 4.0), max: DVec3::new(4.0, 3.0, 4.0) };
        let shaft = Shaft::new(&a, &b);
        // Points on segments between the boxes are inside.
        for k in 0..50 {
            let f = |x: f64| x.fract();
            let pa = DVec3::new(f(k as f64 * 0.37), f(k as f64 * 0.71), 0.0);
            let pb = DVec3::new(3.0 + f(k as f64 * 0.53), 2.0 + f(k as f64 * 0.29), 4.0);
            let p = pa.lerp(pb, f(k as f64 * 0.61));
            assert!(shaft.may_contain_triangle(&[p, p, p], 1e-9));
        }
        // A point inside the union box but far from the segment bundle is culled.
        let p = DVec3::new(4.0, 0.0, 0.0);
        assert!(shaft.bounds.min.cmple(p).all() && p.cmple(shaft.bounds.max).all());
        assert!(!shaft.may_contain_triangle(&[p, p, p], 1e-9));
    }

    /// The early-exit box test decides as the built shaft does.
    #[test]
    fn between_may_contain_box_is_may_contain_box() {
        let f = |k: usize, a: f64| ((k as f64 * a).sin() * 43758.5453).fract().abs() * 4.0;
        let boxed = |k: usize, s: f64| {
            let p = DVec3::new(f(k, 1.1), f(k, 2.3), f(k, 3.7));
            Aabb { min: p, max: p + DVec3::new(f(k, 5.1), f(k, 6.3), f(k, 7.9)) * s }
        };
        let (mut inside, mut outside) = (0, 0);
        for k in 0..5000 {
            let (a, b, x) = (boxed(3 * k, 0.5), boxed(3 * k + 1, 0.5), boxed(3 * k + 2, 0.2));
            let want = Shaft::new(&a, &b).may_contain_box(&x, 1e-9);
            assert_eq!(Shaft::between_may_contain_box(&a, &b, &x, 1e-9), want, "case {k}");
            if want {
                inside += 1;
            } else {
                outside += 1;
            }
        }
        assert!(inside > 100 && outside > 100, "{inside} inside, {outside} outside");
    }
}
