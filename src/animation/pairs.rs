//! Each candidate's new kernel: its visibility (a shaft traversal, or for a static pair a re-check
//! against the moved triangles alone), then the stored series at the new displacement (eq. 16),
//! or quadrature (eq. 6), re-expanded along the motion when that pays (3.3), as new f32 blocks in
//! batches of candidates.

use std::sync::atomic::AtomicUsize;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::Patch;
use crate::kernel::PairContext;
use crate::kernel::assemble::{ElementGeometry, integrate_visible_into};
use crate::kernel::pair::SEPARATION;
use crate::kernel::series::{self, PairSeries, SERIES_MAX_T, SERIES_ORDER};
use crate::links::{LinkStore, PairId};
use crate::system::{Progress, System};
use crate::visibility::{MovedTriangles, Occluders, Visibility};

use super::candidates::{Candidate, PairCandidate};
use super::motion::{FrameMotion, NewFrame};
use super::{AnimationState, CALM_UPDATES, NEVER, UpdateStats};

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Reason {
    Series,
    Bound,
    Direction,
    HalfSpace,
    Visibility,
    NonTranslation,
    Translation,
}

pub(super) enum SeriesAction {
    Keep,
    Drop,
    Set(Box<PairSeries>),
}

/// How a changed pair gets its new kernel.
enum Kernel<'s> {
    /// The stored series at displacement `p`.
    Series(&'s PairSeries, f64),
    /// Just (re-)expanded at the current position.
    Expanded(Box<PairSeries>),
    /// Quadrature (eq. 6) with the pair's visibility.
    Exact,
}

/// A candidate that changed: its new visibility and how to get its kernel.
struct Decision<'s> {
    i: u32,
    j: u32,
    id: Option<PairId>,
    vis: Visibility,
    kernel: Kernel<'s>,
    reason: Reason,
}

impl<'s> Decision<'s> {
    /// The terms a series evaluation will read.
    fn series_terms(&self) -> Option<&'s [f32]> {
        match self.kernel {
            Kernel::Series(ser, p) => Some(ser.terms_at(p)),
            _ => None,
        }
    }
}

/// How many decided pairs ahead the series terms are prefetched.
const PREFETCH_SERIES: usize = 2;

/// The new state of one changed pair (its blocks are in its [`UpdateBatch`]).
pub(super) struct PairUpdate {
    pub(super) i: u32,
    pub(super) j: u32,
    pub(super) id: Option<PairId>,
    /// `Blocked` when the pair no longer exchanges light.
    pub(super) vis: Visibility,
    pub(super) series: SeriesAction,
    pub(super) reason: Reason,
}

/// The updates of a run of candidates: per update, its new blocks `[G_ij | G_ji]` (f32, as
/// stored, `2 nb^2`) in one flat array.
#[derive(Default)]
pub(super) struct UpdateBatch {
    pub(super) updates: Vec<PairUpdate>,
    pub(super) blocks: Vec<f32>,
    /// The f64 blocks being computed.
    scratch: Vec<f64>,
    /// Series terms read.
    pub(super) series_terms: usize,
    /// Visibility by a whole traversal, and by the moved triangles only (`UpdateStats`).
    pub(super) visibility_checks: usize,
    pub(super) visibility_relinked: usize,
}

/// The counts of `batches` into `stats`.
pub(super) fn count(batches: &[UpdateBatch], stats: &mut UpdateStats) {
    stats.visibility_checks = batches.iter().map(|b| b.visibility_checks).sum();
    stats.series_terms = batches.iter().map(|b| b.series_terms).sum();
    stats.visibility_relinked = batches.iter().map(|b| b.visibility_relinked).sum();
}

