//! Visibility inside the kernel (VIS of eq. 2), per link, as a bit mask over pairs of visibility
//! samples: each element carries `m x m` samples at its cell centres, a link `m^4` bits (at most 256).
//! The animation update compares masks to tell when a link's visibility changed.
//!
//! Rays are skipped when nothing lies in the shaft between the two elements ([`shaft`]); when a few
//! triangles do, rays are tested against that short list only, otherwise against the [`bvh`].

pub mod bvh;
mod points;
pub mod shaft;

use glam::DVec3;

use crate::geometry::{Aabb, Patch};
use bvh::{Bvh, Triangle};
use shaft::Shaft;

/// Sample segments tested by [`Occluders::cast`] in this process (all threads and sessions): a
/// count for benches and frame statistics that timing noise does not blur.
static SEGMENTS_TESTED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// [`SEGMENTS_TESTED`] so far; differences of two readings count what happened in between.
pub fn segments_tested() -> u64 {
    SEGMENTS_TESTED.load(std::sync::atomic::Ordering::Relaxed)
}

/// Candidate lists longer than this go through the BVH instead.
pub(crate) const BRUTE_FORCE_CANDIDATES: usize = 24;

/// Segments [`Occluders::share_visible`] tests at most.
const SHARE_SEGMENTS: usize = 4;

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
    let verdict: HashMap<Key, bool> = keys
        .par_iter()
        .map(|(k, (n, d))| (*k, elements.iter().all(|p| p.corners.iter().all(|c| n.dot(*c) - d >= -eps))))
        .collect();
    planes.iter().map(|p| p.map(|p| verdict[&quantize(p)]).unwrap_or(false)).collect()
}

/// All occluders of one frame: the triangles of every element, and each element's plane.
pub struct Occluders {
    bvh: Bvh,
    /// Per BVH triangle: `v0`, `v1 - v0`, `v2 - v0` (the edges [`bvh::segment_hits`] forms).
    edges: Vec<[DVec3; 3]>,
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
        let edges = bvh.triangles().iter().map(|t| triangle_edges(t.v)).collect();
        let eps = 1e-9 * scale;
        let culling_planes = {
            use rayon::prelude::*;
            let tris = bvh.triangles();
            planes
                .par_iter()
                .map(|p| p.filter(|(n, d)| tris.iter().any(|t| t.v.iter().all(|v| n.dot(*v) - d <= eps))))
                .collect()
        };
        let cells = samples_per_axis * samples_per_axis;
        let samples: Vec<DVec3> = elements
            .iter()
            .flat_map(|p| sample_points(p, samples_per_axis).into_iter().take(cells))
            .collect();
        let sample_bounds = samples.chunks(cells).map(Aabb::from_points).collect();
        Occluders { bvh, edges, culling_planes, scale, samples_per_axis, samples, sample_bounds, hull, alias }
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
    fn samples_of(&self, e: usize, p: &Patch) -> &[DVec3] {
        let cells = self.samples_per_axis * self.samples_per_axis;
        let x = &self.samples[e * cells..(e + 1) * cells];
        debug_assert_eq!(x[..], sample_points(p, self.samples_per_axis)[..cells], "element {e}");
        x
    }

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

    /// Visibility between elements `i` and `j`; also returns whether any ray was needed.
    pub fn link_visibility(&self, i: usize, pi: &Patch, j: usize, pj: &Patch) -> Visibility {
        let shaft = Shaft::new(&self.sample_bounds[i], &self.sample_bounds[j]);
        let (culling, count) = self.culling_pair(i, j);
        CANDIDATES.with_borrow_mut(|candidates| {
            // Segments between the fronts of two planar elements stay in front of both planes.
            shaft_candidates(self, &shaft, &culling[..count], self.ids((i as u32, j as u32)), candidates);
            if candidates.is_empty() {
                return Visibility::Full;
            }
            // Without plane culling the candidates are every triangle the shaft may hold, so
            // testing them all gives what the BVH's any-hit gives, however many there are.
            self.cast(i, pi, j, pj, candidates, count == 0)
        })
    }

    /// The culling planes of elements `i` and `j` that exist, packed, and how many.
    fn culling_pair(&self, i: usize, j: usize) -> ([(DVec3, f64); 2], usize) {
        let mut culling = [(DVec3::ZERO, 0.0); 2];
        let mut count = 0;
        for p in [self.culling_planes[i], self.culling_planes[j]].into_iter().flatten() {
            culling[count] = p;
            count += 1;
        }
        (culling, count)
    }

