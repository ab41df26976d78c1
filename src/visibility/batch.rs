//! Many segments against a few triangles at once, branch-free and vectorised: the per-thread
//! buffers, the segments by coordinate, and the candidate triangles with each origin's terms.

use glam::DVec3;

use super::BRUTE_FORCE_CANDIDATES;

/// Per-thread buffers of [`Occluders::relink_visibility`](super::Occluders::relink_visibility)
/// and [`Occluders::cast`](super::Occluders::cast) (no allocation, zeroing or copying per link).
pub(super) struct Scratch {
    /// Per moved vertex, the shaft tests it fails
    /// ([`Shaft::outside_masks`](super::shaft::Shaft::outside_masks)).
    pub(super) masks: Vec<u32>,
    /// Triangles as `v0, v1 - v0, v2 - v0`: the moved ones in the shaft at their previous and new
    /// positions; the candidates being cast.
    pub(super) was: Vec<[DVec3; 3]>,
    pub(super) now: Vec<[DVec3; 3]>,
    pub(super) segments: Segments,
    /// Per segment, non-zero when it hits.
    pub(super) hit: Vec<u64>,
    pub(super) hit_was: Vec<u64>,
}

/// The segments of a link, from each receiver sample to each source sample, by coordinate.
pub(super) struct Segments {
    pub(super) n: usize,
    /// Origins and directions `b - a`: segment `r * cells + s` from receiver sample `r`.
    pub(super) o: [[f64; 256]; 3],
    pub(super) d: [[f64; 256]; 3],
}

impl Scratch {
    pub(super) const fn new() -> Self {
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
    #[inline]
    pub(super) fn set(&mut self, from: &[DVec3], to: &[DVec3]) {
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

    #[inline]
    pub(super) fn origin(&self, k: usize) -> DVec3 {
        DVec3::new(self.o[0][k], self.o[1][k], self.o[2][k])
    }

    #[inline]
    pub(super) fn direction(&self, k: usize) -> DVec3 {
        DVec3::new(self.d[0][k], self.d[1][k], self.d[2][k])
    }
}

crate::simd::multiversion! {
    /// Sets `hit[k]` (leaves it set) when segment `k`, `o + t d` for `t in (1e-9, 1 - 1e-9)`, hits one
    /// of `tris` (each `v0, v1 - v0, v2 - v0`): [`super::bvh::segment_hits`] for each pair, the same operations
    /// in the same order, vectorised over the segments.
    pub(super) fn segments_hit(tris: &[[DVec3; 3]], segments: &Segments, hit: &mut [u64]) {
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
    pub(super) static CANDIDATES: std::cell::RefCell<Vec<usize>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Candidate triangles of a group of links ([`Occluders::group_visibility`]).
    pub(super) static GROUP: std::cell::RefCell<Vec<usize>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Candidate triangles of the batch being cast and one origin's terms ([`Occluders::cast`]).
    pub(super) static CAST: std::cell::RefCell<(CandidateTriangles, FromOrigin)> =
        const { std::cell::RefCell::new((CandidateTriangles::empty(), FromOrigin::empty())) };
    /// Per-thread buffers of [`Occluders::relink_visibility`] and [`Occluders::cast`].
    pub(super) static SCRATCH: std::cell::RefCell<Scratch> = const { std::cell::RefCell::new(Scratch::new()) };
}

/// Up to [`BRUTE_FORCE_CANDIDATES`] triangles by coordinate, for Moeller-Trumbore against many
/// segments: the same operations as [`super::bvh::segment_hits`], each triangle's edges formed once and
/// each origin's `s` and `q` once, all triangles of a segment tested in one branch-free loop.
pub(super) struct CandidateTriangles {
    pub(super) n: usize,
    /// `v0`, `e1 = v1 - v0`, `e2 = v2 - v0`, by coordinate.
    v0: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
    e1: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
    e2: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
}

/// Per-origin terms: `s = o - v0` and `q = s x e1` per triangle.
pub(super) struct FromOrigin {
    s: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
    q: [[f64; BRUTE_FORCE_CANDIDATES]; 3],
}

impl FromOrigin {
    pub(super) const fn empty() -> Self {
        let zero = [[0.0; BRUTE_FORCE_CANDIDATES]; 3];
        Self { s: zero, q: zero }
    }
}

impl CandidateTriangles {
    #[cfg(test)]
    #[inline]
    pub(super) fn gather(edges: &[[DVec3; 3]], candidates: &[usize]) -> Self {
        let mut out = Self::empty();
        out.gather_into(edges, candidates);
        out
    }

    /// The triangles `candidates` (at most [`BRUTE_FORCE_CANDIDATES`]) of `edges`, replacing these.
    #[inline]
    pub(super) fn gather_into(&mut self, edges: &[[DVec3; 3]], candidates: &[usize]) {
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

    pub(super) const fn empty() -> Self {
        let zero = [[0.0; BRUTE_FORCE_CANDIDATES]; 3];
        Self { n: 0, v0: zero, e1: zero, e2: zero }
    }

    /// Appends triangles (`v0, v1 - v0, v2 - v0` each); `false`, changing nothing, when they
    /// would not fit.
    #[inline]
    pub(super) fn extend(&mut self, edges: &[[DVec3; 3]]) -> bool {
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
    #[inline]
    pub(super) fn from(&self, o: DVec3) -> FromOrigin {
        let mut f = FromOrigin::empty();
        self.terms_from(o, &mut f);
        f
    }

    /// The terms from origin `o` ([`FromOrigin`]) into `f` (its first `n` entries); the tests'
    /// `from` returns them in a new one.
    #[inline]
    pub(super) fn terms_from(&self, o: DVec3, f: &mut FromOrigin) {
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
    /// (`f = self.from(o)`): [`super::bvh::segment_hits`] for each, same operations, same decisions.
    #[inline]
    pub(super) fn any_hit(&self, f: &FromOrigin, d: DVec3, t_min: f64, t_max: f64) -> bool {
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
