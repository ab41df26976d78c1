//! A bounding volume hierarchy over the scene's triangles, for the two queries visibility needs:
//! "which triangles overlap this box" (shaft candidates) and "does this segment hit any triangle
//! other than these" (any-hit, early exit).
//!
//! Why our own and not parry3d: parry's trimesh ray cast is closest-hit only and cannot skip the
//! two patches of a link, and the shaft query needs the triangle ids; both are a few lines here.
//! Built by median split on the longest centroid axis: O(n log n), 100k triangles in ~20 ms.

use glam::DVec3;

use crate::geometry::Aabb;

/// A triangle tagged with the element whose surface it approximates (to exclude a link's own patches).
#[derive(Clone, Copy, Debug)]
pub struct Triangle {
    pub v: [DVec3; 3],
    pub element: u32,
}

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first triangle index; inner: index of the left child (right is left + 1).
    start: u32,
    /// Leaf: triangle count (> 0); inner: 0.
    count: u32,
}

const LEAF_SIZE: usize = 4;

/// A traversal of [`Bvh::visit`]: `accept` must be conservative.
pub trait Visitor {
    /// Whether the box `b` (centre `c`, half extent `h`) may hold what is looked for.
    fn accept(&self, b: &Aabb, c: DVec3, h: DVec3) -> bool;
    /// Called with each triangle (and its index) in an accepted leaf whose bounds are accepted.
    fn visit(&mut self, index: usize, triangle: &Triangle);
}

#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    triangles: Vec<Triangle>,
    /// Bounds of each triangle, in `triangles` order.
    bounds: Vec<Aabb>,
    /// Per node, then per triangle: the bounds' centre and half extent, as [`Aabb::centre`] and
    /// `Aabb::diagonal() * 0.5` form them (for box tests against planes).
    node_centred: Vec<(DVec3, DVec3)>,
    triangle_centred: Vec<(DVec3, DVec3)>,
}

impl Bvh {
    pub fn build(mut triangles: Vec<Triangle>) -> Self {
        let mut nodes = Vec::with_capacity(2 * triangles.len() / LEAF_SIZE + 1);
        if triangles.is_empty() {
            return Bvh { nodes, triangles, ..Default::default() };
        }
        nodes.push(Node { bounds: Aabb::EMPTY, start: 0, count: 0 });
        let mut stack = vec![(0usize, 0usize, triangles.len())];
        while let Some((node, lo, hi)) = stack.pop() {
            let tris = &mut triangles[lo..hi];
            let bounds = tris.iter().fold(Aabb::EMPTY, |b, t| b.union(Aabb::from_points(&t.v)));
            if tris.len() <= LEAF_SIZE {
                nodes[node] = Node { bounds, start: lo as u32, count: (hi - lo) as u32 };
                continue;
            }
            let cb = tris.iter().fold(Aabb::EMPTY, |b, t| b.grow(centroid(t)));
            let mid = sah_partition(tris, &cb);
            let left = nodes.len();
            nodes.push(Node { bounds: Aabb::EMPTY, start: 0, count: 0 });
            nodes.push(Node { bounds: Aabb::EMPTY, start: 0, count: 0 });
            nodes[node] = Node { bounds, start: left as u32, count: 0 };
            stack.push((left, lo, lo + mid));
            stack.push((left + 1, lo + mid, hi));
        }
        let bounds: Vec<Aabb> = triangles.iter().map(|t| Aabb::from_points(&t.v)).collect();
        let centred = |b: &Aabb| (b.centre(), b.diagonal() * 0.5);
        let node_centred = nodes.iter().map(|n| centred(&n.bounds)).collect();
        let triangle_centred = bounds.iter().map(centred).collect();
        Bvh { nodes, triangles, bounds, node_centred, triangle_centred }
    }

    pub fn triangles(&self) -> &[Triangle] {
        &self.triangles
    }

    /// Bounds of each triangle, in [`Bvh::triangles`] order.
    pub fn triangle_bounds(&self) -> &[Aabb] {
        &self.bounds
    }

    /// Calls `f` with the index of every triangle whose bounds overlap `query`.
    pub fn for_each_overlapping(&self, query: &Aabb, f: impl FnMut(usize)) {
        self.for_each_accepted(|b| b.overlaps(query), f);
    }