/// The triangles that moved this frame (old and new position), against which a static pair's mask
/// is re-checked, after bringing `culled` ([`AnimationState::culled`]) up to this frame's
/// `occluders`.
pub(super) fn prepare_relink(
    culled: &mut Option<Vec<bool>>,
    sys: &System,
    new: &NewFrame,
    occluders: Option<&Occluders>,
    visibility_samples: usize,
) -> MovedTriangles {
    let (n, moved, old) = (new.elements.len(), &new.moved, &sys.elements);
    // Static pairs re-check their masks against the moved triangles only (exact, see
    // `Occluders::relink_visibility`) when neither element has culled occluders by its plane
    // since the build: then every mask they hold is an any-hit mask over all occluders.
    // (A back's triangles are its front's: crate::backs.)
    let moved_triangles = MovedTriangles::new(
        (0..n).filter(|&e| moved[e] && !new.elements[e].back).map(|e| (&old[e].patch, &new.patches[e])),
    );
    if let Some(o) = occluders {
        let before = culled.take().unwrap_or_else(|| {
            // First update since the build: the system still holds the build's occluders.
            match &sys.occluders {
                Some(b) => (0..n).map(|e| b.culls(e)).collect(),
                None => {
                    let built: Vec<Patch> = old.iter().map(|e| e.patch).collect();
                    let b = crate::system::occluders_of(old, &built, visibility_samples);
                    (0..n).map(|e| b.culls(e)).collect()
                }
            }
        });
        *culled = Some((0..n).map(|e| before[e] || o.culls(e)).collect());
    }
    moved_triangles
}

/// What deciding and computing the candidates' kernels reads.
#[derive(Clone, Copy)]
pub(super) struct PairPhase<'a> {
    pub(super) state: &'a AnimationState,
    /// The store as the last frame left it.
    pub(super) links: &'a LinkStore,
    pub(super) ctx: &'a PairContext<'a>,
    pub(super) geom: &'a ElementGeometry<'a>,
    pub(super) occluders: Option<&'a Occluders>,
    pub(super) moved_triangles: &'a MovedTriangles,
    pub(super) patches: &'a [Patch],
    pub(super) moved: &'a [bool],
    pub(super) motion: &'a FrameMotion,
}

impl<'a> PairPhase<'a> {
    /// The new blocks of every candidate that changed, in batches in candidate order (their
    /// blocks in the buffers of `pool`, the last update's); `progress` is told, and may cancel,
    /// once per run of candidates. Per candidate: its visibility and how its kernel is obtained
    /// ([`Self::decide`]), then its new blocks ([`Self::emit`]), written into the batch of its
    /// run of candidates.
    pub(super) fn run(
        &self,
        candidates: &[PairCandidate],
        mut pool: Vec<Vec<f32>>,
        progress: Progress,
    ) -> Result<Vec<UpdateBatch>> {
        let total = candidates.len();
        let done = AtomicUsize::new(0);
        // Fixed runs of candidates, each into its own batch (no merging copies). Sixteen per thread:
        // the static pairs near a mover, the costly ones, come together in candidate order, and
        // with eight per thread the last runs left a thread idle (pairs 13.9 -> 13.5 ms median).
        let run = candidates.len().div_ceil(16 * rayon::current_num_threads()).max(64);
        pool.resize_with(candidates.len().div_ceil(run), Vec::new);
        candidates
            .par_chunks(run)
            .zip(pool.into_par_iter())
            .map(|(run, mut blocks)| {
                blocks.clear();
                let mut batch = UpdateBatch { blocks, ..Default::default() };
                // Progress and cancellation once per run (a shared counter per candidate made
                // the two threads trade its cache line 29k times a frame).
                let d = done.fetch_add(run.len(), std::sync::atomic::Ordering::Relaxed);
                if !progress(d as f64 / total.max(1) as f64, "kernel update") {
                    return Err(Error::Cancelled);
                }
                // Decided first, then emitted with the series terms a few pairs ahead prefetched:
                // the solve's stream through the store evicts them between frames, and reading
                // them from memory was most of a series evaluation.
                let mut decided = Vec::with_capacity(run.len());
                for &c in run {
                    decided.extend(self.decide(c, &mut batch)?);
                }
                let terms: Vec<Option<&[f32]>> = decided.iter().map(Decision::series_terms).collect();
                for (k, d) in decided.into_iter().enumerate() {
                    if let Some(Some(ahead)) = terms.get(k + PREFETCH_SERIES) {
                        crate::simd::prefetch(ahead);
                    }
                    self.emit(&mut batch, d);
                }
                Ok(batch)
            })
            .collect::<Result<Vec<UpdateBatch>>>()
    }

