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
//! the split follows the detail of what casts the shadow, no finer. Emitters neither split nor
//! are split (their light falls smoothly, and the gather casts its own rays to them).
//!
//! Faces of one object split each other only at a crease ([`Setup::crease`]): where each has a
//! corner in front of the other's plane by more than `sin(`[`CREASE_ANGLE`]`)` of its distance (a
//! wall standing on a platform, eaves over a wall, two walls facing each other across a
//! courtyard). A mesh's smooth, coplanar or convex neighbours touch it along every edge and are
//! no crease: splitting there buys nothing and costs a lot. On the decimated monastery (faces of
//! 5 m^2 at the median, up to 620 m^2), one quadratic per face could not follow the contact
//! shadow and the inter-reflection where its large faces meet (docs/validation-real.md, "The
//! monastery"), and neither rule above reached them. A crease split has no [`FINEST`] limit (the
//! other face is as large as this one); it stops at [`MAX_DEPTH`] or at parts smaller than
//! [`CREASE_FINEST`] of the scene's size, which keeps the small creases of a bunny or a teddy
//! whole. `tests/crease_split.rs` is its differential test.
//!
//! The elements added are bounded ([`MAX_ADDED`] times the faces, at least [`MIN_BUDGET`]). The
//! flat path ([`plan_with_creases`]) splits from one queue, crease parts before contact parts and
//! the largest first, until the budget is spent: where both fit, the contact parts are those of
//! [`plan`], and on the monastery the creases take the budget that the contact split spent on the
//! ground under the buildings (where it bought nothing while every face was one-sided). A scene
//! whose open surfaces have backs ([`crate::backs`]) gives contact parts a budget of their own as
//! large: the undersides of sheets see the contact shadows under them, and with the monastery's
//! ground whole its error against Cycles was 9.6%, split 1.99% (docs/validation-real.md,
//! "Backs"). The hierarchy splits by contacts alone
//! ([`plan`], which drops its deepest level everywhere past the budget). Objects with keys neither
//! split nor are split, so a build at any frame splits alike; the split is kept over an animation
//! ([`parts_of`]; a deforming mesh keeps its first frame's): a part moves with its face.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

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

/// Two faces meet at a crease when each has a corner in front of the other's plane by more
/// than the sine of this angle (degrees) times its distance: a concave angle sharper than
/// 180 - 30 degrees, or two faces that face each other across a gap.
const CREASE_ANGLE: f64 = 30.0;

/// A crease does not split a part whose bounding radius is below this fraction of the
/// diagonal of the scene's bounding box.
const CREASE_FINEST: f64 = 0.04;

/// Per face element (one per face, in [`crate::system::build_elements`] order), the parts of
/// its parameter domain the contact split alone makes (`[Rect::UNIT]` where nothing comes
/// close): the hierarchy's split ahead of linking (`hierarchy::Tree::split_for_contacts`).
pub fn plan(scene: &Scene, faces: &[Element]) -> Vec<Vec<Rect>> {
    Setup::new(scene, faces).contacts(faces, budget(faces.len()))
}

/// The flat path's parts: [`plan`]'s, and parts split where faces of one object meet at a
/// concave crease or face each other close by ([`Setup::crease`], no [`FINEST`] limit), from
/// one queue: crease parts first, then contact parts, each the largest first, within one budget,
/// or within one each when `faces` hold backs ([`crate::backs`]). Where everything fits, the
/// contact parts are [`plan`]'s.
pub fn plan_with_creases(scene: &Scene, faces: &[Element]) -> Vec<Vec<Rect>> {
    let per_kind = faces.iter().any(|f| f.back);
    Setup::new(scene, faces).split_largest_first(faces, budget(faces.len()), per_kind)
}

fn budget(faces: usize) -> usize {
    (MAX_ADDED * faces as f64).max(MIN_BUDGET as f64) as usize
}

/// What the splits need: which faces may split, and the triangles that split them.
struct Setup {
    /// Faces that neither split nor are split (emitters, keyed objects, the hull with Blender
    /// lights or a World).
    fixed: Vec<bool>,
    bvh: Bvh,
    /// Per BVH node, the object of all its triangles ([`crate::visibility::bvh::MIXED`]: of
    /// several): [`Setup::near`] looks only at other objects' triangles.
    node_objects: Vec<u32>,
    /// Per BVH triangle, its size ([`triangle_radius`]) and front normal.
    sizes: Vec<f64>,
    normals: Vec<DVec3>,
    /// Per face, its object.
    object: Vec<u32>,
    /// The smallest bounding radius of a part a crease splits ([`CREASE_FINEST`]).
    finest: f64,
}

