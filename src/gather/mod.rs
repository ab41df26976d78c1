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

use glam::DVec3;
use rayon::prelude::*;

mod moments;
mod nodes;
pub(crate) mod penumbra;
mod row;
use nodes::{GAUSS_POINTS, GaussNodes};

use crate::error::{Error, Result};
use crate::geometry::{Aabb, FrontPlane, Patch, Rect};
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::scene::surface::world_normal;
use crate::solids::Solids;
use crate::system::{Progress, System, corner_params};
use crate::visibility::{MovedOccluders, Occluders, Visibility};

/// How often the gather asks the host whether to go on (and reports progress): every corner and
/// every step of a moment's subdivision looks at the flag, one of them calls the host when this
/// much time has passed, so a cancel is seen within about this long (the solve's is one batch).
const POLL_INTERVAL: std::time::Duration = std::time::Duration::from_millis(10);

/// The gather's cancel and progress: the host's callback, called at most every
/// [`POLL_INTERVAL`] from whichever thread looks first, and what it said.
pub(crate) struct Stop<'a> {
    progress: Progress<'a>,
    start: std::time::Instant,
    /// Microseconds after `start` of the last call of `progress`.
    last_poll: std::sync::atomic::AtomicU64,
    cancelled: std::sync::atomic::AtomicBool,
    /// Points gathered so far, of `total`.
    pub done: std::sync::atomic::AtomicUsize,
    total: usize,
    /// A row's allocation the allocator refused ([`crate::budget::try_vec`]): the gather stops
    /// (as cancelled) and returns it.
    failed: std::sync::Mutex<Option<Error>>,
}

impl<'a> Stop<'a> {
    /// The stop of a gather of `total` points.
    pub fn new(progress: Progress<'a>, total: usize) -> Self {
        Stop {
            progress,
            start: std::time::Instant::now(),
            last_poll: 0.into(),
            cancelled: false.into(),
            done: 0.into(),
            total,
            failed: None.into(),
        }
    }

    /// The gather's outcome once its rows are done: the allocation error that stopped it, else
    /// `Cancelled` when the host asked to stop (a cancel seen inside a row cut it short without
    /// an error), else `Ok`.
    pub fn outcome(&self) -> Result<()> {
        if let Some(e) = self.failed.lock().unwrap_or_else(|p| p.into_inner()).take() {
            return Err(e);
        }
        if self.cancelled.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(Error::Cancelled);
        }
        Ok(())
    }

    /// Room for `len` values, or `None` after stopping the gather with the allocation's error.
    pub fn vec<T>(&self, len: usize) -> Option<Vec<T>> {
        crate::budget::try_vec(len, "the corner gather's rows")
            .map_err(|e| {
                self.failed.lock().unwrap_or_else(|p| p.into_inner()).get_or_insert(e);
                self.cancelled.store(true, std::sync::atomic::Ordering::Relaxed);
            })
            .ok()
    }

    /// Whether the host asked to stop; asks it again when [`POLL_INTERVAL`] has passed.
    pub fn stopped(&self) -> bool {
        use std::sync::atomic::Ordering::Relaxed;
        if self.cancelled.load(Relaxed) {
            return true;
        }
        // The clock is read on one call in 32 per thread: a step of `moments` costs more than
        // a flag load but can be cheaper than a clock read.
        thread_local!(static CALLS: std::cell::Cell<u32> = const { std::cell::Cell::new(0) });
        if CALLS.with(|c| {
            c.set(c.get().wrapping_add(1));
            c.get() % 32 != 0
        }) {
            return false;
        }
        let now = self.start.elapsed().as_micros() as u64;
        let last = self.last_poll.load(Relaxed);
        if now.saturating_sub(last) < POLL_INTERVAL.as_micros() as u64
            || self.last_poll.compare_exchange(last, now, Relaxed, Relaxed).is_err()
        {
            return false;
        }
        let fraction = self.done.load(Relaxed) as f64 / self.total.max(1) as f64;
        if !(self.progress)(fraction.min(1.0), "corner gather") {
            self.cancelled.store(true, Relaxed);
        }
        self.cancelled.load(Relaxed)
    }
}

/// Corners are gathered this far inside their face (in its parameter domain): exactly on an edge,
/// a perpendicular neighbour is seen edge-on and drops out, while a vertex bake and the eye see
/// the limit from inside.
pub const INSET: f64 = 1e-3;

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

