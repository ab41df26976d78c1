//! Packets of segments traced through the [`Bvh`] together: any-hit, each lane leaving the walk
//! when it is blocked, the walk ending when every lane is.
//!
//! The segments of one link run side by side through the same nodes. The walk reads its own
//! copy of the inner nodes, [`Twin`]s: both children's boxes in one cache line, in `f32`, grown
//! by a margin far above the rounding of `f32`, so that one pass over `2 x N` lanes tests `N`
//! segments against both children. Node tests only prune: a triangle blocks a lane by the `f64`
//! test of [`Bvh::occluded`] (the segment's slabs meet the triangle's box, and it crosses the
//! triangle), and every box above such a triangle passes its grown `f32` test, so the walk
//! visits a few more nodes than an exact one and gives the same verdicts.

use glam::DVec3;

use super::{BLOCKERS, Bvh, Node, segment_hits};
use crate::geometry::Aabb;

/// Up to this many segments traverse [`Bvh::occluded_packet`] together.
pub const PACKET: usize = 8;

/// The children of an inner node as the packet walk reads them.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct Twin {
    /// The children's boxes, `[axis][child]`, grown by [`MARGIN`] times the scene's magnitude.
    lo: [[f32; 2]; 3],
    hi: [[f32; 2]; 3],
    /// Per child: its own twin's index when it is inner (`count` 0), else its first triangle.
    start: [u32; 2],
    count: [u32; 2],
}

/// The [`Twin`]s of a BVH's inner nodes, the root's first.
#[derive(Clone, Debug, Default)]
pub(super) struct Twins {
    twins: Vec<Twin>,
    /// The largest coordinate's magnitude in the scene: `f32` rounds a point by about `6e-8`
    /// of it, and the boxes are grown by [`MARGIN`] times it.
    magnitude: f64,
}

/// The boxes' growth, relative to the scene's magnitude: over a hundred times the rounding of
/// a segment's ends, direction and slab distances in `f32` (each about `6e-8` of it).
const MARGIN: f64 = 1.0 / 65536.0;

/// Packets whose ends reach further from the origin than this many scene magnitudes are traced
/// a segment at a time: the margin was set for points of the scene.
const FAR_OUT: f64 = 4.0;

/// `1/d` as the `f32` lanes hold it: finite, so that `0 * inv` is never NaN (a segment with no
/// motion along an axis, its origin on a slab's plane, lies in the slab: the grown box holds
/// it strictly inside, and `(plane - origin) * inv` keeps the sign that says so).
const INV_LIMIT: f64 = 1e30;

impl Twins {
    pub(super) fn build(nodes: &[Node]) -> Self {
        let Some(root) = nodes.first() else { return Self::default() };
        let magnitude = root.bounds.min.abs().max(root.bounds.max.abs()).max_element().max(f64::MIN_POSITIVE);
        let margin = MARGIN * magnitude;
        // Inner nodes in index order (the root is node 0), and each one's twin.
        let mut index = vec![u32::MAX; nodes.len()];
        let inner: Vec<usize> = (0..nodes.len()).filter(|&k| nodes[k].count == 0).collect();
        for (t, &k) in inner.iter().enumerate() {
            index[k] = t as u32;
        }
        // Rounding to nearest moves a coordinate by far less than the margin, so `lo` stays
        // below the box and `hi` above it.
        let twins = inner
            .iter()
            .map(|&k| {
                let children = [nodes[k].start as usize, nodes[k].start as usize + 1];
                let child = |c: usize| &nodes[children[c]];
                Twin {
                    lo: std::array::from_fn(|a| {
                        std::array::from_fn(|c| (child(c).bounds.min[a] - margin) as f32)
                    }),
                    hi: std::array::from_fn(|a| {
                        std::array::from_fn(|c| (child(c).bounds.max[a] + margin) as f32)
                    }),
                    start: std::array::from_fn(|c| match child(c).count {
                        0 => index[children[c]],
                        _ => child(c).start,
                    }),
                    count: std::array::from_fn(|c| child(c).count),
                }
            })
            .collect();
        Self { twins, magnitude }
    }
}

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
        let reach = reach(origins, dirs, span);
        if reach.min.abs().max(reach.max.abs()).max_element() > FAR_OUT * self.twins.magnitude {
            for k in 0..n {
                let (a, b) = match ends {
                    Ends::Shared(a, b) => (a, b),
                    Ends::Each(pairs) => pairs[k],
                };
                blocked[k] = blocked[k] || self.occluded(origins[k], dirs[k], span.0, span.1, a, b);
            }
            return;
        }
        let open = if n <= 4 {
            walk_packet4(
                self,
                &Packet::<4>::new(origins, dirs, span, ends, reach, self.twins.magnitude),
                open,
            )
        } else {
            walk_packet8(
                self,
                &Packet::<PACKET>::new(origins, dirs, span, ends, reach, self.twins.magnitude),
                open,
            )
        };
        for (k, b) in blocked.iter_mut().enumerate() {
            *b = open & 1 << k == 0;
        }
    }
}

