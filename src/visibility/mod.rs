//! Visibility inside the kernel (VIS of eq. 2), per link, as a bit mask over pairs of visibility
//! samples: each element carries `m x m` samples at its cell centres, a link `m^4` bits (at most 256).
//! The animation update compares masks to tell when a link's visibility changed.
//!
//! Rays are skipped when nothing lies in the shaft between the two elements ([`shaft`]); when a few
//! triangles do, rays are tested against that short list only, otherwise against the [`bvh`].

pub mod bvh;
pub mod shaft;

use glam::DVec3;

use crate::geometry::Patch;
use bvh::{Bvh, Triangle};
use shaft::Shaft;

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

    /// The same visibility seen from the other end (receiver and source swapped).
    pub fn transposed(&self, cells: usize) -> Visibility {
        match self {
            Visibility::Partial(bits) => {
                let mut out = [0u64; 4];
                for r in 0..cells {
                    for s in 0..cells {
                        let i = r * cells + s;
                        if (bits[i / 64] >> (i % 64)) & 1 == 1 {
                            let j = s * cells + r;
                            out[j / 64] |= 1 << (j % 64);
                        }
                    }
                }
                Visibility::Partial(Box::new(out))
            }
            v => v.clone(),
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
    /// Per element: unit normal and offset of its plane, `None` when the element is not planar.
    planes: Vec<Option<(DVec3, f64)>>,
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
        Occluders { bvh: Bvh::build(tris), planes, scale, samples_per_axis }
    }

    /// Triangles that can occlude anything (elements on the scene's hull are left out).
    pub fn occluder_triangles(&self) -> usize {
        self.bvh.triangles().len()
    }

    pub fn samples_per_axis(&self) -> usize {
        self.samples_per_axis
    }

    /// Visibility between elements `i` and `j`; also returns whether any ray was needed.
    pub fn link_visibility(&self, i: usize, pi: &Patch, j: usize, pj: &Patch) -> Visibility {
        let shaft = Shaft::new(&pi.bounds(), &pj.bounds());
        let eps = 1e-9 * self.scale;
        let mut candidates: Vec<usize> = Vec::new();
        let in_shaft = |b: &crate::geometry::Aabb| b.overlaps(&shaft.bounds) && shaft.may_contain_box(b, eps);
        self.bvh.for_each_accepted(in_shaft, |t| {
            let tri = &self.bvh.triangles()[t];
            let e = tri.element as usize;
            if e == i || e == j {
                return;
            }
            // Segments between the fronts of two planar elements stay in front of both planes.
            for plane in [self.planes[i], self.planes[j]].into_iter().flatten() {
                if tri.v.iter().all(|v| plane.0.dot(*v) - plane.1 <= eps) {
                    return;
                }
            }
            if shaft.may_contain_triangle(&tri.v, eps) {
                candidates.push(t);
            }
            // (the traversal already kept only nodes and triangle boxes the shaft may contain)
        });
        if candidates.is_empty() {
            return Visibility::Full;
        }
        let m = self.samples_per_axis;
        let cells = m * m;
        let samples = |p: &Patch| -> Vec<DVec3> {
            (0..cells)
                .map(|c| p.point(((c / m) as f64 + 0.5) / m as f64, ((c % m) as f64 + 0.5) / m as f64))
                .collect()
        };
        let (xi, xj) = (samples(pi), samples(pj));
        let mut bits = [0u64; 4];
        let mut visible = 0;
        for (r, a) in xi.iter().enumerate() {
            for (s, b) in xj.iter().enumerate() {
                let d = *b - *a;
                let blocked = if candidates.len() <= BRUTE_FORCE_CANDIDATES {
                    candidates
                        .iter()
                        .any(|&t| bvh::segment_hits(&self.bvh.triangles()[t], *a, d, 1e-9, 1.0 - 1e-9))
                } else {
                    self.bvh.occluded(*a, d, 1e-9, 1.0 - 1e-9, i as u32, j as u32)
                };
                if !blocked {
                    let k = r * cells + s;
                    bits[k / 64] |= 1 << (k % 64);
                    visible += 1;
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
