//! Final gather at face corners: radiosity evaluated at a point from the Galerkin solution,
//!
//! `B(x) = E(x) + rho(x) sum_j integral_j g(x,y) V(x,y) B_j(y) dA_y`   (eq. 1 at one point),
//!
//! with `B_j(y) = sum_l b_j^l Gamma_l(y)` the solved polynomials (eq. 3) and the visibility `V`
//! cast from `x` itself. A face's own polynomial cannot follow what changes inside the face: a
//! corner hidden under a block standing on the floor, or behind a light hung just below the
//! ceiling, and the contact shadow next to it. The gather sees those at the corner, as a path
//! tracer's vertex bake does; where the polynomial is good, both agree to quadrature error. This
//! is the classic "final gather" / local pass of radiosity systems (e.g. Lischinski et al. 1993).
//!
//! Sources are the emitters, always with shadow rays from the corner (direct light casts the
//! sharpest shadows, and a corner on its element's edge can sit in a penumbra none of the
//! element's visibility samples is in), and the elements linked with the corner's element. For
//! those, which rays are cast depends on the link's visibility and on what lies next to the
//! corner: a corner on an element edge can be hidden while every visibility sample of its element
//! sees (a light hung just below the ceiling over a corner), or see while none does, and a pair
//! blocked everywhere has no link at all. So when some occluder comes within the element's radius
//! of the corner, every element in front is a source and every ray is cast; elsewhere a partial
//! link reads its visibility mask from the corner's cell, a fully visible link stays visible and
//! a blocked one blocked. Where the corner touches a source (a block's foot on the floor), the
//! part of the source next to the contact counts with `B` gathered at the foot point (`Foot`).
//!
//! Measured against Cycles (README, "Validation against Cycles"; 819 faces, 4096 spp): corners
//! from the face polynomials 16.8% relative RMSE at order 2, gathered 2.0% (1.6% at order 1).
//!
//! What a corner keeps from frame to frame (the seed's idea applied to the gather): the *moments*
//! `m_j^l = integral_j g(x,y) V(x,y) Gamma_l(y) dA_y` of each source, so that
//! `B(x) = E + rho sum_j sum_l m_j^l b_j^l` is a dot product once the solution changes. A moment
//! is recomputed only when the corner or the source moved, when what decides its visibility
//! changed (the link's mask, the corner's neighbourhood), or when a moving object's swept bounds
//! enter the shaft between the corner and the source.
//!
//! Which sources a corner has, and how each one's visibility is decided, is re-derived only for
//! corners whose element had a pair with a non-emitter added, whose sources came or went with a
//! change of a pair's visibility ([`crate::links::LinkStore::take_visibility_changes`]), or that
//! a moved element may have turned towards or away from. The others visit only their moved
//! sources, those with rays and those whose pair's visibility changed. A kept moment whose shaft
//! a swept box enters holds when its rays meet the moved triangles alike at the old and the new
//! places ([`crate::visibility::MovedOccluders`]). On the moving-light box (1,079 patches, 1,767
//! corner points, 1.33M moments) these took the gather of a frame from 75 to 53-56 ms on one
//! thread, bit-identical.
//!
//! By job: `points.rs` the corner points (merged, inset, their shading points, the buried ones),
//! `row.rs` a point's sources and which kept moments still hold, `moments.rs` a source's moments
//! at a point, `nodes.rs` a source rectangle's Gauss nodes, `penumbra.rs` an emitter's penumbra
//! check, `value.rs` a point's value from its moments, `stop.rs` the cancel and progress; here the
//! frame's driver ([`CornerGather::run`]: what changed since the kept gather, the rows, the
//! values) and what the parts share ([`Gather`]).

use glam::DVec3;
use rayon::prelude::*;

mod moments;
mod nodes;
pub(crate) mod penumbra;
mod points;
mod row;
mod stop;
mod value;
use nodes::{GAUSS_POINTS, GaussNodes};
use points::buried_points;
pub(crate) use points::{CornerPoint, corner_points};
pub use points::{INSET, SMOOTH_LIFT, shading_point};
pub(crate) use stop::Stop;
use value::{received, source_irradiance};

use crate::error::{Error, Result};
use crate::geometry::{Aabb, FrontPlane, Patch, Rect};
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::system::{Progress, System};
use crate::visibility::{MovedOccluders, Occluders, Visibility};

