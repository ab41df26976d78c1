//! Final gather at face corners through the hierarchy: `B` at a corner point from the links that
//! light it, cast from the point itself (the flat system's [`crate::gather`], eq. 1 at a point).
//!
//! A corner's sources are the links (and blocked pairs) of its leaf and of every ancestor
//! ([`sources`]), each source once. The gather takes each of them from the corner instead of
//! from the receiving node:
//!
//! - a surface source `S` (a face or part of one, polynomial `b_S`) by its point moments
//!   `m^l = integral_S g(x,y) V(x,y) Gamma_l(y) dA_y`, integrated with shadow rays from the
//!   corner, so that the contact shadows and the penumbrae inside a large receiving element show
//!   at its corners; `H += sum_l m^l b_S^l` ([`surface`]);
//! - a cluster source by its intensity towards the corner, `I_S(w) T / d^2 max(0, n.(-w))`, with
//!   a transmittance `T` and the exact cosine at the corner (the solve's receiving lobes
//!   truncate it) ([`far`]).
//!
//! Then `B = E + rho (bound(F) H + E_d)`, with `F` the corner's form factors summed (the
//! hemisphere bound, [`crate::hemisphere`]) and `E_d` the lights' direct irradiance at the point.
//! A corner inside another closed surface receives nothing ([`crate::solids`]).
//!
//! Two ways to take the sources ([`Mode`]). The exhaustive gather ([`exhaustive`]) integrates
//! every source from the point with its own rays: a shaft query and up to nine rays per source
//! and sub-rectangle, near sources split to the twelfth level; its cost grows with corners x
//! sources, and a corner under a cluster inherits all of the cluster's links. The fast gather
//! (the default) spends the rays where the light is ([`rank`]): a cluster's sources are split
//! once into the few brightest, which each corner below takes as its own, and a tail of
//! irradiance lobes ([`sources`]); a corner's sources are ranked by the light they could bring
//! it, and the brightest are cast in full (a near source by [`near`]'s recursion, whose parts
//! keep only the occluders of their own shaft and are taken by their exact polygon form factor
//! where none is left; a far one whole by the Gauss rule, [`far`]) until the rest could bring at
//! most a tenth of the corner's light; those take one Gauss sum with a ray per node (a surface)
//! or one packet of rays for the point's transmittance (a cluster: its link's is the receiving
//! cluster's, blind to what shadows only part of it).
//!
//! Three things the first version lacked, measured on the 300-triangle bunny against Cycles per
//! corner (tests/hierarchy.rs; Bunny / Ground relative RMSE at accuracy 1e-4):
//! - a source linked through a cluster link but itself a surface (a light linked with a model's
//!   cluster) is integrated from the point like any surface, with rays: the model's shadows on
//!   itself show (cluster intensity at the point: 34.7% / 4.7%);
//! - a point that touches a source (a model's corner on the floor) takes the part of the source
//!   next to it from `B` gathered at the foot ([`surface`]'s feet, the flat gather's);
//! - pairs the refinement found blocked ([`super::refine::Hierarchy::blocked`]) are sources too:
//!   a corner on the edge of a shadow sees past what every sample of its leaf saw blocked
//!   (without them 7.8% / 4.9%, with them 5.7% / 0.7%; the flat gather 5.2% / 1.4%).
//!
//! Where the fast gather's time goes on a 10k-face crop of the monastery (docs/benchmarks.md,
//! "The hierarchy's corner gather at scale"): half in the foot gathers (a whole gather at each
//! foot), then the near recursion's contact levels and the coarse tail's long rays. The coarser
//! rules tried for them either saved little (1-6% of the decimated monastery's rays, its corners
//! moved by 0.003-0.17% RMS) or moved the corners by 0.2-14% RMS, against a fast gather 0.95%
//! from the exhaustive one.
//!
//! From frame to frame ([`KeptGather`], [`kept`]): each point keeps its sources' values that
//! depend on geometry alone (moments, ball weights, transmittances, the ranking's unoccluded form
//! factors), and the next frame takes those its move cannot have changed, bit for bit.

