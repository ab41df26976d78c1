//! What a link between two nodes carries, and how it is computed.
//!
//! Between two surfaces (faces or parts of faces) a link holds the Galerkin blocks of eq. (6), as
//! the flat system's pairs do, computed by the same pair integrator over the two patches with the
//! visibility masks of their own sample cells. Where a cluster is at one end, the link holds only
//! a transmittance from rays between the two nodes: the transfer itself follows from the nodes'
//! current state (a cluster's intensity lobes, a surface's mean radiosity and normal) and the
//! distance between their centres, [`super::solve`].

use glam::DVec3;

use super::tree::{Kind, NodeId, Surface, Tree};
use crate::geometry::Patch;
use crate::kernel::PairContext;
use crate::kernel::pair::{SEPARATION, integrate_near_coarse, integrate_pair};
use crate::kernel::point::{point_kernel, point_to_polygon};
use crate::kernel::samples::Samples;
use crate::quadrature::GaussLegendre;
use crate::visibility::{Occluders, Visibility};

/// Rays per cluster link (pairs of points that face each other): one packet.
pub(crate) const CLUSTER_RAYS: usize = crate::visibility::bvh::PACKET;

/// A surface link that may carry at most this share of the oracle's bar is made light
/// ([`Coupling::Constants`]): below [`super::refine`]'s share for shadow refinement, so that a
/// light link is never one the oracle would split for a shadow boundary.
pub const LIGHT_SHARE: f64 = 1.0 / 16.0;

/// Gauss points per axis for a light link's outer integral.
pub const LIGHT_POINTS: usize = 2;

#[derive(Clone, Debug)]
pub enum Coupling {
    /// `G_ab` then `G_ba`, `nb x nb` each, row = the receiver's function (eq. 6).
    Surfaces(Box<[f32]>),
    /// Two surfaces whose link carries so little (at most [`LIGHT_SHARE`] of the oracle's bar)
    /// that its error may be all it carries: `G^00` each way (`a` receiving from `b`, then `b`
    /// from `a`), integrated with [`LIGHT_POINTS`] points per axis and the share of
    /// [`crate::visibility::Occluders::share_visible`]'s segments that arrive folded in.
    Constants { ab: f32, ba: f32 },
    /// A cluster at one end at least: the mean over sampled segments between the nodes of
    /// `V d^2 / r^2` (`transmittance` below), which turns the centres' `1/d^2` into the pair's;
    /// `partial` when some of the segments were blocked (the corner gather then casts its own:
    /// what a part of the node sees may be anything from none to all).
    Clusters { transmittance: f32, partial: bool },
}

/// A link between nodes `a` and `b`, both directions.
#[derive(Clone, Debug)]
pub struct Link {
    pub a: NodeId,
    pub b: NodeId,
    pub coupling: Coupling,
}

/// What computing a link needs besides the two nodes.
pub struct LinkContext<'a> {
    pub pair: PairContext<'a>,
    pub occluders: Option<&'a Occluders>,
    /// Gauss rules of 1..=8 points, for the separated pairs' samples.
    rules: Vec<GaussLegendre>,
    /// How near surface pairs are integrated.
    pub near: NearRule,
    /// The rule of light links' outer integral ([`LIGHT_POINTS`]).
    light_rule: GaussLegendre,
    /// An animation's frame: the cluster links' casts of the frame before it may take.
    pub reuse: Option<Reuse<'a>>,
}

/// How a link between two near surfaces (bounding spheres within [`SEPARATION`] radii-sums) is
/// integrated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NearRule {
    /// As the flat system does: split adaptively, analytic at the deepest level.
    Adaptive,
    /// [`integrate_near_coarse`]: the oracle refines the elements where a near link would carry
    /// much, so the links left near carry little and need no more.
    Coarse,
}

impl<'a> LinkContext<'a> {
    pub fn new(pair: PairContext<'a>, occluders: Option<&'a Occluders>) -> Self {
        Self {
            pair,
            occluders,
            rules: (1..=8).map(GaussLegendre::new).collect(),
            near: NearRule::Coarse,
            light_rule: GaussLegendre::new(LIGHT_POINTS),
            reuse: None,
        }
    }
}

/// The outcome of computing a link.
pub struct Computed {
    /// `None` when the two nodes exchange nothing (facing away, blocked).
    pub coupling: Option<Coupling>,
    /// Some rays arrive and some do not: a shadow boundary crosses the link.
    pub partial: bool,
    /// The two nodes face each other but none of the sampled rays arrives: the solve gets
    /// nothing through them, the corner gather may (a corner sees what no sample does).
    pub blocked: bool,
}

/// How much of a link to compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Weight {
    /// Every coefficient, visibility over the sample cells.
    Full,
    /// A surface pair that carries little: [`Coupling::Constants`].
    Light,
}