    /// Whether static pair `(i, j)` may re-check its mask against the moved triangles alone.
    fn relink_ok(&self, i: usize, j: usize) -> bool {
        self.state.culled.as_ref().is_some_and(|c| !c[i] && !c[j])
    }

    /// A candidate's visibility and how its kernel is obtained; `None` when it did not change.
    fn decide(&self, (i, j, kind): PairCandidate, batch: &mut UpdateBatch) -> Result<Option<Decision<'a>>> {
        let PairPhase { state, links, ctx, geom, occluders, moved_triangles, patches, moved, .. } = *self;
        let (shift, translated) = (&self.motion.shift, &self.motion.translated);
        let (iu, ju) = (i as usize, j as usize);
        let id = state.index.get(i, j);
        // A pair that cannot face each other exchanges nothing whatever its visibility
        // (`integrate_visible` gives `None`; a stored pair is emptied with `Blocked`).
        let facing = geom.face_each_other(iu, ju);
        if !facing && (id.is_none() || matches!(kind, Candidate::VisibilityOnly)) {
            // (A static or rigid pair's facing never changes: if stored, it is already empty.)
            return Ok(None);
        }
        let old_vis = id.map_or(&Visibility::Blocked, |p| &links.pair(p).visibility);
        let static_pair = !moved[iu] && !moved[ju];
        let vis = match occluders {
            _ if !facing => Visibility::Blocked,
            Some(o) => {
                // An absent pair, or one stored as `Blocked`, was either blocked or has a
                // kernel that is zero whatever its mask (the one-sided `g >= 0` vanished at
                // every visible sample: then at every sample, as the pair has not moved).
                // Re-checking from `Blocked` is exact in the first case and gives a mask
                // that still yields the zero kernel in the second.
                let relinked = (static_pair && self.relink_ok(iu, ju))
                    .then(|| {
                        o.relink_visibility((iu, &patches[iu]), (ju, &patches[ju]), old_vis, moved_triangles)
                    })
                    .flatten();
                if relinked.is_some() {
                    batch.visibility_relinked += 1;
                }
                relinked.unwrap_or_else(|| {
                    batch.visibility_checks += 1;
                    o.link_visibility(iu, &patches[iu], ju, &patches[ju])
                })
            }
            None => Visibility::Full,
        };
        let existing_series = id.and_then(|p| state.series.get(p as usize)).and_then(|s| s.as_deref());
        let decision = match kind {
            Candidate::VisibilityOnly => {
                if vis == *old_vis || (id.is_none() && vis == Visibility::Blocked) {
                    return Ok(None);
                }
                Decision { i, j, id, vis, kernel: Kernel::Exact, reason: Reason::Visibility }
            }
            Candidate::Moved => {
                let motion = shift[ju] - shift[iu];
                let dir = motion.normalize();
                let both_translated = translated[iu] && translated[ju];
                let mut reason = if both_translated { Reason::Translation } else { Reason::NonTranslation };
                // The one Gauss product a fresh build integrates the pair with now (points per
                // axis), `None` when it is near enough to be split (`integrate_pair_into`): a
                // series stands for the kernel only while the pair keeps the rule it was
                // expanded on.
                let rule = {
                    let ((ci, ri), (cj, rj)) = (geom.sphere(iu), geom.sphere(ju));
                    let ratio = ci.distance(cj) / (ri + rj);
                    (ratio > SEPARATION).then(|| ctx.points_for(ratio))
                };
                if let (true, Some(ser)) = (state.use_series, existing_series) {
                    match series_check(ser, state, patches, (iu, ju), rule, (&vis, old_vis)) {
                        Ok(p) => {
                            let kernel = Kernel::Series(ser, p);
                            return Ok(Some(Decision { i, j, id, vis, kernel, reason: Reason::Series }));
                        }
                        Err(why) => reason = why,
                    }
                }
                // Exact (eq. 6), re-expanded along this frame's motion when the series applies.
                // Expanding costs about as much as 15 quadratures: only worth it when the
                // pair stays within the bound for a few frames at this frame's speed, and
                // when its visibility has held for CALM_UPDATES updates (a pair in a moving
                // penumbra changes again soon, and each change drops its series).
                let calm = id.is_some_and(|p| {
                    let changed = state.visibility_changed.get(p as usize).copied().unwrap_or(NEVER);
                    vis == *old_vis && (changed == NEVER || state.updates - changed >= CALM_UPDATES)
                });
                let expand = state.use_series
                    && both_translated
                    && vis != Visibility::Blocked
                    && calm
                    && rule.is_some_and(|n| n >= MIN_SERIES_POINTS);
                let r_min = expand
                    .then(|| series::eligible(&patches[iu], &patches[ju], dir))
                    .flatten()
                    .filter(|r| SERIES_MAX_T * r >= MIN_SERIES_FRAMES * motion.length());
                match r_min.zip(rule) {
                    Some((r_min, npts)) => {
                        let terms = series::expand(
                            ctx.basis,
                            ctx.vis_axis,
                            geom.samples(iu, npts),
                            geom.samples(ju, npts),
                            &vis,
                            dir,
                        );
                        let ser = PairSeries::new(
                            dir,
                            (patches[iu].corners[0], patches[ju].corners[0]),
                            r_min,
                            (state.epochs[iu], state.epochs[ju]),
                            npts,
                            terms,
                        );
                        Decision { i, j, id, vis, kernel: Kernel::Expanded(Box::new(ser)), reason }
                    }
                    None => {
                        if reason == Reason::Translation
                            && state.use_series
                            && existing_series.is_none()
                            && !series::clip_invariant_with(
                                (&patches[iu], geom.plane(iu)),
                                (&patches[ju], geom.plane(ju)),
                                dir,
                            )
                        {
                            reason = Reason::HalfSpace;
                        }
                        Decision { i, j, id, vis, kernel: Kernel::Exact, reason }
                    }
                }
            }
        };
        Ok(Some(decision))
    }

    /// The new blocks of a decided pair, rounded to the store's f32 (Delta K (b - u), formed from
    /// them once the store is written, is then the change of the stored kernel).
    fn emit(&self, batch: &mut UpdateBatch, d: Decision) {
        let (ctx, geom) = (self.ctx, self.geom);
        let nb = ctx.basis.len();
        let n2 = nb * nb;
        let (iu, ju) = (d.i as usize, d.j as usize);
        batch.scratch.resize(2 * n2, 0.0);
        let scratch = &mut batch.scratch[..];
        let (series, exchanges) = match d.kernel {
            Kernel::Series(ser, p) => {
                batch.series_terms += ser.eval_into(p, scratch) + 1;
                (SeriesAction::Keep, true)
            }
            Kernel::Expanded(ser) => {
                ser.eval_into(0.0, scratch);
                (SeriesAction::Set(ser), true)
            }
            Kernel::Exact => {
                let (ij, ji) = scratch.split_at_mut(n2);
                let exchanges = integrate_visible_into(ctx, geom, iu, ju, &d.vis, ij, ji);
                if !exchanges {
                    scratch.fill(0.0);
                }
                (SeriesAction::Drop, exchanges)
            }
        };
        if d.id.is_none() && !exchanges {
            return;
        }
        let (ij, ji) = scratch.split_at_mut(n2);
        geom.weigh(iu, ju, ij, ji);
        batch.blocks.extend(scratch.iter().map(|&x| x as f32));
        let vis = if exchanges { d.vis } else { Visibility::Blocked };
        batch.updates.push(PairUpdate { i: d.i, j: d.j, id: d.id, vis, series, reason: d.reason });
    }
}

