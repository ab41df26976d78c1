//! A bounding volume hierarchy over the scene's triangles, for the two queries visibility needs:
//! "which triangles overlap this box" (shaft candidates) and "does this segment hit any triangle
//! other than these" (any-hit, early exit), one segment at a time here and in packets of a
//! link's segments in [`packet`] (which walks its own `f32` copy of the inner nodes).
//!
//! Why our own and not parry3d: parry's trimesh ray cast is closest-hit only and cannot skip the
//! two patches of a link, and the shaft query needs the triangle ids; both are a few lines here.
//! Built by a binned surface-area split ([`sah_partition`]): O(n log n).

use glam::DVec3;

use crate::geometry::Aabb;

mod packet;
pub use packet::PACKET;

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

/// [`Bvh::node_tags`]' tag of a node whose triangles' tags differ.
pub const MIXED: u32 = u32::MAX;

/// A traversal of [`Bvh::visit`]: `accept` must be conservative.
pub trait Visitor {
    /// Whether the box `b` (centre `c`, half extent `h`) may hold what is looked for.
    fn accept(&self, b: &Aabb, c: DVec3, h: DVec3) -> bool;
    /// Whether node `node` is entered at all, before its box is tested: a visitor may skip
    /// subtrees by what they hold ([`Bvh::node_tags`]).
    fn enters(&self, _node: usize) -> bool {
        true
    }
    /// Called with each triangle (and its index) in an accepted leaf whose bounds are accepted.
    fn visit(&mut self, index: usize, triangle: &Triangle);
    /// Whether the walk is over, asked after each visit.
    fn done(&self) -> bool {
        false
    }
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
    /// The inner nodes as [`Bvh::occluded_packet`] walks them.
    twins: packet::Twins,
}