/// Computes the link between `a` and `b`, in full.
pub fn compute(ctx: &LinkContext, tree: &Tree, a: NodeId, b: NodeId) -> Computed {
    compute_as(ctx, tree, a, b, Weight::Full)
}

/// Computes the link between `a` and `b`; `weight` applies to surface pairs (a cluster link is
/// light as it is).
pub fn compute_as(ctx: &LinkContext, tree: &Tree, a: NodeId, b: NodeId, weight: Weight) -> Computed {
    compute_cast(ctx, tree, a, b, weight).0
}

/// [`compute_as`], and for a cluster link of an update ([`LinkContext::reuse`]) whose segments
/// were cast against occluders, the cast (for [`Casts`]) and whether it was the last frame's.
pub fn compute_cast(
    ctx: &LinkContext,
    tree: &Tree,
    a: NodeId,
    b: NodeId,
    weight: Weight,
) -> (Computed, Option<Casting>) {
    let (na, nb) = (tree.node(a), tree.node(b));
    match (&na.kind, &nb.kind) {
        (Kind::Surface(sa), Kind::Surface(sb)) => {
            let (ea, eb) = (Side::of(sa, na.centre, na.radius), Side::of(sb, nb.centre, nb.radius));
            let computed = match weight {
                Weight::Full => surfaces(ctx, &ea, &eb),
                Weight::Light => light_surfaces(ctx, &ea, &eb),
            };
            (computed, None)
        }
        _ => {
            // Casts are kept only where a next frame may take them: an update's, against occluders
            // (a first frame's millions are neither converted nor copied).
            let reuse = ctx.reuse.as_ref().filter(|_| ctx.occluders.is_some());
            let (rays, casting) = match reuse.and_then(|r| r.cast_of(a, b)) {
                Some(cast) => (cast.rays, Some(Casting { cast, reused: true })),
                None => {
                    let (rays, segments) = transmittance(ctx, tree, a, b);
                    let cast = reuse.map(|_| Cast::new(&segments, rays));
                    (rays, cast.map(|cast| Casting { cast, reused: false }))
                }
            };
            let t = rays.weighted;
            let computed = Computed {
                coupling: (t > 0.0).then_some(Coupling::Clusters {
                    transmittance: t as f32,
                    partial: rays.arrived < rays.facing,
                }),
                partial: rays.arrived > 0 && rays.arrived < rays.facing,
                blocked: rays.facing > 0 && rays.arrived == 0,
            };
            (computed, casting)
        }
    }
}

/// A cluster link's segments as [`kernel_weighted_combos`] cast them, and what they found.
#[derive(Clone, Copy)]
pub struct Cast {
    /// The first `rays.facing` hold the segments' ends (f32: [`Reuse::cast_of`] tests them
    /// against boxes grown by more than their rounding).
    ends: [[f32; 6]; CLUSTER_RAYS],
    rays: Rays,
}

impl Cast {
    /// The cast of `rays` along `segments` (the first `rays.facing`).
    fn new(segments: &[(DVec3, DVec3); CLUSTER_RAYS], rays: Rays) -> Self {
        let f = |p: DVec3| [p.x as f32, p.y as f32, p.z as f32];
        let ends = segments.map(|(x, y)| {
            let (x, y) = (f(x), f(y));
            [x[0], x[1], x[2], y[0], y[1], y[2]]
        });
        Cast { ends, rays }
    }
}

/// A cluster link's cast as [`compute_cast`] made it: anew, or the last frame's (`reused`).
pub struct Casting {
    pub cast: Cast,
    pub reused: bool,
}

/// The casts of the cluster links an animation's frame computed, by pair, for the next frame
/// to take where it may ([`Reuse`]); kept only by updated frames (a first frame computes
/// millions on a large model). In order of computation, with an index by pair: filed straight
/// into a map, moving 230 bytes a cast, they took 1.8 ms of the moving-light box's frame, about
/// what taking them spares.
#[derive(Default)]
pub struct Casts {
    index: super::pair_tree::PairMap<u32>,
    casts: Vec<Cast>,
}

impl Casts {
    pub fn len(&self) -> usize {
        self.casts.len()
    }

    pub fn is_empty(&self) -> bool {
        self.casts.is_empty()
    }

    /// Room for `more` casts, or [`crate::Error::OutOfMemory`].
    pub fn try_reserve(&mut self, more: usize) -> crate::error::Result<()> {
        let bytes = (self.len() + more) as u64 * (std::mem::size_of::<Cast>() + 16) as u64;
        let fail = |_| crate::budget::out_of_memory("the cluster links' casts", bytes);
        self.index.try_reserve(more).map_err(fail)?;
        self.casts.try_reserve(more).map_err(fail)
    }