/// A source (sub-)rectangle is integrated by the Gauss rule once the distance from the corner to
/// its centre is this many times its bounding radius; closer, it is split in four.
const GAUSS_RATIO: f64 = 3.0;

/// Splits before a source rectangle is taken as a polygon: its exact point-to-polygon form
/// factor times the basis at its centre.
const MAX_DEPTH: u32 = 12;

/// Splits (counted from the whole source) of an emitter's rectangle in a penumbra, at most: one
/// whose Gauss nodes disagree on visibility, or whose corners disagree with its nodes, is split
/// in four, down to a 16th of the light per axis (tests/penumbra.rs).
pub(crate) const PENUMBRA_DEPTH: u32 = 4;

/// A part of a source across the edge of a foot's ball ([`Foot`]) is split while its bounding
/// radius exceeds this fraction of the ball's radius, to [`BALL_DEPTH`] levels at most; then its
/// seen Gauss nodes count on the side of the edge each lies on. (Before 2026-12-08 a part counted
/// wholly on its centre's side, split to an eighth of the ball and to [`MAX_DEPTH`] at most: the
/// edge alone was most of a real mesh's gather, and a ball smaller than a twelfth-level part of a
/// large source, a small face touching a large one, lost its foot. docs/benchmarks.md, "The
/// foot's ball".)
pub(crate) const BALL_EDGE: f64 = 0.25;

/// Deepest split across a foot's ball edge, a guard only: parts `2^-30` of a source's side, a
/// ball a billionth of its source (a centimetre face hovering 10 um over a 200 m floor is
/// `1e-7`; tests/gather.rs). The ring of parts across the edge costs about the same at every
/// level, so the depth a ball needs costs little.
pub(crate) const BALL_DEPTH: u32 = 30;

/// A foot's ball as the recursions carry it: its radius around the point, and the foot's
/// parameters on the source.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ball {
    pub radius: f64,
    pub foot: (f64, f64),
}

/// Where a rectangle of a source lies against a foot's ball ([`Ball::side`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Side {
    /// Wholly inside: its seen form factor counts with `B` at the foot.
    Inside,
    /// Across the edge and coarse against the ball: split in four, each quadrant with the ball.
    Split,
    /// Across the edge, fine enough: taken as any rectangle, its seen nodes shared out by side.
    Across,
    /// Wholly outside: any rectangle.
    Outside,
}

impl Ball {
    /// Where the rectangle `rect` (`sub` of the source, its bounding sphere `distance` from the
    /// point with radius `radius`) lies against the ball, at depth `depth`: the one rule the
    /// flat gather and both of the hierarchy's recursions take it by.
    pub(crate) fn side(&self, rect: &Rect, sub: &Patch, (distance, radius): (f64, f64), depth: u32) -> Side {
        let r = self.radius;
        if distance + radius <= r || (depth >= BALL_DEPTH && distance <= r) {
            Side::Inside
        } else if distance - radius < r {
            // (Written so that a NaN is outside, never split.)
            if self.splits(rect, sub, radius, depth) { Side::Split } else { Side::Across }
        } else {
            Side::Outside
        }
    }

    /// Whether a rectangle across the ball's edge (`sub` of the source, bounding radius `radius`)
    /// is split again: while it is coarse against the ball ([`BALL_EDGE`]) and above
    /// [`BALL_DEPTH`]; past [`MAX_DEPTH`] only near the foot, within as many of its own widths as
    /// the ball spans of its shorter side (at most [`FOOT_REACH`]). A sliver source's rectangles
    /// are far longer than wide, so that their bounding spheres, all across the ball's edge,
    /// would double in number with each level (an arbitrary scene of the C ABI's property test,
    /// a triangle 1e8 long, ran for minutes); near the foot they stay a few hundred at most.
    fn splits(&self, rect: &Rect, sub: &Patch, radius: f64, depth: u32) -> bool {
        if radius <= BALL_EDGE * self.radius || depth >= BALL_DEPTH {
            return false;
        }
        if depth < MAX_DEPTH {
            return true;
        }
        let [c0, c1, _, c3] = sub.corners;
        let side = c0.distance(c1).min(c0.distance(c3));
        let reach = (self.radius / side).ceil().min(FOOT_REACH) + 1.0;
        let (ws, wt) = (reach * (rect.s1 - rect.s0), reach * (rect.t1 - rect.t0));
        let (s, t) = self.foot;
        rect.s0 - ws <= s && s <= rect.s1 + ws && rect.t0 - wt <= t && t <= rect.t1 + wt
    }
}

