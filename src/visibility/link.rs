//! Visibility between two elements (or parts of them): a link's mask over pairs of sample cells,
//! from the triangles in the shaft between them ([`Occluders::link_visibility`]), shared by a
//! group of links from one element ([`Occluders::group_visibility`]), or a light link's share of
//! a few segments ([`Occluders::share_visible`]).

use glam::DVec3;

use super::batch::{CANDIDATES, GROUP, SCRATCH, Scratch, segments_hit};
use super::bvh::{self, Triangle};
use super::shaft::Shaft;
use super::{BRUTE_FORCE_CANDIDATES, Occluders, SEGMENTS_TESTED, Visibility, sample_points};
use crate::geometry::{Aabb, Patch};

/// Segments [`Occluders::share_visible`] tests at most.
const SHARE_SEGMENTS: usize = 4;

impl Occluders {
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

crate::simd::multiversion! {
    /// The occluder triangles, not of the elements `skip`, that `shaft` may hold and that reach in
    /// front of every plane `(n, d)` of `planes` (segments between points in front of a plane
    /// stay in front of it), written to `out`.
    pub(super) fn shaft_candidates(
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
