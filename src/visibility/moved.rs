//! What a move changes: a static link's mask re-checked against the moved triangles alone
//! ([`Occluders::relink_visibility`]), and whether segments meet the movers alike at their old
//! and new places ([`MovedOccluders`]), for the animation's update and the corner gather.

use glam::DVec3;

use super::batch::{CandidateTriangles, FromOrigin, SCRATCH, Scratch, Segments, segments_hit};
use super::bvh;
use super::shaft::Shaft;
use super::{BRUTE_FORCE_CANDIDATES, Occluders, SEGMENTS_TESTED, Visibility, triangle_edges};
use crate::geometry::{Aabb, Patch};

impl Occluders {
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