/// How many of its own widths from the foot a rectangle past [`MAX_DEPTH`] may lie and still split
/// for the ball ([`Ball::splits`]).
const FOOT_REACH: f64 = 8.0;

/// A corner whose normal and a source's are opposed by more than this cosine faces the source.
pub(crate) const FACING: f64 = 0.5;

/// A corner facing a source from closer than this fraction of the source's radius takes the part
/// of the source next to it from a foot ([`Gather::near_facing`]).
pub(crate) const NEAR_FACING: f64 = 0.2;

/// The part of a faced source within this many times the distance counts with the foot's `B`: a
/// disc of radius `sqrt(15) d`, 15/16 of a parallel plane's form factor.
pub(crate) const FOOT_BALL: f64 = 4.0;

/// Moved elements up to this many are tested one by one against a kept moment's rays
/// ([`Gather::unchanged`]); with more, a swept box entering the shaft recomputes the moment.
const MAX_MOVED_OCCLUDERS: usize = 64;

/// Per element, the non-emitter sources whose pair with it changed visibility since the kept
/// gather: `(source, pair)`, sorted, each once.
struct SourceChanges {
    first: Vec<u32>,
    changes: Vec<(u32, u32)>,
}

impl SourceChanges {
    fn of(&self, e: usize) -> &[(u32, u32)] {
        &self.changes[self.first[e] as usize..self.first[e + 1] as usize]
    }
}

/// `B` at every face corner, per object in face order.
pub type CornerValues = Vec<Vec<[f64; 3]>>;

/// Moved elements up to this many get a swept box each; more are boxed per object.
const MAX_SWEPT_BOXES: usize = 32;

/// The corner gather of one frame, kept to update the next one's.
pub struct CornerGather {
    /// Distinct corner points.
    points: Vec<CornerPoint>,
    /// Per point, its sources and their moments.
    rows: Vec<Row>,
    /// The element patches `rows` were computed with.
    patches: Vec<Patch>,
    /// Their Gauss nodes, with the basis and visibility cells they were made for.
    nodes: Vec<GaussNodes>,
    basis: crate::basis::Basis,
    cells_per_axis: usize,
    /// The emitters and whether there were occluders: a row's sources depend on both.
    is_emitter: Vec<bool>,
    /// Pairs in the link store then (those past it were added since).
    pairs: usize,
    occluded: bool,
    /// Per element, on the scene's hull (not an occluder) in this gather's occluders.
    hull: Vec<bool>,
    /// Per point, inside another closed surface (empty: none are, or visibility is off).
    buried: Vec<bool>,
    /// The irradiance `H` at every face corner, as the corners of [`CornerGather::run`]'s
    /// values: `B = E + rho H` (the lights' direct light included; 0 at a buried point).
    irradiance: CornerValues,
    /// The lights this gather's direct light was taken from, and per point its shadow rays'
    /// outcomes, for the next gather to take where no move changed them ([`crate::lights::kept`]).
    lights: Option<std::sync::Arc<crate::lights::direct::DirectLight>>,
    direct_outcomes: Vec<crate::lights::kept::Outcomes>,
}

/// What this frame's gather did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GatherStats {
    /// Distinct corner points and (point, source) moments.
    pub points: usize,
    pub moments: usize,
    /// Moments computed this frame (all of them on a first frame).
    pub recomputed: usize,
    /// The lights' shadow rays at the points traced, and taken from the last gather's
    /// ([`crate::lights::kept`]).
    pub direct_rays_traced: u64,
    pub direct_rays_taken: u64,
}

/// One point's sources, sorted by element, with how their visibility was decided and their
/// moments (`nb` per source).
#[derive(Clone, Debug, Default)]
struct Row {
    near: bool,
    sources: Vec<u32>,
    modes: Vec<Mode>,
    moments: Vec<f32>,
    /// Sources the point touches, whose part next to it counts with `B` at the foot point.
    feet: Vec<Foot>,
}