    /// Keeps `cast` as the pair `(a, b)`'s (replacing an earlier one).
    pub fn insert(&mut self, a: NodeId, b: NodeId, cast: Cast) {
        let slot = *self.index.entry(super::pair_tree::key(a, b)).or_insert(self.casts.len() as u32);
        match self.casts.get_mut(slot as usize) {
            Some(kept) => *kept = cast,
            None => self.casts.push(cast),
        }
    }

    fn get(&self, a: NodeId, b: NodeId) -> Option<&Cast> {
        self.index.get(&super::pair_tree::key(a, b)).map(|&i| &self.casts[i as usize])
    }
}

/// What a frame may take from the casts of the frame before ([`LinkContext::reuse`]).
///
/// A pair that a move touched although neither end holds a moved face (a moved object's swept
/// box meets the shaft between its ends) draws the same points as it did then: the points
/// below a node depend on its faces only ([`sample_point`], seeded by the pair). Its segments
/// are the same, and a segment that meets no swept box (the moved faces' old and new places)
/// is blocked by the same faces as then. So when none does, the cast is what a fresh one
/// would give, bit for bit. On the moving-light box about half of an updated frame's cluster
/// pairs are touched this way: the light's box meets the shafts of the pairs around it.
pub struct Reuse<'a> {
    last: &'a Casts,
    /// Per node of the tree the move was found on: it holds a moved face (nodes made since
    /// hold none of the last frame's pairs).
    holds: &'a [bool],
    /// The moved objects' swept boxes, grown by more than an f32 end's rounding.
    swept: Vec<crate::geometry::Aabb>,
}

impl<'a> Reuse<'a> {
    /// `swept`: the moves' boxes ([`super::touch::Moves::swept`]) on `tree`.
    pub fn new(last: &'a Casts, holds: &'a [bool], swept: &[crate::geometry::Aabb], tree: &Tree) -> Self {
        // An f32 end is within 2^-24 of the scene's largest coordinate of the cast one, and so
        // is every point between two ends.
        let size = tree
            .faces
            .iter()
            .map(|e| e.patch.bounds())
            .chain(swept.iter().copied())
            .map(|x| x.min.abs().max(x.max.abs()).max_element())
            .fold(0.0, f64::max);
        let margin = 1e-6 * size.max(1e-300);
        Self { last, holds, swept: swept.iter().map(|x| x.inflated(margin)).collect() }
    }

    /// The last frame's cast of `(a, b)` where it holds this frame ([`Reuse`]).
    fn cast_of(&self, a: NodeId, b: NodeId) -> Option<Cast> {
        let holds = |x: NodeId| self.holds.get(x as usize).copied().unwrap_or(true);
        if holds(a) || holds(b) {
            return None;
        }
        let cast = self.last.get(a, b)?;
        let end = |e: &[f32; 6], k: usize| DVec3::new(e[k] as f64, e[k + 1] as f64, e[k + 2] as f64);
        let crossed = cast.ends[..cast.rays.facing]
            .iter()
            .any(|e| self.swept.iter().any(|x| x.meets_segment(end(e, 0), end(e, 3))));
        (!crossed).then_some(*cast)
    }
}

/// A surface end of a link, with what every link asks of it kept in its node.
struct Side<'a> {
    surface: &'a Surface,
    /// The patch's bounding sphere (its node's).
    centre: DVec3,
    radius: f64,
}

impl<'a> Side<'a> {
    fn of(surface: &'a Surface, centre: DVec3, radius: f64) -> Self {
        Side { surface, centre, radius }
    }

    /// The face index and the patch.
    fn face_patch(&self) -> (usize, &'a Patch) {
        (self.surface.face as usize, &self.surface.patch)
    }

    /// [`crate::kernel::assemble::may_face`]`(self, other)` from the kept plane.
    fn may_face(&self, other: &Side) -> bool {
        self.surface.front.is_none_or(|pl| pl.any_in_front(&other.surface.patch))
    }

    /// The centres' distance over the sum of the radii (the integrators' separation).
    fn separation(&self, other: &Side) -> f64 {
        self.centre.distance(other.centre) / (self.radius + other.radius)
    }
}