/// The box of the segments' swept parts: a node or a triangle outside it holds no hit for any of
/// them. Grown by a margin far above the rounding of the points, so that it never drops a box
/// whose slabs a segment meets.
fn reach(origins: &[DVec3], dirs: &[DVec3], span: (f64, f64)) -> Aabb {
    let mut reach = Aabb::EMPTY;
    for (&o, &d) in origins.iter().zip(dirs) {
        reach = reach.grow(o + d * span.0).grow(o + d * span.1);
    }
    let margin = 1e-9 * (reach.diagonal().length() + reach.min.abs().max(reach.max.abs()).max_element());
    Aabb { min: reach.min - DVec3::splat(margin), max: reach.max + DVec3::splat(margin) }
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

/// [`Lanes`] in `f32` for the node tests, `1/d` kept finite ([`INV_LIMIT`]).
struct Lanes32<const N: usize> {
    origin: [[f32; N]; 3],
    inv: [[f32; N]; 3],
}

/// What [`walk_packet4`] and [`walk_packet8`] trace: `N` lanes.
struct Packet<'a, const N: usize> {
    lanes: Lanes<N>,
    lanes32: Lanes32<N>,
    origins: &'a [DVec3],
    dirs: &'a [DVec3],
    span: (f64, f64),
    /// `span` widened, in `f32`, for the node tests.
    span32: (f32, f32),
    skip: Skip<N>,
    reach: Aabb,
    /// `reach` grown by the twins' margin, in `f32` (`[axis]`).
    reach_lo: [f32; 3],
    reach_hi: [f32; 3],
}

