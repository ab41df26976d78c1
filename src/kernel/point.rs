//! The point-to-point and point-to-polygon form factor kernels.

use glam::DVec3;
use std::f64::consts::PI;

/// `g(x,y) = cos(theta_x) cos(theta_y) / (pi r^2)`, one-sided: zero unless each point lies in
/// front of the other's surface. `F(x,y) dA_y` of eq. (2); `nx`, `ny` are unit front normals.
#[inline]
pub fn point_kernel(x: DVec3, nx: DVec3, y: DVec3, ny: DVec3) -> f64 {
    let d = y - x;
    let cx = nx.dot(d);
    let cy = -ny.dot(d);
    if cx <= 0.0 || cy <= 0.0 {
        return 0.0;
    }
    let r2 = d.length_squared();
    cx * cy / (PI * r2 * r2)
}

/// Form factor from a differential area at `x` (unit normal `nx`) to a planar polygon, front side
/// only, by Lambert's contour formula `F = 1/(2 pi) sum_i gamma_i n.(a_i x a_{i+1})/|a_i x a_{i+1}|`.
/// The polygon is first clipped to the half-space in front of `x`, where the formula holds.
/// `polygon_normal` is the polygon's front normal: from behind it the result is 0.
pub fn point_to_polygon(x: DVec3, nx: DVec3, polygon: &[DVec3], polygon_normal: DVec3) -> f64 {
    let centre = polygon.iter().copied().sum::<DVec3>() / polygon.len() as f64;
    if polygon_normal.dot(x - centre) <= 0.0 {
        return 0.0;
    }
    let clipped = clip_to_front(x, nx, polygon);
    if clipped.len() < 3 {
        return 0.0;
    }
    let mut sum = 0.0;
    for k in 0..clipped.len() {
        let a = (clipped[k] - x).normalize();
        let b = (clipped[(k + 1) % clipped.len()] - x).normalize();
        let c = a.cross(b);
        let len = c.length();
        if len < 1e-300 {
            continue;
        }
        let gamma = len.atan2(a.dot(b));
        sum += gamma * nx.dot(c) / len;
    }
    (sum / (2.0 * PI)).abs()
}

/// Sutherland-Hodgman clip of a polygon to `nx . (p - x) >= 0`.
fn clip_to_front(x: DVec3, nx: DVec3, polygon: &[DVec3]) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(polygon.len() + 2);
    for k in 0..polygon.len() {
        let p = polygon[k];
        let q = polygon[(k + 1) % polygon.len()];
        let dp = nx.dot(p - x);
        let dq = nx.dot(q - x);
        if dp >= 0.0 {
            out.push(p);
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            out.push(p + (q - p) * (dp / (dp - dq)));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Differential area under the corner of a parallel unit square at distance 1: 0.138532
    /// (references.md, the corner formula with X = Y = 1).
    #[test]
    fn contour_formula_matches_the_corner_closed_form() {
        let sq = [
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(0.0, 1.0, 1.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(1.0, 0.0, 1.0),
        ];
        let f = point_to_polygon(DVec3::ZERO, DVec3::Z, &sq, -DVec3::Z);
        assert!((f - 0.138532).abs() < 1e-6, "{f}");
        // From behind the polygon nothing is seen.
        assert_eq!(point_to_polygon(DVec3::new(0.0, 0.0, 2.0), -DVec3::Z, &sq, -DVec3::Z), 0.0);
    }

    #[test]
    fn clipping_keeps_only_the_visible_part() {
        // A vertical square straddling the tangent plane: only its upper half counts.
        let full = [
            DVec3::new(-1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(-1.0, 1.0, 1.0),
        ];
        let upper = [
            DVec3::new(-1.0, 1.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(-1.0, 1.0, 1.0),
        ];
        let a = point_to_polygon(DVec3::ZERO, DVec3::Z, &full, -DVec3::Y);
        let b = point_to_polygon(DVec3::ZERO, DVec3::Z, &upper, -DVec3::Y);
        assert!(a > 0.0 && (a - b).abs() < 1e-12);
    }
}
