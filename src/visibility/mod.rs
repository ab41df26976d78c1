//! Visibility inside the kernel (VIS of eq. 2), per link, as a bit mask over pairs of visibility
//! samples: each element carries `m x m` samples at its cell centres, a link `m^4` bits (at most 256).
//! The animation update compares masks to tell when a link's visibility changed.
//!
//! Rays are skipped when nothing lies in the shaft between the two elements ([`shaft`]); when a few
//! triangles do, rays are tested against that short list only, otherwise against the [`bvh`].
//!
//! One type, [`Occluders`] (a frame's occluder triangles, the elements' samples and planes),
//! built here, its queries split by what asks: `link` (a link's mask, a group of links from one
//! element, a light link's share), `points` (segments from a point: the corner gathers), `moved`
//! (what a move changes: a static link re-checked against the moved triangles, and
//! [`MovedOccluders`]), and `batch` (many segments against a few triangles at once, with the
//! per-thread buffers they share).

mod batch;
pub mod bvh;
mod link;
mod moved;
mod points;
pub mod shaft;

pub use moved::{MovedOccluders, MovedTriangles};

use glam::DVec3;

use crate::geometry::{Aabb, Patch};
use bvh::{Bvh, Triangle};

/// Sample segments tested by [`Occluders::cast`] in this process (all threads and sessions): a
/// count for benches and frame statistics that timing noise does not blur.
static SEGMENTS_TESTED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// [`SEGMENTS_TESTED`] so far; differences of two readings count what happened in between.
pub fn segments_tested() -> u64 {
    SEGMENTS_TESTED.load(std::sync::atomic::Ordering::Relaxed)
}

/// Candidate lists longer than this go through the BVH instead.
pub(crate) const BRUTE_FORCE_CANDIDATES: usize = 24;

/// Visibility between two elements over their sample cells.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Visibility {
    /// Every sample pair sees each other (or visibility is off).
    Full,
    /// No sample pair does.
    Blocked,
    /// Bit `cell_receiver * m^2 + cell_source` set when that pair is visible.
    Partial(Box<[u64; 4]>),
}

impl Visibility {
    /// Visibility of receiver cell `r` and source cell `s`, with `cells = m^2`.
    #[inline]
    pub fn at(&self, r: usize, s: usize, cells: usize) -> f64 {
        match self {
            Visibility::Full => 1.0,
            Visibility::Blocked => 0.0,
            Visibility::Partial(bits) => {
                let i = r * cells + s;
                ((bits[i / 64] >> (i % 64)) & 1) as f64
            }
        }
    }
}

/// Sample cell (in an `m x m` grid) of the local parameter point `(s,t)`.
#[inline]
pub fn cell_of(s: f64, t: f64, m: usize) -> usize {
    let a = ((s * m as f64) as usize).min(m - 1);
    let b = ((t * m as f64) as usize).min(m - 1);
    a * m + b
}

/// Elements whose plane has the whole scene on its front side can never block a segment between
/// two scene points (such a segment stays in the closed front half-space): the walls, floor and
/// ceiling of a room. They are left out of the BVH. Elements sharing a plane are tested once.
fn on_hull(elements: &[Patch], planes: &[Option<(DVec3, f64)>], eps: f64) -> Vec<bool> {
    use rayon::prelude::*;
    use std::collections::HashMap;
    type Key = ([i64; 3], i64);
    let quantize = |(n, d): (DVec3, f64)| -> Key {
        let q = |x: f64| (x * 1e9).round() as i64;
        ([q(n.x), q(n.y), q(n.z)], (d / eps.max(1e-300) / 1e3).round() as i64)
    };
    let mut unique: HashMap<Key, (DVec3, f64)> = HashMap::new();
    for p in planes.iter().flatten() {
        unique.entry(quantize(*p)).or_insert(*p);
    }
    let keys: Vec<_> = unique.into_iter().collect();
    // A plane inside the scene has some corner behind it, most often one of the scene's extreme
    // corners: those are tried first, and only a plane with all of them in front scans every
    // corner (the scans were most of an updated frame's set-up on a 30k-triangle model).
    let corners = || elements.iter().flat_map(|p| p.corners.iter().copied());
    let extreme = least_along(corners(), |u, p| u.dot(p));
    let verdict: HashMap<Key, bool> = keys
        .par_iter()
        .map(|(k, (n, d))| {
            let in_front = |c: DVec3| n.dot(c) - d >= -eps;
            (*k, extreme.iter().all(|&c| in_front(c)) && corners().all(in_front))
        })
        .collect();
    planes.iter().map(|p| p.map(|p| verdict[&quantize(p)]).unwrap_or(false)).collect()
}

