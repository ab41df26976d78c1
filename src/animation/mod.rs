//! Frame-to-frame update of a solved system (seed, sections 3.1 to 3.4).
//!
//! Each new frame: place the elements, find the pairs whose kernel changed, update them, and turn
//! the change into initial unshot energy, eq. (9):
//! `Delta b_i = Delta e_i + sum_j Delta K_ij b_j + sum_j (K_ij + Delta K_ij) Delta b_j`,
//! so `unshot += Delta e + Delta K (b - u)`, and progressive shooting with the new kernel
//! propagates the rest, starting from the previous solution (3.4). The seed's `b` is a converged
//! solution; ours keeps the shooting invariant `b = e + K (b - u)` with an unshot part `u`, and
//! the new kernel keeps it only with the part already shot, `b - u`: `Delta K b` leaves `b` off by
//! `Delta K u`. That is not always small: the stopping test weighs an unshot value by the power it
//! would deliver, so an element shut in a closed box keeps its unshot (transfer ~0), and once the
//! box opened the frame was wrong (a lamp 21% too dark, `tests/animation_random.rs`).
//!
//! Which pairs change: every pair whose two elements moved relative to each other, and every pair
//! whose shaft the bounds a moving object sweeps (old and new positions, a box per object) may
//! enter or leave: the visibility changes the seed left to a separate shadow algorithm (issue 3,
//! item 4). A static
//! pair's segments do not move, so its mask is re-checked against the moved triangles alone
//! (old and new positions, [`crate::visibility::Occluders::relink_visibility`]); the shaft
//! traversal remains for pairs with a moved element and for the rare segment only the movers'
//! old position blocked.
//!
//! How a changed pair is updated ([`Method::Incremental`](crate::session::Method)): while the
//! relative motion is a translation along the direction of the pair's expansion, within
//! `SERIES_MAX_T r_min` of its reference, with no half-space crossing (Fig. 4) and no visibility
//! change, the kernel is the polynomial `sum p^n Phi_n` (eq. 16, [`crate::kernel::series`]).
//! Otherwise it is recomputed exactly (eq. 6) and, when eligible, re-expanded at the new position
//! along the current motion direction (3.3). Two elements moving together keep their kernel.
//!
//! [`advance`] runs the phases in turn, a file each: `motion.rs` places the new frame's elements
//! and finds how each moved; `candidates.rs` scans the pairs that may have changed; `pairs.rs`
//! decides and computes each one's new kernel; `apply.rs` writes them into the store; `delta_k.rs`
//! forms `Delta K (b - u)` and `Delta K sigma` from the store's changes and the hemisphere bound's;
//! `solve.rs` adds `Delta e`, moves the system to the new frame and solves it.

use crate::error::Result;
use crate::kernel::PairContext;
use crate::kernel::assemble::KeptGeometry;
use crate::kernel::series::PairSeries;
use crate::links::{LinkStore, PairId, ReplacedBlocks};
use crate::quadrature::GaussLegendre;
use crate::replay::Replay;
use crate::scene::Scene;
use crate::system::{Progress, System};

mod apply;
mod candidates;
mod delta_k;
mod motion;
mod pairs;
mod solve;

use candidates::Found;
use delta_k::DeltaK;
use motion::{FrameMotion, NewFrame};
use pairs::PairPhase;

