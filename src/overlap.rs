//! Coplanar faces that cover each other: how much each counts as a source.
//!
//! A face duplicated in place (a mesh duplicated and left where it was, a decal modelled on a
//! wall, the doubled walls of a converted scene) is seen in full from every receiver, once per
//! copy, so the wall sends its light twice (issue 19: a closed box with doubled walls returned
//! more than it emits and reflects, or diverged). A path tracer's ray hits one of the copies,
//! whichever it meets first: each point of the wall is seen once. The expected value of that is
//! a source weight `1 / c(y)` for a point `y` covered by `c` coplanar, same-facing faces.
//!
//! Here the weight is taken per element as the mean over it: `w_j = A_j / (A_j + sum_k O_jk)`
//! with `O_jk` the area of `j` that another coplanar, same-facing element `k` covers. Exact for
//! copies (`1/2` each) and for any set of faces that cover each other wholly; a partial overlap is
//! spread over the element. Receivers are not weighted (each copy sees the scene), and nothing
//! changes for elements that overlap nothing, nearly all of them (`w = 1`).

use glam::{DVec2, DVec3};

use crate::geometry::{Aabb, FrontPlane, Patch};

/// Normals closer than this (1 - cos) and planes closer than this fraction of the scene's size
/// are one plane.
const SAME_NORMAL: f64 = 1e-9;
const SAME_PLANE: f64 = 1e-7;

/// Overlaps below this fraction of an element's area are rounding (faces that share an edge).
const MIN_OVERLAP: f64 = 1e-6;

/// The source weight of each patch (module docs): 1 unless coplanar same-facing patches cover it.
pub fn source_weights(patches: &[Patch]) -> Vec<f64> {
    use std::collections::HashMap;
    let scale = patches.iter().fold(Aabb::EMPTY, |b, p| b.union(p.bounds())).diagonal().length();
    let scale = scale.max(f64::MIN_POSITIVE);
    // Candidates share a cell of (normal, offset) quantized coarser than the tolerances; each
    // planar patch goes in one cell, and pairs found there are checked exactly.
    let planes: Vec<Option<FrontPlane>> = patches.iter().map(Patch::front_plane).collect();
    let mut cells: HashMap<([i64; 3], i64), Vec<usize>> = HashMap::new();
    for (e, plane) in planes.iter().enumerate() {
        if let Some(plane) = plane {
            let n = plane.normal;
            let key = (
                (n * 1e4).round().as_i64vec3().to_array(),
                (n.dot(plane.centre) / (1e-4 * scale)).round() as i64,
            );
            cells.entry(key).or_default().push(e);
        }
    }
    let mut covered = vec![0.0f64; patches.len()];
    for members in cells.values().filter(|m| m.len() > 1) {
        let (u, v) = tangent_frame(planes[members[0]].expect("planar").normal);
        let polygons: Vec<Vec<DVec2>> = members
            .iter()
            .map(|&e| polygon(&patches[e]).iter().map(|p| DVec2::new(p.dot(u), p.dot(v))).collect())
            .collect();
        let bounds: Vec<(DVec2, DVec2)> = polygons
            .iter()
            .map(|poly| {
                poly.iter()
                    .fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(lo, hi), &q| (lo.min(q), hi.max(q)))
            })
            .collect();
        // Sweep along u: each element meets those whose u-range it enters.
        let mut order: Vec<usize> = (0..members.len()).collect();
        order.sort_by(|&a, &b| bounds[a].0.x.total_cmp(&bounds[b].0.x));
        let mut active: Vec<usize> = Vec::new();
        for &a in &order {
            active.retain(|&b| bounds[b].1.x > bounds[a].0.x);
            for &b in &active {
                let (ea, eb) = (members[a], members[b]);
                let (pa, pb) = (planes[ea].expect("planar"), planes[eb].expect("planar"));
                let same = 1.0 - pa.normal.dot(pb.normal) < SAME_NORMAL
                    && (pa.normal.dot(pb.centre - pa.centre)).abs() < SAME_PLANE * scale;
                let meet = bounds[a].0.y < bounds[b].1.y && bounds[b].0.y < bounds[a].1.y;
                if same && meet {
                    let area = overlap_area(&polygons[a], &polygons[b]);
                    if area > MIN_OVERLAP * patches[ea].area().min(patches[eb].area()) {
                        covered[ea] += area;
                        covered[eb] += area;
                    }
                }
            }
            active.push(a);
        }
    }
    patches
        .iter()
        .zip(&covered)
        .map(|(p, &c)| {
            if c > 0.0 {
                let a = p.area();
                a / (a + c)
            } else {
                1.0
            }
        })
        .collect()
}