    /// [`Occluders::link_visibility`] between parts of elements: `pi` lies on element `i`
    /// (a sub-rectangle, or the whole) and `pj` on `j`. The masks are over `pi`'s and `pj`'s own
    /// sample cells; the two elements' triangles are skipped and their planes cull, as for
    /// whole elements (a part of a planar element lies in its plane).
    pub fn part_visibility(&self, i: usize, pi: &Patch, j: usize, pj: &Patch) -> Visibility {
        let m = self.samples_per_axis;
        let (xi, xj) = (sample_points(pi, m), sample_points(pj, m));
        let (xi, xj) = (&xi[..m * m], &xj[..m * m]);
        let shaft = Shaft::new(&Aabb::from_points(xi), &Aabb::from_points(xj));
        let (culling, count) = self.culling_pair(i, j);
        CANDIDATES.with_borrow_mut(|candidates| {
            shaft_candidates(self, &shaft, &culling[..count], self.ids((i as u32, j as u32)), candidates);
            if candidates.is_empty() {
                return Visibility::Full;
            }
            self.cast_between(i, xi, j, xj, candidates, count == 0)
        })
    }

    /// How many of up to [`SHARE_SEGMENTS`] segments between parts of elements (`pi` on element
    /// `i`, `pj` on `j`) arrive unobstructed, and how many were tested: a light link's
    /// visibility, one share for the whole pair. The segments join the centres of the two parts'
    /// `2 x 2` cells, crossed first (cell `k` to cell `3 - k`, so that they span both parts), and
    /// only those whose ends face each other count: the kernel is zero along the others, and a
    /// facing segment lies in front of both planes, so plain any-hit rays give what the culled
    /// masks of [`Occluders::part_visibility`] give. `None` when no pair of cell centres faces
    /// (parts that see each other obliquely, or only in part): [`Occluders::masked_share`] then
    /// decides, at several times the cost.
    /// `ni` and `nj` are the parts' [`Patch::centre_normal`]s.
    pub fn share_visible(
        &self,
        (i, pi, ni): (usize, &Patch, DVec3),
        (j, pj, nj): (usize, &Patch, DVec3),
    ) -> Option<(usize, usize)> {
        let (xi, xj) = (sample_points(pi, 2), sample_points(pj, 2));
        let (mut origins, mut dirs) = ([DVec3::ZERO; SHARE_SEGMENTS], [DVec3::ZERO; SHARE_SEGMENTS]);
        let mut tested = 0;
        'pairs: for shift in [3, 0, 1, 2] {
            for k in 0..4 {
                let (x, y) = (xi[k], xj[k ^ shift]);
                let d = y - x;
                if ni.dot(d) <= 0.0 || nj.dot(d) >= 0.0 {
                    continue;
                }
                (origins[tested], dirs[tested]) = (x, d);
                tested += 1;
                if tested == SHARE_SEGMENTS {
                    break 'pairs;
                }
            }
        }
        SEGMENTS_TESTED.fetch_add(tested as u64, std::sync::atomic::Ordering::Relaxed);
        if tested == 0 {
            return None;
        }
        let mut blocked = [false; SHARE_SEGMENTS];
        let (o, d, b) = (&origins[..tested], &dirs[..tested], &mut blocked[..tested]);
        let (i, j) = self.ids((i as u32, j as u32));
        self.bvh.occluded_packet(o, d, 1e-9, 1.0 - 1e-9, i, j, b);
        Some((b.iter().filter(|&&x| !x).count(), tested))
    }

    /// The share of the cell pairs of [`Occluders::part_visibility`]'s mask that arrive, as
    /// `(arrived, of)`: a light link's visibility where [`Occluders::share_visible`] has no
    /// facing segment to test.
    pub fn masked_share(&self, i: usize, pi: &Patch, j: usize, pj: &Patch) -> (usize, usize) {
        let cells = self.samples_per_axis * self.samples_per_axis;
        match self.part_visibility(i, pi, j, pj) {
            Visibility::Full => (1, 1),
            Visibility::Blocked => (0, 1),
            Visibility::Partial(bits) => (bits.iter().map(|b| b.count_ones() as usize).sum(), cells * cells),
        }
    }

    /// Whether element `e`'s plane culls occluders in [`Occluders::link_visibility`] (some
    /// occluder lies wholly behind it). Links between elements that cull nothing have the masks
    /// of plain any-hit rays against every occluder but their own two elements.
    pub fn culls(&self, e: usize) -> bool {
        self.culling_planes[e].is_some()
    }

    /// [`Occluders::link_visibility`] of a link whose elements `i` and `j` did not move, from its
    /// visibility `old` in the previous frame, when only the elements of `moved` moved: a segment
    /// between two fixed samples changes its verdict only through the moved triangles. A segment
    /// visible before is blocked now iff it hits a moved triangle at its new position; one blocked
    /// before stays blocked if it hits a moved triangle now, or if it missed them all before (then
    /// a fixed occluder blocked it). `None` when a segment was blocked only by the movers' old
    /// positions (whether a fixed occluder blocks it too needs the whole traversal), or when
    /// too many moved triangles lie in the shaft for one batch.
    ///
    /// Requires that neither element culls (see [`Occluders::culls`]) in this frame or the
    /// previous one, so that both frames' masks are any-hit masks over all occluders.
    pub fn relink_visibility(
        &self,
        (i, pi): (usize, &Patch),
        (j, pj): (usize, &Patch),
        old: &Visibility,
        moved: &MovedTriangles,
    ) -> Option<Visibility> {
        let shaft = Shaft::new(&self.sample_bounds[i], &self.sample_bounds[j]);
        let eps = 1e-9 * self.scale;
        SCRATCH.with_borrow_mut(|scratch| {
            let Scratch { masks, was, now, segments, hit, hit_was } = scratch;
            // Only the moved triangles the shaft may hold can meet a segment of the link: those
            // whose three vertices are not all outside one test of `Shaft::may_contain_triangle`.
            masks.resize(moved.x.len(), 0);
            shaft.outside_masks([&moved.x, &moved.y, &moved.z], eps, masks);
            let in_shaft =
                |list: &[([DVec3; 3], [DVec3; 3])], index: &[[u32; 3]], tris: &mut Vec<[DVec3; 3]>| {
                    tris.clear();
                    let mut bounds = Aabb::EMPTY;
                    for ((e, v), [a, b, c]) in list.iter().zip(index) {
                        if masks[*a as usize] & masks[*b as usize] & masks[*c as usize] == 0 {
                            if tris.len() == BRUTE_FORCE_CANDIDATES {
                                return None;
                            }
                            tris.push(*e);
                            bounds = bounds.union(Aabb::from_points(v));
                        }
                    }
                    // Grown so that the slab test below is conservative against rounding.
                    Some(Aabb { min: bounds.min - DVec3::splat(eps), max: bounds.max + DVec3::splat(eps) })
                };
            let was_bounds = in_shaft(&moved.old, &moved.old_index, was)?;
            let now_bounds = in_shaft(&moved.new, &moved.new_index, now)?;
            if was.is_empty() && now.is_empty() {
                return Some(old.clone());
            }
            let m = self.samples_per_axis;
            let cells = m * m;
            let count = cells * cells;
            SEGMENTS_TESTED.fetch_add(count as u64, std::sync::atomic::Ordering::Relaxed);
            segments.set(self.samples_of(i, pi), self.samples_of(j, pj));
            // Segment k hits a list if it meets the list's bounds (a segment that misses them
            // misses its triangles) and one of its triangles.
            let hits = |tris: &[[DVec3; 3]], bounds: &Aabb, segments: &Segments, out: &mut Vec<u64>| {
                out.clear();
                out.resize(count, 0);
                if tris.is_empty() {
                    return;
                }
                segments_hit(tris, segments, out);
                for (k, h) in out.iter_mut().enumerate().filter(|(_, h)| **h != 0) {
                    let (a, d) = (segments.origin(k), segments.direction(k));
                    *h = bvh::slab_hit(bounds, a, d.recip(), 0.0, 1.0) as u64;
                }
            };
            hits(now, &now_bounds, segments, hit);
            // A segment visible before is seen now unless it hits a mover now. One blocked before
            // stays blocked if it hits a mover now, or if it missed every mover before (then a
            // fixed occluder blocked it); if only the movers' old positions blocked it, the
            // whole traversal must decide.
            let open = |k: usize| old.at(k / cells, k % cells, cells) == 1.0;
            if (0..count).any(|k| !open(k) && hit[k] == 0) {
                hits(was, &was_bounds, segments, hit_was);
                if (0..count).any(|k| !open(k) && hit[k] == 0 && hit_was[k] != 0) {
                    return None;
                }
            }
            let mut bits = [0u64; 4];
            let mut visible = 0;
            for k in (0..count).filter(|&k| open(k) && hit[k] == 0) {
                bits[k / 64] |= 1 << (k % 64);
                visible += 1;
            }
            Some(if visible == count {
                Visibility::Full
            } else if visible == 0 {
                Visibility::Blocked
            } else {
                Visibility::Partial(Box::new(bits))
            })
        })
    }

    /// [`Occluders::link_visibility`] of the links `(i, j)` for every `(j, pj)` of `js`, appended to
    /// `out` in order. Sources near each other (a strip of a wall) share one traversal: the
    /// triangles the shaft from `i` to all of them may hold are a superset of each link's, and
    /// for links without plane culling any superset of the candidates gives the same rays' verdicts
    /// (a triangle a ray hits lies in every conservative shaft of the link).
    pub fn group_visibility(&self, i: usize, pi: &Patch, js: &[(usize, &Patch)], out: &mut Vec<Visibility>) {
        if js.len() < 2 || self.culling_planes[i].is_some() {
            out.extend(js.iter().map(|&(j, pj)| self.link_visibility(i, pi, j, pj)));
            return;
        }
        let bi = self.sample_bounds[i];
        let union = js.iter().fold(Aabb::EMPTY, |b, &(j, _)| b.union(self.sample_bounds[j]));
        let group = Shaft::new(&bi, &union);
        let eps = 1e-9 * self.scale;
        let (tris, bounds) = (self.bvh.triangles(), self.bvh.triangle_bounds());
        GROUP.with_borrow_mut(|list| {
            list.clear();
            let in_group = |b: &crate::geometry::Aabb| {
                b.overlaps(&group.bounds) && group.may_contain_overlapping_box(b, eps)
            };
            let own = self.id(i);
            self.bvh.for_each_accepted(in_group, |t| {
                if tris[t].element != own && group.may_contain_triangle(&tris[t].v, eps) {
                    list.push(t);
                }
            });
            for &(j, pj) in js {
                if self.culling_planes[j].is_some() {
                    out.push(self.link_visibility(i, pi, j, pj));
                    continue;
                }
                if list.is_empty() {
                    out.push(Visibility::Full);
                    continue;
                }
                let shaft = Shaft::new(&bi, &self.sample_bounds[j]);
                out.push(CANDIDATES.with_borrow_mut(|candidates| {
                    candidates.clear();
                    candidates.extend(list.iter().copied().filter(|&t| {
                        let b = &bounds[t];
                        tris[t].element != self.id(j)
                            && b.overlaps(&shaft.bounds)
                            && shaft.may_contain_overlapping_box(b, eps)
                            && shaft.may_contain_triangle(&tris[t].v, eps)
                    }));
                    if candidates.is_empty() {
                        Visibility::Full
                    } else {
                        self.cast(i, pi, j, pj, candidates, true)
                    }
                }));
            }
        });
    }

    /// The rays of a link whose shaft holds `candidates`; `complete` when they are all the
    /// triangles (other than the link's own) that the shaft may hold.
    fn cast(
        &self,
        i: usize,
        pi: &Patch,
        j: usize,
        pj: &Patch,
        candidates: &[usize],
        complete: bool,
    ) -> Visibility {
        self.cast_between(i, self.samples_of(i, pi), j, self.samples_of(j, pj), candidates, complete)
    }

    /// [`Occluders::cast`] between the sample points `xi` (on element `i`) and `xj` (on `j`).
    fn cast_between(
        &self,
        i: usize,
        xi: &[DVec3],
        j: usize,
        xj: &[DVec3],
        candidates: &[usize],
        complete: bool,
    ) -> Visibility {
        let m = self.samples_per_axis;
        let cells = m * m;
        SEGMENTS_TESTED.fetch_add((cells * cells) as u64, std::sync::atomic::Ordering::Relaxed);
        let mut bits = [0u64; 4];
        let mut visible = 0;
        if candidates.len() <= BRUTE_FORCE_CANDIDATES || complete {
            // Every segment against every candidate, vectorised over the segments; a segment's
            // verdict is whether any candidate blocks it, in whatever order they are tested.
            SCRATCH.with_borrow_mut(|scratch| {
                let Scratch { now: tris, segments, hit, .. } = scratch;
                segments.set(xi, xj);
                hit.clear();
                hit.resize(cells * cells, 0);
                for batch in candidates.chunks(8) {
                    tris.clear();
                    tris.extend(batch.iter().map(|&t| self.edges[t]));
                    segments_hit(tris, segments, hit);
                    if hit.iter().all(|&h| h != 0) {
                        break;
                    }
                }
                for (k, _) in hit.iter().enumerate().filter(|(_, h)| **h == 0) {
                    bits[k / 64] |= 1 << (k % 64);
                    visible += 1;
                }
            });
        } else {
            let (ii, jj) = self.ids((i as u32, j as u32));
            for (r, a) in xi.iter().enumerate() {
                for (s, b) in xj.iter().enumerate() {
                    if !self.bvh.occluded(*a, *b - *a, 1e-9, 1.0 - 1e-9, ii, jj) {
                        let k = r * cells + s;
                        bits[k / 64] |= 1 << (k % 64);
                        visible += 1;
                    }
                }
            }
        }
        if visible == cells * cells {
            Visibility::Full
        } else if visible == 0 {
            Visibility::Blocked
        } else {
            Visibility::Partial(Box::new(bits))
        }
    }
}