/// The displacement `p` at which the stored series gives this frame's kernel, or why it cannot.
/// `rule` is the Gauss product the pair takes at its new position (`None`: split), `vis` its new
/// visibility and `old_vis` the stored one.
fn series_check(
    ser: &PairSeries,
    state: &AnimationState,
    patches: &[Patch],
    (i, j): (usize, usize),
    rule: Option<usize>,
    (vis, old_vis): (&Visibility, &Visibility),
) -> std::result::Result<f64, Reason> {
    if ser.epochs != (state.epochs[i], state.epochs[j]) {
        return Err(Reason::NonTranslation);
    }
    // Out of the series' domain, as beyond its bound: the quadrature it was integrated with is no
    // longer the pair's (a stop-and-reverse brought a pair expanded at 1.5006 radii-sums to 1.4983,
    // where a fresh build splits it: 2e-2 of the peak block entry apart; `PairSeries::points`).
    if rule != Some(ser.points) {
        return Err(Reason::Bound);
    }
    if !series::clip_invariant(&patches[i], &patches[j], ser.dir) {
        return Err(Reason::HalfSpace);
    }
    if vis != old_vis {
        return Err(Reason::Visibility);
    }
    let d = ser.displacement(patches[i].corners[0], patches[j].corners[0]);
    let p = d.dot(ser.dir);
    // Off the expansion line: the series in p along dir no longer describes the position.
    if (d - p * ser.dir).length() > 1e-7 * ser.r_min {
        return Err(Reason::Direction);
    }
    if p.abs() > SERIES_MAX_T * ser.r_min {
        return Err(Reason::Bound);
    }
    Ok(p)
}

