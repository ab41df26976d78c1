//! Box-box shafts (Haines and Wallace 1991, "Shaft culling for efficient ray-cast radiosity"):
//! the union box of two boxes, cut by planes through the edges where one box sticks out and the
//! other defines the union. Anything outside the shaft cannot block a segment between the boxes.

use glam::DVec3;

use crate::geometry::Aabb;

/// At most one plane per pair of faces on different axes where A defines one face of the union
/// box and B the other, hence at most 8: with `a_k` of axis `k`'s two faces defined by A alone and
/// `b_k <= 2 - a_k` by B alone, the pairs number `sum a_k * sum b_k - sum a_k b_k`, at most 9 only
/// when every `a_k` is 0 or 2, which makes `sum a_k` even (then 8).
const MAX_PLANES: usize = 8;

#[derive(Clone, Debug)]
pub struct Shaft {
    pub bounds: Aabb,
    /// Planes `n . p > d` is outside, the first `count` of them (no heap: one shaft per link),
    /// by coordinate so that the box and point tests take all lanes at once: `n` and `d`. Lanes
    /// past `count` hold `n = 0, d = +inf`, which never leave anything out.
    count: usize,
    n: [[f64; MAX_PLANES]; 3],
    d: [f64; MAX_PLANES],
}

impl Shaft {
    pub fn new(a: &Aabb, b: &Aabb) -> Self {
        let bounds = a.union(*b);
        let mut shaft = Shaft { bounds, count: 0, n: [[0.0; MAX_PLANES]; 3], d: [f64::INFINITY; MAX_PLANES] };
        for_each_plane(a, b, |n, d| {
            let k = shaft.count;
            for c in 0..3 {
                shaft.n[c][k] = n[c];
            }
            shaft.d[k] = d;
            shaft.count += 1;
            true
        });
        shaft
    }

    /// Whether box `x`, grown by `eps`, meets the shaft between `a` and `b`: their convex hull,
    /// which is the union over `t in [0, 1]` of the boxes `(1 - t) a + t b` (bounds interpolated).
    /// So `x` meets it iff some `t` has every interpolated bound on the right side of `x`'s: six
    /// conditions linear in `t`, each keeping a part of `[0, 1]`. Exact for the hull, where the
    /// planes of [`Shaft::may_contain_box`] test only the union box's and the shaft's own faces
    /// as separating planes (and so may keep a box outside the hull near an edge).
    pub fn between_may_contain_box(a: &Aabb, b: &Aabb, x: &Aabb, eps: f64) -> bool {
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        // f0 + t (f1 - f0) <= c for t in [lo, hi].
        let mut keep = |f0: f64, f1: f64, c: f64| {
            let slope = f1 - f0;
            if slope > 0.0 {
                hi = hi.min((c - f0) / slope);
            } else if slope < 0.0 {
                lo = lo.max((c - f0) / slope);
            } else if f0 > c {
                hi = -1.0;
            }
        };
        for k in 0..3 {
            // The interpolated box's min is below x's max, and its max above x's min.
            keep(a.min[k], b.min[k], x.max[k] + eps);
            keep(-a.max[k], -b.max[k], -(x.min[k] - eps));
        }
        lo <= hi
    }

    /// False only if the triangle lies wholly outside the shaft (a conservative test).
    #[inline(always)]
    pub fn may_contain_triangle(&self, v: &[DVec3; 3], eps: f64) -> bool {
        self.may_contain_points(v, eps)
    }

    /// False only if the convex hull of `v` lies wholly outside the shaft (a conservative test).
    #[inline(always)]
    pub fn may_contain_points(&self, v: &[DVec3], eps: f64) -> bool {
        for axis in 0..3 {
            if v.iter().all(|p| p[axis] < self.bounds.min[axis] - eps)
                || v.iter().all(|p| p[axis] > self.bounds.max[axis] + eps)
            {
                return false;
            }
        }
        // Some plane with every point outside, `n . p > d + eps` (all planes at once).
        let mut outside = [true; MAX_PLANES];
        for p in v {
            for k in 0..MAX_PLANES {
                let dot = (self.n[0][k] * p.x) + (self.n[1][k] * p.y) + (self.n[2][k] * p.z);
                outside[k] &= dot > self.d[k] + eps;
            }
        }
        !outside.iter().fold(false, |a, &o| a | o)
    }