impl Row {
    /// Moments held, the feet's included.
    fn moment_count(&self) -> usize {
        self.sources.len() + self.feet.iter().map(|f| f.row.moment_count()).sum::<usize>()
    }
}

/// Where a corner touches a source (the foot of a block on the floor, a room's edge), nearly all
/// of that source's form factor comes from a millimetre around the contact, where the source's
/// own polynomial is worst when the contact line crosses it (a floor face half under the block).
/// That part of the source (`weight = integral g V dA` over it) counts with `B` gathered at the
/// foot point instead (`row`, itself without feet).
#[derive(Clone, Debug)]
struct Foot {
    element: u32,
    weight: f32,
    row: Row,
    /// The foot point's local `(s,t)` on `element` (for the lights' direct light there).
    at: (f64, f64),
}

/// How a moment's visibility was decided; a different decision recomputes the moment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// Everything visible (a fully visible link, or visibility off).
    Open,
    /// Shadow rays from the corner.
    Rays,
    /// The link's mask from the corner's visibility cell: bit `s` for the source's cell `s`.
    Mask(u16),
}

impl CornerGather {
    /// Gathers every face corner of `sys` (placed as `scene` is at `frame`), reusing what
    /// `previous` (the last frame's gather of the same system) computed where nothing that
    /// decides it changed. `changed` lists the pairs of `sys.links` added or whose visibility
    /// changed since `previous` was made ([`crate::links::LinkStore::take_visibility_changes`];
    /// `None`: unknown). Returns the corners per object in face order (the order of
    /// [`crate::scene::json::ObjectResult::corner_radiosity`]) and the gather to keep.
    pub fn run(
        sys: &System,
        scene: &Scene,
        frame: f64,
        occluders: Option<&Occluders>,
        previous: Option<CornerGather>,
        changed: Option<&[crate::links::PairId]>,
        progress: Progress,
    ) -> Result<(CornerValues, CornerGather, GatherStats)> {
        let rule = GaussLegendre::new(GAUSS_POINTS);
        let patches: Vec<Patch> = sys.elements.iter().map(|e| e.patch).collect();
        let cells_per_axis = scene.settings.visibility_samples;
        // An element that did not move keeps its nodes (the same computation on the same patch).
        let mut previous = previous;
        let kept_nodes: Vec<Option<GaussNodes>> = match previous.as_mut() {
            Some(p)
                if (p.basis, p.cells_per_axis, p.patches.len())
                    == (sys.basis, cells_per_axis, patches.len()) =>
            {
                let old = std::mem::take(&mut p.nodes);
                old.into_iter()
                    .zip(p.patches.iter().zip(&patches))
                    .map(|(n, (a, b))| (a == b).then_some(n))
                    .collect()
            }
            _ => (0..patches.len()).map(|_| None).collect(),
        };
        let nodes: Vec<GaussNodes> = patches
            .par_iter()
            .zip(kept_nodes)
            .map(|(p, kept)| {
                kept.unwrap_or_else(|| GaussNodes::new(p, &Rect::UNIT, &rule, sys.basis, cells_per_axis))
            })
            .collect();
        let nb = sys.basis.len();
        let is_emitter: Vec<bool> =
            (0..patches.len()).map(|e| sys.emission[e * nb].iter().any(|&x| x > 0.0)).collect();
        let emitters: Vec<usize> = (0..patches.len()).filter(|&e| is_emitter[e]).collect();
        let (points, point_of_corner, corners_per_object) = corner_points(
            scene,
            frame,
            |o, f, s, t| sys.element_of_face(o, f, s, t),
            |e| sys.elements[e].patch,
        );

        // What moved since `previous`, by object: each object's old and new bounds.
        let previous = previous.filter(|p| p.points == points && p.patches.len() == patches.len());
        let moved: Vec<bool> = match &previous {
            Some(p) => patches.iter().zip(&p.patches).map(|(a, b)| a != b).collect(),
            None => vec![true; patches.len()],
        };
        let kept_buried = previous
            .as_ref()
            .filter(|p| !moved.iter().any(|&m| m) && p.occluded == occluders.is_some())
            .map(|p| p.buried.clone());
        let mut swept: Vec<Aabb> = Vec::new();
        if let Some(p) = &previous {
            // One box per moved element while they are few (tighter: fewer shafts crossed), else
            // one per moving object (fewer tests per moment).
            let movers: Vec<usize> = (0..patches.len()).filter(|&e| moved[e]).collect();
            let mut boxes = std::collections::BTreeMap::new();
            for &e in &movers {
                let key = if movers.len() <= MAX_SWEPT_BOXES { e } else { sys.elements[e].object as usize };
                let b = boxes.entry(key).or_insert(Aabb::EMPTY);
                *b = b.union(patches[e].bounds()).union(p.patches[e].bounds());
            }
            swept.extend(boxes.into_values());
        }
        // Rows whose sources cannot have changed skip re-deriving them (`Gather::settled`): when
        // the emitters and the occluders' presence are those of `previous`, and the changed
        // pairs are known. Per element, whether a pair with a non-emitter source (one that
        // `Gather::element_links` lists) was added, and the non-emitter sources whose pair
        // changed visibility, sorted, each once (`first[e]..first[e + 1]` of `changes`).
        let settled_ok = previous.as_ref().is_some_and(|p| {
            p.is_emitter == is_emitter && p.occluded == occluders.is_some() && changed.is_some()
        });
        let mut links_added = vec![!settled_ok; patches.len()];
        let mut by_element: Vec<(u32, u32, u32)> = Vec::new();
        if let (Some(p), Some(changed)) = (previous.as_ref().filter(|_| settled_ok), changed) {
            for &id in changed {
                let pair = sys.links.pair(id);
                for (e, j) in [(pair.a, pair.b), (pair.b, pair.a)] {
                    if is_emitter[j as usize] {
                        continue;
                    }
                    if id as usize >= p.pairs {
                        links_added[e as usize] = true;
                    } else {
                        by_element.push((e, j, id));
                    }
                }
            }
        }
        by_element.sort_unstable();
        by_element.dedup();
        let mut first = vec![0u32; patches.len() + 1];
        for &(e, ..) in &by_element {
            first[e as usize + 1] += 1;
        }
        for e in 0..patches.len() {
            first[e + 1] += first[e];
        }
        let source_changes =
            SourceChanges { first, changes: by_element.iter().map(|&(_, j, p)| (j, p)).collect() };
        let movers: Vec<u32> = (0..patches.len()).filter(|&e| moved[e]).map(|e| e as u32).collect();
        // The moved elements' triangles at their old and new places, when both are occluders
        // (on the hull at neither place), for `Gather::unchanged`.
        let hull: Vec<bool> =
            occluders.map_or(Vec::new(), |o| (0..patches.len()).map(|e| o.on_hull(e)).collect());
        let moved_occluders = previous
            .as_ref()
            .filter(|_| movers.len() <= MAX_MOVED_OCCLUDERS)
            .filter(|p| {
                let occluder = |h: &[bool], e: u32| h.get(e as usize) == Some(&false);
                movers.iter().all(|&e| occluder(&hull, e) && occluder(&p.hull, e))
            })
            .map(|p| {
                MovedOccluders::new(movers.iter().map(|&e| (&p.patches[e as usize], &patches[e as usize])))
            });
        let stop = Stop::new(progress, points.len());
        // Asked once before any corner (later polls wait for POLL_INTERVAL).
        if !progress(0.0, "corner gather") {
            return Err(Error::Cancelled);
        }
        let scale = patches.iter().fold(Aabb::EMPTY, |b, p| b.union(p.bounds())).diagonal().length();
        let planes: Vec<Option<FrontPlane>> = patches.iter().map(Patch::front_plane).collect();
        let radii: Vec<f64> = patches.iter().map(|p| p.bounding_sphere().1).collect();
        let gather = Gather {
            sys,
            stop: &stop,
            planes: &planes,
            radii: &radii,
            emitters: &emitters,
            is_emitter: &is_emitter,
            patches: &patches,
            nodes: &nodes,
            rule: &rule,
            occluders,
            cells_per_axis,
            moved: &moved,
            movers: &movers,
            links_added: &links_added,
            source_changes: &source_changes,
            swept: &swept,
            moved_occluders: moved_occluders.as_ref(),
            swept_union: swept.iter().fold(Aabb::EMPTY, |u, b| u.union(*b)),
            union_eps: union_eps(&patches, &swept, 1e-9 * scale.max(1e-300)),
            eps: 1e-9 * scale.max(1e-300),
            links: (0..patches.len()).map(|_| std::sync::OnceLock::new()).collect(),
            kinds: {
                let mut kinds = crate::budget::try_vec(sys.links.len(), "the corner gather's link kinds")?;
                kinds.par_extend(sys.links.pairs().par_iter().map(|p| match p.visibility {
                    Visibility::Full => VisKind::Full,
                    Visibility::Blocked => VisKind::Blocked,
                    Visibility::Partial(_) => VisKind::Partial,
                }));
                kinds
            },
        };
        // The lights' direct light at every point, its shadow rays taken from the last gather's
        // where no move can have changed them.
        let (direct, direct_outcomes, direct_rays) =
            direct_at_points(sys, &points, previous.as_ref(), &moved, &swept);
        let kept_rows: Vec<Option<Row>> = match previous {
            Some(p) => p.rows.into_iter().map(Some).collect(),
            None => vec![None; points.len()],
        };
        // Four points at a time: their rows, then their values, the four sums interleaved (each
        // in its own order, as one at a time); reading kept moments overlaps other chunks' rays.
        // Per point: its row, how many moments were computed, and `[B, H]`. (Reserved whole
        // first, so the allocator's refusal of the results is an error; a chunk cut short by a
        // stop adds nothing, and the stop is checked below.)
        type Gathered = (Row, usize, [[f64; 3]; 2]);
        let mut gathered: Vec<Gathered> =
            crate::budget::try_vec(points.len(), "the corner gather's results")?;
        let chunks = points.par_chunks(4).zip(direct.par_chunks(4)).zip(kept_rows.into_par_iter().chunks(4));
        gathered.par_extend(chunks.flat_map_iter(|((points, direct), kept)| {
            stop.done.fetch_add(points.len(), std::sync::atomic::Ordering::Relaxed);
            if stop.stopped() {
                return Vec::new();
            }
            let rows: Vec<(Row, usize)> = points
                .iter()
                .zip(kept)
                .map(|(point, kept)| match point.at {
                    Some((e, s, t)) => gather.row(e, s, t, point.normal, kept, true),
                    None => (Row::default(), 0),
                })
                .collect();
            let mut values: Vec<[f64; 3]> = points
                .iter()
                .map(|p| match p.at {
                    Some(_) => [0.0; 3],
                    None => p.exitance(scene, frame),
                })
                .collect();
            let at: Vec<(usize, usize)> =
                points.iter().enumerate().filter_map(|(k, p)| Some((k, p.at?.0))).collect();
            // `H`, the light the point receives (without its own emission and reflectance),
            // beside `B = E + rho H`.
            let mut light = vec![[0.0; 3]; points.len()];
            let sums: Vec<[f64; 3]> = if let [a, b, c, d] = at[..] {
                source_irradiance(sys, [&rows[a.0].0, &rows[b.0].0, &rows[c.0].0, &rows[d.0].0]).to_vec()
            } else {
                at.iter().map(|&(k, _)| source_irradiance(sys, [&rows[k].0])[0]).collect()
            };
            for (&(k, e), sum) in at.iter().zip(sums) {
                light[k] = received(sys, &rows[k].0, sum);
                let (rho, emission) = (sys.surface_reflectance[e], sys.emission[e * nb]);
                values[k] = std::array::from_fn(|c| emission[c] + rho[c] * light[k][c]);
            }
            for (k, (p, direct)) in points.iter().zip(direct).enumerate() {
                let (Some(at), Some(direct)) = (p.at, direct) else { continue };
                for c in 0..3 {
                    light[k][c] += direct[c];
                    values[k][c] += sys.surface_reflectance[at.0][c] * direct[c];
                }
            }
            rows.into_iter()
                .zip(values)
                .zip(light)
                .map(|(((row, n), v), h)| (row, n, [v, h]))
                .collect::<Vec<_>>()
        }));
        stop.outcome()?;
        let mut values: Vec<[f64; 3]> = crate::budget::try_vec(points.len(), "the corner gather's results")?;
        values.extend(gathered.iter().map(|g| g.2[0]));
        let mut light: Vec<[f64; 3]> = crate::budget::try_vec(points.len(), "the corner gather's results")?;
        light.extend(gathered.iter().map(|g| g.2[1]));
        // A point inside another closed surface receives nothing (crate::solids); which points
        // are is decided again only when something moved.
        let buried = match kept_buried {
            Some(b) => b,
            None if occluders.is_some() => buried_points(sys, scene, frame, &patches, &points),
            None => Vec::new(),
        };
        for (k, _) in buried.iter().enumerate().filter(|(_, b)| **b) {
            let e = points[k].at.expect("a buried point is on an element").0;
            values[k] = sys.emission[e * nb];
            light[k] = [0.0; 3];
        }
        let rows: Vec<(Row, usize)> = gathered.into_iter().map(|(r, n, ..)| (r, n)).collect();
        let stats = GatherStats {
            points: points.len(),
            moments: rows.iter().map(|(r, _)| r.moment_count()).sum(),
            recomputed: rows.iter().map(|(_, n)| n).sum(),
            direct_rays_traced: direct_rays.traced,
            direct_rays_taken: direct_rays.taken,
        };
        let per_object = |values: &[[f64; 3]]| {
            let mut out: CornerValues = Vec::with_capacity(corners_per_object.len());
            let mut it = point_of_corner.iter().map(|&k| values[k]);
            for &n in &corners_per_object {
                out.push(it.by_ref().take(n).collect());
            }
            out
        };
        let (out, irradiance) = (per_object(&values), per_object(&light));
        let rows = rows.into_iter().map(|(r, _)| r).collect();
        let kept = CornerGather {
            points,
            rows,
            patches,
            nodes,
            basis: sys.basis,
            cells_per_axis,
            is_emitter,
            pairs: sys.links.len(),
            occluded: occluders.is_some(),
            hull,
            buried,
            irradiance,
            lights: sys.lights.clone(),
            direct_outcomes,
        };
        Ok((out, kept, stats))
    }
}