mod exhaustive;
mod far;
mod kept;
mod near;
mod polygon;
mod rank;
mod sources;
mod surface;

use std::sync::atomic::{AtomicU64, Ordering};

use glam::DVec3;
use rayon::prelude::*;

use super::Lighting;
use super::coupling::Link;
use super::refine::Hierarchy;
use super::solve::State;
use super::tree::{NodeId, Tree};
use crate::error::Result;
use crate::gather::{CornerValues, Stop, corner_points, shading_point};
use crate::lights::direct::DirectLight;
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::solids::Solids;
use crate::system::Progress;
use crate::visibility::Occluders;
use sources::Sources;

pub use kept::{Changes, KeptGather, Reuse};
use kept::{Memo, Slot};

/// A source (sub-)rectangle is integrated by the Gauss rule once the distance from the corner to
/// its centre is this many times its bounding radius; closer, it is split in four (as
/// [`crate::gather`] does).
const GAUSS_RATIO: f64 = 3.0;

/// Gauss points per axis of a source rectangle.
const GAUSS_POINTS: usize = 3;

/// Past this many bounding radii a source rectangle takes [`FAR_POINTS`] per axis: 4 rays
/// instead of 9. Measured on the bunny against Cycles (accuracy 1e-4, tests/hierarchy.rs):
/// 5.66% / 0.66% per corner with 3 x 3 everywhere, 5.71% / 0.69% with this, 4 radii 5.72% /
/// 0.92%; the decimated monastery's gather 83 -> 63 s, the bunny's 4.5 -> 3.4 s (one run).
const FAR_RATIO: f64 = 6.0;
const FAR_POINTS: usize = 2;

/// A surface source nearer the point than this many of its bounding radii is near: the fast
/// gather integrates it from the point with rays ([`near`]); farther, it is far ([`far`]). The
/// Gauss rule's own threshold: a far source is one the exhaustive gather takes whole.
const NEAR_RATIO: f64 = GAUSS_RATIO;

/// What the gather of one hierarchical frame reads.
pub struct Inputs<'a> {
    pub tree: &'a Tree,
    pub links: &'a [Link],
    /// Pairs whose sampled rays were all blocked ([`super::refine::Hierarchy::blocked`]).
    pub blocked: &'a [(NodeId, NodeId)],
    pub state: &'a State,
    /// Per face, its exitance.
    pub emission: &'a [[f64; 3]],
    pub occluders: Option<&'a Occluders>,
    pub lights: Option<&'a DirectLight>,
}

impl<'a> Inputs<'a> {
    /// The gather's inputs for the frame `hierarchy` and `state` solved under `lit`.
    pub fn new(hierarchy: &'a Hierarchy, state: &'a State, lit: &'a Lighting) -> Self {
        Self {
            tree: &hierarchy.tree,
            links: &hierarchy.links,
            blocked: &hierarchy.blocked,
            state,
            emission: &lit.emission,
            occluders: lit.occluders.as_ref(),
            lights: lit.lights.as_ref(),
        }
    }
}

/// How the gather takes its sources.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Rays where the corner's own visibility decides: near sources, and the far ones that
    /// carry most of its light ([`near`], [`far`]).
    Fast,
    /// Every source integrated from the point with its own shadow rays: the reference the fast
    /// gather is tested against.
    Exhaustive,
}

/// What a gather did, summed over its points.
#[derive(Clone, Debug, Default)]
pub struct Counts {
    /// Distinct corner points gathered.
    pub points: usize,
    /// (point, source) pairs looked at, feet included.
    pub sources: u64,
    /// Of those, the near ones integrated with rays ([`near`]), and the far ones cast from the
    /// point because they carry much of its light ([`far`]).
    pub near: u64,
    pub far_cast: u64,
    /// Of the rest, the surfaces taken coarsely (one Gauss sum, or one ray, without splitting).
    pub coarse: u64,
    /// Shadow rays cast (segments tested against occluders).
    pub rays: u64,
    /// Occluder queries of the BVH for a shaft (candidate triangles gathered).
    pub shafts: u64,
    /// Points that touch a source and gather again at its foot.
    pub feet: u64,
}