    /// Per point `(x[k], y[k], z[k])`, the tests of [`Shaft::may_contain_points`] it lies outside
    /// of, as bits of `out[k]` (the union box's six faces, then the planes): the hull of some
    /// points lies wholly outside the shaft, by the same comparisons, iff the AND of their masks
    /// is not zero. Points shared by several triangles are tested once.
    pub fn outside_masks(&self, xyz: [&[f64]; 3], eps: f64, out: &mut [u32]) {
        outside_masks(self, xyz, eps, out);
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
    #[inline(always)]
    pub fn may_contain_overlapping_box(&self, b: &Aabb, eps: f64) -> bool {
        self.may_contain_centred_box(b.centre(), b.diagonal() * 0.5, eps)
    }

    /// [`Shaft::may_contain_overlapping_box`] of the box with centre `c = b.centre()` and half
    /// extent `h = b.diagonal() * 0.5`: whether no plane has the box's nearest corner outside,
    /// `n . c - |n| . h > d + eps` (all planes at once).
    #[inline(always)]
    pub fn may_contain_centred_box(&self, c: DVec3, h: DVec3, eps: f64) -> bool {
        let mut outside = false;
        for k in 0..MAX_PLANES {
            let nc = (self.n[0][k] * c.x) + (self.n[1][k] * c.y) + (self.n[2][k] * c.z);
            let ah = (self.n[0][k].abs() * h.x) + (self.n[1][k].abs() * h.y) + (self.n[2][k].abs() * h.z);
            outside |= nc - ah > self.d[k] + eps;
        }
        !outside
    }
}

crate::simd::multiversion! {
    /// [`Shaft::outside_masks`], vectorised over the points.
    fn outside_masks(shaft: &Shaft, xyz: [&[f64]; 3], eps: f64, out: &mut [u32]) {
        let [x, y, z] = xyz;
        let n = out.len();
        let (x, y, z) = (&x[..n], &y[..n], &z[..n]);
        let (lo, hi) = (shaft.bounds.min - DVec3::splat(eps), shaft.bounds.max + DVec3::splat(eps));
        for k in 0..n {
            out[k] = (x[k] < lo.x) as u32
                | ((x[k] > hi.x) as u32) << 1
                | ((y[k] < lo.y) as u32) << 2
                | ((y[k] > hi.y) as u32) << 3
                | ((z[k] < lo.z) as u32) << 4
                | ((z[k] > hi.z) as u32) << 5;
        }
        for p in 0..shaft.count {
            let (nx, ny, nz, limit) = (shaft.n[0][p], shaft.n[1][p], shaft.n[2][p], shaft.d[p] + eps);
            for k in 0..n {
                // `n.dot(point)`, in glam's order.
                let dot = (nx * x[k]) + (ny * y[k]) + (nz * z[k]);
                out[k] |= ((dot > limit) as u32) << (6 + p);
            }
        }
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

    /// A pseudo-random number in [0, 4) from `k` and a frequency `a`.
    fn f(k: usize, a: f64) -> f64 {
        ((k as f64 * a).sin() * 43758.5453).fract().abs() * 4.0
    }

    /// A pseudo-random box of test case `k`, its sides scaled by `s`.
    fn boxed(k: usize, s: f64) -> Aabb {
        let p = DVec3::new(f(k, 1.1), f(k, 2.3), f(k, 3.7));
        Aabb { min: p, max: p + DVec3::new(f(k, 5.1), f(k, 6.3), f(k, 7.9)) * s }
    }

    /// The box test is the hull's: every box it keeps the built shaft keeps too (the shaft's
    /// planes are a conservative test of the same hull); a small box around a point between the
    /// two boxes is kept; and a box it rejects has no point of the hull, checked by sampling.
    #[test]
    fn between_may_contain_box_is_the_hulls_test() {
        let (mut inside, mut outside, mut tighter) = (0, 0, 0);
        for k in 0..5000 {
            let (a, b, x) = (boxed(3 * k, 0.5), boxed(3 * k + 1, 0.5), boxed(3 * k + 2, 0.2));
            let shaft = Shaft::new(&a, &b).may_contain_box(&x, 1e-9);
            let hull = Shaft::between_may_contain_box(&a, &b, &x, 1e-9);
            assert!(!hull || shaft, "case {k}: kept by the hull test, not by the shaft");
            tighter += (shaft && !hull) as usize;
            if hull {
                inside += 1;
            } else {
                outside += 1;
                // No point (1 - t) p + t q, p in a, q in b, lies in x.
                for m in 0..200 {
                    let t = f(k * 200 + m, 9.7) / 4.0;
                    let (p, q) = (
                        a.min + (a.max - a.min) * DVec3::new(f(m, 1.3), f(m, 2.9), f(m, 4.1)) / 4.0,
                        b.min + (b.max - b.min) * DVec3::new(f(m, 5.3), f(m, 6.7), f(m, 8.9)) / 4.0,
                    );
                    let y = p * (1.0 - t) + q * t;
                    assert!(!(y.cmpge(x.min).all() && y.cmple(x.max).all()), "case {k}: {y} in x");
                }
            }
            // A small box around a point of the hull is kept.
            let t = f(k, 3.3) / 4.0;
            let y = a.centre() * (1.0 - t) + b.centre() * t;
            let small = Aabb { min: y - DVec3::splat(1e-6), max: y + DVec3::splat(1e-6) };
            assert!(Shaft::between_may_contain_box(&a, &b, &small, 0.0), "case {k}");
        }
        assert!(inside > 100 && outside > 100, "{inside} inside, {outside} outside");
        eprintln!("{tighter} of 5000 boxes kept by the shaft's planes are outside the hull");
    }

    /// The per-point masks decide as `may_contain_triangle` does, also for points on the planes.
    #[test]
    fn outside_masks_are_may_contain_triangle() {
        let (mut inside, mut outside) = (0, 0);
        for k in 0..2000 {
            let shaft = Shaft::new(&boxed(2 * k, 0.5), &boxed(2 * k + 1, 0.5));
            // Points on a coarse grid (some on the shaft's faces and planes), three per triangle.
            let points: Vec<DVec3> = (0..12)
                .map(|p| DVec3::new(f(k * 13 + p, 1.3), f(k * 13 + p, 2.9), f(k * 13 + p, 4.1)).floor())
                .collect();
            let coordinate = |c: usize| points.iter().map(|p| p[c]).collect::<Vec<f64>>();
            let (x, y, z) = (coordinate(0), coordinate(1), coordinate(2));
            let mut masks = vec![0; points.len()];
            shaft.outside_masks([&x, &y, &z], 1e-9, &mut masks);
            for t in 0..points.len() - 2 {
                let want = shaft.may_contain_triangle(&[points[t], points[t + 1], points[t + 2]], 1e-9);
                assert_eq!(masks[t] & masks[t + 1] & masks[t + 2] == 0, want, "case {k} triangle {t}");
                if want {
                    inside += 1;
                } else {
                    outside += 1;
                }
            }
        }
        assert!(inside > 1000 && outside > 1000, "{inside} inside, {outside} outside");
    }
}