impl<'a, const N: usize> Packet<'a, N> {
    fn new(
        origins: &'a [DVec3],
        dirs: &'a [DVec3],
        span: (f64, f64),
        ends: Ends,
        reach: Aabb,
        magnitude: f64,
    ) -> Self {
        let n = origins.len();
        let mut lanes = Lanes { origin: [[0.0; N]; 3], inv: [[0.0; N]; 3] };
        let mut lanes32 = Lanes32 { origin: [[0.0; N]; 3], inv: [[0.0; N]; 3] };
        for k in 0..n {
            let inv = dirs[k].recip();
            for a in 0..3 {
                (lanes.origin[a][k], lanes.inv[a][k]) = (origins[k][a], inv[a]);
                lanes32.origin[a][k] = origins[k][a] as f32;
                lanes32.inv[a][k] = inv[a].clamp(-INV_LIMIT, INV_LIMIT) as f32;
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
        let widen = |t: f64| 1e-6 * (1.0 + t.abs());
        let span32 = ((span.0 - widen(span.0)) as f32, (span.1 + widen(span.1)) as f32);
        let margin = MARGIN * magnitude;
        let reach_lo = std::array::from_fn(|a| (reach.min[a] - margin) as f32);
        let reach_hi = std::array::from_fn(|a| (reach.max[a] + margin) as f32);
        Self { lanes, lanes32, origins, dirs, span, span32, skip, reach, reach_lo, reach_hi }
    }
}

/// Per child of `twin`, bit `k` set where lane `k`'s segment may meet the child's (grown) box
/// within the packet's span and reach: both children against every lane in one pass.
#[inline(always)]
fn twin_masks<const N: usize>(twin: &Twin, p: &Packet<N>) -> [u32; 2] {
    let (t_min, t_max) = p.span32;
    let (mut near, mut far) = ([[t_min; N]; 2], [[t_max; N]; 2]);
    for a in 0..3 {
        for c in 0..2 {
            for k in 0..N {
                let t0 = (twin.lo[a][c] - p.lanes32.origin[a][k]) * p.lanes32.inv[a][k];
                let t1 = (twin.hi[a][c] - p.lanes32.origin[a][k]) * p.lanes32.inv[a][k];
                let (lo, hi) = if t0 < t1 { (t0, t1) } else { (t1, t0) };
                near[c][k] = if lo > near[c][k] { lo } else { near[c][k] };
                far[c][k] = if hi < far[c][k] { hi } else { far[c][k] };
            }
        }
    }
    // Plain loops: `array::from_fn` and `all` were left as calls in the wider builds.
    let mut masks = [0; 2];
    for c in 0..2 {
        let mut within = true;
        for a in 0..3 {
            within &= twin.lo[a][c] <= p.reach_hi[a] && p.reach_lo[a] <= twin.hi[a][c];
        }
        let mut hit = [false; N];
        for k in 0..N {
            hit[k] = near[c][k] <= far[c][k];
        }
        masks[c] = if within { lane_bits(hit) } else { 0 };
    }
    masks
}

/// Bit `k` set where `hit[k]`: eight lanes at a time, their bytes (0 or 1) gathered into bits by
/// one multiply (byte `i` lands alone on bit `56 + i`).
#[inline(always)]
fn lane_bits<const N: usize>(hit: [bool; N]) -> u32 {
    let mut bits = 0;
    for (i, chunk) in hit.chunks(8).enumerate() {
        let mut bytes = [0u8; 8];
        for (b, &h) in bytes.iter_mut().zip(chunk) {
            *b = h as u8;
        }
        let gathered = u64::from_le_bytes(bytes).wrapping_mul(0x0102_0408_1020_4080) >> 56;
        bits |= (gathered as u32) << (8 * i);
    }
    bits
}

/// Bit `k` set where lane `k`'s segment meets the slabs of `b` within `span`:
/// [`slab_hit`](super::slab_hit) lane by lane with the same operations (a free axis, NaN, sets no
/// bound), so the same verdicts.
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
    let mut hit = [false; N];
    for k in 0..N {
        hit[k] = near[k] <= far[k];
    }
    lane_bits(hit)
}

/// Tests triangle `i` against the lanes of `lanes` and takes those it blocks out of `open`;
/// `true` if it blocked any. Each segment's own hit as [`Bvh::occluded`] tests it (its slabs
/// meet the triangle's box, and it crosses the triangle), so that a triangle reached for another
/// segment of the packet, or tried first from the cache, gives every segment the verdict of its
/// own traversal. One box test rules a triangle out for the whole packet (most of the triangles
/// tried are the leaves' neighbours of the segments' ends, and the cached blockers).
#[inline(always)]
fn test_triangle<const N: usize>(bvh: &Bvh, p: &Packet<N>, i: usize, lanes: u32, open: &mut u32) -> bool {
    let t = &bvh.triangles[i];
    let lanes_here = match p.skip {
        Skip::Shared(a, b) if t.element == a || t.element == b => return false,
        Skip::Shared(..) => lanes,
        Skip::PerLane(ends) => {
            let own = (0..N).fold(0u32, |m, k| {
                m | ((ends[0][k] == t.element) as u32 | (ends[1][k] == t.element) as u32) << k
            });
            lanes & !own
        }
    };
    if lanes_here == 0 || !bvh.bounds[i].overlaps(&p.reach) {
        return false;
    }
    let mut lanes = slab_mask(&bvh.bounds[i], &p.lanes, p.span) & lanes_here;
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

/// Tests the triangles `start..start + count` of a leaf against the lanes of `lanes` still open.
#[inline(always)]
fn test_leaf<const N: usize>(
    bvh: &Bvh,
    p: &Packet<N>,
    (start, count): (u32, u32),
    lanes: u32,
    open: &mut u32,
) {
    for k in start..start + count {
        if test_triangle(bvh, p, k as usize, lanes & *open, open) {
            BLOCKERS.with_borrow_mut(|b| b.remember(k));
        }
    }
}

/// The traversal of [`Bvh::occluded_packet`]: the lanes of `open` still unblocked when it ends.
/// Each stacked twin carries the lanes that entered its parent's box: the others cannot meet
/// anything below it.
#[inline(always)]
fn walk<const N: usize>(bvh: &Bvh, p: &Packet<N>, open: u32) -> u32 {
    let mut open = open;
    // The triangles that blocked this thread's last segments first: neighbouring links,
    // which follow each other here, are mostly blocked by the same few.
    let recent = BLOCKERS.with_borrow(|b| b.recent);
    for k in recent {
        if (k as usize) < bvh.triangles.len() {
            test_triangle(bvh, p, k as usize, open, &mut open);
        }
    }
    let root = &bvh.nodes[0];
    if root.count > 0 {
        test_leaf(bvh, p, (root.start, root.count), open, &mut open);
        return open;
    }
    let mut stack = [(0u32, 0u32); 64];
    stack[0] = (0, open);
    let mut sp = 1;
    while sp > 0 && open != 0 {
        sp -= 1;
        let (t, entered) = stack[sp];
        let lanes = entered & open;
        if lanes == 0 {
            continue;
        }
        let twin = &bvh.twins.twins[t as usize];
        let masks = twin_masks(twin, p);
        for c in 0..2 {
            let lanes = masks[c] & lanes;
            if lanes == 0 {
                continue;
            }
            if twin.count[c] > 0 {
                test_leaf(bvh, p, (twin.start[c], twin.count[c]), lanes, &mut open);
            } else {
                stack[sp] = (twin.start[c], lanes);
                sp += 1;
            }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::visibility::bvh::Triangle;

    #[test]
    fn lane_bits_gathers_every_pattern() {
        for pattern in 0u32..1 << PACKET {
            let hit: [bool; PACKET] = std::array::from_fn(|k| pattern & 1 << k != 0);
            assert_eq!(lane_bits(hit), pattern);
        }
    }

    /// Every grown `f32` box holds its node's `f64` box, so the walk prunes nothing the exact
    /// boxes keep.
    #[test]
    fn twins_hold_their_children() {
        let tris: Vec<Triangle> = (0..500)
            .map(|k| {
                let p = |j: usize| {
                    let x = ((k * 7 + j * 3) as f64 * 0.618_034).fract();
                    DVec3::new(1e3 + 40.0 * x, -7.3 + 0.01 * (k + j) as f64, 123.456 * x * x)
                };
                Triangle { v: [p(0), p(1), p(2)], element: k as u32 }
            })
            .collect();
        let bvh = Bvh::build(tris);
        // The twins follow the inner nodes in index order.
        let inner = bvh.nodes.iter().filter(|n| n.count == 0);
        let mut checked = 0;
        for (node, twin) in inner.zip(&bvh.twins.twins) {
            for c in 0..2 {
                let child = &bvh.nodes[node.start as usize + c];
                for a in 0..3 {
                    assert!((twin.lo[a][c] as f64) < child.bounds.min[a]);
                    assert!((twin.hi[a][c] as f64) > child.bounds.max[a]);
                }
                checked += 1;
            }
        }
        assert!(checked > 100, "{checked} children");
    }

    /// Segments whose ends lie far outside the scene (where the margin, set for the scene's own
    /// coordinates, would not cover `f32` rounding) get each segment's own verdict.
    #[test]
    fn far_segments_keep_their_verdicts() {
        let tris: Vec<Triangle> = (0..64)
            .map(|k| {
                let (x, y) = ((k % 8) as f64, (k / 8) as f64);
                let v = [DVec3::new(x, y, 0.0), DVec3::new(x + 1.0, y, 0.0), DVec3::new(x, y + 1.0, 0.0)];
                Triangle { v, element: k as u32 }
            })
            .collect();
        let bvh = Bvh::build(tris);
        let (mut hits, mut misses) = (0, 0);
        for k in 0..200 {
            let target = DVec3::new((k as f64 * 0.618).fract() * 8.0, (k as f64 * 0.414).fract() * 8.0, -1.0);
            let origin = DVec3::new(3.0, 4.0, 1e6);
            let origins = [origin; 4];
            let dirs = [target - origin; 4];
            let mut blocked = [false; 4];
            bvh.occluded_packet(&origins, &dirs, 1e-9, 1.0 - 1e-9, u32::MAX, u32::MAX, &mut blocked);
            let want = bvh.occluded(origin, dirs[0], 1e-9, 1.0 - 1e-9, u32::MAX, u32::MAX);
            assert!(blocked.iter().all(|&b| b == want), "segment {k}");
            if want { hits += 1 } else { misses += 1 }
        }
        assert!(hits > 20 && misses > 20, "{hits} hits, {misses} misses");
    }
}