/// Directions the scans of [`on_hull`] and the culling planes try first: a cube's 6 faces, 12
/// edges and 8 corners seen from its centre.
fn probe_directions() -> impl Iterator<Item = DVec3> {
    (-1..=1)
        .flat_map(|x| {
            (-1..=1).flat_map(move |y| (-1..=1).map(move |z| DVec3::new(x as f64, y as f64, z as f64)))
        })
        .filter(|u| *u != DVec3::ZERO)
}

/// Per probe direction `u`, the item of `items` whose `key(u, item)` is least, the first of
/// equals (as `min_by`), in one pass over the items: a pass per direction, each recomputing the
/// key on both sides of every comparison, made the hull's scan most of the occluders' set-up.
fn least_along<T: Copy>(items: impl Iterator<Item = T>, key: impl Fn(DVec3, T) -> f64) -> Vec<T> {
    let directions: Vec<DVec3> = probe_directions().collect();
    let mut least: Vec<Option<(f64, T)>> = vec![None; directions.len()];
    for x in items {
        for (&u, best) in directions.iter().zip(&mut least) {
            let k = key(u, x);
            match best {
                Some((b, _)) if !k.total_cmp(b).is_lt() => {}
                _ => *best = Some((k, x)),
            }
        }
    }
    least.into_iter().flatten().map(|(_, x)| x).collect()
}

/// Per probe direction `u`, the triangle whose highest vertex along `u` is lowest: the likeliest
/// to lie wholly behind a plane facing `-u`.
fn extreme_triangles(tris: &[Triangle]) -> Vec<[DVec3; 3]> {
    let top = |u: DVec3, t: &Triangle| t.v.iter().map(|v| u.dot(*v)).fold(f64::NEG_INFINITY, f64::max);
    least_along(tris.iter(), top).into_iter().map(|t| t.v).collect()
}

/// All occluders of one frame: the triangles of every element, and each element's plane.
pub struct Occluders {
    bvh: Bvh,
    /// Per BVH triangle: `v0`, `v1 - v0`, `v2 - v0` (the edges [`bvh::segment_hits`] forms).
    edges: Vec<[DVec3; 3]>,
    /// Per BVH triangle, its plane `(n, d)` (`n . p = d`, `n` unit; zero for a degenerate
    /// triangle, which blocks nothing): for [`Occluders::crosses`], which asks it of every
    /// candidate of a corner's source.
    triangle_planes: Vec<(DVec3, f64)>,
    /// Per element: its plane when some occluder triangle lies wholly behind it (the only case
    /// in which the plane test in [`Occluders::link_visibility`] drops anything).
    culling_planes: Vec<Option<(DVec3, f64)>>,
    /// Scene size, for tolerances.
    scale: f64,
    samples_per_axis: usize,
    /// Per element, its `m x m` visibility samples ([`sample_points`]), computed once per
    /// placement instead of once per link (2% of an animation frame's time).
    samples: Vec<DVec3>,
    /// Per element, the bounds of its samples: a link's segments lie in the shaft between its
    /// two elements' sample bounds, which is narrower than the one between their patch bounds.
    sample_bounds: Vec<Aabb>,
    /// Per element: on the scene's hull, hence not an occluder.
    hull: Vec<bool>,
    /// Per element, the element whose triangles stand for it (itself, or a back's front: a
    /// back adds no triangles, and its rays skip its front's as the front's own rays do); empty
    /// when every element stands for itself.
    alias: Vec<u32>,
}