fn surfaces(ctx: &LinkContext, a: &Side, b: &Side) -> Computed {
    let none = Computed { coupling: None, partial: false, blocked: false };
    let ((fa, pa), (fb, pb)) = (a.face_patch(), b.face_patch());
    if fa == fb || !a.may_face(b) || !b.may_face(a) {
        return none;
    }
    let vis = match ctx.occluders {
        Some(o) => o.part_visibility(fa, pa, fb, pb),
        None => Visibility::Full,
    };
    if vis == Visibility::Blocked {
        return Computed { blocked: true, ..none };
    }
    let partial = matches!(vis, Visibility::Partial(_));
    let p = &ctx.pair;
    let ratio = a.separation(b);
    // Separated pairs take whole-patch samples; near ones are split by the integrator itself.
    let samples = (ratio > SEPARATION).then(|| {
        let rule = &ctx.rules[p.points_for(ratio) - 1];
        let make =
            |patch: &Patch| Samples::new(patch, &crate::geometry::Rect::UNIT, rule, p.basis, p.vis_axis);
        (make(pa), make(pb))
    });
    let whole = |second: bool, _n: usize| {
        let (x, y) = samples.as_ref().expect("separated pairs only");
        if second { y } else { x }
    };
    let c = if samples.is_none() && ctx.near == NearRule::Coarse {
        let mut c = crate::kernel::pair::PairCoefficients::zeros(p.basis.len());
        integrate_near_coarse(p, pa, pb, &vis, &mut c.ij, &mut c.ji);
        c
    } else {
        integrate_pair(p, pa, pb, whole, &vis)
    };
    if c.ij.iter().chain(&c.ji).all(|&x| x == 0.0) {
        return none;
    }
    let blocks: Box<[f32]> = c.ij.iter().chain(&c.ji).map(|&x| x as f32).collect();
    Computed { coupling: Some(Coupling::Surfaces(blocks)), partial, blocked: false }
}

/// A light link between two surfaces: `G^00` both ways with [`LIGHT_POINTS`] points per axis
/// (near pairs by the coarse analytic rule, as full links), unoccluded, times the share of a few
/// sampled segments between them that arrive. What it leaves out (the higher coefficients, the
/// visibility's variation over the pair) is at most what it carries, which the oracle bounds.
fn light_surfaces(ctx: &LinkContext, a: &Side, b: &Side) -> Computed {
    let none = Computed { coupling: None, partial: false, blocked: false };
    let ((fa, pa), (fb, pb)) = (a.face_patch(), b.face_patch());
    if fa == fb || !a.may_face(b) || !b.may_face(a) {
        return none;
    }
    let g = || {
        let (xa, xb) = (LightPoints::new(pa, &ctx.light_rule), LightPoints::new(pb, &ctx.light_rule));
        if a.separation(b) > SEPARATION { xa.gauss(&xb) } else { (xa.to_polygon(pb), xb.to_polygon(pa)) }
    };
    // The segments first, and the kernel only for pairs that some of them cross (most pairs
    // tested here are blocked whole); where no segment faces, the kernel first, and the masks'
    // dearer share only for pairs that exchange something (about a seventh of the light links
    // of a monastery crop have no facing segment, and most of those none of the kernel either).
    let ((arrived, tested), (g_ab, g_ba)) = match ctx
        .occluders
        .map(|o| (o, o.share_visible((fa, pa, a.surface.normal), (fb, pb, b.surface.normal))))
    {
        None => ((1, 1), g()),
        Some((_, Some(share))) => {
            if share.0 == 0 {
                return Computed { blocked: true, ..none };
            }
            (share, g())
        }
        Some((occluders, None)) => {
            let g = g();
            if g.0 as f32 == 0.0 && g.1 as f32 == 0.0 {
                return none;
            }
            let share = occluders.masked_share(fa, pa, fb, pb);
            if share.0 == 0 {
                return Computed { blocked: true, ..none };
            }
            (share, g)
        }
    };
    let share = arrived as f64 / tested as f64;
    let (ab, ba) = ((g_ab * share) as f32, (g_ba * share) as f32);
    if ab == 0.0 && ba == 0.0 {
        return none;
    }
    Computed { coupling: Some(Coupling::Constants { ab, ba }), partial: arrived < tested, blocked: false }
}

/// The [`LIGHT_POINTS`] x [`LIGHT_POINTS`] Gauss points of a whole patch, on the stack: a light
/// link's `G^00` needs nothing else (a light link is one of the refinement's most frequent
/// computations, and `Samples` allocates ten vectors each).
struct LightPoints {
    position: [DVec3; LIGHT_SAMPLES],
    normal: [DVec3; LIGHT_SAMPLES],
    /// Weight in the parameter measure, and times the area element `A(s,t)`.
    weight: [f64; LIGHT_SAMPLES],
    area_weight: [f64; LIGHT_SAMPLES],
}

/// A light link's points per patch.
const LIGHT_SAMPLES: usize = LIGHT_POINTS * LIGHT_POINTS;

impl LightPoints {
    /// The points as `Samples::new` makes them over the whole domain (`Gamma_0 = 1`).
    fn new(patch: &Patch, rule: &GaussLegendre) -> Self {
        debug_assert_eq!(rule.len(), LIGHT_POINTS);
        let mut p = Self {
            position: [DVec3::ZERO; LIGHT_SAMPLES],
            normal: [DVec3::ZERO; LIGHT_SAMPLES],
            weight: [0.0; LIGHT_SAMPLES],
            area_weight: [0.0; LIGHT_SAMPLES],
        };
        for (k, ((u, wu), (v, wv))) in
            rule.iter().flat_map(|a| rule.iter().map(move |b| (a, b))).enumerate().take(LIGHT_SAMPLES)
        {
            let av = patch.area_vector(u, v);
            let a = av.length();
            p.position[k] = patch.point(u, v);
            p.normal[k] = if a > 0.0 { av / a } else { DVec3::ZERO };
            p.weight[k] = wu * wv;
            p.area_weight[k] = wu * wv * a;
        }
        p
    }

