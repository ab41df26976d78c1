//! The exact form factor from a point to a quadrilateral, without allocating:
//! [`crate::kernel::point::point_to_polygon`] for the four corners of a patch, with the clip to
//! the point's front half-space in a fixed array (the gather takes it for every small part of a
//! near source).

use std::f64::consts::PI;

use glam::DVec3;

/// Form factor from a differential area at `x` (unit normal `nx`) to the polygon `corners`
/// (front normal `normal`), front side only: Lambert's contour formula on the part in front of
/// `x`'s tangent plane, as [`crate::kernel::point::point_to_polygon`] computes it.
pub fn form_factor(x: DVec3, nx: DVec3, corners: &[DVec3; 4], normal: DVec3) -> f64 {
    let centre = corners.iter().copied().sum::<DVec3>() / 4.0;
    if normal.dot(x - centre) <= 0.0 {
        return 0.0;
    }
    // Sutherland-Hodgman clip to `nx . (p - x) >= 0`: a quadrilateral keeps at most 5 corners.
    let mut clipped = [DVec3::ZERO; 8];
    let mut n = 0;
    for k in 0..4 {
        let (p, q) = (corners[k], corners[(k + 1) % 4]);
        let (dp, dq) = (nx.dot(p - x), nx.dot(q - x));
        if dp >= 0.0 {
            clipped[n] = p;
            n += 1;
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            clipped[n] = p + (q - p) * (dp / (dp - dq));
            n += 1;
        }
    }
    if n < 3 {
        return 0.0;
    }
    let mut sum = 0.0;
    for k in 0..n {
        let a = (clipped[k] - x).normalize();
        let b = (clipped[(k + 1) % n] - x).normalize();
        let c = a.cross(b);
        let len = c.length();
        if len < 1e-300 {
            continue;
        }
        sum += len.atan2(a.dot(b)) * nx.dot(c) / len;
    }
    (sum / (2.0 * PI)).abs()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::point::point_to_polygon;

    /// The same numbers as the kernel's allocating version, for points in front, behind, above
    /// an edge and beside a collapsed edge (a triangle's apex).
    #[test]
    fn form_factor_is_point_to_polygon() {
        let quads = [
            [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y],
            [DVec3::ZERO, DVec3::X, DVec3::new(0.5, 1.0, 0.0), DVec3::new(0.5, 1.0, 0.0)],
        ];
        let points = [
            (DVec3::new(0.3, 0.4, 1.0), DVec3::NEG_Z),
            (DVec3::new(0.3, 0.4, 1e-3), DVec3::new(0.0, 0.6, -0.8)),
            (DVec3::new(1.5, 0.4, 0.2), DVec3::new(-1.0, 0.0, -1.0).normalize()),
            (DVec3::new(0.5, 1.0, 1e-3), DVec3::X),
            (DVec3::new(0.3, 0.4, -1.0), DVec3::Z),
        ];
        for q in &quads {
            for &(x, n) in &points {
                let want = point_to_polygon(x, n, q, DVec3::Z);
                let got = form_factor(x, n, q, DVec3::Z);
                assert!((got - want).abs() <= 1e-15 * want.max(1.0), "{x} {n}: {got} vs {want}");
            }
        }
    }
}