const _: () = assert!(SERIES_ORDER >= 2);

/// A pair is expanded only if, at the current speed, the series would serve at least this many
/// frames before `p` reaches `SERIES_MAX_T r_min`. Timed per pair (session 7, thread time): an
/// expansion 8.5-9 us, about 15 far-pair quadratures (0.4-0.7 us), which an evaluation
/// (0.27-0.42 us) undercuts by about 0.3 us a frame, so an expansion pays back after some 25
/// frames of use. At 3 (before session 7) the Fig. 5a room, whose light moves far relative to
/// its pairs' distances, re-expanded 500-900 pairs a frame after 3 frames each: 13.7-15.5 ms of
/// kernels a frame against 8.9-11.9 ms for `--exact`. At 15 it expands none (9.1-10.8 ms), and the
/// moving-light box keeps the series for the pairs that use it long (4.9-5.6 ms, as at 3; 30
/// drops those too: 6.6-6.9 ms). `--exact` there: 4.8 ms.
const MIN_SERIES_FRAMES: f64 = 15.0;

/// Gauss points per axis below which a pair is not expanded: its quadrature is cheaper than
/// reading its series. Timed in the moving-light box's frames (session 11, `perf` of
/// `kernel_update` with and without `--exact`, 39 frames each), a series evaluation takes 1.5 us
/// there, not the 0.3-0.4 us it takes with its terms in cache (above): its ~4.5 KB of terms come
/// from memory, the solve having streamed the link store through the caches since the last
/// frame. A 3 x 3-point quadrature (81 point pairs, order 2's far and middle rules) takes 0.65 us,
/// so those pairs are recomputed. From 4 x 4 points (256 point pairs, ~2 us: order 2's near rule,
/// order 3's far one, or adaptive quadrature off) the series is level with the quadrature, not
/// cheaper: session 12, 5 interleaved runs of 24 frames, kernel update median 52.0 ms against
/// 52.2 for `--exact` at order 3, 29.7 against 27.5 with adaptive quadrature off (`tools.ab
/// --bench-arg`; the re-expansions of pairs whose bound the light outruns eat the evaluations'
/// margin). Kept at 4 so that the series, the seed's method, serves where it does not lose.
const MIN_SERIES_POINTS: usize = 4;