    /// Calls `f` with the index of every triangle in a leaf reached through nodes (and with
    /// triangle bounds) that `accept` keeps: `accept` must be conservative.
    pub fn for_each_accepted(&self, accept: impl Fn(&Aabb) -> bool, f: impl FnMut(usize)) {
        /// The two closures as a [`Visitor`] (the centre and half extent go unused).
        struct Closures<A, F>(A, F);
        impl<A: Fn(&Aabb) -> bool, F: FnMut(usize)> Visitor for Closures<A, F> {
            fn accept(&self, b: &Aabb, _: DVec3, _: DVec3) -> bool {
                (self.0)(b)
            }
            fn visit(&mut self, index: usize, _: &Triangle) {
                (self.1)(index)
            }
        }
        self.visit(&mut Closures(accept, f));
    }

    /// Visits every triangle in a leaf reached through nodes (and with triangle bounds) that the
    /// visitor accepts; its box test also gets the centre and half extent of each box (inlined
    /// whole, also into functions compiled for wider vectors).
    #[inline(always)]
    pub fn visit(&self, visitor: &mut impl Visitor) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = [0u32; 64];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let k = stack[sp] as usize;
            let (node, (c, h)) = (&self.nodes[k], self.node_centred[k]);
            if !visitor.accept(&node.bounds, c, h) {
                continue;
            }
            if node.count > 0 {
                for i in node.start as usize..(node.start + node.count) as usize {
                    let (c, h) = self.triangle_centred[i];
                    if visitor.accept(&self.bounds[i], c, h) {
                        visitor.visit(i, &self.triangles[i]);
                    }
                }
            } else {
                stack[sp] = node.start;
                stack[sp + 1] = node.start + 1;
                sp += 2;
            }
        }
    }

    /// True if the open segment `origin + t * dir, t in (t_min, t_max)` hits a triangle whose element
    /// is neither `skip_a` nor `skip_b`.
    pub fn occluded(
        &self,
        origin: DVec3,
        dir: DVec3,
        t_min: f64,
        t_max: f64,
        skip_a: u32,
        skip_b: u32,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let inv = dir.recip();
        // A hit is one the traversal would find: the segment's slabs meet the triangle's box
        // (so they meet every box above it: the slab test is monotone in the box, rounding
        // included) and it crosses the triangle. Tested so everywhere, a triangle tried first
        // from the cache gives the traversal's verdict, whichever thread asks.
        let hits = |k: usize| {
            let t = &self.triangles[k];
            t.element != skip_a
                && t.element != skip_b
                && slab_hit(&self.bounds[k], origin, inv, t_min, t_max)
                && segment_hits(t, origin, dir, t_min, t_max)
        };
        if BLOCKERS.with_borrow(|b| {
            b.recent.iter().any(|&k| (k as usize) < self.triangles.len() && hits(k as usize))
        }) {
            return true;
        }
        let mut stack = [0u32; 64];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let node = &self.nodes[stack[sp] as usize];
            if !slab_hit(&node.bounds, origin, inv, t_min, t_max) {
                continue;
            }
            if node.count > 0 {
                for k in node.start..node.start + node.count {
                    if hits(k as usize) {
                        BLOCKERS.with_borrow_mut(|b| b.remember(k));
                        return true;
                    }
                }
            } else {
                stack[sp] = node.start;
                stack[sp + 1] = node.start + 1;
                sp += 2;
            }
        }
        false
    }
}

/// The last triangles that blocked a segment on this thread, tried before a traversal. Any hit
/// among them is a hit (they are looked up in the BVH being asked, whichever BVH put them
/// there), so the verdicts are the traversal's own, only found sooner.
struct Blockers {
    recent: [u32; 8],
    next: usize,
}

impl Blockers {
    fn remember(&mut self, k: u32) {
        if !self.recent.contains(&k) {
            self.recent[self.next] = k;
            self.next = (self.next + 1) % self.recent.len();
        }
    }
}

thread_local! {
    static BLOCKERS: std::cell::RefCell<Blockers> =
        const { std::cell::RefCell::new(Blockers { recent: [u32::MAX; 8], next: 0 }) };
}

/// Up to this many segments traverse [`Bvh::occluded_packet`] together.
pub const PACKET: usize = 8;