impl Occluders {
    pub fn new(elements: &[Patch], samples_per_axis: usize) -> Self {
        Self::with_aliases(elements, samples_per_axis, Vec::new())
    }

    /// [`Occluders::new`] where element `e`'s triangles are `alias[e]`'s (`alias[e] == e` for an
    /// element that stands for itself, else it adds none and skips `alias[e]`'s): the backs of
    /// open surfaces ([`crate::backs`]) share their faces' triangles.
    pub fn with_aliases(elements: &[Patch], samples_per_axis: usize, alias: Vec<u32>) -> Self {
        debug_assert!(alias.is_empty() || alias.len() == elements.len());
        let alias = if alias.iter().enumerate().all(|(e, &a)| a as usize == e) { Vec::new() } else { alias };
        let bounds = elements.iter().fold(crate::geometry::Aabb::EMPTY, |b, p| b.union(p.bounds()));
        let scale = bounds.diagonal().length().max(1e-300);
        let planes: Vec<Option<(DVec3, f64)>> = elements
            .iter()
            .map(|p| {
                (p.non_planarity() < 1e-9).then(|| {
                    let n = p.centre_normal();
                    (n, n.dot(p.point(0.5, 0.5)))
                })
            })
            .collect();
        let hull = on_hull(elements, &planes, 1e-9 * scale);
        let mut tris = Vec::with_capacity(elements.len() * 2);
        for (e, p) in elements.iter().enumerate() {
            if hull[e] || alias.get(e).is_some_and(|&a| a as usize != e) {
                continue;
            }
            for v in p.triangles() {
                tris.push(Triangle { v, element: e as u32 });
            }
        }
        let bvh = Bvh::build(tris);
        let edges: Vec<[DVec3; 3]> = bvh.triangles().iter().map(|t| triangle_edges(t.v)).collect();
        let triangle_planes = edges
            .iter()
            .map(|[v0, e1, e2]| {
                let n = e1.cross(*e2).normalize_or_zero();
                (n, n.dot(*v0))
            })
            .collect();
        let eps = 1e-9 * scale;
        let culling_planes = {
            use rayon::prelude::*;
            let tris = bvh.triangles();
            // The likeliest triangles first, as `on_hull` tries the extreme corners.
            let likely = extreme_triangles(tris);
            planes
                .par_iter()
                .map(|p| {
                    p.filter(|(n, d)| {
                        let behind = |v: &[DVec3; 3]| v.iter().all(|v| n.dot(*v) - d <= eps);
                        likely.iter().any(behind) || tris.iter().any(|t| behind(&t.v))
                    })
                })
                .collect()
        };
        let cells = samples_per_axis * samples_per_axis;
        let samples: Vec<DVec3> = elements
            .iter()
            .flat_map(|p| sample_points(p, samples_per_axis).into_iter().take(cells))
            .collect();
        let sample_bounds = samples.chunks(cells).map(Aabb::from_points).collect();
        Occluders {
            bvh,
            edges,
            triangle_planes,
            culling_planes,
            scale,
            samples_per_axis,
            samples,
            sample_bounds,
            hull,
            alias,
        }
    }

    /// The id element `e`'s own triangles carry ([`Occluders::with_aliases`]): the one a ray
    /// from or to `e` skips.
    #[inline]
    fn id(&self, e: usize) -> u32 {
        self.alias.get(e).copied().unwrap_or(e as u32)
    }

    /// [`Occluders::id`] of both ends of a segment.
    #[inline]
    fn ids(&self, (i, j): (u32, u32)) -> (u32, u32) {
        (self.id(i as usize), self.id(j as usize))
    }

    /// Whether element `e` lies on the scene's hull and so occludes nothing (its triangles are
    /// left out).
    pub fn on_hull(&self, e: usize) -> bool {
        self.hull[e]
    }

    /// Triangles that can occlude anything (elements on the scene's hull are left out).
    pub fn occluder_triangles(&self) -> usize {
        self.bvh.triangles().len()
    }