/// What one update did.
#[derive(Clone, Debug, Default)]
pub struct UpdateStats {
    pub moved_elements: usize,
    /// Pairs whose kernel came from the series.
    pub links_series: usize,
    /// Pairs recomputed by quadrature, all reasons.
    pub links_recomputed: usize,
    /// Series abandoned: `p` beyond `SERIES_MAX_T r_min`, or the pair no longer on the Gauss rule
    /// it was expanded with (`PairSeries::points`).
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
    /// Terms `Phi_n` read by the series evaluations (at most `SERIES_ORDER + 1` per pair: see
    /// `series::SERIES_TAIL`).
    pub series_terms: usize,
    /// Static pairs whose shaft was tested against the moving elements' swept bounds.
    pub shaft_tests: usize,
    /// Pairs examined in detail: moved relative to each other, or shaft entered by the swept bounds.
    pub candidates: usize,
    /// Link visibility evaluations by a shaft traversal
    /// ([`crate::visibility::Occluders::link_visibility`]).
    pub visibility_checks: usize,
    /// Static pairs whose visibility was re-checked against the moved triangles only
    /// ([`crate::visibility::Occluders::relink_visibility`]).
    pub visibility_relinked: usize,
    /// Sample segments tested against occluders (`m^4` per link that needed rays).
    pub segments_tested: u64,
    /// The lights' shadow rays for this frame's direct light traced, and taken from the last
    /// frame's where no move could have changed them ([`crate::lights::direct::DirectLight::project_keeping`]).
    pub direct_rays_traced: u64,
    pub direct_rays_taken: u64,
    pub kernel_seconds: f64,
    /// Parts of `kernel_seconds`: placing the elements and finding the candidates; deciding
    /// each candidate's visibility and kernel (series, quadrature, expansion); writing the
    /// store and forming `Delta K (b - u)`.
    pub scan_seconds: f64,
    pub pairs_seconds: f64,
    pub apply_seconds: f64,
    pub solve_seconds: f64,
    pub shots: usize,
    /// How much of the last frame's shots were replayed before the solve (`crate::replay`): 0
    /// without a replay, near 1 under steady motion.
    pub replay_scale: f64,
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
    /// Pair ids by their two elements.
    index: PairIndex,
    /// The element geometry of the last update, for elements that do not move in the next.
    geometry: Option<KeptGeometry>,
    /// Per element: whether its plane has culled occluders
    /// ([`crate::visibility::Occluders::culls`]) in any frame since the build; `None` before the
    /// first update.
    culled: Option<Vec<bool>>,
    /// Buffers of the last update, reused so that a frame does not fault in fresh pages: the
    /// batches' blocks and the blocks the store replaced.
    block_pool: Vec<Vec<f32>>,
    replaced: ReplacedBlocks,
    /// `b - u` of the last solution, the part already shot (`Delta K (b - u)`, module docs), kept
    /// for the same reason.
    sent: Vec<[f64; 3]>,
    /// The last solve's shots, replayed as the next frame's first guess.
    replay: Option<Replay>,
    /// Updates made so far.
    updates: u32,
    /// Per pair id: the update in which its visibility last changed, or in which it was added
    /// ([`NEVER`] for the pairs of the build); see [`CALM_UPDATES`].
    visibility_changed: Vec<u32>,
}

impl AnimationState {
    pub fn new(n_elements: usize, use_series: bool) -> Self {
        Self {
            series: Vec::new(),
            epochs: vec![0; n_elements],
            use_series,
            index: PairIndex::default(),
            geometry: None,
            culled: None,
            block_pool: Vec::new(),
            replaced: ReplacedBlocks::default(),
            sent: Vec::new(),
            replay: None,
            updates: 0,
            visibility_changed: Vec::new(),
        }
    }

    /// Bumps the epoch of every element that did not move by a pure translation this frame.
    fn bump_epochs(&mut self, translated: &[bool]) {
        for (e, &t) in translated.iter().enumerate() {
            if !t {
                self.epochs[e] = self.epochs[e].wrapping_add(1);
            }
        }
    }

    /// Pairs holding a series, and the bytes their terms take.
    pub fn series_memory(&self) -> (usize, usize) {
        let held: Vec<_> = self.series.iter().flatten().collect();
        (held.len(), held.iter().map(|s| s.terms.len() * 4).sum())
    }
}

/// The stored pairs by their two elements: per element `a`, the pairs `(b, id)` with `b > a`,
/// sorted by `b`. A candidate `(a, b)` is a binary search in `a`'s row, and the candidates of one
/// element come in increasing `b`, so consecutive lookups read the same few cache lines. (A hash
/// map of the ~320k pairs of the moving-light box, keyed by both elements, read a random line per
/// candidate: 0.35 us of the decision's ~1 us; [`LinkStore::find`] scans an unsorted adjacency.)
#[derive(Default)]
struct PairIndex {
    rows: Vec<Vec<(u32, PairId)>>,
    /// Pairs `0..indexed` of the store are in `rows` (the store only appends).
    indexed: usize,
}

impl PairIndex {
    /// Adds the pairs the store gained since the last call (all of them the first time).
    fn sync(&mut self, links: &LinkStore) {
        if links.len() < self.indexed {
            *self = Self::default();
        }
        let mut touched = Vec::new();
        for p in self.indexed..links.len() {
            let pair = links.pair(p as PairId);
            let (a, b) = (pair.a.min(pair.b) as usize, pair.a.max(pair.b));
            if self.rows.len() <= a {
                self.rows.resize_with(a + 1, Vec::new);
            }
            self.rows[a].push((b, p as PairId));
            touched.push(a);
        }
        touched.sort_unstable();
        touched.dedup();
        for a in touched {
            self.rows[a].sort_unstable();
        }
        self.indexed = links.len();
    }

