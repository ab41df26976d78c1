//! The update's last phases: emission changes enter as `Delta e` (eq. 9), the system takes the new
//! frame's elements, areas and materials, and the replay of the last frame's shots and progressive
//! shooting solve it.

use crate::error::Result;
use crate::geometry::Aabb;
use crate::lights::direct::{DirectLight, LastFrame};
use crate::replay::Replay;
use crate::scene::Scene;
use crate::solver;
use crate::system::{Element, Progress, System};

use super::UpdateStats;

/// Adds the emission changes to `delta_b` and `delta_b` to the solution, then moves the system to
/// the new frame's `elements` at `frame`; `moved` says which elements moved since the system's,
/// inside the boxes `swept`.
pub(super) fn enter_frame(
    sys: &mut System,
    next: &Scene,
    frame: f64,
    elements: Vec<Element>,
    (moved, swept): (&[bool], &[Aabb]),
    delta_b: &mut [[f64; 3]],
    stats: &mut UpdateStats,
) {
    // Emission changes, the lights' direct light among them, enter as Delta e (eq. 9). The last
    // frame's shadow rays are taken again where no move can have changed them.
    let last = sys.lights.as_deref().map(|lights| LastFrame { lights, moved, swept });
    let sources = crate::system::frame_sources(next, frame, &elements, sys.basis, last);
    if let Some(rays) = sources.2.as_deref().map(DirectLight::kept_rays) {
        (stats.direct_rays_traced, stats.direct_rays_taken) = (rays.traced, rays.taken);
    }
    sys.take_sources(sources, delta_b);
    sys.add_unshot(delta_b);
    sys.elements = elements;
    // The transfers were moved with the previous areas; a scaled element reweighs them all.
    sys.links.set_receiver_areas(&sys.areas());
    let surface: Vec<[f64; 3]> = sys.elements.iter().map(|e| e.reflectance(next)).collect();
    if surface != sys.surface_reflectance {
        // A material changed: Delta K is not formed for that (as before the bound), the bound
        // is taken afresh.
        sys.reflectance = crate::system::bounded_reflectances(&sys.links, &surface);
        sys.surface_reflectance = surface;
    }
}

/// Solves the system to `tolerance` of its emitted power: replays the last frame's shots (`replay`,
/// with `delta_k_sigma`, `Delta K sigma`), then shoots what is left. Returns this frame's shots,
/// to be replayed in the next.
pub(super) fn solve(
    sys: &mut System,
    replay: Option<Replay>,
    delta_k_sigma: &[[f64; 3]],
    tolerance: f64,
    progress: Progress,
    stats: &mut UpdateStats,
) -> Result<Replay> {
    let solve_start = std::time::Instant::now();
    // Replay the last frame's shots, then shoot what is left; record this frame's for the next.
    let before = sys.solution.clone();
    // (Under other reflectances than the recorded ones the replay would not keep the invariant.)
    if let Some(r) = replay.as_ref().filter(|r| r.applies_to(&sys.surface_reflectance)) {
        stats.replay_scale = r.apply(&mut sys.solution, delta_k_sigma, sys.links.transfers());
    }
    let stop = tolerance * sys.emitted_power();
    let cancel = || !progress(1.0, "solve");
    let shot = solver::shoot(&sys.links, &sys.reflectance, &mut sys.solution, stop, &cancel)?;
    let recorded = Replay::record(&before, &sys.solution, &sys.surface_reflectance);
    stats.solve_seconds = solve_start.elapsed().as_secs_f64();
    stats.shots = shot.shots;
    Ok(recorded)
}