    pub fn samples_per_axis(&self) -> usize {
        self.samples_per_axis
    }

    /// Element `e`'s visibility samples; `p` is its patch, as given to [`Occluders::new`].
    #[inline]
    fn samples_of(&self, e: usize, p: &Patch) -> &[DVec3] {
        let cells = self.samples_per_axis * self.samples_per_axis;
        let x = &self.samples[e * cells..(e + 1) * cells];
        debug_assert_eq!(x[..], sample_points(p, self.samples_per_axis)[..cells], "element {e}");
        x
    }
}

/// The bounds of an element's `m x m` visibility samples (those of [`Occluders`]): every segment
/// a link traces lies in the shaft between its two elements' sample bounds, so an occluder outside
/// that shaft cannot change the link's mask (the patch bounds are wider: by a quarter of the
/// patch on each side at `m = 2`).
pub fn sample_bounds(p: &Patch, m: usize) -> Aabb {
    Aabb::from_points(&sample_points(p, m)[..m * m])
}

/// The visibility samples of an element: cell centres of an `m x m` grid (at most 16).
#[inline]
fn sample_points(p: &Patch, m: usize) -> [DVec3; 16] {
    let mut x = [DVec3::ZERO; 16];
    // Cell `c = a * m + b` at `s = (a + 1/2) / m`, `t = (b + 1/2) / m` (no integer division).
    for a in 0..m {
        for b in 0..m {
            let (s, t) = ((a as f64 + 0.5) / m as f64, (b as f64 + 0.5) / m as f64);
            x[a * m + b] = p.point(s, t);
        }
    }
    x
}

/// A triangle as the segment tests read it, `v0, v1 - v0, v2 - v0`: the edges
/// [`bvh::segment_hits`] forms, in one place so that every list of them rounds alike (and so
/// decides alike).
#[inline]
fn triangle_edges(v: [DVec3; 3]) -> [DVec3; 3] {
    [v[0], v[1] - v[0], v[2] - v[0]]
}

#[cfg(test)]
mod tests {
    use super::batch::{CandidateTriangles, Segments, segments_hit};
    use super::*;

    /// The scans that try the extreme corners and triangles first decide as the plain scans do:
    /// random triangles and quads in a box with a floor and two walls (on the hull) and faces
    /// inside it, in several orders.
    #[test]
    fn hull_and_culling_planes_as_by_the_plain_scans() {
        for round in 0..6 {
            let mut patches = vec![
                Patch::from_corners(&[DVec3::ZERO, DVec3::X * 4.0, DVec3::new(4., 4., 0.), DVec3::Y * 4.0]),
                Patch::from_corners(&[DVec3::ZERO, DVec3::Z * 4.0, DVec3::new(4., 0., 4.), DVec3::X * 4.0]),
                Patch::from_corners(&[DVec3::ZERO, DVec3::Y * 4.0, DVec3::new(0., 4., 4.), DVec3::Z * 4.0]),
            ];
            for k in 0..40 {
                let p = |j: usize| {
                    let i = 100 * round + 7 * k + j;
                    DVec3::new(grid(i, 12.9898), grid(i, 78.233), grid(i, 37.719)) * 0.9 + DVec3::splat(0.2)
                };
                let c = [p(0), p(1), p(2)];
                if (c[1] - c[0]).cross(c[2] - c[0]).length() > 1e-6 {
                    patches.push(Patch::from_corners(&c));
                }
            }
            if round % 2 == 1 {
                patches.reverse();
            }
            let occ = Occluders::new(&patches, 2);
            let eps = 1e-9 * occ.scale;
            let tris = occ.bvh.triangles();
            for (e, p) in patches.iter().enumerate() {
                let plane = (p.non_planarity() < 1e-9).then(|| {
                    let n = p.centre_normal();
                    (n, n.dot(p.point(0.5, 0.5)))
                });
                let plain_hull = plane.is_some_and(|(n, d)| {
                    patches.iter().all(|q| q.corners.iter().all(|c| n.dot(*c) - d >= -eps))
                });
                assert_eq!(occ.on_hull(e), plain_hull, "round {round}, element {e}: on the hull");
                let plain_culling =
                    plane.filter(|(n, d)| tris.iter().any(|t| t.v.iter().all(|v| n.dot(*v) - d <= eps)));
                assert_eq!(occ.culling_planes[e], plain_culling, "round {round}, element {e}: culling plane");
            }
            assert!(
                (0..patches.len()).filter(|&e| occ.on_hull(e)).count() >= 3,
                "round {round}: the box's walls"
            );
        }
    }

