//! Faces split into elements where another object comes close (issue 19).
//!
//! A face's polynomial (eq. 3) cannot follow the contact shadow of an object standing on it: a
//! 0.25 m ground quad half under a bunny is fitted by a quadratic that is too bright next to the
//! bunny and negative under it. The corner gather reads the bunny's lower corners from that
//! polynomial, which made most of the bunny's error against Cycles (measured with
//! `examples/corner_truth.rs`: the brute-force irradiance from the solved polynomials was 6.6%
//! from Cycles per corner, and 3.5% once the hits on the ground within 0.2 m took `B` gathered
//! at the hit point instead of the ground's polynomial; hits on the bunny itself, 6.4%). Split
//! uniformly 4 x 4 and 8 x 8, the ground brought the bunny to 3.7% and 3.4% from 5.2%.
//!
//! So before linking, the flat path splits a face into quadrants (`Rect`s of its parameter
//! domain, each a bilinear patch: every kernel sees only patches) where a triangle of another
//! object lies in front of it within [`NEAR`] radii of the part's sphere, while the part is
//! larger than [`FINEST`] times that triangle (its corners' largest distance from its centroid):
//! the split follows the detail of what casts the shadow, no finer. Faces of one object do not
//! split each other (a mesh's own neighbours touch it along every edge), and emitters neither
//! split nor are split (their light falls smoothly, and the gather casts its own rays to them).
//! The elements added are bounded ([`MAX_ADDED`] times the faces, at least [`MIN_BUDGET`]):
//! past it the deepest level is dropped everywhere. Objects with keys neither split nor are
//! split, so a build at any frame splits alike; the split is kept over an animation
//! ([`parts_of`]; a deforming mesh keeps its first frame's): a part moves with its face.

use glam::DVec3;
use rayon::prelude::*;

use crate::basis::Basis;
use crate::geometry::{Aabb, Patch, Rect};
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::system::{Element, element};
use crate::visibility::bvh::{Bvh, Triangle};

/// A triangle within this many bounding radii of a part's sphere (measured from its centre:
/// `(1 + NEAR) r`) splits it.
const NEAR: f64 = 2.0;

/// A part is not split below this times the shortest edge of the nearest such triangle.
const FINEST: f64 = 2.0;

/// Splits below a face, at most.
const MAX_DEPTH: u32 = 6;

/// Elements added, at most, as a fraction of the faces (or [`MIN_BUDGET`] in a small scene).
const MAX_ADDED: f64 = 1.0;
const MIN_BUDGET: usize = 1024;