/// [`Counts`] while the points are gathered in parallel.
#[derive(Default)]
struct Counters {
    sources: AtomicU64,
    near: AtomicU64,
    far_cast: AtomicU64,
    coarse: AtomicU64,
    rays: AtomicU64,
    shafts: AtomicU64,
    feet: AtomicU64,
}

impl Counters {
    fn add(counter: &AtomicU64, n: u64) {
        if n > 0 {
            counter.fetch_add(n, Ordering::Relaxed);
        }
    }

    fn counts(&self, points: usize) -> Counts {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        Counts {
            points,
            sources: get(&self.sources),
            near: get(&self.near),
            far_cast: get(&self.far_cast),
            coarse: get(&self.coarse),
            rays: get(&self.rays),
            shafts: get(&self.shafts),
            feet: get(&self.feet),
        }
    }
}

/// What [`corners_with`] returns.
pub struct Gathered {
    /// `B` per object per corner.
    pub radiosity: CornerValues,
    /// The light received `H` per object per corner.
    pub irradiance: CornerValues,
    pub counts: Counts,
    /// Sources whose values were taken from the frame before, and computed ([`KeptGather`]).
    pub reuse: Reuse,
    /// What this gather keeps for the next frame, when asked to.
    pub kept: Option<KeptGather>,
}

/// What a gather may take from the frame before, and whether it keeps its own values.
#[derive(Clone, Copy, Default)]
pub struct Keeping<'a> {
    /// The last frame's kept values and what changed since.
    pub from: Option<(&'a KeptGather, Changes<'a>)>,
    /// Keep this frame's, at most this many bytes (0: keep nothing).
    pub cap: usize,
}

/// `B` and the light received `H` (`B = E + rho H`) at every face corner of `scene` (placed at
/// `frame`), per object in face order (the order of
/// [`crate::scene::json::ObjectResult::corner_radiosity`]), and the number of distinct points:
/// the fast gather ([`Mode::Fast`]).
pub fn corners(
    inputs: &Inputs,
    scene: &Scene,
    frame: f64,
    progress: Progress,
) -> Result<(CornerValues, CornerValues, usize)> {
    let g = corners_with(inputs, scene, frame, progress, Mode::Fast)?;
    Ok((g.radiosity, g.irradiance, g.counts.points))
}

/// [`corners`] with the sources taken as `mode` says, and what it did.
pub fn corners_with(
    inputs: &Inputs,
    scene: &Scene,
    frame: f64,
    progress: Progress,
    mode: Mode,
) -> Result<Gathered> {
    corners_keeping(inputs, scene, frame, progress, mode, Keeping::default())
}