    /// A pseudo-random coordinate on a coarse binary grid (multiples of 1/4), so that segments
    /// run through vertices and along edges.
    fn grid(k: usize, a: f64) -> f64 {
        (((k as f64 * a).sin() * 43758.5453).fract().abs() * 4.0).floor() * 0.25
    }

    /// `count` triangles of test `round` on the grid, and their `v0, v1 - v0, v2 - v0`.
    fn grid_triangles(round: usize, count: usize) -> (Vec<bvh::Triangle>, Vec<[DVec3; 3]>) {
        let tris: Vec<bvh::Triangle> = (0..count)
            .map(|t| {
                let k = round * 97 + t * 7;
                let z = grid(k, 0.7) - 0.5;
                let v =
                    |o: usize| DVec3::new(grid(k + o, 1.1), grid(k + o, 2.3), z + 0.25 * grid(k + o, 3.7));
                bvh::Triangle { v: [v(0), v(1), v(2)], element: t as u32 }
            })
            .collect();
        let edges = tris.iter().map(|t| [t.v[0], t.v[1] - t.v[0], t.v[2] - t.v[0]]).collect();
        (tris, edges)
    }

    /// A small square sliding across the segments from a point to a far square: segments it
    /// crosses at one place and not the other are told apart; a slide that stays clear of the
    /// shaft, or that covers the same segments before and after, meets them alike.
    #[test]
    fn moved_occluders_meet_alike_only_when_each_segment_is_met_at_both_places_or_neither() {
        let p = DVec3::new;
        let square = |x: f64, y: f64, z: f64, h: f64| {
            Patch::from_corners(&[
                p(x - h, y - h, z),
                p(x + h, y - h, z),
                p(x + h, y + h, z),
                p(x - h, y + h, z),
            ])
        };
        let x = p(0.0, 0.0, 0.0);
        let source = square(0.0, 0.0, 10.0, 1.0);
        let bounds = source.bounds();
        let targets: Vec<DVec3> = [-0.5, 0.0, 0.5]
            .iter()
            .flat_map(|&a| [-0.5, 0.0, 0.5].map(|b| source.point(0.5 + 0.5 * a, 0.5 + 0.5 * b)))
            .collect();
        let alike = |from: Patch, to: Patch| {
            MovedOccluders::new([(&from, &to)].into_iter()).meet_alike(x, &bounds, &targets, 1e-9)
        };
        // Into the middle of the shaft from beside it: segments met now, not before.
        assert!(!alike(square(5.0, 0.0, 5.0, 0.3), square(0.0, 0.0, 5.0, 0.3)));
        // Far outside the shaft at both places.
        assert!(alike(square(5.0, 0.0, 5.0, 0.3), square(6.0, 0.0, 5.0, 0.3)));
        // A wide square covering every segment at both places.
        assert!(alike(square(0.0, 0.0, 5.0, 3.0), square(0.1, 0.0, 5.0, 3.0)));
        // A small square moving between segments (from the middle one to beside it).
        assert!(!alike(square(0.0, 0.0, 5.0, 0.05), square(0.07, 0.0, 5.0, 0.05)));
    }