impl Setup {
    fn new(scene: &Scene, faces: &[Element]) -> Setup {
        // An emitter's light falls smoothly (the gather casts its own rays to it), and its own
        // radiosity is its emission: emitters neither split nor are split.
        let emits: Vec<bool> =
            faces.iter().map(|f| scene.may_emit(f.object as usize, f.face as usize, f.material)).collect();
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
            // (A back's triangles are its front's: crate::backs.)
            if emits[e] || keyed[e] || f.back {
                continue;
            }
            for v in f.patch.triangles() {
                tris.push(Triangle { v, element: e as u32 });
            }
        }
        let bvh = Bvh::build(tris);
        let sizes: Vec<f64> = bvh.triangles().iter().map(|t| triangle_radius(&t.v)).collect();
        let normals: Vec<DVec3> = bvh
            .triangles()
            .iter()
            .map(|t| (t.v[1] - t.v[0]).cross(t.v[2] - t.v[0]).normalize_or_zero())
            .collect();
        let object: Vec<u32> = faces.iter().map(|f| f.object).collect();
        let scene_box = faces.iter().fold(Aabb::EMPTY, |b, f| b.union(f.patch.bounds()));
        let finest = if faces.is_empty() { 0.0 } else { CREASE_FINEST * scene_box.diagonal().length() };
        let fixed = (0..faces.len()).map(|e| emits[e] || keyed[e] || hull[e]).collect();
        let node_objects = bvh.node_tags(|t| object[t.element as usize]);
        Setup { fixed, bvh, node_objects, sizes, normals, object, finest }
    }

    /// The contact split alone: each face's parts, at most `budget` added (the deepest level
    /// dropped everywhere until they fit).
    fn contacts(&self, faces: &[Element], budget: usize) -> Vec<Vec<Rect>> {
        let mut depth = MAX_DEPTH;
        loop {
            let parts: Vec<Vec<Rect>> = faces
                .par_iter()
                .enumerate()
                .map(|(e, face)| {
                    if self.fixed[e] {
                        return vec![Rect::UNIT];
                    }
                    let mut out = Vec::new();
                    self.split(e, &face.patch, Rect::UNIT, depth, &mut out);
                    out
                })
                .collect();
            let added: usize = parts.iter().map(|p| p.len() - 1).sum();
            if added <= budget || depth == 0 {
                return parts;
            }
            depth -= 1;
        }
    }

    /// Faces split from whole while [`Setup::wants_split`] says so, crease parts before contact
    /// parts and the largest first, until `budget` elements are added (by each kind when
    /// `per_kind`).
    fn split_largest_first(&self, faces: &[Element], budget: usize, per_kind: bool) -> Vec<Vec<Rect>> {
        let candidate = |e: usize, r: Rect| {
            self.wants_split(faces, e, &r)
                .map(|crease| Candidate(crease, faces[e].patch.sub_patch(&r).area(), e, r))
        };
        let mut heap: BinaryHeap<Candidate> = (0..faces.len())
            .into_par_iter()
            .filter(|&e| !self.fixed[e])
            .filter_map(|e| candidate(e, Rect::UNIT))
            .collect();
        let mut parts = vec![vec![Rect::UNIT]; faces.len()];
        // Elements added by contact parts and by crease parts (all in the first without `per_kind`).
        let mut added = [0; 2];
        while let Some(Candidate(crease, _, e, rect)) = heap.pop() {
            let kind = (crease && per_kind) as usize;
            if added[kind] + 3 > budget {
                if !per_kind || added[1 - kind] + 3 > budget {
                    break;
                }
                continue;
            }
            let at = parts[e].iter().position(|r| *r == rect).expect("a candidate is a part");
            let quadrants = rect.quadrants();
            parts[e].splice(at..=at, quadrants);
            added[kind] += 3;
            heap.extend(quadrants.into_par_iter().filter_map(|q| candidate(e, q)).collect::<Vec<_>>());
        }
        parts
    }

    /// Whether part `rect` of face `e` is split, and whether for a crease: it meets another face
    /// at a crease ([`Setup::crease`]), or another object's triangle comes close ([`Setup::near`]).
    fn wants_split(&self, faces: &[Element], e: usize, rect: &Rect) -> Option<bool> {
        if depth_of(rect) >= MAX_DEPTH {
            return None;
        }
        let sub = faces[e].patch.sub_patch(rect);
        let (centre, radius) = sub.bounding_sphere();
        if self.crease(e, &sub, centre, radius) {
            Some(true)
        } else if self.near(e, &sub, centre, radius) {
            Some(false)
        } else {
            None
        }
    }

    /// Whether part `sub` (centre, radius) of face `e`, larger than `finest`, meets the triangle
    /// of another face of its own object (another object's come under [`Setup::near`]) within
    /// `(1 + NEAR) radius` of its centre at a crease: a corner of the triangle lies in front of
    /// the part's plane by more than `sin(CREASE_ANGLE)` of its distance from the centre, and a
    /// corner or the centre of the part in front of the triangle's plane by more than as much of
    /// its distance from the triangle. Coplanar and convex neighbours are neither.
    fn crease(&self, e: usize, sub: &Patch, centre: DVec3, radius: f64) -> bool {
        if radius <= self.finest {
            return false;
        }
        let reach = (1.0 + NEAR) * radius;
        let query = Aabb { min: centre - DVec3::splat(reach), max: centre + DVec3::splat(reach) };
        let normal = sub.centre_normal();
        let sine = CREASE_ANGLE.to_radians().sin();
        let points = [sub.corners[0], sub.corners[1], sub.corners[2], sub.corners[3], centre];
        let mut found = false;
        self.bvh.for_each_overlapping(&query, |k| {
            if found {
                return;
            }
            let t = &self.bvh.triangles()[k];
            let f = t.element as usize;
            if f == e || self.object[f] != self.object[e] {
                return;
            }
            let faces_part = t.v.iter().any(|v| {
                let h = normal.dot(*v - centre);
                h > 1e-9 * radius && h > sine * v.distance(centre)
            });
            if !faces_part || point_triangle_distance(centre, &t.v) >= reach {
                return;
            }
            let n = self.normals[k];
            found = points.iter().any(|p| {
                let h = n.dot(*p - t.v[0]);
                h > 1e-9 * radius && h > sine * point_triangle_distance(*p, &t.v)
            });
        });
        found
    }

    /// Splits `rect` of face `e` (patch `patch`) while another object's triangle comes close,
    /// `depth` more times at most, pushing the parts kept to `out`.
    fn split(&self, e: usize, patch: &Patch, rect: Rect, depth: u32, out: &mut Vec<Rect>) {
        let sub = patch.sub_patch(&rect);
        let (centre, radius) = sub.bounding_sphere();
        if depth == 0 || !self.near(e, &sub, centre, radius) {
            out.push(rect);
            return;
        }
        for q in rect.quadrants() {
            self.split(e, patch, q, depth - 1, out);
        }
    }

    /// Whether a triangle of another object than face `e`'s lies in front of `sub` (centre,
    /// radius) within `(1 + NEAR) radius` of its centre and is smaller than `radius / FINEST`.
    fn near(&self, e: usize, sub: &Patch, centre: DVec3, radius: f64) -> bool {
        let reach = (1.0 + NEAR) * radius;
        let query = Aabb { min: centre - DVec3::splat(reach), max: centre + DVec3::splat(reach) };
        let normal = sub.centre_normal();
        // The walk skips the subtrees of the part's own object and stops at the first triangle
        // found: a face of a large model overlaps many of its own model's triangles (the full
        // monastery's contact split took 1.9 s, and takes 0.19 s so).
        let mut found = false;
        self.bvh.for_each_overlapping_except(&query, &self.node_objects, self.object[e], |k| {
            let t = &self.bvh.triangles()[k];
            if self.object[t.element as usize] == self.object[e] || FINEST * self.sizes[k] >= radius {
                return false;
            }
            let in_front = t.v.iter().any(|v| normal.dot(*v - centre) > 1e-9 * radius);
            found = in_front && point_triangle_distance(centre, &t.v) < reach;
            found
        });
        found
    }
}

