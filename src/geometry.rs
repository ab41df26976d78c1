//! Patches in world space: bilinear quads, triangles as collapsed quads.
//!
//! `X(s,t) = (1-s)(1-t)P0 + s(1-t)P1 + s t P2 + (1-s) t P3` over `[0,1]^2` (issue 2, item 1), corners in
//! face order. A triangle `(P0,P1,P2)` is the quad `(P0,P1,P2,P2)`: its edge `t = 1` collapses onto P2.
//! The front is the side of `(P1-P0) x (P2-P0)`. `A(s,t) = |dX/ds x dX/dt|` is the area element of
//! eq. (2). A sub-rectangle of a bilinear patch is again a bilinear patch, which is how elements
//! below a face (hierarchical refinement) reuse everything here.

use glam::DVec3;

use crate::quadrature::GaussLegendre;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: DVec3,
    pub max: DVec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb { min: DVec3::splat(f64::INFINITY), max: DVec3::splat(f64::NEG_INFINITY) };

    pub fn from_points(points: &[DVec3]) -> Self {
        points.iter().fold(Self::EMPTY, |b, p| b.grow(*p))
    }

    pub fn grow(self, p: DVec3) -> Self {
        Aabb { min: self.min.min(p), max: self.max.max(p) }
    }

    pub fn union(self, o: Aabb) -> Self {
        Aabb { min: self.min.min(o.min), max: self.max.max(o.max) }
    }

    pub fn overlaps(&self, o: &Aabb) -> bool {
        self.min.cmple(o.max).all() && o.min.cmple(self.max).all()
    }

    pub fn centre(&self) -> DVec3 {
        (self.min + self.max) * 0.5
    }

    pub fn diagonal(&self) -> DVec3 {
        self.max - self.min
    }

    /// The box grown by `margin` on every side.
    pub fn inflated(&self, margin: f64) -> Self {
        Aabb { min: self.min - DVec3::splat(margin), max: self.max + DVec3::splat(margin) }
    }

    /// The segment from `p` to `q` has a point in the box (the slab test, closed).
    pub fn meets_segment(&self, p: DVec3, q: DVec3) -> bool {
        let d = q - p;
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for k in 0..3 {
            if d[k] == 0.0 {
                if p[k] < self.min[k] || p[k] > self.max[k] {
                    return false;
                }
                continue;
            }
            let (a, b) = ((self.min[k] - p[k]) / d[k], (self.max[k] - p[k]) / d[k]);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
            if t0 > t1 {
                return false;
            }
        }
        true
    }
}

/// A rectangle `[s0,s1] x [t0,t1]` of a patch's parameter domain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    pub s0: f64,
    pub s1: f64,
    pub t0: f64,
    pub t1: f64,
}

impl Rect {
    pub const UNIT: Rect = Rect { s0: 0.0, s1: 1.0, t0: 0.0, t1: 1.0 };

    /// Maps local `(s,t)` in `[0,1]^2` into this rectangle.
    pub fn map(&self, s: f64, t: f64) -> (f64, f64) {
        (self.s0 + s * (self.s1 - self.s0), self.t0 + t * (self.t1 - self.t0))
    }

    pub fn measure(&self) -> f64 {
        (self.s1 - self.s0) * (self.t1 - self.t0)
    }

    /// The four quadrants, in the order (s low, t low), (s high, t low), (s high, t high), (s low, t high).
    pub fn quadrants(&self) -> [Rect; 4] {
        let sm = 0.5 * (self.s0 + self.s1);
        let tm = 0.5 * (self.t0 + self.t1);
        [
            Rect { s0: self.s0, s1: sm, t0: self.t0, t1: tm },
            Rect { s0: sm, s1: self.s1, t0: self.t0, t1: tm },
            Rect { s0: sm, s1: self.s1, t0: tm, t1: self.t1 },
            Rect { s0: self.s0, s1: sm, t0: tm, t1: self.t1 },
        ]
    }
}

/// The plane of a planar patch, for side tests of other patches against its front.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrontPlane {
    pub normal: DVec3,
    /// The patch's centre `X(0.5, 0.5)`.
    pub centre: DVec3,
    /// Its bounding-sphere radius: side tests use a tolerance of `1e-9` of it.
    pub radius: f64,
}

impl FrontPlane {
    fn in_front(&self, p: DVec3) -> bool {
        self.normal.dot(p - self.centre) > 1e-9 * self.radius
    }

