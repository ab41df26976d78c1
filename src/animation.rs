//! Frame-to-frame update of a solved system (seed, sections 3.1 to 3.4).
//!
//! Each new frame: place the elements, find the pairs whose kernel changed, update them, and turn
//! the change into initial unshot energy, eq. (9):
//! `Delta b_i = Delta e_i + sum_j Delta K_ij b_j + sum_j (K_ij + Delta K_ij) Delta b_j`,
//! so `unshot = Delta e + Delta K b` (with the previous frame's `b`), and progressive shooting with
//! the new kernel propagates the rest, starting from the previous solution (3.4).
//!
//! Which pairs change: every pair whose two elements moved relative to each other, and every pair
//! whose shaft the moving elements' swept bounds (old and new positions) may enter or leave: the
//! visibility changes the seed left to a separate shadow algorithm (issue 3, item 4).
//!
//! How a changed pair is updated ([`Method::Incremental`](crate::session::Method)): while the
//! relative motion is a translation along the direction of the pair's expansion, within
//! `SERIES_MAX_T r_min` of its reference, with no half-space crossing (Fig. 4) and no visibility
//! change, the kernel is the polynomial `sum p^n Phi_n` (eq. 16, [`crate::kernel::series`]).
//! Otherwise it is recomputed exactly (eq. 6) and, when eligible, re-expanded at the new position
//! along the current motion direction (3.3). Two elements moving together keep their kernel.

use rayon::prelude::*;

use glam::DVec3;

use crate::error::{Error, Result};
use crate::geometry::{Aabb, Patch};
use crate::kernel::PairContext;
use crate::kernel::assemble::{ElementGeometry, integrate_visible};
use crate::kernel::series::{self, PairSeries, SERIES_MAX_T, SERIES_ORDER};
use crate::links::PairId;
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::solver;
use crate::system::{Progress, System, build_elements};
use crate::visibility::shaft::Shaft;
use crate::visibility::{Occluders, Visibility};

/// What one update did.
#[derive(Clone, Debug, Default)]
pub struct UpdateStats {
    pub moved_elements: usize,
    /// Pairs whose kernel came from the series.
    pub links_series: usize,
    /// Pairs recomputed by quadrature, all reasons.
    pub links_recomputed: usize,
    /// Series abandoned: `p` beyond `SERIES_MAX_T r_min`.
    pub recomputed_bound: usize,
    /// Series abandoned: the motion left the expansion direction.
    pub recomputed_direction: usize,
    /// A patch entered or left the other's front half-space (Fig. 4), or the pair is not all-front.
    pub recomputed_half_space: usize,
    /// Visibility between the two patches changed.
    pub recomputed_visibility: usize,
    /// Rotation, scale or deformation.
    pub recomputed_non_translation: usize,
    /// Translated pairs with no series (the `--exact` method, or a pair the series does not cover).
    pub recomputed_translation: usize,
    /// Pairs (re-)expanded this frame.
    pub series_expanded: usize,
    pub kernel_seconds: f64,
    pub solve_seconds: f64,
    pub shots: usize,
}

/// Why an update cannot proceed and the frame must be rebuilt from scratch.
pub enum Outcome {
    Updated(UpdateStats),
    /// Topology changed (faces appeared, vanished or became degenerate).
    NeedsRebuild,
}

/// What the update keeps between frames besides the system.
pub struct AnimationState {
    /// Per pair id: its series, when expanded.
    series: Vec<Option<Box<PairSeries>>>,
    /// Per element: bumped whenever it moves by anything but a translation.
    epochs: Vec<u32>,
    use_series: bool,
}

impl AnimationState {
    pub fn new(n_elements: usize, use_series: bool) -> Self {
        Self { series: Vec::new(), epochs: vec![0; n_elements], use_series }
    }