/// The lights' direct irradiance at every point (`None` off the elements or without lights),
/// and its shadow rays' outcomes per point: taken from `previous`'s where its lights were placed
/// as these, the point's element did not move (`moved`) and no box in `swept` meets a ray
/// ([`crate::lights::kept`]), bit for bit what tracing them gives.
fn direct_at_points(
    sys: &System,
    points: &[CornerPoint],
    previous: Option<&CornerGather>,
    moved: &[bool],
    swept: &[Aabb],
) -> (Vec<Option<[f64; 3]>>, Vec<crate::lights::kept::Outcomes>, crate::lights::direct::KeptRays) {
    let Some(lights) = sys.lights.as_deref() else {
        return (vec![None; points.len()], Vec::new(), Default::default());
    };
    // (`previous` holds the same points: the caller kept it only then.) Sources placed otherwise
    // since (a light that moved) cast their rays again; the others' are taken where they hold.
    let kept = previous.filter(|p| p.direct_outcomes.len() == points.len()).and_then(|p| {
        let changed = lights.changed_sources(p.lights.as_deref()?)?;
        Some((p, changed))
    });
    let (last, changed) = kept.map_or((None, Vec::new()), |(p, changed)| (Some(p), changed));
    let swept = lights.swept_for_rays(swept);
    let each: Vec<_> = points
        .par_iter()
        .enumerate()
        .map(|(k, p)| {
            let Some((e, s, t)) = p.at else { return (None, Default::default(), Default::default()) };
            let kept = last.filter(|_| !moved[e]).map(|l| &l.direct_outcomes[k]);
            let (x, n) = shading_point(&sys.elements[e].patch, s, t, p.normal);
            let (irradiance, outcomes, rays) =
                lights.irradiance_keeping(x, n, e as u32, (kept, &changed), &swept);
            (Some(irradiance), outcomes, rays)
        })
        .collect();
    let mut rays = crate::lights::direct::KeptRays::default();
    let mut direct = Vec::with_capacity(each.len());
    let mut outcomes = Vec::with_capacity(each.len());
    for (d, o, r) in each {
        rays.add(r);
        direct.push(d);
        outcomes.push(o);
    }
    (direct, outcomes, rays)
}