    /// `G^00` both ways between two separated patches by the tensor Gauss rule (eq. 6 with the
    /// point kernel `cos cos / (pi r^2)`, unoccluded): `self` receiving from `other`, then
    /// `other` from `self`.
    fn gauss(&self, other: &Self) -> (f64, f64) {
        let mut m = [[0.0; LIGHT_SAMPLES]; LIGHT_SAMPLES];
        for (a, row) in m.iter_mut().enumerate() {
            for (b, g) in row.iter_mut().enumerate() {
                *g = point_kernel(self.position[a], self.normal[a], other.position[b], other.normal[b]);
            }
        }
        let (mut ab, mut ba) = (0.0, 0.0);
        for a in 0..LIGHT_SAMPLES {
            let t: f64 = (0..LIGHT_SAMPLES).map(|b| m[a][b] * other.area_weight[b]).sum();
            ab += self.weight[a] * t;
        }
        for b in 0..LIGHT_SAMPLES {
            let t: f64 = (0..LIGHT_SAMPLES).map(|a| m[a][b] * self.area_weight[a]).sum();
            ba += other.weight[b] * t;
        }
        (ab, ba)
    }

    /// `G^00` of `self` receiving from the whole `source` of a near pair: the exact form factor
    /// from each point to the source's polygon (Lambert's contour formula, as
    /// [`integrate_near_coarse`] does it).
    fn to_polygon(&self, source: &Patch) -> f64 {
        let normal = source.centre_normal();
        let mut corners = source.corners.to_vec();
        corners.dedup();
        (0..LIGHT_SAMPLES)
            .map(|a| self.weight[a] * point_to_polygon(self.position[a], self.normal[a], &corners, normal))
            .sum()
    }
}

/// The transmittance of the pair `a`, `b`: [`kernel_weighted_combos`] between
/// [`CLUSTER_RAYS`] points drawn below each (eq. 1 integrated over both ends against the
/// centres' model).
fn transmittance(
    ctx: &LinkContext,
    tree: &Tree,
    a: NodeId,
    b: NodeId,
) -> (Rays, [(DVec3, DVec3); CLUSTER_RAYS]) {
    let (ca, cb) = (tree.node(a).centre, tree.node(b).centre);
    let mut rng = SplitMix(((a as u64) << 32) ^ b as u64 ^ 0x5851_F42D_4C95_7F2D);
    let xs: [End; CLUSTER_RAYS] = std::array::from_fn(|_| sample_point(tree, a, &mut rng));
    let ys: [End; CLUSTER_RAYS] = std::array::from_fn(|_| sample_point(tree, b, &mut rng));
    kernel_weighted_combos(ctx.occluders, ca, cb, &xs, &ys)
}