    /// The Moeller-Trumbore vectorised over segments gives the decisions of `segment_hits` for
    /// every segment and triangle, including segments through vertices and along edges.
    #[test]
    fn segments_hit_matches_segment_hits() {
        let mut segments = Segments { n: 0, o: [[0.0; 256]; 3], d: [[0.0; 256]; 3] };
        let (mut hits, mut misses) = (0, 0);
        for round in 0..100 {
            let (tris, edges) = grid_triangles(round, 1 + round % 13);
            let cells = [1, 4, 9, 16][round % 4];
            let point = |k: usize, z: f64| DVec3::new(grid(k, 5.1), grid(k, 6.3), z);
            let from: Vec<DVec3> = (0..cells).map(|r| point(round * 31 + r, -1.0)).collect();
            let to: Vec<DVec3> = (0..cells).map(|r| point(round * 37 + r + 1000, 1.0)).collect();
            segments.set(&from, &to);
            let mut hit = vec![0u64; cells * cells];
            segments_hit(&edges, &segments, &mut hit);
            for (k, &h) in hit.iter().enumerate() {
                let (o, d) = (from[k / cells], to[k % cells] - from[k / cells]);
                let want = tris.iter().any(|t| bvh::segment_hits(t, o, d, 1e-9, 1.0 - 1e-9));
                assert_eq!(h != 0, want, "round {round} segment {k}");
                if want {
                    hits += 1;
                } else {
                    misses += 1;
                }
            }
        }
        assert!(hits > 500 && misses > 500, "{hits} hits, {misses} misses");
    }

    /// The batched Moeller-Trumbore gives the decisions of `segment_hits`, including segments
    /// through vertices and along edges (coordinates on a coarse binary grid).
    #[test]
    fn batched_segment_tests_match_segment_hits() {
        let (mut hits, mut misses) = (0, 0);
        for round in 0..200 {
            let (tris, edges) = grid_triangles(round, BRUTE_FORCE_CANDIDATES);
            let n = 1 + round % BRUTE_FORCE_CANDIDATES;
            let ids: Vec<usize> = (0..n).collect();
            let batch = CandidateTriangles::gather(&edges, &ids);
            for ray in 0..20 {
                let k = round * 31 + ray;
                let o = DVec3::new(grid(k, 5.1), grid(k, 6.3), -1.0);
                let d = DVec3::new(grid(k, 8.1), grid(k, 9.3), 1.0) - o;
                let want = tris[..n].iter().any(|t| bvh::segment_hits(t, o, d, 1e-9, 1.0 - 1e-9));
                let got = batch.any_hit(&batch.from(o), d, 1e-9, 1.0 - 1e-9);
                assert_eq!(got, want, "round {round} ray {ray}");
                if want {
                    hits += 1;
                } else {
                    misses += 1;
                }
            }
        }
        assert!(hits > 500 && misses > 500, "{hits} hits, {misses} misses");
    }

    /// The elements of a 5 x 5 Cornell box (blocks and light included) and their occluders.
    fn cornell_box_occluders() -> (Vec<Patch>, Occluders) {
        let scene = crate::scenes::cornell_box(5, crate::scene::Settings::default());
        let elements = crate::system::build_elements(&scene, 1.0, crate::basis::Basis::new(0));
        let patches: Vec<Patch> = elements.iter().map(|e| e.patch).collect();
        let occ = Occluders::new(&patches, 2);
        (patches, occ)
    }