impl Bvh {
    pub fn build(mut triangles: Vec<Triangle>) -> Self {
        if triangles.is_empty() {
            return Bvh { nodes: Vec::new(), triangles, ..Default::default() };
        }
        let nodes = build_nodes(&mut triangles, 0);
        let bounds: Vec<Aabb> = triangles.iter().map(|t| Aabb::from_points(&t.v)).collect();
        let centred = |b: &Aabb| (b.centre(), b.diagonal() * 0.5);
        let node_centred = nodes.iter().map(|n| centred(&n.bounds)).collect();
        let triangle_centred = bounds.iter().map(centred).collect();
        let twins = packet::Twins::build(&nodes);
        Bvh { nodes, triangles, bounds, node_centred, triangle_centred, twins }
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

    /// Per node, the tag that `tag` gives every triangle below it, or [`MIXED`]: what
    /// [`Bvh::for_each_overlapping_except`] skips whole subtrees by.
    pub fn node_tags(&self, tag: impl Fn(&Triangle) -> u32) -> Vec<u32> {
        let mut tags = vec![MIXED; self.nodes.len()];
        // Children come after their parent: the last nodes first.
        for k in (0..self.nodes.len()).rev() {
            let node = &self.nodes[k];
            tags[k] = if node.count > 0 {
                let mut below =
                    self.triangles[node.start as usize..(node.start + node.count) as usize].iter().map(&tag);
                let first = below.next().unwrap_or(MIXED);
                if below.all(|t| t == first) { first } else { MIXED }
            } else {
                let (l, r) = (tags[node.start as usize], tags[node.start as usize + 1]);
                if l == r { l } else { MIXED }
            };
        }
        tags
    }

    /// [`Bvh::for_each_overlapping`] without the subtrees whose triangles all have the tag `skip`
    /// (`tags` from [`Bvh::node_tags`]), stopping once `f` returns `true`. Triangles of that tag
    /// in mixed leaves still reach `f`.
    pub fn for_each_overlapping_except(
        &self,
        query: &Aabb,
        tags: &[u32],
        skip: u32,
        f: impl FnMut(usize) -> bool,
    ) {
        /// The query as a [`Visitor`] that skips the subtrees of tag `skip`.
        struct Except<'a, F> {
            query: &'a Aabb,
            tags: &'a [u32],
            skip: u32,
            f: F,
            found: bool,
        }
        impl<F: FnMut(usize) -> bool> Visitor for Except<'_, F> {
            fn accept(&self, b: &Aabb, _: DVec3, _: DVec3) -> bool {
                b.overlaps(self.query)
            }
            fn enters(&self, node: usize) -> bool {
                self.tags[node] != self.skip
            }
            fn visit(&mut self, index: usize, _: &Triangle) {
                self.found = (self.f)(index);
            }
            fn done(&self) -> bool {
                self.found
            }
        }
        self.visit(&mut Except { query, tags, skip, f, found: false });
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
            if !visitor.enters(k) || !visitor.accept(&node.bounds, c, h) {
                continue;
            }
            if node.count > 0 {
                for i in node.start as usize..(node.start + node.count) as usize {
                    let (c, h) = self.triangle_centred[i];
                    if visitor.accept(&self.bounds[i], c, h) {
                        visitor.visit(i, &self.triangles[i]);
                        if visitor.done() {
                            return;
                        }
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

/// Surface area of a box (SAH cost weight).
fn half_area(b: &Aabb) -> f64 {
    let d = (b.max - b.min).max(DVec3::ZERO);
    d.x * d.y + d.y * d.z + d.z * d.x
}

/// Triangles at and above which [`build_nodes`] builds a node's two subtrees in parallel.
const PARALLEL_BUILD: usize = 1 << 14;

/// The nodes over `tris` (their indices in the whole list from `first` on), the root first and
/// each parent before its children, child indices into the returned list. Large lists build
/// their two halves in parallel and lay them out as `[root, left, right, left's below, right's
/// below]`; the tree (which triangles each leaf holds, and in what order) is the one the serial
/// build makes, only the nodes' places differ: every traversal visits the same triangles in the
/// same order.
fn build_nodes(tris: &mut [Triangle], first: usize) -> Vec<Node> {
    if tris.len() < PARALLEL_BUILD {
        return build_serial(tris, first);
    }
    let bounds = tris.iter().fold(Aabb::EMPTY, |b, t| b.union(Aabb::from_points(&t.v)));
    let cb = tris.iter().fold(Aabb::EMPTY, |b, t| b.grow(centroid(t)));
    let mid = sah_partition(tris, &cb);
    let (l, r) = tris.split_at_mut(mid);
    let (left, right) = rayon::join(|| build_nodes(l, first), || build_nodes(r, first + mid));
    // Local index j of the left list goes to 1 (j = 0) or j + 2; of the right list to 2 or
    // j + left.len() + 1. Children are never a list's root.
    let moved = |n: &Node, shift: usize| match n.count {
        0 => Node { start: n.start + shift as u32, ..*n },
        _ => *n,
    };
    let (ls, rs) = (2, left.len() + 1);
    let mut nodes = Vec::with_capacity(left.len() + right.len() + 1);
    nodes.push(Node { bounds, start: 1, count: 0 });
    nodes.push(moved(&left[0], ls));
    nodes.push(moved(&right[0], rs));
    nodes.extend(left[1..].iter().map(|n| moved(n, ls)));
    nodes.extend(right[1..].iter().map(|n| moved(n, rs)));
    nodes
}

/// [`build_nodes`] on one thread: a node's children made one after the other.
fn build_serial(tris: &mut [Triangle], first: usize) -> Vec<Node> {
    let mut nodes = Vec::with_capacity(2 * tris.len() / LEAF_SIZE + 1);
    nodes.push(Node { bounds: Aabb::EMPTY, start: 0, count: 0 });
    let mut stack = vec![(0usize, 0usize, tris.len())];
    while let Some((node, lo, hi)) = stack.pop() {
        let tris = &mut tris[lo..hi];
        let bounds = tris.iter().fold(Aabb::EMPTY, |b, t| b.union(Aabb::from_points(&t.v)));
        if tris.len() <= LEAF_SIZE {
            nodes[node] = Node { bounds, start: (first + lo) as u32, count: (hi - lo) as u32 };
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
    nodes
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

    /// A query that skips one tag finds the triangles of the other tags the plain query finds,
    /// with tags in blocks (whole subtrees skipped) and scattered (mixed leaves), and stops at
    /// the first one its callback takes.
    #[test]
    fn a_query_without_a_tag_finds_the_other_tags() {
        let tris = grid(20);
        let bvh = Bvh::build(tris);
        for tag in [|e: u32| e / 100, |e: u32| e % 3] {
            let tags = bvh.node_tags(|t| tag(t.element));
            for k in 0..50 {
                let (x, y) = ((k as f64 * 0.618).fract() * 18.0, (k as f64 * 0.414).fract() * 18.0);
                let size = 0.5 + (k % 7) as f64;
                let q = Aabb { min: DVec3::new(x, y, -1.0), max: DVec3::new(x + size, y + size, 1.0) };
                let skip = k as u32 % 4;
                let mut want = Vec::new();
                bvh.for_each_overlapping(&q, |i| want.push(i));
                want.retain(|&i| tag(bvh.triangles()[i].element) != skip);
                want.sort();
                let mut got = Vec::new();
                bvh.for_each_overlapping_except(&q, &tags, skip, |i| {
                    if tag(bvh.triangles()[i].element) != skip {
                        got.push(i);
                    }
                    false
                });
                got.sort();
                assert_eq!(got, want, "query {k}");
                let mut calls = 0;
                bvh.for_each_overlapping_except(&q, &tags, skip, |_| {
                    calls += 1;
                    true
                });
                assert!(calls <= 1, "query {k}: {calls} calls after the first was taken");
            }
        }
        let tags = bvh.node_tags(|t| t.element / 100);
        assert!(tags.iter().filter(|&&t| t != MIXED).count() > tags.len() / 2, "few subtrees of one tag");
    }

    /// The parallel build makes the serial build's tree (each node's bounds and children, each
    /// leaf's triangles, the triangles' order), its nodes only in other places.
    #[test]
    fn the_parallel_build_makes_the_serial_tree() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let tris: Vec<Triangle> = (0..3 * PARALLEL_BUILD)
            .map(|k| {
                let c = DVec3::new(next() * 10.0, next() * 10.0, next() * next() * 10.0);
                let v =
                    [c, c + DVec3::new(next(), 0.0, next()) * 0.3, c + DVec3::new(0.0, next(), next()) * 0.3];
                Triangle { v, element: k as u32 }
            })
            .collect();
        let (mut a, mut b) = (tris.clone(), tris);
        let (serial, parallel) = (build_serial(&mut a, 0), build_nodes(&mut b, 0));
        assert_eq!(
            a.iter().map(|t| t.element).collect::<Vec<_>>(),
            b.iter().map(|t| t.element).collect::<Vec<_>>()
        );
        assert_eq!(serial.len(), parallel.len());
        let mut pairs = vec![(0usize, 0usize)];
        let mut inner = 0;
        while let Some((i, j)) = pairs.pop() {
            let (x, y) = (&serial[i], &parallel[j]);
            assert_eq!(
                (x.bounds.min, x.bounds.max, x.count),
                (y.bounds.min, y.bounds.max, y.count),
                "nodes {i}, {j}"
            );
            if x.count > 0 {
                assert_eq!(x.start, y.start, "leaves {i}, {j}");
            } else {
                inner += 1;
                pairs.push((x.start as usize, y.start as usize));
                pairs.push((x.start as usize + 1, y.start as usize + 1));
            }
        }
        assert!(inner > 2 * PARALLEL_BUILD / LEAF_SIZE / 2, "{inner} inner nodes: a shallow tree");
        assert!(
            parallel.iter().zip(&serial).any(|(p, s)| p.start != s.start),
            "the same layout: nothing split in parallel"
        );
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