/// [`kernel_weighted_rays`] over every pairing of the points `xs` (below the node at `ca`) with
/// the points `ys` (below the node at `cb`), `m x m` segments from `2m` points (`m` =
/// [`CLUSTER_RAYS`]): the model's sum over all of them, the visibility from the first `m` that
/// face each other, taken a diagonal at a time (`x_i` with `y_(i+k) mod m`, so that each point is
/// in one segment before any is in two), their arriving kernel scaled by the facing pairings'
/// count over theirs. (The unoccluded kernel over every facing pairing times the share of the
/// cast segments' kernel that arrives, a ratio of two sums of 8, came out 6% low on average
/// behind a blocker: `blocked_pairings_estimate_the_visible_kernel_ratio`.) Drawing a pair of
/// points for each segment until `m` faced took 22 draws a link on average (of at most 32) on
/// the 30k-triangle monastery, and drawing a point (a face by area, then the point) was a tenth
/// of its first frame. Also returns the segments cast (the first `facing`).
pub(crate) fn kernel_weighted_combos(
    occluders: Option<&Occluders>,
    ca: DVec3,
    cb: DVec3,
    xs: &[End; CLUSTER_RAYS],
    ys: &[End; CLUSTER_RAYS],
) -> (Rays, [(DVec3, DVec3); CLUSTER_RAYS]) {
    const M: usize = CLUSTER_RAYS;
    let d2 = ca.distance_squared(cb);
    let w = (cb - ca).normalize_or_zero();
    let mut rays = Rays { facing: 0, arrived: 0, weighted: 0.0 };
    // The model `cos_x(w)+ cos_y(-w)+` summed over every pairing factors into the two ends'.
    let model = xs.iter().map(|x| x.2.dot(w).max(0.0)).sum::<f64>()
        * ys.iter().map(|y| y.2.dot(-w).max(0.0)).sum::<f64>();
    let (mut ends, mut faces) = ([(DVec3::ZERO, DVec3::ZERO); M], [(0, 0); M]);
    let (mut kernels, mut distance_only) = ([0.0; M], [0.0; M]);
    let mut facing_pairs = 0;
    for k in 0..M {
        for (i, &(fx, x, nx)) in xs.iter().enumerate() {
            let (fy, y, ny) = ys[(i + k) % M];
            let d = y - x;
            let (cx, cy) = (nx.dot(d), ny.dot(-d));
            if cx <= 0.0 || cy <= 0.0 {
                continue;
            }
            facing_pairs += 1;
            if rays.facing < M {
                let r2 = d.length_squared();
                let j = rays.facing;
                (ends[j], faces[j]) = ((x, y), (fx, fy));
                (kernels[j], distance_only[j]) = (cx * cy / (r2 * r2) * d2, d2 / r2);
                rays.facing += 1;
            }
        }
    }
    let cast = rays.facing;
    let mut visible = [true; M];
    if let Some(occ) = occluders {
        occ.segments_visible(&ends[..cast], &faces[..cast], &mut visible[..cast]);
    }
    let (mut arriving, mut arriving_distance) = (0.0, 0.0);
    for j in (0..cast).filter(|&j| visible[j]) {
        rays.arrived += 1;
        arriving += kernels[j];
        arriving_distance += distance_only[j];
    }
    if cast > 0 {
        rays.weighted = if model > 0.0 {
            (arriving * (facing_pairs as f64 / cast as f64) / model).min(MAX_KERNEL_RATIO)
        } else {
            arriving_distance / cast as f64
        };
    }
    (rays, ends)
}

/// The most [`kernel_weighted_rays`] may scale the centres' model by: near pairs of clusters see
/// each other a little brighter than their centres say (the mean of `cos cos / r^2` over the
/// pairs of points exceeds its value at the centres), never by this much; a larger ratio is the
/// sampling's noise where the model's cosines vanish.
const MAX_KERNEL_RATIO: f64 = 4.0;

/// The ratio of the exact kernel to the centres' model, `sum V cos_x cos_y / r^2` over `sum
/// cos_x(w)+ cos_y(-w)+ / d^2` on the same drawn pairs (`w` the centres' direction, each drawn
/// face's own cosine in it: the lobes are sums of those), as [`Rays::weighted`]: the solve's
/// cluster transfer is the model times it. Drawn pairs that do not face each other count in the
/// model's sum only. Falls back to the mean `V d^2 / r^2` over the facing pairs (the factor that
/// turns the centres' `1/d^2` into the pairs' mean `1/r^2`) where no drawn pair faces along `w`.
/// Pairs are drawn (`draw`) until [`CLUSTER_RAYS`] face each other, at most four times that: the
/// corner gather's estimate from a point ([`super::gather`]); a link's is
/// [`kernel_weighted_combos`].
pub(crate) fn kernel_weighted_rays(
    occluders: Option<&Occluders>,
    ca: DVec3,
    cb: DVec3,
    mut draw: impl FnMut() -> (End, End),
) -> Rays {
    let d2 = ca.distance_squared(cb);
    let w = (cb - ca).normalize_or_zero();
    let mut rays = Rays { facing: 0, arrived: 0, weighted: 0.0 };
    let mut model = 0.0;
    // The facing pairs first, then their visibility as one packet (the verdicts of one segment
    // at a time, in one traversal: about 5% of the 20k-face monastery crop's link phase).
    let (mut ends, mut faces) = ([(DVec3::ZERO, DVec3::ZERO); CLUSTER_RAYS], [(0, 0); CLUSTER_RAYS]);
    let mut cosines = [(0.0, 0.0); CLUSTER_RAYS];
    for _ in 0..4 * CLUSTER_RAYS {
        let ((fx, x, nx), (fy, y, ny)) = draw();
        model += nx.dot(w).max(0.0) * ny.dot(-w).max(0.0);
        let d = y - x;
        let (cx, cy) = (nx.dot(d), ny.dot(-d));
        if cx <= 0.0 || cy <= 0.0 {
            continue;
        }
        (ends[rays.facing], faces[rays.facing], cosines[rays.facing]) = ((x, y), (fx, fy), (cx, cy));
        rays.facing += 1;
        if rays.facing == CLUSTER_RAYS {
            break;
        }
    }
    let mut visible = [true; CLUSTER_RAYS];
    if let Some(occ) = occluders {
        occ.segments_visible(&ends[..rays.facing], &faces[..rays.facing], &mut visible[..rays.facing]);
    }
    let (mut exact, mut distance_only) = (0.0, 0.0);
    for k in (0..rays.facing).filter(|&k| visible[k]) {
        rays.arrived += 1;
        let ((x, y), (cx, cy)) = (ends[k], cosines[k]);
        let r2 = (y - x).length_squared();
        exact += cx * cy / (r2 * r2) * d2;
        distance_only += d2 / r2;
    }
    if rays.facing > 0 {
        rays.weighted = if model > 0.0 {
            (exact / model).min(MAX_KERNEL_RATIO)
        } else {
            distance_only / rays.facing as f64
        };
    }
    rays
}