    /// True when some corner of `b` lies in front (so some point of `b` may be lit by this patch).
    pub fn any_in_front(&self, b: &Patch) -> bool {
        b.corners.iter().any(|p| self.in_front(*p))
    }

    /// True when every corner, hence every point, of `b` lies strictly in front.
    pub fn all_in_front(&self, b: &Patch) -> bool {
        b.corners.iter().all(|p| self.in_front(*p))
    }
}

/// A bilinear patch in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Patch {
    pub corners: [DVec3; 4],
}

impl Patch {
    /// A quad from 4 corners, or a collapsed quad from 3.
    pub fn from_corners(c: &[DVec3]) -> Self {
        match c.len() {
            3 => Patch { corners: [c[0], c[1], c[2], c[2]] },
            4 => Patch { corners: [c[0], c[1], c[2], c[3]] },
            n => panic!("a patch has 3 or 4 corners, not {n}"),
        }
    }

    /// `X(s,t)`.
    pub fn point(&self, s: f64, t: f64) -> DVec3 {
        let [p0, p1, p2, p3] = self.corners;
        (1.0 - s) * (1.0 - t) * p0 + s * (1.0 - t) * p1 + s * t * p2 + (1.0 - s) * t * p3
    }

    /// `dX/ds x dX/dt`: the front normal scaled by the area element `A(s,t)`.
    pub fn area_vector(&self, s: f64, t: f64) -> DVec3 {
        let [p0, p1, p2, p3] = self.corners;
        let ds = (1.0 - t) * (p1 - p0) + t * (p2 - p3);
        let dt = (1.0 - s) * (p3 - p0) + s * (p2 - p1);
        ds.cross(dt)
    }

    /// The parameters `(s,t)` of the point of the patch nearest to `p` (Gauss-Newton on
    /// `|X(s,t) - p|^2` from the centre), unclamped: outside `[0,1]^2` when `p` lies beyond an edge.
    pub fn locate(&self, p: DVec3) -> (f64, f64) {
        let [p0, p1, p2, p3] = self.corners;
        let (mut s, mut t) = (0.5, 0.5);
        for _ in 0..8 {
            let ds = (1.0 - t) * (p1 - p0) + t * (p2 - p3);
            let dt = (1.0 - s) * (p3 - p0) + s * (p2 - p1);
            let r = self.point(s, t) - p;
            let (a, b, c) = (ds.dot(ds), ds.dot(dt), dt.dot(dt));
            let det = a * c - b * b;
            if det.abs() < 1e-300 {
                break;
            }
            let (gs, gt) = (ds.dot(r), dt.dot(r));
            s -= (c * gs - b * gt) / det;
            t -= (a * gt - b * gs) / det;
        }
        (s, t)
    }

    /// Area by 4x4 Gauss (exact for planar patches, whose `A(s,t)` is bilinear).
    pub fn area(&self) -> f64 {
        // The rule made once: making it (Newton's iterations for the nodes, two vectors) was 1%
        // of a flat updated frame, every element and part asking for its area.
        static RULE: std::sync::LazyLock<GaussLegendre> = std::sync::LazyLock::new(|| GaussLegendre::new(4));
        let q = &*RULE;
        let mut a = 0.0;
        for (s, ws) in q.iter() {
            for (t, wt) in q.iter() {
                a += ws * wt * self.area_vector(s, t).length();
            }
        }
        a
    }

    /// Unit front normal at the centre (the normal of `(P1-P0) x (P2-P0)` for planar patches).
    pub fn centre_normal(&self) -> DVec3 {
        self.area_vector(0.5, 0.5).normalize_or_zero()
    }

    /// The sub-patch over a rectangle of the parameter domain (itself bilinear).
    pub fn sub_patch(&self, r: &Rect) -> Patch {
        Patch {
            corners: [
                self.point(r.s0, r.t0),
                self.point(r.s1, r.t0),
                self.point(r.s1, r.t1),
                self.point(r.s0, r.t1),
            ],
        }
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(&self.corners)
    }

    /// Centre and radius of a sphere bounding the patch (a bilinear patch lies in its corners' hull).
    pub fn bounding_sphere(&self) -> (DVec3, f64) {
        let c = self.point(0.5, 0.5);
        let r = self.corners.iter().map(|p| p.distance(c)).fold(0.0, f64::max);
        (c, r)
    }