    /// Pairs holding a series, and the bytes their terms take.
    pub fn series_memory(&self) -> (usize, usize) {
        let held: Vec<_> = self.series.iter().flatten().collect();
        (held.len(), held.iter().map(|s| s.terms.len() * 4).sum())
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Reason {
    Series,
    Bound,
    Direction,
    HalfSpace,
    Visibility,
    NonTranslation,
    Translation,
}

enum SeriesAction {
    Keep,
    Drop,
    Set(Box<PairSeries>),
}

/// The new state of one changed pair.
struct PairUpdate {
    i: u32,
    j: u32,
    /// `(G_ij, G_ji, visibility)`, or `None` when the pair no longer exchanges light.
    coefficients: Option<(Vec<f64>, Vec<f64>, Visibility)>,
    series: SeriesAction,
    reason: Reason,
}

/// Relative motion of the frame for the candidates with a moved element.
#[derive(Clone, Copy)]
enum Candidate {
    /// The two elements moved relative to each other.
    Moved,
    /// Only visibility may have changed (a static pair near a moving object, or a rigid pair).
    VisibilityOnly,
}

/// Updates `sys` (solved for `prev`) to `next` at `frame`.
pub fn advance(
    sys: &mut System,
    state: &mut AnimationState,
    next: &Scene,
    frame: f64,
    progress: Progress,
) -> Result<Outcome> {
    let start = std::time::Instant::now();
    let s = &next.settings;
    let basis = sys.basis;
    let nb = basis.len();
    let new_elements = build_elements(next, frame, basis);
    if new_elements.len() != sys.elements.len()
        || new_elements.iter().zip(&sys.elements).any(|(a, b)| (a.object, a.face) != (b.object, b.face))
    {
        return Ok(Outcome::NeedsRebuild);
    }
    let n = new_elements.len();
    let patches: Vec<Patch> = new_elements.iter().map(|e| e.patch).collect();
    let old: Vec<&Patch> = sys.elements.iter().map(|e| &e.patch).collect();
    let moved: Vec<bool> = (0..n).map(|e| patches[e] != *old[e]).collect();
    let scene_scale = patches.iter().fold(Aabb::EMPTY, |b, p| b.union(p.bounds())).diagonal().length();
    let eps = 1e-12 * scene_scale.max(1e-300);
    // This frame's motion of each element, and whether it is a pure translation.
    let shift: Vec<DVec3> = (0..n).map(|e| patches[e].corners[0] - old[e].corners[0]).collect();
    let translated: Vec<bool> = (0..n)
        .map(|e| (0..4).all(|c| (patches[e].corners[c] - old[e].corners[c] - shift[e]).length() <= eps))
        .collect();
    for e in 0..n {
        if !translated[e] {
            state.epochs[e] = state.epochs[e].wrapping_add(1);
        }
    }
    let swept = (0..n)
        .filter(|&e| moved[e])
        .fold(Aabb::EMPTY, |b, e| b.union(old[e].bounds()).union(patches[e].bounds()));
    let mut stats =
        UpdateStats { moved_elements: moved.iter().filter(|&&m| m).count(), ..Default::default() };
    let mut delta_b = vec![[0.0f64; 3]; n * nb];

    if stats.moved_elements > 0 {
        let rule = GaussLegendre::new(s.quadrature_order);
        let ctx = PairContext {
            basis,
            rule: &rule,
            vis_axis: s.visibility_samples,
            adaptive: s.adaptive_quadrature,
        };
        let occluders = s.visibility.then(|| Occluders::new(&patches, s.visibility_samples));
        let geom = ElementGeometry::new(&patches, &ctx);
        let shaft_eps = 1e-9 * scene_scale;
        let candidates: Vec<(u32, u32, Candidate)> = (0..n)
            .into_par_iter()
            .flat_map_iter(|i| {
                let (moved, translated, shift, patches, swept) =
                    (&moved, &translated, &shift, &patches, &swept);
                ((i + 1)..n).filter_map(move |j| {
                    let rigid = translated[i] && translated[j] && (shift[j] - shift[i]).length() <= eps;
                    if (moved[i] || moved[j]) && !rigid {
                        return Some((i as u32, j as u32, Candidate::Moved));
                    }
                    if !s.visibility {
                        return None;
                    }
                    let (bi, bj) = (patches[i].bounds(), patches[j].bounds());
                    if !bi.union(bj).overlaps(swept) {
                        return None;
                    }
                    Shaft::new(&bi, &bj).may_contain_box(swept, shaft_eps).then_some((
                        i as u32,
                        j as u32,
                        Candidate::VisibilityOnly,
                    ))
                })
            })
            .collect();
        let total = candidates.len();
        let done = std::sync::atomic::AtomicUsize::new(0);
        let ids: Vec<Option<PairId>> = candidates.par_iter().map(|&(i, j, _)| sys.links.find(i, j)).collect();
        let updates: Vec<Option<PairUpdate>> = candidates
            .par_iter()
            .zip(&ids)
            .map(|(&(i, j, kind), &id)| {
                let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if d.is_multiple_of(2048) && !progress(d as f64 / total.max(1) as f64, "kernel update") {
                    return Err(Error::Cancelled);
                }
                let (iu, ju) = (i as usize, j as usize);
                let vis = match &occluders {
                    Some(o) => o.link_visibility(iu, &patches[iu], ju, &patches[ju]),
                    None => Visibility::Full,
                };
                let old_vis = id.map_or(Visibility::Blocked, |p| sys.links.pair(p).visibility.clone());
                let existing_series =
                    id.and_then(|p| state.series.get(p as usize)).and_then(|s| s.as_deref());
                let update = match kind {
                    Candidate::VisibilityOnly => {
                        if vis == old_vis || (id.is_none() && vis == Visibility::Blocked) {
                            return Ok(None);
                        }
                        let c = integrate_visible(&ctx, &geom, iu, ju, &vis);
                        PairUpdate {
                            i,
                            j,
                            coefficients: c.map(|c| (c.ij, c.ji, vis)),
                            series: SeriesAction::Drop,
                            reason: Reason::Visibility,
                        }
                    }
                    Candidate::Moved => {
                        let motion = shift[ju] - shift[iu];
                        let both_translated = translated[iu] && translated[ju];
                        let mut reason =
                            if both_translated { Reason::Translation } else { Reason::NonTranslation };
                        if let (true, Some(ser)) = (state.use_series, existing_series) {
                            match series_check(ser, state, &patches, iu, ju, &vis, &old_vis) {
                                Ok(p) => {
                                    let (ab, ba) = ser.eval(p, nb);
                                    return Ok(Some(PairUpdate {
                                        i,
                                        j,
                                        coefficients: Some((ab, ba, vis)),
                                        series: SeriesAction::Keep,
                                        reason: Reason::Series,
                                    }));
                                }
                                Err(why) => reason = why,
                            }
                        }
                        // Exact (eq. 6), re-expanded along this frame's motion when the series applies.
                        // Expanding costs about SERIES_ORDER + 1 quadratures: only worth it when the
                        // pair stays within the bound for a few frames at this frame's speed.
                        let r_min = (state.use_series && both_translated && vis != Visibility::Blocked)
                            .then(|| series::eligible(&patches[iu], &patches[ju]))
                            .flatten()
                            .filter(|r| SERIES_MAX_T * r >= MIN_SERIES_FRAMES * motion.length());
                        match r_min {
                            Some(r_min) => {
                                let (ci, ri) = patches[iu].bounding_sphere();
                                let (cj, rj) = patches[ju].bounding_sphere();
                                let npts = ctx.points_for(ci.distance(cj) / (ri + rj));
                                let dir = motion.normalize();
                                let terms = series::expand(
                                    basis,
                                    ctx.vis_axis,
                                    geom.samples(iu, npts),
                                    geom.samples(ju, npts),
                                    &vis,
                                    dir,
                                );
                                let ser = PairSeries {
                                    dir,
                                    ref_a: patches[iu].corners[0],
                                    ref_b: patches[ju].corners[0],
                                    r_min,
                                    epochs: (state.epochs[iu], state.epochs[ju]),
                                    terms,
                                };
                                let (ab, ba) = ser.eval(0.0, nb);
                                PairUpdate {
                                    i,
                                    j,
                                    coefficients: Some((ab, ba, vis)),
                                    series: SeriesAction::Set(Box::new(ser)),
                                    reason,
                                }
                            }
                            None => {
                                if reason == Reason::Translation
                                    && state.use_series
                                    && existing_series.is_none()
                                    && !series::mutually_in_front(&patches[iu], &patches[ju])
                                {
                                    reason = Reason::HalfSpace;
                                }
                                let c = integrate_visible(&ctx, &geom, iu, ju, &vis);
                                PairUpdate {
                                    i,
                                    j,
                                    coefficients: c.map(|c| (c.ij, c.ji, vis)),
                                    series: SeriesAction::Drop,
                                    reason,
                                }
                            }
                        }
                    }
                };
                Ok(Some(update))
            })
            .collect::<Result<_>>()?;

        let zeros = vec![0.0; nb * nb];
        for (update, id) in updates.into_iter().zip(ids) {
            let Some(u) = update else { continue };
            if id.is_none() && u.coefficients.is_none() {
                continue;
            }
            let (old_ij, old_ji) = match id {
                Some(p) => sys.links.blocks_f64(p, u.i),
                None => (zeros.clone(), zeros.clone()),
            };
            let (new_ij, new_ji, vis) =
                u.coefficients.unwrap_or_else(|| (zeros.clone(), zeros.clone(), Visibility::Blocked));
            match u.reason {
                Reason::Series => stats.links_series += 1,
                Reason::Bound => stats.recomputed_bound += 1,
                Reason::Direction => stats.recomputed_direction += 1,
                Reason::HalfSpace => stats.recomputed_half_space += 1,
                Reason::Visibility => stats.recomputed_visibility += 1,
                Reason::NonTranslation => stats.recomputed_non_translation += 1,
                Reason::Translation => stats.recomputed_translation += 1,
            }
            if u.reason != Reason::Series {
                stats.links_recomputed += 1;
            }
            // Delta K b with the previous frame's b, both directions (eq. 9).
            add_delta(&mut delta_b, sys, u.i as usize, u.j as usize, &new_ij, &old_ij);
            add_delta(&mut delta_b, sys, u.j as usize, u.i as usize, &new_ji, &old_ji);
            let p = match id {
                Some(p) => {
                    let (ab, ba) =
                        if sys.links.pair(p).a == u.i { (&new_ij, &new_ji) } else { (&new_ji, &new_ij) };
                    sys.links.set(p, ab, ba, vis);
                    p
                }
                None => sys.links.push(u.i, u.j, &new_ij, &new_ji, vis),
            };
            if state.series.len() <= p as usize {
                state.series.resize_with(p as usize + 1, || None);
            }
            match u.series {
                SeriesAction::Keep => {}
                SeriesAction::Drop => state.series[p as usize] = None,
                SeriesAction::Set(ser) => {
                    // Series are stored with the pair's own orientation (a, b).
                    debug_assert_eq!(sys.links.pair(p).a, u.i);
                    stats.series_expanded += 1;
                    state.series[p as usize] = Some(ser);
                }
            }
        }
    }
    stats.kernel_seconds = start.elapsed().as_secs_f64();

    // Emission changes enter as Delta e (eq. 9).
    let mut emission = vec![[0.0; 3]; n * nb];
    for (i, e) in new_elements.iter().enumerate() {
        emission[i * nb] = next.emission_at(e.material as usize, frame);
        for c in 0..3 {
            delta_b[i * nb][c] += emission[i * nb][c] - sys.emission[i * nb][c];
        }
    }
    for (k, d) in delta_b.iter().enumerate() {
        for c in 0..3 {
            sys.solution.b[k][c] += d[c];
            sys.solution.unshot[k][c] += d[c];
        }
    }
    sys.elements = new_elements;
    sys.emission = emission;
    sys.reflectance = sys.elements.iter().map(|e| next.materials[e.material as usize].reflectance).collect();

    let solve_start = std::time::Instant::now();
    let stop = s.tolerance * sys.emitted_power();
    let cancel = || !progress(1.0, "solve");
    let shot = solver::shoot(&sys.links, &sys.reflectance, &sys.areas(), &mut sys.solution, stop, &cancel)?;
    stats.solve_seconds = solve_start.elapsed().as_secs_f64();
    stats.shots = shot.shots;
    Ok(Outcome::Updated(stats))
}

/// The displacement `p` at which the stored series gives this frame's kernel, or why it cannot.
fn series_check(
    ser: &PairSeries,
    state: &AnimationState,
    patches: &[Patch],
    i: usize,
    j: usize,
    vis: &Visibility,
    old_vis: &Visibility,
) -> std::result::Result<f64, Reason> {
    if ser.epochs != (state.epochs[i], state.epochs[j]) {
        return Err(Reason::NonTranslation);
    }
    if !series::mutually_in_front(&patches[i], &patches[j]) {
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
/// frames before `p` reaches `SERIES_MAX_T r_min` (measured: below 3, re-expansions cost more
/// than the quadratures they save; benches/animation.rs).
const MIN_SERIES_FRAMES: f64 = 3.0;

/// `delta_b_r += rho_r (G_new - G_old) b_s` for receiver `r`, source `s`.
fn add_delta(delta_b: &mut [[f64; 3]], sys: &System, r: usize, s: usize, new: &[f64], old: &[f64]) {
    let nb = sys.basis.len();
    let rho = sys.reflectance[r];
    for k in 0..nb {
        for l in 0..nb {
            let d = new[k * nb + l] - old[k * nb + l];
            if d == 0.0 {
                continue;
            }
            for c in 0..3 {
                delta_b[r * nb + k][c] += rho[c] * d * sys.solution.b[s * nb + l][c];
            }
        }
    }
}