/// An end of a sampled segment: face, position, normal.
pub(crate) type End = (u32, DVec3, DVec3);

/// What [`kernel_weighted_rays`] and [`kernel_weighted_combos`] found.
#[derive(Clone, Copy)]
pub(crate) struct Rays {
    /// Segments cast (whose ends face each other; at most [`CLUSTER_RAYS`]), and those of them
    /// that arrive.
    pub facing: usize,
    pub arrived: usize,
    /// The transmittance: the kernel's ratio to the centres' model (or the arriving ones'
    /// `d^2 / r^2` over `facing` where the model's cosines vanish on every drawn pair).
    pub weighted: f64,
}

/// A point below node `id` (face, position, normal): below a cluster, on a face drawn by area
/// ([`Tree::draw_face`]); on a surface, uniform in its parameters.
pub(crate) fn sample_point(tree: &Tree, id: NodeId, rng: &mut SplitMix) -> (u32, DVec3, DVec3) {
    let (face, patch) = match &tree.node(id).kind {
        Kind::Surface(s) => (s.face, &s.patch),
        Kind::Cluster { .. } => tree.draw_face_patch(id, rng.next()),
    };
    let (u, v) = (rng.next(), rng.next());
    let n = patch.area_vector(u, v).normalize_or_zero();
    (face, patch.point(u, v), n)
}

/// Deterministic uniform numbers in [0,1) (splitmix64).
pub(crate) struct SplitMix(pub u64);