impl Bvh {
    /// [`Bvh::occluded`] for a few segments at once (at most [`PACKET`]), all skipping the same
    /// two elements: `blocked[k]` is set when segment `k` (`origins[k] + t dirs[k]`, `t` in
    /// `(t_min, t_max)`) hits a triangle of another element, and left as it is otherwise (set
    /// ones are not traced). One traversal for the lot: the segments of a link between two near
    /// parts run side by side through the same nodes, which a traversal each visited again.
    #[allow(clippy::too_many_arguments)]
    pub fn occluded_packet(
        &self,
        origins: &[DVec3],
        dirs: &[DVec3],
        t_min: f64,
        t_max: f64,
        skip_a: u32,
        skip_b: u32,
        blocked: &mut [bool],
    ) {
        self.packet(origins, dirs, (t_min, t_max), Ends::Shared(skip_a, skip_b), blocked);
    }

    /// [`Bvh::occluded_packet`] for segments that each skip their own two elements, `skips[k]`
    /// (segments between points drawn on two clusters' faces).
    pub fn occluded_each(
        &self,
        origins: &[DVec3],
        dirs: &[DVec3],
        (t_min, t_max): (f64, f64),
        skips: &[(u32, u32)],
        blocked: &mut [bool],
    ) {
        assert_eq!(skips.len(), origins.len(), "a skip pair per segment");
        self.packet(origins, dirs, (t_min, t_max), Ends::Each(skips), blocked);
    }

    /// Traces a packet in lanes of 4 when it has no more segments (a light link's), else of
    /// [`PACKET`].
    fn packet(&self, origins: &[DVec3], dirs: &[DVec3], span: (f64, f64), ends: Ends, blocked: &mut [bool]) {
        let n = origins.len();
        assert!(n <= PACKET && dirs.len() == n && blocked.len() == n, "a packet of at most {PACKET}");
        let open = (0..n).filter(|&k| !blocked[k]).fold(0u32, |m, k| m | 1 << k);
        if self.nodes.is_empty() || open == 0 {
            return;
        }
        let open = if n <= 4 {
            walk_packet4(self, &Packet::<4>::new(origins, dirs, span, ends), open)
        } else {
            walk_packet8(self, &Packet::<PACKET>::new(origins, dirs, span, ends), open)
        };
        for (k, b) in blocked.iter_mut().enumerate() {
            *b = open & 1 << k == 0;
        }
    }
}

/// The elements each segment of a packet passes through without being blocked (its own ends').
#[derive(Clone, Copy)]
enum Ends<'a> {
    /// The same two for every segment (a link's).
    Shared(u32, u32),
    /// A pair per segment.
    Each(&'a [(u32, u32)]),
}

/// The elements a packet's segments pass through without being blocked, by lane.
#[derive(Clone, Copy)]
enum Skip<const N: usize> {
    Shared(u32, u32),
    /// Two per lane (`[end][lane]`).
    PerLane([[u32; N]; 2]),
}

/// A packet's segments by coordinate (`[axis][lane]`), so that a box's slab test runs over the
/// lanes at once; lanes past the packet's segments hold zeros, and their verdicts are masked out.
struct Lanes<const N: usize> {
    origin: [[f64; N]; 3],
    inv: [[f64; N]; 3],
}

/// What [`walk_packet4`] and [`walk_packet8`] trace: `N` lanes.
struct Packet<'a, const N: usize> {
    lanes: Lanes<N>,
    origins: &'a [DVec3],
    dirs: &'a [DVec3],
    span: (f64, f64),
    skip: Skip<N>,
    reach: Aabb,
}

impl<'a, const N: usize> Packet<'a, N> {
    fn new(origins: &'a [DVec3], dirs: &'a [DVec3], span: (f64, f64), ends: Ends) -> Self {
        let n = origins.len();
        let mut lanes = Lanes { origin: [[0.0; N]; 3], inv: [[0.0; N]; 3] };
        for k in 0..n {
            let inv = dirs[k].recip();
            for a in 0..3 {
                (lanes.origin[a][k], lanes.inv[a][k]) = (origins[k][a], inv[a]);
            }
        }
        let skip = match ends {
            Ends::Shared(a, b) => Skip::Shared(a, b),
            Ends::Each(pairs) => {
                let mut lanes = [[u32::MAX; N]; 2];
                for (k, &(a, b)) in pairs.iter().enumerate() {
                    (lanes[0][k], lanes[1][k]) = (a, b);
                }
                Skip::PerLane(lanes)
            }
        };
        // The box of the segments' swept parts: a node or a triangle outside it holds no hit for
        // any of them. Grown by a margin far above the rounding of the points, so that it never
        // drops a box whose slabs a segment meets.
        let mut reach = Aabb::EMPTY;
        for k in 0..n {
            reach = reach.grow(origins[k] + dirs[k] * span.0).grow(origins[k] + dirs[k] * span.1);
        }
        let margin = 1e-9 * (reach.diagonal().length() + reach.min.abs().max(reach.max.abs()).max_element());
        reach = Aabb { min: reach.min - DVec3::splat(margin), max: reach.max + DVec3::splat(margin) };
        Self { lanes, origins, dirs, span, skip, reach }
    }
}