/// The traversal of [`shaft_candidates`].
struct InShaft<'a> {
    shaft: &'a Shaft,
    planes: &'a [(DVec3, f64)],
    /// `|n|` of each of `planes`.
    abs_n: [DVec3; 2],
    eps: f64,
    skip: (u32, u32),
    out: &'a mut Vec<usize>,
}

impl bvh::Visitor for InShaft<'_> {
    #[inline(always)]
    fn accept(&self, b: &Aabb, c: DVec3, h: DVec3) -> bool {
        // A box wholly behind one of the planes holds only triangles the plane test below drops
        // (half of eps covers the rounding of the box form), so the traversal skips it.
        let behind = || {
            self.planes.iter().zip(self.abs_n).any(|((n, d), a)| n.dot(c) + a.dot(h) - d <= 0.5 * self.eps)
        };
        b.overlaps(&self.shaft.bounds) && self.shaft.may_contain_centred_box(c, h, self.eps) && !behind()
    }

    #[inline(always)]
    fn visit(&mut self, t: usize, tri: &Triangle) {
        if tri.element == self.skip.0 || tri.element == self.skip.1 {
            return;
        }
        let eps = self.eps;
        if self.planes.iter().any(|(n, d)| tri.v.iter().all(|v| n.dot(*v) - d <= eps)) {
            return;
        }
        // (the traversal already kept only nodes and triangle boxes the shaft may contain)
        if self.shaft.may_contain_triangle(&tri.v, eps) {
            self.out.push(t);
        }
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
fn triangle_edges(v: [DVec3; 3]) -> [DVec3; 3] {
    [v[0], v[1] - v[0], v[2] - v[0]]
}

/// The occluder triangles of the elements that moved, at their previous and at their new places,
/// as [`Occluders`] holds them, to tell whether segments meet them alike at both places
/// ([`MovedOccluders::meet_alike`]). The moved elements must be occluders at both places (not
/// on the scene's hull, [`Occluders::on_hull`]).
pub struct MovedOccluders {
    /// Per moved element: the bounds of its old and new places, and its triangles at each as
    /// `v0, v1 - v0, v2 - v0`, formed as `Occluders::new` forms them (the same rounding, hence
    /// the same decisions of the segment test).
    swept: Vec<Aabb>,
    old: Vec<Vec<[DVec3; 3]>>,
    new: Vec<Vec<[DVec3; 3]>>,
}

impl MovedOccluders {
    /// `moved` yields each moved element's patch at the previous and at the new place.
    pub fn new<'a>(moved: impl Iterator<Item = (&'a Patch, &'a Patch)>) -> Self {
        let (mut swept, mut old, mut new) = (Vec::new(), Vec::new(), Vec::new());
        for (a, b) in moved {
            let (a, b) = (a.triangles(), b.triangles());
            swept.push(a.iter().chain(&b).fold(Aabb::EMPTY, |u, t| u.union(Aabb::from_points(t))));
            old.push(a.into_iter().map(triangle_edges).collect());
            new.push(b.into_iter().map(triangle_edges).collect());
        }
        Self { swept, old, new }
    }

    /// Whether each segment from `x` to a point of `targets` (all inside `bounds`), over
    /// `t in (1e-9, 1 - 1e-9)` as [`Occluders::point_visibility`] casts it, meets some old
    /// triangle exactly when it meets some new one (decided by the same test). Then, as nothing
    /// else moved, each segment gets the verdict it got before (with the old places) whatever
    /// other occluders it meets. Only the elements whose swept bounds the shaft between `x` and
    /// `bounds` may hold (by `eps`) are tested; `false` also when they have more than
    /// [`BRUTE_FORCE_CANDIDATES`] triangles at either place.
    pub fn meet_alike(&self, x: DVec3, bounds: &Aabb, targets: &[DVec3], eps: f64) -> bool {
        let point = Aabb { min: x, max: x };
        CAST_MOVED.with_borrow_mut(|(old, new, from_old, from_new)| {
            (old.n, new.n) = (0, 0);
            for m in 0..self.swept.len() {
                if !Shaft::between_may_contain_box(&point, bounds, &self.swept[m], eps) {
                    continue;
                }
                if !(old.extend(&self.old[m]) && new.extend(&self.new[m])) {
                    return false;
                }
            }
            if old.n == 0 && new.n == 0 {
                return true;
            }
            old.terms_from(x, from_old);
            new.terms_from(x, from_new);
            targets.iter().all(|&y| {
                let d = y - x;
                old.any_hit(from_old, d, 1e-9, 1.0 - 1e-9) == new.any_hit(from_new, d, 1e-9, 1.0 - 1e-9)
            })
        })
    }
}