impl CornerGather {
    /// The irradiance `H` at every face corner, per object in face order (the corners of the
    /// values [`CornerGather::run`] returned), handed over once.
    pub fn take_irradiance(&mut self) -> CornerValues {
        std::mem::take(&mut self.irradiance)
    }
}

/// `eps` plus a margin for testing the union of the swept boxes against a corner-source shaft:
/// `n.c - |n|.h > d + eps` evaluated in f64 errs by a few ulps of the largest coordinate, so a
/// union box outside by `union_eps` has every box inside it outside by `eps` as computed too.
fn union_eps(patches: &[Patch], swept: &[Aabb], eps: f64) -> f64 {
    let extent = patches
        .iter()
        .map(Patch::bounds)
        .chain(swept.iter().copied())
        .fold(0.0f64, |m, b| m.max(b.min.abs().max_element()).max(b.max.abs().max_element()));
    eps + 1e-10 * extent
}

/// What every corner needs: the solved system, its elements' geometry, the occluders, and what
/// moved since the kept gather.
struct Gather<'a> {
    sys: &'a System,
    /// Polled by every corner and every step of [`Gather::moments`]: once it says stop, rows
    /// are cut short and `run` returns `Cancelled`.
    stop: &'a Stop<'a>,
    /// Elements with emission, and the flag per element.
    emitters: &'a [usize],
    is_emitter: &'a [bool],
    patches: &'a [Patch],
    /// Per element: its plane (planar ones) and bounding radius.
    planes: &'a [Option<FrontPlane>],
    radii: &'a [f64],
    /// Per element: its Gauss nodes over the whole element, the common far case.
    nodes: &'a [GaussNodes],
    rule: &'a GaussLegendre,
    occluders: Option<&'a Occluders>,
    /// Visibility samples per axis of the link masks.
    cells_per_axis: usize,
    /// Per element: moved since the kept gather (all, without one); the moved ones, ascending.
    moved: &'a [bool],
    movers: &'a [u32],
    /// Per element: its sources may differ from the kept gather's ([`Gather::settled`]) because
    /// a pair of it with a non-emitter was added (all, when what changed is unknown).
    links_added: &'a [bool],
    /// Per element, the non-emitter sources whose pair with it changed visibility.
    source_changes: &'a SourceChanges,
    /// Old-and-new bounds of each moving object.
    swept: &'a [Aabb],
    /// The moved elements' triangles at their old and new places (`None`: no kept gather, or
    /// a moved element on the scene's hull at either place).
    moved_occluders: Option<&'a MovedOccluders>,
    /// The union of `swept`, and a margin past `eps` within which a plane test of the union
    /// box cannot round differently from one of a box inside it (see `unchanged`).
    swept_union: Aabb,
    union_eps: f64,
    eps: f64,
    /// Per pair of the link store, the kind of its visibility.
    kinds: Vec<VisKind>,
    /// Per element, built on first use: its linked sources (see [`Gather::element_links`]).
    links: Vec<std::sync::OnceLock<Vec<Linked>>>,
}