/// Bit `k` set where lane `k`'s segment meets the slabs of `b` within `span`: [`slab_hit`] lane
/// by lane with the same operations (a free axis, NaN, sets no bound), so the same verdicts.
#[inline(always)]
fn slab_mask<const N: usize>(b: &Aabb, lanes: &Lanes<N>, (t_min, t_max): (f64, f64)) -> u32 {
    let (mut near, mut far) = ([t_min; N], [t_max; N]);
    for a in 0..3 {
        let (lo_b, hi_b) = (b.min[a], b.max[a]);
        for k in 0..N {
            let t0 = (lo_b - lanes.origin[a][k]) * lanes.inv[a][k];
            let t1 = (hi_b - lanes.origin[a][k]) * lanes.inv[a][k];
            let free = t0.is_nan() | t1.is_nan();
            let (lo, hi) = if t0 < t1 { (t0, t1) } else { (t1, t0) };
            let (lo, hi) = if free { (f64::NEG_INFINITY, f64::INFINITY) } else { (lo, hi) };
            near[k] = if lo > near[k] { lo } else { near[k] };
            far[k] = if hi < far[k] { hi } else { far[k] };
        }
    }
    (0..N).fold(0, |m, k| m | ((near[k] <= far[k]) as u32) << k)
}

/// Tests triangle `i` against the lanes of `open` of [`walk`]'s packet, and takes the
/// lanes it blocks out of `open`; `true` if it blocked any. Each segment's own hit as
/// [`Bvh::occluded`] tests it (its slabs meet the triangle's box, and it crosses the triangle), so
/// that a triangle reached for another segment of the packet, or tried first from the cache, gives
/// every segment the verdict of its own traversal. One box test rules a triangle out for the whole
/// packet (most of the triangles tried are the leaves' neighbours of the segments' ends, and the
/// cached blockers).
#[inline(always)]
fn test_triangle<const N: usize>(bvh: &Bvh, p: &Packet<N>, i: usize, open: &mut u32) -> bool {
    let t = &bvh.triangles[i];
    let open_here = match p.skip {
        Skip::Shared(a, b) if t.element == a || t.element == b => return false,
        Skip::Shared(..) => *open,
        Skip::PerLane(ends) => {
            let own = (0..N).fold(0u32, |m, k| {
                m | ((ends[0][k] == t.element) as u32 | (ends[1][k] == t.element) as u32) << k
            });
            *open & !own
        }
    };
    if open_here == 0 || !bvh.bounds[i].overlaps(&p.reach) {
        return false;
    }
    let mut lanes = slab_mask(&bvh.bounds[i], &p.lanes, p.span) & open_here;
    let mut any = false;
    while lanes != 0 {
        let k = lanes.trailing_zeros() as usize;
        lanes &= lanes - 1;
        if segment_hits(t, p.origins[k], p.dirs[k], p.span.0, p.span.1) {
            *open &= !(1 << k);
            any = true;
        }
    }
    any
}

/// The traversal of [`Bvh::occluded_packet`]: the lanes of `open` still unblocked when it ends.
#[inline(always)]
fn walk<const N: usize>(bvh: &Bvh, p: &Packet<N>, open: u32) -> u32 {
    let mut open = open;
    // The triangles that blocked this thread's last segments first: neighbouring links,
    // which follow each other here, are mostly blocked by the same few.
    let recent = BLOCKERS.with_borrow(|b| b.recent);
    for k in recent {
        if (k as usize) < bvh.triangles.len() {
            test_triangle(bvh, p, k as usize, &mut open);
        }
    }
    let mut stack = [0u32; 64];
    let mut sp = 1;
    while sp > 0 && open != 0 {
        sp -= 1;
        let node = &bvh.nodes[stack[sp] as usize];
        if !node.bounds.overlaps(&p.reach) || slab_mask(&node.bounds, &p.lanes, p.span) & open == 0 {
            continue;
        }
        if node.count > 0 {
            for k in node.start..node.start + node.count {
                if test_triangle(bvh, p, k as usize, &mut open) {
                    BLOCKERS.with_borrow_mut(|b| b.remember(k));
                }
            }
        } else {
            stack[sp] = node.start;
            stack[sp + 1] = node.start + 1;
            sp += 2;
        }
    }
    open
}