    /// Records pair `p`, just pushed to the store.
    fn insert(&mut self, a: u32, b: u32, p: PairId) {
        debug_assert_eq!(p as usize, self.indexed);
        let (a, b) = (a.min(b) as usize, a.max(b));
        if self.rows.len() <= a {
            self.rows.resize_with(a + 1, Vec::new);
        }
        let row = &mut self.rows[a];
        let at = row.partition_point(|&(other, _)| other < b);
        row.insert(at, (b, p));
        self.indexed += 1;
    }

    fn get(&self, a: u32, b: u32) -> Option<PairId> {
        let row = self.rows.get(a.min(b) as usize)?;
        let b = a.max(b);
        row.binary_search_by_key(&b, |&(other, _)| other).ok().map(|k| row[k].1)
    }
}

/// Updates `sys` (solved for `prev`) to `next` at `frame`. The phases: the new frame's elements
/// and their motion (`motion.rs`; a change of topology rebuilds), with anything moved the kernel's
/// changes (`update_kernel`), then `Delta e` and the solve (`solve.rs`).
pub fn advance(
    sys: &mut System,
    state: &mut AnimationState,
    next: &Scene,
    frame: f64,
    progress: Progress,
) -> Result<Outcome> {
    let start = std::time::Instant::now();
    state.updates += 1;
    let segments_before = crate::visibility::segments_tested();
    let Some(new) = NewFrame::place(sys, next, frame) else {
        return Ok(Outcome::NeedsRebuild);
    };
    let motion = FrameMotion::of(&new, &sys.elements);
    state.bump_epochs(&motion.translated);
    let mut stats = UpdateStats { moved_elements: new.moved_count(), ..Default::default() };
    let coefficients = new.elements.len() * sys.basis.len();
    let mut delta_b = vec![[0.0f64; 3]; coefficients];
    // The last frame's shots, replayed as this frame's first guess (`crate::replay`). Taken out
    // of the state: it goes back only with a finished solve (it must describe the kernel the
    // changes below start from).
    let replay = state.replay.take();
    // `Delta K sigma`, for the replay, formed with `Delta K (b - u)` (zero without a replay).
    let mut delta_k_sigma = vec![[0.0f64; 3]; coefficients];
    if stats.moved_elements > 0 {
        let moving = Moving { next, new: &new, motion: &motion, start, progress };
        update_kernel(sys, state, &moving, replay.as_ref(), [&mut delta_b, &mut delta_k_sigma], &mut stats)?;
    }
    stats.segments_tested = crate::visibility::segments_tested() - segments_before;
    stats.kernel_seconds = start.elapsed().as_secs_f64();
    solve::enter_frame(sys, next, frame, new.elements, (&new.moved, &motion.swept), &mut delta_b, &mut stats);
    let tolerance = next.settings.tolerance;
    state.replay = Some(solve::solve(sys, replay, &delta_k_sigma, tolerance, progress, &mut stats)?);
    Ok(Outcome::Updated(stats))
}

/// A frame in which elements moved, as the kernel update reads it.
struct Moving<'a> {
    next: &'a Scene,
    new: &'a NewFrame,
    motion: &'a FrameMotion,
    /// When the update started (the stats time its parts from it).
    start: std::time::Instant,
    progress: Progress<'a>,
}