/// [`corners_with`], taking what `keeping` holds from the frame before where it still holds and
/// keeping this frame's values for the next ([`KeptGather`]): the same values as a fresh
/// gather, bit for bit.
pub fn corners_keeping(
    inputs: &Inputs,
    scene: &Scene,
    frame: f64,
    progress: Progress,
    mode: Mode,
    keeping: Keeping,
) -> Result<Gathered> {
    let tree = inputs.tree;
    let nb = tree.basis.len();
    let (points, point_of_corner, corners_per_object) = corner_points(
        scene,
        frame,
        |o, f, s, t| {
            let key = (o as u32, f as u32, false);
            let face = tree.faces.binary_search_by(|e| (e.object, e.face, e.back).cmp(&key)).ok()?;
            // The face's own parameters (a mirrored face runs its `s` backwards, as
            // `HierarchicalFrame::eval_face` reads it).
            let s = if tree.faces[face].mirrored { 1.0 - s } else { s };
            Some((face, s, t))
        },
        |face| tree.faces[face].patch,
    );
    let stop = Stop::new(progress, points.len());
    if !progress(0.0, "corner gather") {
        return Err(crate::error::Error::Cancelled);
    }
    let mut gather = Gather::new(inputs, &stop, mode)?;
    // The points' direct light takes its kept shadow rays when the kept values' lights cast
    // alike, but for the sources placed otherwise since (crate::lights::kept).
    gather.direct_kept = keeping.from.and_then(|(kept, changes)| {
        let (now, then) = (inputs.lights?, kept.lights.as_deref()?);
        let changed = now.changed_sources(then)?;
        Some((now.swept_for_rays(changes.swept()), changed))
    });
    let solids = inputs
        .occluders
        .is_some()
        .then(|| Solids::new(&tree.faces, scene.objects.len()))
        .filter(|s| !s.is_empty());
    // Points keep their values while the kept bytes stay under the cap (which points is a
    // matter of the threads' timing; the values are the same either way).
    let kept_bytes = AtomicU64::new(0);
    // Which faces emit: an emitter's values are not a dark face's.
    let emitting: Vec<bool> = inputs.emission.iter().map(|e| *e != [0.0; 3]).collect();
    let lit_or_dimmed = keeping.from.map_or_else(Vec::new, |(kept, _)| kept.lit_or_dimmed(tree, &emitting));
    let from = keeping.from.map(|(kept, changes)| (kept, changes.with_lit_or_dimmed(&lit_or_dimmed)));
    let gathered: Vec<([[f64; 3]; 2], Option<kept::KeptPoint>, Reuse)> = points
        .par_iter()
        .enumerate()
        .map(|(k, p)| {
            stop.done.fetch_add(1, Ordering::Relaxed);
            if stop.stopped() {
                return ([[0.0; 3]; 2], None, Reuse::default());
            }
            let Some(at) = p.at else {
                return ([p.exitance(scene, frame), [0.0; 3]], None, Reuse::default());
            };
            let previous = from.and_then(|(kept, changes)| Some((kept.point(k, mode, nb)?, changes)));
            let mut memo = Memo::new(previous, nb, keeping.cap > 0);
            let values = gather.point(at, p.normal, solids.as_ref(), true, &mut memo);
            let reuse = memo.reuse;
            let kept = memo.into_kept().filter(|kp| {
                let bytes = kp.bytes() as u64;
                kept_bytes.fetch_add(bytes, Ordering::Relaxed) + bytes <= keeping.cap as u64
            });
            (values, kept, reuse)
        })
        .collect();
    stop.outcome()?;
    let reuse = gathered.iter().fold(Reuse::default(), |a, (_, _, r)| Reuse {
        kept: a.kept + r.kept,
        computed: a.computed + r.computed,
    });
    let per_object = |which: usize| {
        let mut out = Vec::with_capacity(corners_per_object.len());
        let mut it = point_of_corner.iter().map(|&k| gathered[k].0[which]);
        for &n in &corners_per_object {
            out.push(it.by_ref().take(n).collect());
        }
        out
    };
    let counts = gather.counters.counts(points.len());
    let (radiosity, irradiance) = (per_object(0), per_object(1));
    let kept = (keeping.cap > 0)
        .then(|| KeptGather::new(mode, nb, emitting, gathered.into_iter().map(|g| g.1).collect()));
    Ok(Gathered { radiosity, irradiance, counts, reuse, kept })
}

/// The point being gathered: where it is and which face it is on (its rays skip that face).
struct Receiver {
    x: DVec3,
    n: DVec3,
    face: u32,
    /// Its face's bounding radius.
    radius: f64,
}

/// The light a point has gathered so far: `H`, and the form factors summed for the hemisphere
/// bound.
#[derive(Clone, Copy, Default)]
struct Received {
    h: [f64; 3],
    form_factors: f64,
}

impl Received {
    fn add(&mut self, h: [f64; 3], form_factor: f64) {
        for c in 0..3 {
            self.h[c] += h[c];
        }
        self.form_factors += form_factor;
    }
}

struct Gather<'a> {
    inputs: &'a Inputs<'a>,
    stop: &'a Stop<'a>,
    mode: Mode,
    sources: Sources<'a>,
    rule: GaussLegendre,
    /// The rule past [`FAR_RATIO`].
    far_rule: GaussLegendre,
    counters: Counters,
    /// With the kept values' lights cast alike, the boxes the moves since swept and the sources
    /// placed otherwise since, for the points' direct light ([`Memo::direct`]).
    direct_kept: Option<(Vec<crate::geometry::Aabb>, Vec<bool>)>,
}