/// A foot's ball ([`Foot`]) is told from the rest of its source to this fraction of its radius:
/// past it the part of a rectangle the ball holds counts with the side its centre is on. (To
/// [`MAX_DEPTH`], the ball's edge was most of a real mesh's gather: 53M rectangles at the last
/// level of the decimated monastery's 3.7M corner-source pairs.)
pub(crate) const BALL_EDGE: f64 = 1.0 / 8.0;

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
}

/// What this frame's gather did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GatherStats {
    /// Distinct corner points and (point, source) moments.
    pub points: usize,
    pub moments: usize,
    /// Moments computed this frame (all of them on a first frame).
    pub recomputed: usize,
}

/// A corner point: faces of one object meeting at a vertex with the same normal and material see
/// the same light there (4 faces per vertex of a grid), gathered once. A smooth-shaded corner
/// has the mesh's interpolated normal ([`crate::scene::Surface::corner_normals`]), so the faces
/// of a smooth vertex share one point and one value: no facets, as Cycles bakes them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CornerPoint {
    /// The element covering it and the local point (inset), or `None` for a skipped face.
    pub at: Option<(usize, f64, f64)>,
    pub material: u32,
    /// The object and face it was made for: a skipped face's point shows that face's exitance
    /// ([`Scene::emission_of`]).
    pub face: (u32, u32),
    /// The world-space shading normal, where it is not the face's own.
    pub normal: Option<DVec3>,
}

impl CornerPoint {
    /// The exitance of the face the point was made for at `frame`.
    pub fn exitance(&self, scene: &Scene, frame: f64) -> [f64; 3] {
        scene.emission_of(self.face.0 as usize, self.face.1 as usize, self.material, frame)
    }
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
        gathered.par_extend(points.par_chunks(4).zip(kept_rows.into_par_iter().chunks(4)).flat_map_iter(
            |(points, kept)| {
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
                for (k, p) in points.iter().enumerate() {
                    let Some(at) = p.at else { continue };
                    let Some(direct) = sys.direct_irradiance(at, p.normal) else { break };
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
            },
        ));
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
        };
        Ok((out, kept, stats))
    }
}

impl CornerGather {
    /// The irradiance `H` at every face corner, per object in face order (the corners of the
    /// values [`CornerGather::run`] returned), handed over once.
    pub fn take_irradiance(&mut self) -> CornerValues {
        std::mem::take(&mut self.irradiance)
    }
}

/// The distinct corner points of the scene's faces, the point of each face corner, and the
/// number of face corners per object. `locate(o, f, s, t)` gives the element covering face `f`
/// of object `o` at its parameters `(s,t)` and the local point there (`None`: a skipped face),
/// `patch(e)` that element's patch: the flat system's elements, or the hierarchy's faces.
pub(crate) fn corner_points(
    scene: &Scene,
    frame: f64,
    locate: impl Fn(usize, usize, f64, f64) -> Option<(usize, f64, f64)>,
    patch: impl Fn(usize) -> Patch,
) -> (Vec<CornerPoint>, Vec<usize>, Vec<usize>) {
    let mut points = Vec::new();
    let mut point_of_corner = Vec::new();
    let mut per_object = Vec::with_capacity(scene.objects.len());
    let mut shared = std::collections::HashMap::new();
    for (o, obj) in scene.objects.iter().enumerate() {
        let before = point_of_corner.len();
        let shading = scene.corner_normals(o);
        let world_from_object = obj.world_from_object(frame);
        for (f, face) in obj.faces.iter().enumerate() {
            let first = point_of_corner.len() - before;
            for (k, (&v, (s, t))) in face.iter().zip(corner_params(face.len())).enumerate() {
                // A triangle's apex is the collapsed edge t = 1: the inset corner (1, 1) would lie
                // on the edge P1 P2 (INSET^2 inside), seeing the neighbour across it edge-on;
                // halfway along the collapsed edge it lies INSET inside along the median.
                let s = if face.len() == 3 && t == 1.0 { 0.5 } else { s };
                let (si, ti) = (s.clamp(INSET, 1.0 - INSET), t.clamp(INSET, 1.0 - INSET));
                let at = locate(o, f, si, ti);
                let material = obj.face_materials[f];
                let normal = shading.get(first + k).and_then(|&n| world_normal(&world_from_object, n));
                // Faces with their own reflectance or emission scale (a texture's means) share a
                // point only with faces of the same ones, as faces of one material do.
                let own = |pick: fn(&crate::scene::Surface) -> &Vec<[f64; 3]>| {
                    scene.surfaces.get(o).and_then(|s| pick(s).get(f)).map(|r| r.map(f64::to_bits))
                };
                let (rho, scale) = (own(|s| &s.face_reflectance), own(|s| &s.face_emission));
                let key = at.map(|(e, s, t)| {
                    let n = normal.unwrap_or_else(|| patch(e).area_vector(s, t).normalize_or_zero());
                    (o, v, material, rho, scale, (n * 1e6).round().as_i64vec3().to_array())
                });
                let k = match key.and_then(|k| shared.get(&k)) {
                    Some(&k) => k,
                    None => {
                        points.push(CornerPoint { at, material, face: (o as u32, f as u32), normal });
                        if let Some(key) = key {
                            shared.insert(key, points.len() - 1);
                        }
                        points.len() - 1
                    }
                };
                point_of_corner.push(k);
            }
        }
        per_object.push(point_of_corner.len() - before);
    }
    (points, point_of_corner, per_object)
}