/// The kernel's changes under the motion of `m` (sections 3.1 to 3.3): the candidate pairs
/// (`candidates.rs`), their new kernels (`pairs.rs`), written into the store (`apply.rs`), and
/// the changes `Delta K (b - u)` and `Delta K sigma` added to `delta` (`delta_k.rs`), with
/// `replay`'s sigma. The system takes the frame's occluders, the state its geometry and buffers.
fn update_kernel(
    sys: &mut System,
    state: &mut AnimationState,
    m: &Moving,
    replay: Option<&Replay>,
    delta: [&mut [[f64; 3]]; 2],
    stats: &mut UpdateStats,
) -> Result<()> {
    let s = &m.next.settings;
    let rule = GaussLegendre::new(s.quadrature_order);
    let ctx = PairContext {
        basis: sys.basis,
        rule: &rule,
        vis_axis: s.visibility_samples,
        adaptive: s.adaptive_quadrature,
    };
    let Found { pairs: candidates, shaft_tests, occluders, geom } =
        candidates::find(m.new, m.motion, state.geometry.take(), &ctx, s);
    state.index.sync(&sys.links);
    stats.shaft_tests = shaft_tests;
    stats.candidates = candidates.len();
    let moved_triangles =
        pairs::prepare_relink(&mut state.culled, sys, m.new, occluders.as_ref(), s.visibility_samples);
    stats.scan_seconds = m.start.elapsed().as_secs_f64();

    let pool = std::mem::take(&mut state.block_pool);
    let mut replaced = std::mem::take(&mut state.replaced);
    let phase = PairPhase {
        state,
        links: &sys.links,
        ctx: &ctx,
        geom: &geom,
        occluders: occluders.as_ref(),
        moved_triangles: &moved_triangles,
        patches: &m.new.patches,
        moved: &m.new.moved,
        motion: m.motion,
    };
    let mut batches = phase.run(&candidates, pool, m.progress)?;
    stats.pairs_seconds = m.start.elapsed().as_secs_f64() - stats.scan_seconds;
    pairs::count(&batches, stats);

    let written = apply::write_store(sys, state, &mut batches, &mut replaced, stats)?;
    let no_replay = vec![[0.0f64; 3]; m.new.elements.len() * sys.basis.len()];
    let sigma = replay.map_or(&no_replay[..], Replay::sigma);
    let sent = delta_k::shot_part(&sys.solution, std::mem::take(&mut state.sent));
    let k_sigma = replay.map(Replay::k_sigma);
    let mut delta_k = DeltaK { x: [&sent, sigma], k_sigma, out: delta };
    let first = delta_k.add_pair_changes(sys, &written, &replaced);
    delta_k.add_bound_changes(sys, &first, &m.new.elements, m.next);
    drop(written);
    state.sent = sent;
    state.block_pool = batches.into_iter().map(|b| b.blocks).collect();
    state.replaced = replaced;
    stats.apply_seconds = m.start.elapsed().as_secs_f64() - stats.scan_seconds - stats.pairs_seconds;
    state.geometry = Some(geom.into_kept(&ctx));
    // The new placement's occluders serve the corner gather and the next update.
    sys.occluders = occluders;
    Ok(())
}

/// A pair whose visibility changed (or that was added) is not expanded until its visibility has
/// held for this many updates. In a moving penumbra a pair's mask changes every few frames, and
/// each change drops its series: re-expanded the next frame, as before session 7, the moving-light
/// box spent 3.5-4 ms of thread time a frame on expansions and 8.2-8.6 ms on all its kernels
/// (series, quadratures, expansions) against 5.3-5.6 ms for `--exact`'s quadratures. Waiting 8
/// updates: 1.5-1.9 ms on expansions, 5.1-6.5 ms in all, level with `--exact` (4 or 16 were
/// no better; timers around each kind of kernel, 2 runs of 30 frames, thread time per frame).
const CALM_UPDATES: u32 = 8;

/// [`AnimationState::visibility_changed`] of a pair that never changed.
const NEVER: u32 = u32::MAX;