crate::simd::multiversion! {
    /// [`walk`] in lanes of 4.
    fn walk_packet4(bvh: &Bvh, p: &Packet<4>, open: u32) -> u32 {
        walk(bvh, p, open)
    }
}

crate::simd::multiversion! {
    /// [`walk`] in lanes of [`PACKET`].
    fn walk_packet8(bvh: &Bvh, p: &Packet<PACKET>, open: u32) -> u32 {
        walk(bvh, p, open)
    }
}

/// Surface area of a box (SAH cost weight).
fn half_area(b: &Aabb) -> f64 {
    let d = (b.max - b.min).max(DVec3::ZERO);
    d.x * d.y + d.y * d.z + d.z * d.x
}

/// Reorders `tris` around the best binned surface-area-heuristic split (12 bins per axis,
/// Wald 2007) and returns the split index; a median split on the longest axis when every
/// centroid falls in one bin. Large planar walls make median splits poor: measured in
/// benches/rays.rs.
fn sah_partition(tris: &mut [Triangle], cb: &Aabb) -> usize {
    const BINS: usize = 12;
    let d = cb.diagonal();
    let mut best = (f64::INFINITY, 0usize, 0usize); // (cost, axis, last bin on the left)
    for axis in 0..3 {
        if d[axis] <= 0.0 {
            continue;
        }
        let scale = BINS as f64 / d[axis];
        let bin_of = |t: &Triangle| (((centroid(t)[axis] - cb.min[axis]) * scale) as usize).min(BINS - 1);
        let mut counts = [0usize; BINS];
        let mut boxes = [Aabb::EMPTY; BINS];
        for t in tris.iter() {
            let b = bin_of(t);
            counts[b] += 1;
            boxes[b] = boxes[b].union(Aabb::from_points(&t.v));
        }
        // Sweep from the right for the right-hand costs, then from the left.
        let mut right_area = [0.0; BINS];
        let mut right_count = [0usize; BINS];
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for b in (1..BINS).rev() {
            acc = acc.union(boxes[b]);
            n += counts[b];
            right_area[b] = half_area(&acc);
            right_count[b] = n;
        }
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for b in 0..BINS - 1 {
            acc = acc.union(boxes[b]);
            n += counts[b];
            if n == 0 || right_count[b + 1] == 0 {
                continue;
            }
            let cost = half_area(&acc) * n as f64 + right_area[b + 1] * right_count[b + 1] as f64;
            if cost < best.0 {
                best = (cost, axis, b);
            }
        }
    }
    if !best.0.is_finite() {
        let axis = if d.x >= d.y && d.x >= d.z {
            0
        } else if d.y >= d.z {
            1
        } else {
            2
        };
        let mid = tris.len() / 2;
        tris.select_nth_unstable_by(mid, |a, b| centroid(a)[axis].total_cmp(&centroid(b)[axis]));
        return mid;
    }
    let (_, axis, last) = best;
    let scale = BINS as f64 / d[axis];
    let left = |t: &Triangle| (((centroid(t)[axis] - cb.min[axis]) * scale) as usize).min(BINS - 1) <= last;
    // In-place partition: left-bin triangles first.
    let mut i = 0;
    for j in 0..tris.len() {
        if left(&tris[j]) {
            tris.swap(i, j);
            i += 1;
        }
    }
    i
}

fn centroid(t: &Triangle) -> DVec3 {
    (t.v[0] + t.v[1] + t.v[2]) / 3.0
}

pub(crate) fn slab_hit(b: &Aabb, o: DVec3, inv: DVec3, t_min: f64, t_max: f64) -> bool {
    let t0 = (b.min - o) * inv;
    let t1 = (b.max - o) * inv;
    // A segment that runs in a slab's boundary plane (no motion along that axis, the origin on
    // the plane) gives 0 * inf = NaN there, and it lies in the slab whatever `t`: that axis sets
    // no bound. (`min`/`max` alone keep the other operand, an infinity, which rejected such a
    // segment: segments along a face's plane passed through the boxes of what stands on it,
    // and the test was not monotone in the box.)
    let free = t0.is_nan_mask() | t1.is_nan_mask();
    let lo = DVec3::select(free, DVec3::NEG_INFINITY, t0.min(t1));
    let hi = DVec3::select(free, DVec3::INFINITY, t0.max(t1));
    let near = lo.max_element().max(t_min);
    let far = hi.min_element().min(t_max);
    near <= far
}