/// A smooth-shaded point is lifted this far (times its element's bounding radius) along its
/// shading normal: the inset point lies below the planes of the other faces at a convex vertex
/// by about `INSET` of their size, and a shadow ray towards a light the shading normal faces but
/// the face does not would leave under them (measured on Suzanne under a Point light: dark
/// corners on the lit side, 0.33 relative RMSE against Cycles' smooth bake without the lift).
pub const SMOOTH_LIFT: f64 = 4.0 * INSET;

/// The point at `(s,t)` of `patch` and the normal it is gathered with: the face's own, or the
/// shading normal `normal` with the point lifted by [`SMOOTH_LIFT`] along it.
pub fn shading_point(patch: &Patch, s: f64, t: f64, normal: Option<DVec3>) -> (DVec3, DVec3) {
    let x = patch.point(s, t);
    match normal {
        Some(n) => (x + SMOOTH_LIFT * patch.bounding_sphere().1 * n, n),
        None => (x, patch.area_vector(s, t).normalize_or_zero()),
    }
}

/// The touch of a source at `foot` (on its plane) when the foot falls on the source.
fn foot_on(source: &Patch, foot: DVec3, radius: f64) -> Option<Touch> {
    let (s, t) = source.locate(foot);
    ((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t)).then_some(Touch { s, t, radius })
}