    /// Links whose planes cull nothing take their visibility from the shaft's candidates alone,
    /// however many there are: the same masks as any-hit rays through the whole BVH (on facing
    /// pairs; a ray lying in a box face is missed by the BVH's slab test, not by the candidates).
    #[test]
    fn shaft_candidates_give_the_bvh_any_hit_masks() {
        let (patches, occ) = cornell_box_occluders();
        let (m, cells) = (2, 4);
        let (mut partial, mut blocked) = (0, 0);
        for i in 0..patches.len() {
            for j in (i + 1)..patches.len() {
                let facing = crate::kernel::assemble::may_face(&patches[i], &patches[j])
                    && crate::kernel::assemble::may_face(&patches[j], &patches[i]);
                if !facing || occ.culling_planes[i].is_some() || occ.culling_planes[j].is_some() {
                    continue;
                }
                let point =
                    |p: &Patch, c: usize| p.point(((c / m) as f64 + 0.5) / 2.0, ((c % m) as f64 + 0.5) / 2.0);
                let mut bits = [0u64; 4];
                let mut visible = 0;
                for r in 0..cells {
                    for s in 0..cells {
                        let (a, b) = (point(&patches[i], r), point(&patches[j], s));
                        if !occ.bvh.occluded(a, b - a, 1e-9, 1.0 - 1e-9, i as u32, j as u32) {
                            let k = r * cells + s;
                            bits[k / 64] |= 1 << (k % 64);
                            visible += 1;
                        }
                    }
                }
                let want = match visible {
                    16 => Visibility::Full,
                    0 => Visibility::Blocked,
                    _ => Visibility::Partial(Box::new(bits)),
                };
                partial += matches!(want, Visibility::Partial(_)) as usize;
                blocked += (want == Visibility::Blocked) as usize;
                assert_eq!(occ.link_visibility(i, &patches[i], j, &patches[j]), want, "pair {i} {j}");
            }
        }
        assert!(partial > 100 && blocked > 100, "{partial} partial, {blocked} blocked");
    }

    /// A point's segments to a source get the BVH's any-hit verdict, ray by ray, also where the
    /// source's plane culls (the light's coplanar elements, what lies behind a wall element).
    #[test]
    fn point_visibility_is_the_bvh_any_hit() {
        let (patches, occ) = cornell_box_occluders();
        let targets_of = |p: &Patch| -> Vec<DVec3> {
            (0..9).map(|k| p.point((k / 3) as f64 / 3.0 + 0.17, (k % 3) as f64 / 3.0 + 0.17)).collect()
        };
        let (mut culled, mut blocked, mut seen) = (0, 0, 0);
        for i in 0..patches.len() {
            let (x, n) = (patches[i].point(0.01, 0.01), patches[i].area_vector(0.01, 0.01).normalize());
            for (j, pj) in patches.iter().enumerate() {
                let in_front = |y: DVec3| n.dot(y - x) > 0.0 && pj.area_vector(0.5, 0.5).dot(x - y) > 0.0;
                let targets: Vec<DVec3> = targets_of(pj).into_iter().filter(|&y| in_front(y)).collect();
                if j == i || targets.is_empty() {
                    continue;
                }
                let mut got = vec![false; targets.len()];
                occ.point_visibility(x, n, (i as u32, j as u32), &pj.bounds(), &targets, &mut got);
                culled += occ.culling_planes[j].is_some() as usize;
                for (y, got) in targets.iter().zip(got) {
                    let want = !occ.bvh.occluded(x, *y - x, 1e-9, 1.0 - 1e-9, i as u32, j as u32);
                    assert_eq!(got, want, "point of {i} to {y} on {j}");
                    (blocked, seen) = (blocked + !want as usize, seen + want as usize);
                }
            }
        }
        assert!(
            culled > 500 && blocked > 1000 && seen > 10000,
            "{culled} culled, {blocked} blocked, {seen} seen"
        );
    }

    /// A group of sources gives each link the visibility it has alone.
    #[test]
    fn group_visibility_is_link_visibility() {
        let (patches, occ) = cornell_box_occluders();
        let mut partial = 0;
        for i in 0..patches.len() {
            for start in ((i + 1)..patches.len()).step_by(7) {
                let js: Vec<(usize, &Patch)> = (start..patches.len().min(start + 7))
                    .filter(|&j| {
                        crate::kernel::assemble::may_face(&patches[i], &patches[j])
                            && crate::kernel::assemble::may_face(&patches[j], &patches[i])
                    })
                    .map(|j| (j, &patches[j]))
                    .collect();
                let mut got = Vec::new();
                occ.group_visibility(i, &patches[i], &js, &mut got);
                for (&(j, pj), v) in js.iter().zip(&got) {
                    assert_eq!(*v, occ.link_visibility(i, &patches[i], j, pj), "pair {i} {j}");
                    partial += matches!(v, Visibility::Partial(_)) as usize;
                }
            }
        }
        assert!(partial > 100, "{partial} partial");
    }
}