thread_local! {
    /// [`MovedOccluders::meet_alike`]'s triangles and per-origin terms, old and new.
    static CAST_MOVED: std::cell::RefCell<(CandidateTriangles, CandidateTriangles, FromOrigin, FromOrigin)> =
        const { std::cell::RefCell::new((CandidateTriangles::empty(), CandidateTriangles::empty(), FromOrigin::empty(), FromOrigin::empty())) };
}

/// The occluder triangles of the elements that moved this frame, at their previous and at their
/// new positions, for [`Occluders::relink_visibility`].
pub struct MovedTriangles {
    /// `v0, v1 - v0, v2 - v0` as [`Occluders`] stores them (the same rounding, hence the same
    /// decisions of the segment test), then the vertices for the bounds.
    old: Vec<([DVec3; 3], [DVec3; 3])>,
    new: Vec<([DVec3; 3], [DVec3; 3])>,
    /// The distinct vertices of both lists by coordinate, for the shaft test (a quad's two
    /// triangles share two vertices, neighbouring quads their edges).
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    /// Per triangle of `old` and of `new`, its vertices' indices in `x`, `y`, `z`.
    old_index: Vec<[u32; 3]>,
    new_index: Vec<[u32; 3]>,
}

impl MovedTriangles {
    /// `moved` yields each moved element's patch at the previous and at the new frame. Elements on
    /// the scene's hull are included: they never block a segment, so testing them changes nothing.
    pub fn new<'a>(moved: impl Iterator<Item = (&'a Patch, &'a Patch)>) -> Self {
        let tri = |v: [DVec3; 3]| (triangle_edges(v), v);
        let (mut old, mut new) = (Vec::new(), Vec::new());
        for (a, b) in moved {
            old.extend(a.triangles().into_iter().map(tri));
            new.extend(b.triangles().into_iter().map(tri));
        }
        Self::from_lists(old, new)
    }

    fn from_lists(old: Vec<([DVec3; 3], [DVec3; 3])>, new: Vec<([DVec3; 3], [DVec3; 3])>) -> Self {
        let mut vertices: Vec<[u64; 3]> = Vec::new();
        let mut seen: std::collections::HashMap<[u64; 3], u32> = std::collections::HashMap::new();
        let mut index = |list: &[([DVec3; 3], [DVec3; 3])]| -> Vec<[u32; 3]> {
            list.iter()
                .map(|(_, v)| {
                    v.map(|p| {
                        // Bitwise equal only: a shared vertex has the very coordinates of each copy.
                        let key = p.to_array().map(f64::to_bits);
                        *seen.entry(key).or_insert_with(|| {
                            vertices.push(key);
                            (vertices.len() - 1) as u32
                        })
                    })
                })
                .collect()
        };
        let (old_index, new_index) = (index(&old), index(&new));
        let coordinate = |c: usize| vertices.iter().map(|q| f64::from_bits(q[c])).collect();
        let (x, y, z) = (coordinate(0), coordinate(1), coordinate(2));
        Self { old, new, x, y, z, old_index, new_index }
    }
}