/// Records that pair `p`'s visibility changed (or that it was added) in this update.
fn mark_visibility_change(state: &mut AnimationState, p: PairId) {
    if state.visibility_changed.len() <= p as usize {
        state.visibility_changed.resize(p as usize + 1, NEVER);
    }
    state.visibility_changed[p as usize] = state.updates;
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::scene::{Key, KeyTransform, Material, Settings};
    use crate::scenes::subdivided_quad;
    use crate::system::no_progress;

    /// A light sliding over a floor past a thin occluder, frames 1-81, at basis `order` (corners
    /// from the polynomials), solved at frame 1, and a fresh update state.
    fn light_past_an_occluder(order: usize, adaptive: bool) -> (Scene, System, AnimationState) {
        let settings = Settings {
            basis_order: order,
            corner_gather: false,
            adaptive_quadrature: adaptive,
            ..Settings::default()
        };
        let p = DVec3::new;
        let floor =
            subdivided_quad("floor", [p(0., 0., 0.), p(1., 0., 0.), p(1., 1., 0.), p(0., 1., 0.)], 4, 0);
        let occluder = subdivided_quad(
            "occluder",
            [p(0.6, 0., 0.5), p(0.65, 0., 0.5), p(0.65, 1., 0.5), p(0.6, 1., 0.5)],
            1,
            0,
        );
        let mut light = subdivided_quad(
            "light",
            [p(0.4, 0.4, 1.), p(0.4, 0.6, 1.), p(0.6, 0.6, 1.), p(0.6, 0.4, 1.)],
            1,
            1,
        );
        light.animation = vec![
            Key { frame: 1.0, transform: KeyTransform::Translation(DVec3::ZERO) },
            // 0.0125 a frame: slow enough for the series to serve MIN_SERIES_FRAMES frames.
            Key { frame: 81.0, transform: KeyTransform::Translation(p(1.0, 0., 0.)) },
        ];
        let materials = vec![
            Material { name: "grey".into(), reflectance: [0.5; 3], emission: [0.0; 3] },
            Material { name: "light".into(), reflectance: [0.0; 3], emission: [5.0; 3] },
        ];
        let scene =
            Scene::new(settings, (1, 81), materials, vec![vec![]; 2], vec![floor, occluder, light]).unwrap();
        let mut sys = System::build(&scene, 1.0, &no_progress).unwrap();
        sys.solve(scene.settings.tolerance, &|| false).unwrap();
        let state = AnimationState::new(sys.elements.len(), true);
        (scene, sys, state)
    }

    /// The occluder's shadow sweeps the floor: the light-floor pairs' masks change frame after
    /// frame. No pair is expanded before its visibility has held for `CALM_UPDATES` updates, and
    /// pairs whose visibility changed are expanded again once it has.
    #[test]
    fn pairs_are_expanded_only_after_their_visibility_has_held() {
        // Every pair on the 4 x 4-point rule, where the series is used (`MIN_SERIES_POINTS`).
        let (scene, mut sys, mut state) = light_past_an_occluder(1, false);
        let reference = |s: &AnimationState| -> Vec<Option<(DVec3, DVec3)>> {
            s.series.iter().map(|x| x.as_ref().map(|x| (x.ref_a, x.ref_b))).collect()
        };
        let (mut changes, mut late_expansions) = (0, 0);
        for f in 2..=81 {
            let before = reference(&state);
            let changed_before = state.visibility_changed.clone();
            let Outcome::Updated(_) = advance(&mut sys, &mut state, &scene, f as f64, &no_progress).unwrap()
            else {
                panic!("topology changed")
            };
            for (p, now) in reference(&state).iter().enumerate() {
                let changed = state.visibility_changed.get(p).copied().unwrap_or(NEVER);
                if changed != changed_before.get(p).copied().unwrap_or(NEVER) {
                    changes += 1;
                }
                let expanded = now.is_some() && before.get(p).copied().flatten() != *now;
                if expanded && changed != NEVER {
                    let held = state.updates - changed;
                    assert!(
                        held >= CALM_UPDATES,
                        "frame {f}: pair {p} expanded {held} updates after a change"
                    );
                    late_expansions += 1;
                }
            }
        }
        assert!(changes >= 10, "only {changes} visibility changes: the shadow does not sweep the floor");
        assert!(late_expansions > 0, "no pair was expanded again after its visibility changed");
    }

    /// Pairs whose quadrature is cheaper than reading a series are recomputed, not expanded:
    /// with adaptive quadrature on, order 1 takes 2, 3 or 4 points per axis by distance, and
    /// every pair holding a series is on the 4-point rule (here none is), while with it off
    /// (every pair on 4 points) pairs are expanded; order 3's far rule has 4 points, and its
    /// pairs are expanded with adaptive quadrature on.
    #[test]
    fn only_pairs_on_a_dear_rule_are_expanded() {
        let held = |order: usize, adaptive: bool| -> Vec<(usize, usize)> {
            let (scene, mut sys, mut state) = light_past_an_occluder(order, adaptive);
            let rule = GaussLegendre::new(scene.settings.quadrature_order);
            let ctx = PairContext { basis: sys.basis, rule: &rule, vis_axis: 4, adaptive };
            let mut held = Vec::new();
            for f in 2..=40 {
                advance(&mut sys, &mut state, &scene, f as f64, &no_progress).unwrap();
                for (p, ser) in state.series.iter().enumerate() {
                    if ser.is_some() {
                        let pair = sys.links.pair(p as PairId);
                        let (a, b) =
                            (sys.elements[pair.a as usize].patch, sys.elements[pair.b as usize].patch);
                        let ((ca, ra), (cb, rb)) = (a.bounding_sphere(), b.bounding_sphere());
                        held.push((p, ctx.points_for(ca.distance(cb) / (ra + rb))));
                    }
                }
            }
            held
        };
        let adaptive = held(1, true);
        // (4, not the constant: the test is that 3-point pairs stay unexpanded.)
        let cheap = adaptive.iter().filter(|&&(_, n)| n < 4).count();
        assert_eq!(cheap, 0, "{cheap} series held by pairs on a rule under 4 points");
        assert!(!held(1, false).is_empty(), "on the 4-point rule no pair was expanded");
        let order_3 = held(3, true);
        assert!(!order_3.is_empty(), "order 3, adaptive: no pair was expanded");
        assert!(order_3.iter().all(|&(_, n)| n >= 4), "order 3 has no rule under 4 points");
    }
}