impl SplitMix {
    pub(crate) fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square of side 1 centred at `c`, spanned by the unit vectors `u` and `v` (its normal
    /// `u x v`): the point at `(s, t)` in `[0,1]^2`, with the normal, on face `face`.
    fn square(face: u32, c: DVec3, u: DVec3, v: DVec3) -> impl Fn(f64, f64) -> End {
        move |s, t| (face, c + (s - 0.5) * u + (t - 0.5) * v, u.cross(v))
    }

    /// `square`'s patch, for the occluders.
    fn square_patch(c: DVec3, u: DVec3, v: DVec3) -> Patch {
        let corner = |s: f64, t: f64| c + (s - 0.5) * u + (t - 0.5) * v;
        Patch { corners: [corner(0.0, 0.0), corner(1.0, 0.0), corner(1.0, 1.0), corner(0.0, 1.0)] }
    }

    /// By brute force over a 40 x 40 grid on each of `a` and `b`: the mean over the pairs of
    /// points of `cos cos / r^4` (the kernel times `r^2`, as `kernel_weighted_*` weigh it, less
    /// `d^2`) for the pairs not `hidden(x, y)`, the same for every pair, and the share of the
    /// pairs that face each other.
    fn brute_force(
        a: impl Fn(f64, f64) -> End,
        b: impl Fn(f64, f64) -> End,
        hidden: impl Fn(DVec3, DVec3) -> bool,
    ) -> (f64, f64, f64) {
        let n = 40;
        let grid = |k: usize| (k as f64 + 0.5) / n as f64;
        let (mut visible, mut all, mut facing) = (0.0, 0.0, 0);
        for (i, j, k, l) in (0..n * n * n * n).map(|x| (x % n, x / n % n, x / (n * n) % n, x / (n * n * n))) {
            let ((_, x, nx), (_, y, ny)) = (a(grid(i), grid(j)), b(grid(k), grid(l)));
            let d = y - x;
            let r2 = d.length_squared();
            let kernel = (nx.dot(d).max(0.0) * ny.dot(-d).max(0.0)) / (r2 * r2);
            facing += usize::from(nx.dot(d) > 0.0 && ny.dot(-d) > 0.0);
            all += kernel;
            visible += if hidden(x, y) { 0.0 } else { kernel };
        }
        let pairs = (n * n * n * n) as f64;
        (visible / pairs, all / pairs, facing as f64 / pairs)
    }

    /// The mean over `draws` draws of [`kernel_weighted_combos`] between [`CLUSTER_RAYS`] points
    /// drawn uniformly on each of `a` and `b`, and whether every cast segment arrived.
    fn mean_estimate(
        a: impl Fn(f64, f64) -> End,
        b: impl Fn(f64, f64) -> End,
        (ca, cb): (DVec3, DVec3),
        occluders: Option<&Occluders>,
        seed: u64,
    ) -> (f64, bool) {
        let draws = 4000;
        let mut rng = SplitMix(seed);
        let (mut mean, mut all_arrived) = (0.0, true);
        for _ in 0..draws {
            let xs: [End; CLUSTER_RAYS] = std::array::from_fn(|_| a(rng.next(), rng.next()));
            let ys: [End; CLUSTER_RAYS] = std::array::from_fn(|_| b(rng.next(), rng.next()));
            let (rays, _) = kernel_weighted_combos(occluders, ca, cb, &xs, &ys);
            all_arrived &= rays.arrived == rays.facing;
            mean += rays.weighted / draws as f64;
        }
        (mean, all_arrived)
    }

    /// The centres' model `cos_x(w)+ cos_y(-w)+ / d^2` between the squares `a` and `b` at `ca`
    /// and `cb`.
    fn model(a: &impl Fn(f64, f64) -> End, b: &impl Fn(f64, f64) -> End, ca: DVec3, cb: DVec3) -> f64 {
        let (w, d2) = ((cb - ca).normalize(), ca.distance_squared(cb));
        a(0.5, 0.5).2.dot(w).max(0.0) * b(0.5, 0.5).2.dot(-w).max(0.0) / d2
    }

    /// With a blocker between the two squares (hiding 30-70% of the kernel), the pairings'
    /// estimate averaged over many draws is the visible kernel ratio integrated by brute force
    /// (each segment tested against the blocker's rectangle).
    #[test]
    fn blocked_pairings_estimate_the_visible_kernel_ratio() {
        let (ca, cb) = (DVec3::ZERO, DVec3::new(0.4, 0.0, 0.5));
        let tilt = 0.6f64;
        let (ua, va) = (DVec3::X, DVec3::Y);
        let (ub, vb) = (DVec3::new(tilt.cos(), 0.0, tilt.sin()), DVec3::NEG_Y);
        // The blocker: 0.3 x 2 in x and y at height 0.12, centred at x = 0.35, facing down.
        let (cx, hx, z) = (0.35, 0.15, 0.12);
        let blocker = square_patch(DVec3::new(cx, 0.0, z), DVec3::Y * 2.0, DVec3::X * (2.0 * hx));
        let occluders = crate::visibility::Occluders::new(
            &[square_patch(ca, ua, va), square_patch(cb, ub, vb), blocker],
            2,
        );
        let (a, b) = (square(0, ca, ua, va), square(1, cb, ub, vb));
        // A segment from `x` (on z = 0) to `y` (above the blocker) crosses its plane here.
        let hidden = |x: DVec3, y: DVec3| {
            let p = x + (y - x) * ((z - x.z) / (y.z - x.z));
            (p.x - cx).abs() < hx && p.y.abs() < 1.0
        };
        let (visible, all, _) = brute_force(&a, &b, hidden);
        let exact = visible / model(&a, &b, ca, cb);
        let (mean, _) = mean_estimate(&a, &b, (ca, cb), Some(&occluders), 11);
        let share = visible / all;
        assert!(share > 0.3 && share < 0.7, "a blocker worth testing: {share} of the kernel visible");
        assert!((mean / exact - 1.0).abs() < 0.02, "pairings {mean}, brute force {exact}");
    }

    /// Unoccluded, the pairings' estimate of the kernel ratio averaged over many draws is the
    /// ratio integrated by brute force: the mean of `cos cos / r^2` over the two over the model
    /// `cos_x(w)+ cos_y(-w)+ / d^2` at the centres. The receiving square is tilted so that a
    /// part of the pairings do not face each other (18%: they carry nothing), and near enough
    /// that the ratio is well above 1 (1.48), but not near [`MAX_KERNEL_RATIO`], whose clipping
    /// of single draws lowers the mean (at a ratio of 2.5, 9.6% low).
    #[test]
    fn the_pairings_estimate_the_kernel_ratio_of_brute_force_integration() {
        let (ca, cb) = (DVec3::ZERO, DVec3::new(0.4, 0.0, 0.5));
        let tilt = 0.6f64;
        let a = square(0, ca, DVec3::X, DVec3::Y);
        let b = square(0, cb, DVec3::new(tilt.cos(), 0.0, tilt.sin()), DVec3::NEG_Y);
        let (kernel, _, facing) = brute_force(&a, &b, |_, _| false);
        assert!(facing > 0.5 && facing < 0.95, "some pairings face away: {facing}");
        let exact = kernel / model(&a, &b, ca, cb);
        let (mean, all_arrived) = mean_estimate(&a, &b, (ca, cb), None, 7);
        assert!(all_arrived, "nothing blocks");
        assert!(exact > 1.2 && exact < MAX_KERNEL_RATIO, "a ratio worth testing: {exact}");
        assert!((mean / exact - 1.0).abs() < 0.01, "pairings {mean}, brute force {exact}");
    }
}