/// Per-thread buffers of [`Occluders::relink_visibility`] and [`Occluders::cast`] (no
/// allocation, zeroing or copying per link).
struct Scratch {
    /// Per moved vertex, the shaft tests it fails ([`Shaft::outside_masks`]).
    masks: Vec<u32>,
    /// Triangles as `v0, v1 - v0, v2 - v0`: the moved ones in the shaft at their previous and new
    /// positions; the candidates being cast.
    was: Vec<[DVec3; 3]>,
    now: Vec<[DVec3; 3]>,
    segments: Segments,
    /// Per segment, non-zero when it hits.
    hit: Vec<u64>,
    hit_was: Vec<u64>,
}

/// The segments of a link, from each receiver sample to each source sample, by coordinate.
struct Segments {
    n: usize,
    /// Origins and directions `b - a`: segment `r * cells + s` from receiver sample `r`.
    o: [[f64; 256]; 3],
    d: [[f64; 256]; 3],
}

impl Scratch {
    const fn new() -> Self {
        let segments = Segments { n: 0, o: [[0.0; 256]; 3], d: [[0.0; 256]; 3] };
        Scratch {
            masks: Vec::new(),
            was: Vec::new(),
            now: Vec::new(),
            segments,
            hit: Vec::new(),
            hit_was: Vec::new(),
        }
    }
}