/// Per point, whether it lies inside another closed surface of the scene
/// ([`Solids::buries_surface_point`]). The solids are made of the faces, not of the elements: a
/// face split into parts ([`crate::contact_split`]) leaves edges that only its own parts share.
/// (Without parts the elements are the faces: nothing more is allocated, which a bake near its
/// memory limit needs.)
fn buried_points(
    sys: &System,
    scene: &Scene,
    frame: f64,
    patches: &[Patch],
    points: &[CornerPoint],
) -> Vec<bool> {
    let split = sys.elements.iter().any(|e| e.domain != Rect::UNIT);
    let faces = split.then(|| crate::system::build_elements(scene, frame, crate::basis::Basis::new(0)));
    let solids = Solids::new(faces.as_deref().unwrap_or(&sys.elements), scene.objects.len());
    if solids.is_empty() {
        return Vec::new();
    }
    points
        .par_iter()
        .map(|p| {
            p.at.is_some_and(|(e, s, t)| {
                let (centre, radius) = patches[e].bounding_sphere();
                let (x, n) = (patches[e].point(s, t), patches[e].area_vector(s, t).normalize_or_zero());
                solids.buries_surface_point(x, n, centre, radius)
            })
        })
        .collect()
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

/// `B = E_i + rho_i sum_j sum_l m_j^l b_j^l` at a point of element `i`.
fn radiosity(sys: &System, i: usize, row: &Row) -> [f64; 3] {
    let [irradiance] = source_irradiance(sys, [row]);
    finish(sys, i, row, irradiance)
}

/// `sum_j sum_l m_j^l b_j^l` of each of `K` rows, each summed in its own order (sources, then
/// basis functions), the rows interleaved so that their chains of additions overlap.
fn source_irradiance<const K: usize>(sys: &System, rows: [&Row; K]) -> [[f64; 3]; K] {
    let nb = sys.basis.len();
    let b = &sys.solution.b;
    let mut irradiance = [[0.0; 3]; K];
    let add = |irradiance: &mut [f64; 3], row: &Row, k: usize| {
        let m = &row.moments[k * nb..(k + 1) * nb];
        let j = row.sources[k] as usize;
        let (b, w) = (&b[j * nb..(j + 1) * nb], sys.source_weights[j]);
        for l in 0..nb {
            for c in 0..3 {
                irradiance[c] += w * m[l] as f64 * b[l][c];
            }
        }
    };
    let common = rows.iter().map(|r| r.sources.len()).min().unwrap_or(0);
    for k in 0..common {
        for (irradiance, row) in irradiance.iter_mut().zip(rows) {
            add(irradiance, row, k);
        }
    }
    for (irradiance, row) in irradiance.iter_mut().zip(rows) {
        for k in common..row.sources.len() {
            add(irradiance, row, k);
        }
    }
    irradiance
}

/// [`radiosity`] from the sources' part of the irradiance: the feet's added, bounded by the
/// point's hemisphere, then `E + rho` times it.
fn finish(sys: &System, i: usize, row: &Row, irradiance: [f64; 3]) -> [f64; 3] {
    let nb = sys.basis.len();
    let irradiance = received(sys, row, irradiance);
    let (rho, e) = (sys.surface_reflectance[i], sys.emission[i * nb]);
    std::array::from_fn(|c| e[c] + rho[c] * irradiance[c])
}

/// The irradiance `H` a point receives from the surfaces (the lights' direct light is added
/// apart), from the sources' part: the feet's added, bounded by the point's hemisphere.
/// [`finish`] makes `B = E + rho H` of it.
fn received(sys: &System, row: &Row, mut irradiance: [f64; 3]) -> [f64; 3] {
    for foot in &row.feet {
        let mut b = [radiosity(sys, foot.element as usize, &foot.row)];
        sys.add_direct_light(
            std::iter::once(Some(((foot.element as usize, foot.at.0, foot.at.1), None))),
            &mut b,
        );
        let [b] = b;
        let w = foot.weight as f64 * sys.source_weights[foot.element as usize];
        for c in 0..3 {
            irradiance[c] += w * b[c];
        }
    }
    let bound = if sys.corner_bound { crate::hemisphere::bound(form_factor_sum(sys, row)) } else { 1.0 };
    irradiance.map(|x| bound * x)
}

/// The point's form factors summed over its sources (`m_j^0`, `Gamma_0 = 1`) and feet, each
/// with its source weight: at most 1 for a point that sees its hemisphere ([`crate::hemisphere`]).
fn form_factor_sum(sys: &System, row: &Row) -> f64 {
    let nb = sys.basis.len();
    let w = &sys.source_weights;
    let sources: f64 =
        row.moments.iter().step_by(nb).zip(&row.sources).map(|(&m, &j)| m as f64 * w[j as usize]).sum();
    sources + row.feet.iter().map(|f| f.weight as f64 * w[f.element as usize]).sum::<f64>()
}

/// The link's visibility bits from the corner's cell to each of the source's `cells` cells: bit `s`
/// is `vis.at(corner, s)` (`vis.at(s, corner)` when the corner's element is `b`) is not zero.
fn mask_row(vis: &Visibility, cells: usize, corner: usize, corner_is_a: bool) -> u16 {
    if let Visibility::Partial(words) = vis
        && cells <= 16
    {
        // The bits `Visibility::at` reads, without going through f64: the corner's row is
        // `cells` consecutive bits (one shift while they sit in one word), its column every
        // `cells`-th bit.
        let bit = |i: usize| (words[i / 64] >> (i % 64)) & 1;
        if corner_is_a {
            let first = corner * cells;
            if first % 64 + cells <= 64 {
                return ((words[first / 64] >> (first % 64)) & ((1u64 << cells) - 1)) as u16;
            }
            return (0..cells).fold(0u16, |m, s| m | (bit(first + s) as u16) << s);
        }
        return (0..cells).fold(0u16, |m, s| m | (bit(s * cells + corner) as u16) << s);
    }
    (0..cells).fold(0u16, |bits, s| {
        let seen = if corner_is_a { vis.at(corner, s, cells) } else { vis.at(s, corner, cells) };
        bits | (u16::from(seen > 0.0) << s)
    })
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The bits read straight from the words are those `Visibility::at` gives, both ways round,
    /// also for a row that straddles two words.
    #[test]
    fn mask_row_is_visibility_at() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for m in 1..=4 {
            let cells = m * m;
            for _ in 0..50 {
                let vis = Visibility::Partial(Box::new([next(), next(), next(), next()]));
                for corner in 0..cells {
                    for corner_is_a in [true, false] {
                        let want = (0..cells).fold(0u16, |bits, s| {
                            let seen =
                                if corner_is_a { vis.at(corner, s, cells) } else { vis.at(s, corner, cells) };
                            bits | (u16::from(seen > 0.0) << s)
                        });
                        assert_eq!(mask_row(&vis, cells, corner, corner_is_a), want, "m {m} corner {corner}");
                    }
                }
            }
        }
        for vis in [Visibility::Full, Visibility::Blocked] {
            assert_eq!(mask_row(&vis, 16, 3, true), if vis == Visibility::Full { 0xffff } else { 0 });
        }
    }
}