    /// Largest distance of a corner from the plane through the centre with the centre normal,
    /// relative to the patch size: 0 for planar patches.
    pub fn non_planarity(&self) -> f64 {
        let (c, r) = self.bounding_sphere();
        let n = self.centre_normal();
        let d = self.corners.iter().map(|p| (*p - c).dot(n).abs()).fold(0.0, f64::max);
        if r > 0.0 { d / r } else { 0.0 }
    }

    /// The patch's plane, or `None` when it is not planar (to 1e-9 of its size).
    pub fn front_plane(&self) -> Option<FrontPlane> {
        if self.non_planarity() > 1e-9 {
            return None;
        }
        let (centre, radius) = self.bounding_sphere();
        Some(FrontPlane { normal: self.centre_normal(), centre, radius })
    }

    /// The patch as one or two triangles (for ray casting), in the front orientation.
    pub fn triangles(&self) -> Vec<[DVec3; 3]> {
        let [p0, p1, p2, p3] = self.corners;
        if p2 == p3 { vec![[p0, p1, p2]] } else { vec![[p0, p1, p2], [p0, p2, p3]] }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn locate_inverts_point() {
        let q = Patch::from_corners(&[
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(2.0, 0.1, 0.0),
            DVec3::new(2.2, 1.5, 0.0),
            DVec3::new(-0.1, 1.0, 0.0),
        ]);
        for &(s, t) in &[(0.5, 0.5), (0.01, 0.9), (0.99, 0.02), (1.1, 0.5)] {
            let (ls, lt) = q.locate(q.point(s, t));
            assert!((ls - s).abs() < 1e-9 && (lt - t).abs() < 1e-9, "({s},{t}) -> ({ls},{lt})");
        }
    }

    use super::*;

    /// The slab test against points sampled densely along the segment: a segment meets the
    /// box exactly when one of its points is in it (up to the sampling's step), in thin and
    /// flat boxes too (a moving light's swept box has no height).
    #[test]
    fn a_segment_meets_a_box_where_its_points_are_in_it() {
        let boxes = [
            Aabb { min: DVec3::new(-1.0, -0.5, 0.2), max: DVec3::new(0.5, 0.5, 1.0) },
            Aabb { min: DVec3::new(-0.3, 0.4, -0.3), max: DVec3::new(0.3, 0.4, 0.3) },
        ];
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
        };
        let inside = |x: &Aabb, p: DVec3| x.min.cmple(p).all() && p.cmple(x.max).all();
        let mut met = 0;
        for x in &boxes {
            for i in 0..4000 {
                let p = DVec3::new(next(), next(), next());
                // Every fourth segment along an axis, and some at the flat box's height.
                let mut q = DVec3::new(next(), next(), next());
                if i % 4 == 0 {
                    q = DVec3::new(p.x, p.y, q.z);
                }
                let (p, q) =
                    if i % 5 == 0 { (DVec3::new(p.x, 0.4, p.z), DVec3::new(q.x, 0.4, q.z)) } else { (p, q) };
                let sampled = (0..=20_000).any(|k| inside(x, p.lerp(q, k as f64 / 20_000.0)));
                let meets = x.meets_segment(p, q);
                if sampled {
                    assert!(meets, "{p} -> {q} passes through {x:?}");
                    met += 1;
                }
                if meets && !sampled {
                    // Only a graze shorter than the sampling's step.
                    let near = x.inflated((q - p).length() / 20_000.0);
                    assert!((0..=20_000).any(|k| inside(&near, p.lerp(q, k as f64 / 20_000.0))));
                }
            }
        }
        assert!(met > 400, "too few segments met a box to test anything: {met}");
    }

    #[test]
    fn triangle_is_a_collapsed_quad_with_half_the_area() {
        let t = Patch::from_corners(&[DVec3::ZERO, DVec3::X, DVec3::Y]);
        assert!((t.area() - 0.5).abs() < 1e-14);
        assert!((t.centre_normal() - DVec3::Z).length() < 1e-14);
        assert_eq!(t.point(0.3, 1.0), DVec3::Y);
    }

    #[test]
    fn sub_patch_is_the_restriction() {
        let p = Patch::from_corners(&[
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.3),
            DVec3::new(2.5, 1.0, 0.0),
            DVec3::Y,
        ]);
        let r = Rect { s0: 0.25, s1: 0.75, t0: 0.5, t1: 1.0 };
        let sub = p.sub_patch(&r);
        let (s, t) = r.map(0.3, 0.6);
        assert!((sub.point(0.3, 0.6) - p.point(s, t)).length() < 1e-14);
    }
}