impl<'a> Gather<'a> {
    fn new(inputs: &'a Inputs<'a>, stop: &'a Stop<'a>, mode: Mode) -> Result<Self> {
        Ok(Self {
            inputs,
            stop,
            mode,
            sources: Sources::new(
                inputs.tree,
                inputs.state,
                inputs.links,
                inputs.blocked,
                mode == Mode::Fast,
            )?,
            rule: GaussLegendre::new(GAUSS_POINTS),
            far_rule: GaussLegendre::new(FAR_POINTS),
            counters: Counters::default(),
            direct_kept: None,
        })
    }

    /// `B` and `H` at `(s,t)` of face `f` (its patch's parameters), gathered with the shading normal
    /// `normal` where it is not the face's own; with `feet`, the part of a touched source next
    /// to the point counts with `B` gathered at the foot point (itself without feet).
    fn point(
        &self,
        (f, s, t): (usize, f64, f64),
        normal: Option<DVec3>,
        solids: Option<&Solids>,
        feet: bool,
        memo: &mut Memo,
    ) -> [[f64; 3]; 2] {
        let tree = self.inputs.tree;
        let face = &tree.faces[f];
        let (x, n) = shading_point(&face.patch, s, t, normal);
        let emission = self.inputs.emission[f];
        if let Some(solids) = solids {
            let (centre, radius) = face.patch.bounding_sphere();
            let (p, nf) = (face.patch.point(s, t), face.patch.area_vector(s, t).normalize_or_zero());
            if solids.buries_surface_point(p, nf, centre, radius) {
                return [emission, [0.0; 3]];
            }
        }
        memo.at(x, n);
        let rx = Receiver { x, n, face: f as u32, radius: face.patch.bounding_sphere().1 };
        let feet = feet.then_some(solids);
        let (leaf, _, _) = tree.leaf_at(f, s, t);
        let kept = self.direct_kept.as_ref().map(|(swept, changed)| (&swept[..], &changed[..]));
        let direct = self.inputs.lights.map_or([0.0; 3], |l| memo.direct(l, (x, n, f as u32), kept));
        let mut got = Received::default();
        let mut ranked = Vec::new();
        let mut tails = [0.0; 3];
        self.sources.each(
            leaf,
            |linked| {
                Counters::add(&self.counters.sources, 1);
                match self.mode {
                    Mode::Fast => ranked.extend(self.rank(&rx, linked, feet.is_some(), memo)),
                    // A surface source is integrated from the point whatever the link (a light
                    // linked with the cluster of a model's faces casts the model's own shadows on
                    // them).
                    Mode::Exhaustive if tree.node(linked.source).is_cluster() => {
                        got.add(self.cluster_cast(&rx, (linked.source, Slot::NONE), memo), 0.0)
                    }
                    Mode::Exhaustive => {
                        self.surface_source(&rx, (linked.source, Slot::NONE), feet, &mut got, memo)
                    }
                }
                !self.stop.stopped()
            },
            |tail| {
                let e = crate::hierarchy::lobes::eval(tail, n);
                for c in 0..3 {
                    tails[c] += e[c];
                }
            },
        );
        got.add(tails, 0.0);
        self.settle(&rx, &ranked, direct.iter().sum(), feet, &mut got, memo);
        if self.stop.stopped() {
            return [[0.0; 3]; 2];
        }
        let bound = crate::hemisphere::bound(got.form_factors);
        let rho = tree.reflectance[f];
        let received: [f64; 3] = std::array::from_fn(|c| bound * got.h[c] + direct[c]);
        [std::array::from_fn(|c| emission[c] + rho[c] * received[c]), received]
    }

    /// Whether the surface node `source` is near the point ([`NEAR_RATIO`]).
    fn is_near(&self, rx: &Receiver, source: NodeId) -> bool {
        let node = self.inputs.tree.node(source);
        rx.x.distance(node.centre) < NEAR_RATIO * node.radius
    }
}