/// Per face element (one per face, in [`crate::system::build_elements`] order), the parts of
/// its parameter domain it is split into (`[Rect::UNIT]` where nothing comes close).
pub fn plan(scene: &Scene, faces: &[Element]) -> Vec<Vec<Rect>> {
    // An emitter's light falls smoothly (the gather casts its own rays to it), and its own
    // radiosity is its emission: emitters neither split nor are split.
    let emits: Vec<bool> = faces.iter().map(|f| emits_at_some_frame(scene, f)).collect();
    // Only objects without keys split or are split: a fresh build at any frame then splits as
    // the first one did, which the animation keeps (`parts_of`), so both have the same elements.
    let keyed: Vec<bool> = faces.iter().map(|f| scene.objects[f.object as usize].is_animated()).collect();
    // With Blender lights or a World, the scene's hull (a room's walls, a ground plane) is not
    // split: their shadow rays (crate::lights, the hull included as a caster: a sun shines in
    // from outside) meet it at T-junctions between parts of different sizes, where a ray through
    // a vertex can slip between the triangles (a closed box let 0.03% of the World's light reach
    // a floor inside, tests/lights.rs). Emitting faces' rays never test the hull.
    let hull: Vec<bool> = if scene.lights.is_empty() && scene.world.is_none() {
        vec![false; faces.len()]
    } else {
        let patches: Vec<Patch> = faces.iter().map(|f| f.patch).collect();
        let occluders = crate::visibility::Occluders::new(&patches, 1);
        (0..faces.len()).map(|e| occluders.on_hull(e)).collect()
    };
    let mut tris = Vec::with_capacity(faces.len() * 2);
    for (e, f) in faces.iter().enumerate() {
        if emits[e] || keyed[e] {
            continue;
        }
        for v in f.patch.triangles() {
            tris.push(Triangle { v, element: e as u32 });
        }
    }
    let bvh = Bvh::build(tris);
    let sizes: Vec<f64> = bvh.triangles().iter().map(|t| triangle_radius(&t.v)).collect();
    let object: Vec<u32> = faces.iter().map(|f| f.object).collect();
    let mut depth = MAX_DEPTH;
    loop {
        let parts: Vec<Vec<Rect>> = faces
            .par_iter()
            .enumerate()
            .map(|(e, face)| {
                if emits[e] || keyed[e] || hull[e] {
                    return vec![Rect::UNIT];
                }
                let mut out = Vec::new();
                split(&bvh, &sizes, &object, e, &face.patch, Rect::UNIT, depth, &mut out);
                out
            })
            .collect();
        let added: usize = parts.iter().map(|p| p.len() - 1).sum();
        let budget = (MAX_ADDED * faces.len() as f64).max(MIN_BUDGET as f64);
        if added as f64 <= budget || depth == 0 {
            return parts;
        }
        depth -= 1;
    }
}

/// Splits `rect` of face `e` (patch `patch`) while another object's triangle comes close,
/// `depth` more times at most, pushing the parts kept to `out`.
#[allow(clippy::too_many_arguments)]
fn split(
    bvh: &Bvh,
    sizes: &[f64],
    object: &[u32],
    e: usize,
    patch: &Patch,
    rect: Rect,
    depth: u32,
    out: &mut Vec<Rect>,
) {
    let sub = patch.sub_patch(&rect);
    let (centre, radius) = sub.bounding_sphere();
    if depth == 0 || !near(bvh, sizes, object, e, &sub, centre, radius) {
        out.push(rect);
        return;
    }
    for q in rect.quadrants() {
        split(bvh, sizes, object, e, patch, q, depth - 1, out);
    }
}

/// Whether a triangle of another object than face `e`'s (`object`, per face) lies in front of
/// `sub` (centre, radius) within `(1 + NEAR) radius` of its centre and is smaller than
/// `radius / FINEST`.
fn near(bvh: &Bvh, sizes: &[f64], object: &[u32], e: usize, sub: &Patch, centre: DVec3, radius: f64) -> bool {
    let reach = (1.0 + NEAR) * radius;
    let query = Aabb { min: centre - DVec3::splat(reach), max: centre + DVec3::splat(reach) };
    let normal = sub.centre_normal();
    let mut found = false;
    bvh.for_each_overlapping(&query, |k| {
        if found {
            return;
        }
        let t = &bvh.triangles()[k];
        if object[t.element as usize] == object[e] || FINEST * sizes[k] >= radius {
            return;
        }
        let in_front = t.v.iter().any(|v| normal.dot(*v - centre) > 1e-9 * radius);
        found = in_front && point_triangle_distance(centre, &t.v) < reach;
    });
    found
}

/// Whether face element `f` emits at its material's base or at any of its keys (not only at the
/// frame built: the split must not change when a keyed light comes on).
fn emits_at_some_frame(scene: &Scene, f: &Element) -> bool {
    let m = f.material as usize;
    let scale = scene.emission_scale(f.object as usize, f.face as usize);
    let lit = |e: [f64; 3]| e.iter().zip(scale).any(|(&x, s)| x * s > 0.0);
    lit(scene.materials[m].emission) || scene.emission_keys[m].iter().any(|k| lit(k.emission))
}