/// The splits below a face that made `rect`.
fn depth_of(rect: &Rect) -> u32 {
    (1.0 / (rect.s1 - rect.s0)).log2().round() as u32
}

/// A part to split: whether at a crease (those first), its area (the largest first), its face
/// and domain (ties in face order, then the lower corner first).
struct Candidate(bool, f64, usize, Rect);

impl PartialEq for Candidate {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Candidate {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0
            .cmp(&other.0)
            .then_with(|| self.1.total_cmp(&other.1))
            .then_with(|| other.2.cmp(&self.2))
            .then_with(|| other.3.s0.total_cmp(&self.3.s0))
            .then_with(|| other.3.t0.total_cmp(&self.3.t0))
    }
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
        let key = (face.object, face.face, face.back);
        let start = previous.partition_point(|p| (p.object, p.face, p.back) < key);
        let before = &previous[start..];
        for rect in rects {
            let patch = face.patch.sub_patch(rect);
            let kept = before
                .iter()
                .take_while(|p| (p.object, p.face, p.back) == key)
                .find(|p| p.domain == *rect && p.patch == patch && p.material == face.material);
            match kept.filter(|p| p.moments.len() == basis.len()) {
                Some(p) => out.push(p.clone()),
                None => {
                    let mut el = element(face.object, face.face, *rect, patch, face.material, basis, &rule);
                    el.mirrored = face.mirrored;
                    el.back = face.back;
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
            let key = (f.object, f.face, f.back);
            let start = elements.partition_point(|p| (p.object, p.face, p.back) < key);
            let parts: Vec<Rect> = elements[start..]
                .iter()
                .take_while(|p| (p.object, p.face, p.back) == key)
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
