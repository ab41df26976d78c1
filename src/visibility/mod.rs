//! Visibility inside the kernel (VIS of eq. 2), per link, as a bit mask over pairs of visibility
//! samples: each element carries `m x m` samples at its cell centres, a link `m^4` bits (at most 256).
//! The animation update compares masks to tell when a link's visibility changed.
//!
//! Rays are skipped when nothing lies in the shaft between the two elements ([`shaft`]); when a few
//! triangles do, rays are tested against that short list only, otherwise against the [`bvh`].

pub mod bvh;
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
const BRUTE_FORCE_CANDIDATES: usize = 24;

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
}

impl Occluders {
    pub fn new(elements: &[Patch], samples_per_axis: usize) -> Self {
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
            if hull[e] {
                continue;
            }
            for v in p.triangles() {
                tris.push(Triangle { v, element: e as u32 });
            }
        }
        let bvh = Bvh::build(tris);
        let edges = bvh.triangles().iter().map(|t| [t.v[0], t.v[1] - t.v[0], t.v[2] - t.v[0]]).collect();
        let eps = 1e-9 * scale;
        let culling_planes = {
            use rayon::prelude::*;
            let tris = bvh.triangles();
            planes
                .par_iter()
                .map(|p| p.filter(|(n, d)| tris.iter().any(|t| t.v.iter().all(|v| n.dot(*v) - d <= eps))))
                .collect()
        };
        Occluders { bvh, edges, culling_planes, scale, samples_per_axis }
    }

    /// Triangles that can occlude anything (elements on the scene's hull are left out).
    pub fn occluder_triangles(&self) -> usize {
        self.bvh.triangles().len()
    }

    pub fn samples_per_axis(&self) -> usize {
        self.samples_per_axis
    }

    /// Whether the segment from `a` (on element `i`) to `b` (on element `j`) is unobstructed by
    /// any other element: one ray, for point queries such as the corner gather.
    pub fn segment_visible(&self, a: DVec3, b: DVec3, i: u32, j: u32) -> bool {
        !self.bvh.occluded(a, b - a, 1e-9, 1.0 - 1e-9, i, j)
    }

    /// Which segments from the point `x` (on element `i`, front normal `n`) to `targets` (points
    /// of element `j`, inside `bounds`) are unobstructed, written to `out` (as long as `targets`). Triangles are
    /// first gathered from the shaft between `x` and `bounds` (usually none: no rays at all);
    /// short lists are tested directly, long ones through the BVH.
    pub fn point_visibility(
        &self,
        x: DVec3,
        n: DVec3,
        (i, j): (u32, u32),
        bounds: &crate::geometry::Aabb,
        targets: &[DVec3],
        out: &mut [bool],
    ) {
        let shaft = Shaft::new(&crate::geometry::Aabb { min: x, max: x }, bounds);
        // Segments leave `x` to its front: triangles wholly behind its tangent plane cannot block.
        CANDIDATES.with_borrow_mut(|candidates| {
            self.shaft_candidates(&shaft, &[(n, n.dot(x))], (i, j), candidates);
            if candidates.is_empty() {
                out.fill(true);
            } else if candidates.len() <= BRUTE_FORCE_CANDIDATES {
                let tris = CandidateTriangles::gather(&self.edges, candidates);
                let from = tris.from(x);
                for (o, &y) in out.iter_mut().zip(targets) {
                    *o = !tris.any_hit(&from, y - x, 1e-9, 1.0 - 1e-9);
                }
            } else {
                for (o, &y) in out.iter_mut().zip(targets) {
                    *o = !self.bvh.occluded(x, y - x, 1e-9, 1.0 - 1e-9, i, j);
                }
            }
        });
    }

    /// Whether some occluder triangle, not of element `i`, has bounds within `r` of the point `x`
    /// and reaches in front of its tangent plane (normal `n`) by more than `r / 100`: something
    /// may hide `x` from close by. (The margin keeps the neighbours on a gently curved or
    /// twisted surface, such as the Cornell box's left wall, from counting.)
    pub fn any_near(&self, x: DVec3, n: DVec3, r: f64, i: u32) -> bool {
        let query = crate::geometry::Aabb { min: x - DVec3::splat(r), max: x + DVec3::splat(r) };
        let eps = 1e-2 * r;
        let mut found = false;
        self.bvh.for_each_overlapping(&query, |t| {
            let tri = &self.bvh.triangles()[t];
            found |= tri.element != i && tri.v.iter().any(|v| n.dot(*v - x) > eps);
        });
        found
    }

    /// Visibility between elements `i` and `j`; also returns whether any ray was needed.
    pub fn link_visibility(&self, i: usize, pi: &Patch, j: usize, pj: &Patch) -> Visibility {
        let shaft = Shaft::new(&pi.bounds(), &pj.bounds());
        let planes = [self.culling_planes[i], self.culling_planes[j]];
        let mut culling = [(DVec3::ZERO, 0.0); 2];
        let mut count = 0;
        for p in planes.into_iter().flatten() {
            culling[count] = p;
            count += 1;
        }
        CANDIDATES.with_borrow_mut(|candidates| {
            // Segments between the fronts of two planar elements stay in front of both planes.
            self.shaft_candidates(&shaft, &culling[..count], (i as u32, j as u32), candidates);
            if candidates.is_empty() {
                return Visibility::Full;
            }
            // Without plane culling the candidates are every triangle the shaft may hold, so
            // testing them all gives what the BVH's any-hit gives, however many there are.
            let complete = planes == [None, None];
            self.cast(i, pi, j, pj, candidates, complete)
        })
    }

    /// The occluder triangles, not of the elements `skip`, that `shaft` may hold and that reach in
    /// front of every plane `(n, d)` of `planes` (segments between points in front of a plane
    /// stay in front of it), written to `out`.
    fn shaft_candidates(
        &self,
        shaft: &Shaft,
        planes: &[(DVec3, f64)],
        skip: (u32, u32),
        out: &mut Vec<usize>,
    ) {
        out.clear();
        let eps = 1e-9 * self.scale;
        // A box wholly behind one of the planes holds only triangles the plane test below drops
        // (half of eps covers the rounding of the box form), so the traversal skips it.
        let behind = |b: &crate::geometry::Aabb| {
            let (c, h) = (b.centre(), b.diagonal() * 0.5);
            planes.iter().any(|(n, d)| n.dot(c) + n.abs().dot(h) - d <= 0.5 * eps)
        };
        let in_shaft = |b: &crate::geometry::Aabb| {
            b.overlaps(&shaft.bounds) && shaft.may_contain_overlapping_box(b, eps) && !behind(b)
        };
        self.bvh.for_each_accepted(in_shaft, |t| {
            let tri = &self.bvh.triangles()[t];
            if tri.element == skip.0 || tri.element == skip.1 {
                return;
            }
            if planes.iter().any(|(n, d)| tri.v.iter().all(|v| n.dot(*v) - d <= eps)) {
                return;
            }
            // (the traversal already kept only nodes and triangle boxes the shaft may contain)
            if shaft.may_contain_triangle(&tri.v, eps) {
                out.push(t);
            }
        });
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
        (pi, pj): (&Patch, &Patch),
        old: &Visibility,
        moved: &MovedTriangles,
    ) -> Option<Visibility> {
        let shaft = Shaft::new(&pi.bounds(), &pj.bounds());
        let eps = 1e-9 * self.scale;
        // Only the moved triangles the shaft may hold can meet a segment of the link.
        let in_shaft = |list: &[([DVec3; 3], [DVec3; 3])]| -> Option<(CandidateTriangles, Aabb)> {
            let mut tris = CandidateTriangles::empty();
            let mut bounds = Aabb::EMPTY;
            for (e, v) in list {
                if shaft.may_contain_triangle(v, eps) {
                    if tris.n == BRUTE_FORCE_CANDIDATES {
                        return None;
                    }
                    tris.push(e);
                    bounds = bounds.union(Aabb::from_points(v));
                }
            }
            // Grown so that the slab test below is conservative against rounding.
            Some((tris, Aabb { min: bounds.min - DVec3::splat(eps), max: bounds.max + DVec3::splat(eps) }))
        };
        let ((was, was_bounds), (now, now_bounds)) = (in_shaft(&moved.old)?, in_shaft(&moved.new)?);
        if was.n == 0 && now.n == 0 {
            return Some(old.clone());
        }
        let m = self.samples_per_axis;
        let cells = m * m;
        SEGMENTS_TESTED.fetch_add((cells * cells) as u64, std::sync::atomic::Ordering::Relaxed);
        let (xi, xj) = (sample_points(pi, m), sample_points(pj, m));
        // A segment that misses a list's bounds misses its triangles.
        let hits = |tris: &CandidateTriangles, bounds: &Aabb, from: &FromOrigin, a: DVec3, d: DVec3| {
            tris.n > 0
                && bvh::slab_hit(bounds, a, d.recip(), 0.0, 1.0)
                && tris.any_hit(from, d, 1e-9, 1.0 - 1e-9)
        };
        let mut bits = [0u64; 4];
        let mut visible = 0;
        for (r, a) in xi[..cells].iter().enumerate() {
            let from_now = now.from(*a);
            let mut from_was = None;
            for (s, b) in xj[..cells].iter().enumerate() {
                let d = *b - *a;
                let hit_now = hits(&now, &now_bounds, &from_now, *a, d);
                let seen = if old.at(r, s, cells) == 1.0 {
                    !hit_now
                } else if hit_now {
                    false
                } else if !hits(&was, &was_bounds, from_was.get_or_insert_with(|| was.from(*a)), *a, d) {
                    // Blocked before by a fixed occluder, which still blocks it.
                    false
                } else {
                    return None;
                };
                if seen {
                    let k = r * cells + s;
                    bits[k / 64] |= 1 << (k % 64);
                    visible += 1;
                }
            }
        }
        Some(if visible == cells * cells {
            Visibility::Full
        } else if visible == 0 {
            Visibility::Blocked
        } else {
            Visibility::Partial(Box::new(bits))
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
        let bi = pi.bounds();
        let union = js.iter().fold(crate::geometry::Aabb::EMPTY, |b, (_, p)| b.union(p.bounds()));
        let group = Shaft::new(&bi, &union);
        let eps = 1e-9 * self.scale;
        let (tris, bounds) = (self.bvh.triangles(), self.bvh.triangle_bounds());
        GROUP.with_borrow_mut(|list| {
            list.clear();
            let in_group = |b: &crate::geometry::Aabb| {
                b.overlaps(&group.bounds) && group.may_contain_overlapping_box(b, eps)
            };
            self.bvh.for_each_accepted(in_group, |t| {
                if tris[t].element as usize != i && group.may_contain_triangle(&tris[t].v, eps) {
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
                let shaft = Shaft::new(&bi, &pj.bounds());
                out.push(CANDIDATES.with_borrow_mut(|candidates| {
                    candidates.clear();
                    candidates.extend(list.iter().copied().filter(|&t| {
                        let b = &bounds[t];
                        tris[t].element as usize != j
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
        let m = self.samples_per_axis;
        let cells = m * m;
        SEGMENTS_TESTED.fetch_add((cells * cells) as u64, std::sync::atomic::Ordering::Relaxed);
        let (xi, xj) = (sample_points(pi, m), sample_points(pj, m));
        let (xi, xj) = (&xi[..cells], &xj[..cells]);
        let mut bits = [0u64; 4];
        let mut visible = 0;
        if candidates.len() <= BRUTE_FORCE_CANDIDATES || complete {
            // Batches of candidates; a ray blocked by one batch is not tested against the next.
            let mut blocked = [false; 256];
            for batch in candidates.chunks(BRUTE_FORCE_CANDIDATES) {
                let tris = CandidateTriangles::gather(&self.edges, batch);
                for (r, a) in xi.iter().enumerate() {
                    let from = tris.from(*a);
                    for (s, b) in xj.iter().enumerate() {
                        let k = r * cells + s;
                        if !blocked[k] && tris.any_hit(&from, *b - *a, 1e-9, 1.0 - 1e-9) {
                            blocked[k] = true;
                        }
                    }
                }
            }
            for (k, _) in blocked[..cells * cells].iter().enumerate().filter(|(_, b)| !**b) {
                bits[k / 64] |= 1 << (k % 64);
                visible += 1;
            }
        } else {
            for (r, a) in xi.iter().enumerate() {
                for (s, b) in xj.iter().enumerate() {
                    if !self.bvh.occluded(*a, *b - *a, 1e-9, 1.0 - 1e-9, i as u32, j as u32) {
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

/// The visibility samples of an element: cell centres of an `m x m` grid (at most 16).
fn sample_points(p: &Patch, m: usize) -> [DVec3; 16] {
    let mut x = [DVec3::ZERO; 16];
    for c in 0..m * m {
        let (s, t) = (((c / m) as f64 + 0.5) / m as f64, ((c % m) as f64 + 0.5) / m as f64);
        x[c] = p.point(s, t);
    }
    x
}

/// The occluder triangles of the elements that moved this frame, at their previous and at their
/// new positions, for [`Occluders::relink_visibility`].
pub struct MovedTriangles {
    /// `v0, v1 - v0, v2 - v0` as [`Occluders`] stores them (the same rounding, hence the same
    /// decisions of the segment test), then the vertices for the shaft test.
    old: Vec<([DVec3; 3], [DVec3; 3])>,
    new: Vec<([DVec3; 3], [DVec3; 3])>,
}

impl MovedTriangles {
    /// `moved` yields each moved element's patch at the previous and at the new frame. Elements on
    /// the scene's hull are included: they never block a segment, so testing them changes nothing.
    pub fn new<'a>(moved: impl Iterator<Item = (&'a Patch, &'a Patch)>) -> Self {
        let tri = |v: [DVec3; 3]| ([v[0], v[1] - v[0], v[2] - v[0]], v);
        let (mut old, mut new) = (Vec::new(), Vec::new());
        for (a, b) in moved {
            old.extend(a.triangles().into_iter().map(tri));
            new.extend(b.triangles().into_iter().map(tri));
        }
        Self { old, new }
    }
}

thread_local! {
    /// Candidate triangles of the link being cast on this thread (reused, no per-link allocation).
    static CANDIDATES: std::cell::RefCell<Vec<usize>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Candidate triangles of a group of links ([`Occluders::group_visibility`]).
    static GROUP: std::cell::RefCell<Vec<usize>> = const { std::cell::RefCell::new(Vec::new()) };
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

impl CandidateTriangles {
    fn gather(edges: &[[DVec3; 3]], candidates: &[usize]) -> Self {
        let zero = [[0.0; BRUTE_FORCE_CANDIDATES]; 3];
        let mut out = Self { n: candidates.len(), v0: zero, e1: zero, e2: zero };
        for (k, &t) in candidates.iter().enumerate() {
            let [v0, e1, e2] = edges[t];
            for c in 0..3 {
                out.v0[c][k] = v0[c];
                out.e1[c][k] = e1[c];
                out.e2[c][k] = e2[c];
            }
        }
        out
    }

    fn empty() -> Self {
        let zero = [[0.0; BRUTE_FORCE_CANDIDATES]; 3];
        Self { n: 0, v0: zero, e1: zero, e2: zero }
    }

    /// Appends a triangle given as `v0, v1 - v0, v2 - v0`; there must be room.
    fn push(&mut self, [v0, e1, e2]: &[DVec3; 3]) {
        let k = self.n;
        for c in 0..3 {
            self.v0[c][k] = v0[c];
            self.e1[c][k] = e1[c];
            self.e2[c][k] = e2[c];
        }
        self.n += 1;
    }

    fn from(&self, o: DVec3) -> FromOrigin {
        let zero = [[0.0; BRUTE_FORCE_CANDIDATES]; 3];
        let mut f = FromOrigin { s: zero, q: zero };
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
        f
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

    /// The batched Moeller-Trumbore gives the decisions of `segment_hits`, including segments
    /// through vertices and along edges (coordinates on a coarse binary grid).
    #[test]
    fn batched_segment_tests_match_segment_hits() {
        let f = |k: usize, a: f64| ((k as f64 * a).sin() * 43758.5453).fract().abs();
        let grid = |k: usize, a: f64| (f(k, a) * 4.0).floor() * 0.25;
        let (mut hits, mut misses) = (0, 0);
        for round in 0..200 {
            let tris: Vec<bvh::Triangle> = (0..BRUTE_FORCE_CANDIDATES)
                .map(|t| {
                    let k = round * 97 + t * 7;
                    let z = grid(k, 0.7) - 0.5;
                    let v = |o: usize| {
                        DVec3::new(grid(k + o, 1.1), grid(k + o, 2.3), z + 0.25 * grid(k + o, 3.7))
                    };
                    bvh::Triangle { v: [v(0), v(1), v(2)], element: t as u32 }
                })
                .collect();
            let edges: Vec<[DVec3; 3]> =
                tris.iter().map(|t| [t.v[0], t.v[1] - t.v[0], t.v[2] - t.v[0]]).collect();
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

    /// Links whose planes cull nothing take their visibility from the shaft's candidates alone,
    /// however many there are: the same masks as any-hit rays through the whole BVH (on facing
    /// pairs; a ray lying in a box face is missed by the BVH's slab test, not by the candidates).
    #[test]
    fn shaft_candidates_give_the_bvh_any_hit_masks() {
        let scene = crate::scenes::cornell_box(5, crate::scene::Settings::default());
        let elements = crate::system::build_elements(&scene, 1.0, crate::basis::Basis::new(0));
        let patches: Vec<Patch> = elements.iter().map(|e| e.patch).collect();
        let occ = Occluders::new(&patches, 2);
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

    /// A group of sources gives each link the visibility it has alone.
    #[test]
    fn group_visibility_is_link_visibility() {
        let scene = crate::scenes::cornell_box(5, crate::scene::Settings::default());
        let elements = crate::system::build_elements(&scene, 1.0, crate::basis::Basis::new(0));
        let patches: Vec<Patch> = elements.iter().map(|e| e.patch).collect();
        let occ = Occluders::new(&patches, 2);
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