/// A triangle's size: the largest distance from its centroid to a corner (a sliver's shortest
/// edge says nothing of the shadow it casts).
fn triangle_radius(v: &[DVec3; 3]) -> f64 {
    let c = (v[0] + v[1] + v[2]) / 3.0;
    v.iter().map(|p| p.distance(c)).fold(0.0, f64::max)
}

/// Distance from `p` to the triangle `v` (Ericson, Real-Time Collision Detection, 5.1.5).
pub fn point_triangle_distance(p: DVec3, v: &[DVec3; 3]) -> f64 {
    let (a, b, c) = (v[0], v[1], v[2]);
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return p.distance(a);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return p.distance(b);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return p.distance(a + ab * (d1 / (d1 - d3)));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return p.distance(c);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return p.distance(a + ac * (d2 / (d2 - d6)));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return p.distance(b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))));
    }
    let denom = 1.0 / (va + vb + vc);
    p.distance(a + ab * (vb * denom) + ac * (vc * denom))
}

/// The elements of `faces` split as `parts` says (each face's parts in order, the face's own
/// element where it has one part), reusing from `previous` (elements of another frame, sorted by
/// face) each part whose patch did not change.
pub fn split_faces(
    faces: Vec<Element>,
    parts: &[Vec<Rect>],
    basis: Basis,
    previous: &[Element],
) -> Vec<Element> {
    let rule = GaussLegendre::new(4);
    let mut out = Vec::with_capacity(parts.iter().map(Vec::len).sum());
    for (face, rects) in faces.into_iter().zip(parts) {
        if rects.len() == 1 && rects[0] == Rect::UNIT {
            out.push(face);
            continue;
        }
        let start = previous.partition_point(|p| (p.object, p.face) < (face.object, face.face));
        let before = &previous[start..];
        for rect in rects {
            let patch = face.patch.sub_patch(rect);
            let kept = before
                .iter()
                .take_while(|p| (p.object, p.face) == (face.object, face.face))
                .find(|p| p.domain == *rect && p.patch == patch && p.material == face.material);
            match kept.filter(|p| p.moments.len() == basis.len()) {
                Some(p) => out.push(p.clone()),
                None => {
                    let mut el = element(face.object, face.face, *rect, patch, face.material, basis, &rule);
                    el.mirrored = face.mirrored;
                    out.push(el);
                }
            }
        }
    }
    out
}

/// Each face's parts as `elements` (sorted by face, as [`split_faces`] makes them) hold them,
/// for the faces of `faces`: a face `elements` does not hold keeps one part.
pub fn parts_of(faces: &[Element], elements: &[Element]) -> Vec<Vec<Rect>> {
    faces
        .iter()
        .map(|f| {
            let start = elements.partition_point(|p| (p.object, p.face) < (f.object, f.face));
            let parts: Vec<Rect> = elements[start..]
                .iter()
                .take_while(|p| (p.object, p.face) == (f.object, f.face))
                .map(|p| p.domain)
                .collect();
            if parts.is_empty() { vec![Rect::UNIT] } else { parts }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed form against points sampled on the triangle (the minimum over a dense grid).
    #[test]
    fn point_triangle_distance_is_the_nearest_point() {
        let v = [DVec3::new(0.0, 0.0, 0.0), DVec3::new(2.0, 0.1, 0.0), DVec3::new(0.3, 1.5, 0.4)];
        let mut state = 7u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 6.0 - 3.0
        };
        for _ in 0..200 {
            let p = DVec3::new(next(), next(), next());
            let n = 300;
            let mut best = f64::INFINITY;
            for a in 0..=n {
                for b in 0..=(n - a) {
                    let (u, w) = (a as f64 / n as f64, b as f64 / n as f64);
                    best = best.min(p.distance(v[0] + (v[1] - v[0]) * u + (v[2] - v[0]) * w));
                }
            }
            let d = point_triangle_distance(p, &v);
            assert!(d <= best + 1e-12 && best - d < 1e-2, "{p}: {d} against {best}");
        }
    }
}