/// The patch's corners without the collapsed one of a triangle.
fn polygon(p: &Patch) -> Vec<DVec3> {
    let c = p.corners;
    if c[3] == c[2] { c[..3].to_vec() } else { c.to_vec() }
}

/// Two unit vectors spanning the plane of normal `n`.
fn tangent_frame(n: DVec3) -> (DVec3, DVec3) {
    let a = if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let u = n.cross(a).normalize();
    (u, n.cross(u))
}

/// Signed area of a 2D polygon (counter-clockwise positive).
fn signed_area(p: &[DVec2]) -> f64 {
    (0..p.len()).map(|k| p[k].perp_dot(p[(k + 1) % p.len()])).sum::<f64>() / 2.0
}

/// Area of the intersection of two convex polygons (Sutherland-Hodgman: `a` clipped by each edge
/// of `b`).
fn overlap_area(a: &[DVec2], b: &[DVec2]) -> f64 {
    let orient =
        |p: &[DVec2]| if signed_area(p) < 0.0 { p.iter().rev().copied().collect() } else { p.to_vec() };
    let (mut out, b) = (orient(a), orient(b));
    for k in 0..b.len() {
        let (p, q) = (b[k], b[(k + 1) % b.len()]);
        let side = |x: DVec2| (q - p).perp_dot(x - p);
        let input = std::mem::take(&mut out);
        for m in 0..input.len() {
            let (c, d) = (input[m], input[(m + 1) % input.len()]);
            let (sc, sd) = (side(c), side(d));
            if sc >= 0.0 {
                out.push(c);
            }
            if (sc >= 0.0) != (sd >= 0.0) {
                out.push(c + (d - c) * (sc / (sc - sd)));
            }
        }
        if out.len() < 3 {
            return 0.0;
        }
    }
    signed_area(&out).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(x0: f64, x1: f64, y0: f64, y1: f64) -> Patch {
        let p = |x, y| DVec3::new(x, y, 0.0);
        Patch::from_corners(&[p(x0, y0), p(x1, y0), p(x1, y1), p(x0, y1)])
    }

    #[test]
    fn copies_weigh_half_and_neighbours_one() {
        let w = source_weights(&[quad(0., 1., 0., 1.), quad(0., 1., 0., 1.), quad(1., 2., 0., 1.)]);
        assert!((w[0] - 0.5).abs() < 1e-12 && (w[1] - 0.5).abs() < 1e-12, "{w:?}");
        assert_eq!(w[2], 1.0, "a neighbour sharing an edge is not covered");
    }

    #[test]
    fn a_partial_overlap_counts_its_area() {
        // A quarter of the unit square is covered by a second square.
        let w = source_weights(&[quad(0., 1., 0., 1.), quad(0.5, 1.5, 0.5, 1.5)]);
        assert!((w[0] - 1.0 / 1.25).abs() < 1e-12, "{w:?}");
        // Facing the other way, or in a parallel plane, is not covering.
        let mut flipped = quad(0., 1., 0., 1.);
        flipped.corners.reverse();
        let lifted = Patch { corners: quad(0., 1., 0., 1.).corners.map(|c| c + DVec3::Z * 1e-3) };
        assert_eq!(source_weights(&[quad(0., 1., 0., 1.), flipped, lifted]), vec![1.0; 3]);
    }
}