/// Moeller-Trumbore, both faces: a triangle blocks light from either side.
#[inline]
pub fn segment_hits(t: &Triangle, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> bool {
    let e1 = t.v[1] - t.v[0];
    let e2 = t.v[2] - t.v[0];
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-300 {
        return false;
    }
    let inv_det = 1.0 / det;
    let s = o - t.v[0];
    let u = s.dot(p) * inv_det;
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv_det;
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    let h = e2.dot(q) * inv_det;
    h > t_min && h < t_max
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whatever this thread's cache of recent blockers holds, a segment's verdict is its
    /// traversal's: segments from random points on the planes of an axis-aligned box room (walls
    /// split into triangles, a block standing on the floor against one, as scenes touch) to
    /// others, each asked with an empty cache and then with each triangle cached alone.
    #[test]
    fn a_cached_blocker_gives_the_traversals_verdict() {
        let quad = |p: [DVec3; 4], element: u32| {
            [Triangle { v: [p[0], p[1], p[2]], element }, Triangle { v: [p[0], p[2], p[3]], element }]
        };
        let mut tris = Vec::new();
        let boxes = [(DVec3::ZERO, DVec3::ONE), (DVec3::new(0.6, 0.0, 0.2), DVec3::new(1.0, 0.3, 0.5))];
        for (b, (lo, hi)) in boxes.iter().enumerate() {
            for axis in 0..3 {
                for side in [lo[axis], hi[axis]] {
                    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                    let corner = |a: f64, b: f64| {
                        let mut p = DVec3::ZERO;
                        p[axis] = side;
                        p[u] = a;
                        p[v] = b;
                        p
                    };
                    let p = [
                        corner(lo[u], lo[v]),
                        corner(hi[u], lo[v]),
                        corner(hi[u], hi[v]),
                        corner(lo[u], hi[v]),
                    ];
                    tris.extend(quad(p, (b * 6 + axis * 2 + usize::from(side == hi[axis])) as u32));
                }
            }
        }
        let bvh = Bvh::build(tris.clone());
        let reset = || BLOCKERS.with_borrow_mut(|b| *b = Blockers { recent: [u32::MAX; 8], next: 0 });
        let mut state = 0x853C_49E6_748F_EA9Bu64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        // A point on a plane of one of the boxes' faces, on a coarse grid (so that segments run
        // along faces and through edges), or anywhere.
        let mut point = || {
            let (lo, hi) = boxes[(next() * 2.0) as usize];
            let mut p = DVec3::new(next(), next(), next());
            if next() < 0.7 {
                p = (p * 10.0).round() / 10.0;
            }
            let axis = (next() * 3.0) as usize;
            p[axis] = if next() < 0.5 { lo[axis] } else { hi[axis] };
            p
        };
        let (mut cases, mut blocked) = (0, 0);
        for _ in 0..4000 {
            let (a, b) = (point(), point());
            reset();
            let fresh = bvh.occluded(a, b - a, 1e-9, 1.0 - 1e-9, u32::MAX, u32::MAX);
            blocked += usize::from(fresh);
            for k in 0..bvh.triangles.len() as u32 {
                reset();
                BLOCKERS.with_borrow_mut(|c| c.remember(k));
                let cached = bvh.occluded(a, b - a, 1e-9, 1.0 - 1e-9, u32::MAX, u32::MAX);
                assert_eq!(cached, fresh, "segment {a} -> {b}: triangle {k} cached");
                cases += 1;
            }
        }
        assert!(blocked > 100 && cases > 10_000, "{blocked} blocked segments, {cases} cases");
    }

    fn grid(n: usize) -> Vec<Triangle> {
        let mut tris = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (x, y) = (i as f64, j as f64);
                let v = [DVec3::new(x, y, 0.0), DVec3::new(x + 1.0, y, 0.0), DVec3::new(x, y + 1.0, 0.0)];
                tris.push(Triangle { v, element: (i * n + j) as u32 });
            }
        }
        tris
    }

    /// A packet's verdicts are each segment's own any-hit, whatever else is in the packet, with
    /// the packet's two skipped elements or each segment's own.
    #[test]
    fn packets_agree_with_single_segments() {
        let mut tris = grid(12);
        // A second, tilted layer, so that some segments pass and some do not.
        for (k, t) in grid(12).into_iter().enumerate() {
            if k % 3 == 0 {
                let v = t.v.map(|p| DVec3::new(p.x + 0.3, p.y, 0.5 + 0.1 * p.x));
                tris.push(Triangle { v, element: 1000 + k as u32 });
            }
        }
        let bvh = Bvh::build(tris);
        let point = |k: usize, z: f64| {
            DVec3::new(0.2 + (k as f64 * 0.618).fract() * 11.5, 0.2 + (k as f64 * 0.414).fract() * 11.5, z)
        };
        let (mut hits, mut misses) = (0, 0);
        for round in 0..300 {
            let n = 1 + round % PACKET;
            let origins: Vec<DVec3> =
                (0..n).map(|k| point(round * 17 + k, -0.5 + 1.5 * (k % 2) as f64)).collect();
            let dirs: Vec<DVec3> = (0..n)
                .map(|k| point(round * 29 + k + 500, 2.0 - 2.5 * (k % 2) as f64) - origins[k])
                .collect();
            let (skip_a, skip_b) = ((round % 144) as u32, 1000 + (round % 50) as u32 * 3);
            // A third of the packets run in the grid's plane (or along a box face: 0 * inf in
            // the slab tests, where the axis must set no bound).
            let (origins, dirs) = if round % 3 == 2 {
                let flat = |p: DVec3| DVec3::new(p.x, p.y, 0.0);
                (origins.into_iter().map(flat).collect::<Vec<_>>(), dirs.into_iter().map(flat).collect())
            } else {
                (origins, dirs)
            };
            let mut blocked = vec![false; n];
            bvh.occluded_packet(&origins, &dirs, 1e-9, 1.0 - 1e-9, skip_a, skip_b, &mut blocked);
            for k in 0..n {
                let want = bvh.occluded(origins[k], dirs[k], 1e-9, 1.0 - 1e-9, skip_a, skip_b);
                assert_eq!(blocked[k], want, "round {round} segment {k}");
                if want { hits += 1 } else { misses += 1 }
            }
            // Each segment skipping its own two elements.
            let skips: Vec<(u32, u32)> = (0..n)
                .map(|k| (((round + 7 * k) % 144) as u32, 1000 + ((round + k) % 50) as u32 * 3))
                .collect();
            let mut each = vec![false; n];
            bvh.occluded_each(&origins, &dirs, (1e-9, 1.0 - 1e-9), &skips, &mut each);
            for k in 0..n {
                let want = bvh.occluded(origins[k], dirs[k], 1e-9, 1.0 - 1e-9, skips[k].0, skips[k].1);
                assert_eq!(each[k], want, "round {round} segment {k}, its own skips");
            }
        }
        assert!(hits > 100 && misses > 100, "{hits} hits, {misses} misses: a weak test");
    }

    #[test]
    fn queries_agree_with_brute_force() {
        let tris = grid(20);
        let bvh = Bvh::build(tris.clone());
        let q = Aabb { min: DVec3::new(3.5, 4.5, -1.0), max: DVec3::new(7.2, 5.1, 1.0) };
        let mut got: Vec<u32> = Vec::new();
        bvh.for_each_overlapping(&q, |i| got.push(bvh.triangles()[i].element));
        got.sort();
        let mut want: Vec<u32> =
            tris.iter().filter(|t| Aabb::from_points(&t.v).overlaps(&q)).map(|t| t.element).collect();
        want.sort();
        assert_eq!(got, want);
        for k in 0..200 {
            let x = 0.1 + (k as f64 * 0.618).fract() * 19.0;
            let y = 0.1 + (k as f64 * 0.414).fract() * 19.0;
            let o = DVec3::new(x, y, 1.0);
            let d = DVec3::new(0.0, 0.0, -2.0);
            let brute = tris.iter().any(|t| segment_hits(t, o, d, 0.0, 1.0));
            assert_eq!(bvh.occluded(o, d, 0.0, 1.0, u32::MAX, u32::MAX), brute, "ray {k}");
            // Stopping short of the plane never hits.
            assert!(!bvh.occluded(o, d, 0.0, 0.4, u32::MAX, u32::MAX));
        }
    }
}