impl Segments {
    fn set(&mut self, from: &[DVec3], to: &[DVec3]) {
        self.n = from.len() * to.len();
        for (r, a) in from.iter().enumerate() {
            let range = r * to.len()..(r + 1) * to.len();
            for c in 0..3 {
                for ((o, d), b) in
                    self.o[c][range.clone()].iter_mut().zip(&mut self.d[c][range.clone()]).zip(to)
                {
                    *o = a[c];
                    // (`b - a` as glam forms it)
                    *d = b[c] - a[c];
                }
            }
        }
    }

    fn origin(&self, k: usize) -> DVec3 {
        DVec3::new(self.o[0][k], self.o[1][k], self.o[2][k])
    }

    fn direction(&self, k: usize) -> DVec3 {
        DVec3::new(self.d[0][k], self.d[1][k], self.d[2][k])
    }
}

crate::simd::multiversion! {
    /// The occluder triangles, not of the elements `skip`, that `shaft` may hold and that reach in
    /// front of every plane `(n, d)` of `planes` (segments between points in front of a plane
    /// stay in front of it), written to `out`.
    fn shaft_candidates(
        occluders: &Occluders,
        shaft: &Shaft,
        planes: &[(DVec3, f64)],
        skip: (u32, u32),
        out: &mut Vec<usize>,
    ) {
        out.clear();
        debug_assert!(planes.len() <= 2);
        let abs_n = [0, 1].map(|k| planes.get(k).map_or(DVec3::ZERO, |(n, _)| n.abs()));
        let mut visitor = InShaft { shaft, planes, abs_n, eps: 1e-9 * occluders.scale, skip, out };
        occluders.bvh.visit(&mut visitor);
    }
}