/// One linked source: the other element, the pair and the kind of its visibility.
#[derive(Clone, Copy, Debug)]
struct Linked {
    j: u32,
    pair: u32,
    kind: VisKind,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum VisKind {
    Full,
    Blocked,
    Partial,
}

/// A touched source: the foot point's parameters on it and the radius around the corner that
/// counts with the foot's `B`.
#[derive(Clone, Copy, Debug)]
struct Touch {
    s: f64,
    t: f64,
    radius: f64,
}

/// The receiving point and what its rays skip.
struct Receiver {
    x: DVec3,
    n: DVec3,
    element: u32,
    /// Visibility cell of `x` in its element.
    cell: usize,
}

/// Where a Gauss sum's rays look for occluders: in the shaft from the corner to these bounds, or
/// among these triangles (a penumbra's, found once for the rectangle its parts split from).
#[derive(Clone, Copy)]
enum Among<'a> {
    Bounds(&'a Aabb),
    Candidates(&'a [usize]),
}

/// Whether `sub` (of bounding radius `radius`) lies wholly behind the tangent plane of the point
/// `x` with normal `n` (a corner's), by a margin far above rounding: then every Gauss node of it,
/// a convex combination of its corners, has a negative cosine at `x` and its polygon clips away,
/// so it adds nothing and its recursion is skipped (the decimated monastery's gather: 40.6 s ->
/// 35.0 s, bit-identical).
pub(crate) fn behind_plane(x: DVec3, n: DVec3, sub: &Patch, radius: f64) -> bool {
    let margin = 1e-9 * radius;
    sub.corners.iter().all(|p| n.dot(*p - x) < -margin)
}