crate::simd::multiversion! {
    /// Sets `hit[k]` (leaves it set) when segment `k`, `o + t d` for `t in (1e-9, 1 - 1e-9)`, hits one
    /// of `tris` (each `v0, v1 - v0, v2 - v0`): [`bvh::segment_hits`] for each pair, the same operations
    /// in the same order, vectorised over the segments.
    fn segments_hit(tris: &[[DVec3; 3]], segments: &Segments, hit: &mut [u64]) {
        let n = hit.len().min(segments.n);
        let [ox, oy, oz] = &segments.o;
        let [dx, dy, dz] = &segments.d;
        let (ox, oy, oz, dx, dy, dz) = (&ox[..n], &oy[..n], &oz[..n], &dx[..n], &dy[..n], &dz[..n]);
        let (t_min, t_max) = (1e-9, 1.0 - 1e-9);
        for [v0, e1, e2] in tris {
            for k in 0..n {
                // s = o - v0; q = s x e1 (as glam's cross)
                let (sx, sy, sz) = (ox[k] - v0.x, oy[k] - v0.y, oz[k] - v0.z);
                let qx = sy * e1.z - e1.y * sz;
                let qy = sz * e1.x - e1.z * sx;
                let qz = sx * e1.y - e1.x * sy;
                // p = d x e2; det = e1 . p
                let px = dy[k] * e2.z - e2.y * dz[k];
                let py = dz[k] * e2.x - e2.z * dx[k];
                let pz = dx[k] * e2.y - e2.x * dy[k];
                let det = e1.x * px + e1.y * py + e1.z * pz;
                let inv_det = 1.0 / det;
                let u = (sx * px + sy * py + sz * pz) * inv_det;
                let v = (dx[k] * qx + dy[k] * qy + dz[k] * qz) * inv_det;
                let h = (e2.x * qx + e2.y * qy + e2.z * qz) * inv_det;
                // Non-short-circuit `&`, so the loop has no branches. (A NaN `det` fails on `u`.)
                let blocks = (det.abs() >= 1e-300)
                    & (0.0..=1.0).contains(&u)
                    & !(v < 0.0 || u + v > 1.0)
                    & (h > t_min)
                    & (h < t_max);
                hit[k] |= blocks as u64;
            }
        }
    }
}

thread_local! {
    /// Candidate triangles of the link being cast on this thread (reused, no per-link allocation).
    static CANDIDATES: std::cell::RefCell<Vec<usize>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Candidate triangles of a group of links ([`Occluders::group_visibility`]).
    static GROUP: std::cell::RefCell<Vec<usize>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Candidate triangles of the batch being cast and one origin's terms ([`Occluders::cast`]).
    static CAST: std::cell::RefCell<(CandidateTriangles, FromOrigin)> =
        const { std::cell::RefCell::new((CandidateTriangles::empty(), FromOrigin::empty())) };
    /// Per-thread buffers of [`Occluders::relink_visibility`] and [`Occluders::cast`].
    static SCRATCH: std::cell::RefCell<Scratch> = const { std::cell::RefCell::new(Scratch::new()) };
}

/// Up to [`BRUTE_FORCE_CANDIDATES`] triangles by coordinate, for Moeller-Trumbore against many
/// segments: the same operations as [`bvh::segment_hits`], each triangle's edges formed once and
/// each origin's `s` and `q` once, all triangles of a segment tested in one branch-free loop.
struct CandidateTriangles {
    n: usize,
    /// `v0`, `e1 = v1 - v0`, `e2 = v2 - v0`, by coordinate.
    v0: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
    e1: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
    e2: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
}

/// Per-origin terms: `s = o - v0` and `q = s x e1` per triangle.
struct FromOrigin {
    s: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
    q: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
}

impl FromOrigin {
    const fn empty() -> Self {
        let zero = [[0.0; BRUTE_FORCE_CANDIDATES]; 3];
        Self { s: zero, q: zero }
    }
}

impl CandidateTriangles {
    #[cfg(test)]
    fn gather(edges: &[[DVec3; 3]], candidates: &[usize]) -> Self {
        let mut out = Self::empty();
        out.gather_into(edges, candidates);
        out
    }

    /// The triangles `candidates` (at most [`BRUTE_FORCE_CANDIDATES`]) of `edges`, replacing these.
    fn gather_into(&mut self, edges: &[[DVec3; 3]], candidates: &[usize]) {
        self.n = candidates.len();
        for (k, &t) in candidates.iter().enumerate() {
            let [v0, e1, e2] = edges[t];
            for c in 0..3 {
                self.v0[c][k] = v0[c];
                self.e1[c][k] = e1[c];
                self.e2[c][k] = e2[c];
            }
        }
    }

    const fn empty() -> Self {
        let zero = [[0.0; BRUTE_FORCE_CANDIDATES]; 3];
        Self { n: 0, v0: zero, e1: zero, e2: zero }
    }

    /// Appends triangles (`v0, v1 - v0, v2 - v0` each); `false`, changing nothing, when they
    /// would not fit.
    fn extend(&mut self, edges: &[[DVec3; 3]]) -> bool {
        if self.n + edges.len() > BRUTE_FORCE_CANDIDATES {
            return false;
        }
        for [v0, e1, e2] in edges {
            for c in 0..3 {
                self.v0[c][self.n] = v0[c];
                self.e1[c][self.n] = e1[c];
                self.e2[c][self.n] = e2[c];
            }
            self.n += 1;
        }
        true
    }

    #[cfg(test)]
    fn from(&self, o: DVec3) -> FromOrigin {
        let mut f = FromOrigin::empty();
        self.terms_from(o, &mut f);
        f
    }

    /// [`CandidateTriangles::from`] into `f` (its first `n` entries).
    fn terms_from(&self, o: DVec3, f: &mut FromOrigin) {
        let [e1x, e1y, e1z] = &self.e1;
        for k in 0..self.n {
            let (sx, sy, sz) = (o.x - self.v0[0][k], o.y - self.v0[1][k], o.z - self.v0[2][k]);
            f.s[0][k] = sx;
            f.s[1][k] = sy;
            f.s[2][k] = sz;
            // q = s x e1, as glam's cross.
            f.q[0][k] = sy * e1z[k] - e1y[k] * sz;
            f.q[1][k] = sz * e1x[k] - e1z[k] * sx;
            f.q[2][k] = sx * e1y[k] - e1x[k] * sy;
        }
    }

    /// True if the segment `o + t d`, `t in (t_min, t_max)`, hits one of the triangles
    /// (`f = self.from(o)`): [`bvh::segment_hits`] for each, same operations, same decisions.
    fn any_hit(&self, f: &FromOrigin, d: DVec3, t_min: f64, t_max: f64) -> bool {
        let [e1x, e1y, e1z] = &self.e1;
        let [e2x, e2y, e2z] = &self.e2;
        let [sx, sy, sz] = &f.s;
        let [qx, qy, qz] = &f.q;
        let mut hits = 0u32;
        for k in 0..self.n {
            // p = d x e2; det = e1 . p
            let px = d.y * e2z[k] - e2y[k] * d.z;
            let py = d.z * e2x[k] - e2z[k] * d.x;
            let pz = d.x * e2y[k] - e2x[k] * d.y;
            let det = e1x[k] * px + e1y[k] * py + e1z[k] * pz;
            let inv_det = 1.0 / det;
            let u = (sx[k] * px + sy[k] * py + sz[k] * pz) * inv_det;
            let v = (d.x * qx[k] + d.y * qy[k] + d.z * qz[k]) * inv_det;
            let h = (e2x[k] * qx[k] + e2y[k] * qy[k] + e2z[k] * qz[k]) * inv_det;
            // Non-short-circuit `&`, so the loop has no branches. (A NaN `det` fails on `u`.)
            let hit = (det.abs() >= 1e-300)
                & (0.0..=1.0).contains(&u)
                & !(v < 0.0 || u + v > 1.0)
                & (h > t_min)
                & (h < t_max);
            hits |= hit as u32;
        }
        hits != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
