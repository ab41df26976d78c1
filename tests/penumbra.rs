//! The corner gather's direct light in a penumbra, against brute force (issue 19, the
//! monastery's ground).
//!
//! The gather integrates an emitter with shadow rays to its Gauss nodes: 3 x 3 per rectangle, a
//! rectangle split in four while the corner is closer than three of its radii. In a penumbra a
//! corner sees some nodes and not others, so its direct light moves in steps of a ninth of a
//! rectangle's light: the monastery's ground, under a 62 m light 79 m up, was 6.3% (RMS, of its
//! mean) from the brute force of the same scene, up to 10% at single corners beside a building
//! (docs/validation-real.md, "The monastery"). An emitter's rectangle whose nodes disagree, or
//! whose corners disagree with its nodes, is now split further (`gather::PENUMBRA_DEPTH` levels).
//!
//! Here: a grey 2 x 2 m ground of 16 x 16 quads under a 1 m light quad 1 m up, and a black
//! 0.5 x 0.5 x 0.1 m box floating 0.4 m above the ground, off the light's axis, so that its
//! penumbra on the ground is wide. Nothing but the light lights the ground (the box is black,
//! the ground flat), so a ground corner's exact `B` is `rho E_d`, `E_d` by brute force (the light
//! cut into 64 x 64 pieces, each piece's exact point-to-polygon form factor times one shadow ray
//! to its centre through the box's triangles). Nothing touches the ground, so no foot or contact
//! split enters. Over the 775 ground corners in the penumbra (some of the light's pieces seen,
//! some hidden): before, 5.59% relative RMS error (of their mean `B`), the worst corner 20.9%;
//! splitting only rectangles whose nodes disagree, 1.72% and 10.7% (a shadow edge crossing a
//! rectangle between its nodes and its edge went unseen); with the corners' rays too, 0.20% and
//! 0.55%. Through the hierarchy's corner gather (the light a far source there): 4.01% and 11.9%
//! before its Gauss sums split an emitter's rectangles alike, 0.29% and 1.10% after.

use galerkin_radiosity::geometry::Patch;
use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
use galerkin_radiosity::scene::Scene;
use galerkin_radiosity::scene::json::ObjectResult;
use galerkin_radiosity::scenes::{box_mesh, facing, subdivided_quad};
use galerkin_radiosity::system::no_progress;
use galerkin_radiosity::visibility::bvh::Triangle;
use glam::DVec3;

#[path = "common/brute_force.rs"]
mod brute_force;

const RHO: f64 = 0.7;
const EXITANCE: f64 = 10.0;
const LIGHT_HALF: f64 = 0.5;
const LIGHT_HEIGHT: f64 = 1.0;
const BOX_MIN: DVec3 = DVec3::new(-0.1, -0.35, 0.4);
const BOX_MAX: DVec3 = DVec3::new(0.4, 0.15, 0.5);

fn light_corners() -> [DVec3; 4] {
    brute_force::ceiling_light(LIGHT_HALF, LIGHT_HEIGHT)
}

fn scene() -> Scene {
    let p = |x, y| DVec3::new(x, y, 0.0);
    let ground = subdivided_quad(
        "ground",
        facing([p(-1.0, -1.0), p(1.0, -1.0), p(1.0, 1.0), p(-1.0, 1.0)], DVec3::Z, false),
        16,
        0,
    );
    let occluder = box_mesh("box", BOX_MIN, BOX_MAX, 1, false, 1);
    let light = subdivided_quad("light", light_corners(), 1, 2);
    brute_force::grey_black_light(RHO, EXITANCE, vec![ground, occluder, light])
}

/// `E_d` at `y` (normal +z) by brute force, shadowed by `occluders`; and whether some of the
/// light's pieces are hidden and some seen (a penumbra).
fn direct(y: DVec3, occluders: &[Triangle]) -> (f64, bool) {
    let light = Patch::from_corners(&light_corners());
    let d = brute_force::direct_light(&light, y, DVec3::Z, occluders, 64);
    (EXITANCE * d.form_factor, d.seen > 0 && d.hidden > 0)
}

/// Over the ground corners in the penumbra: how many, and their relative RMS and worst error
/// against brute force (of their mean `B`).
fn penumbra_error(scene: &Scene, results: &[ObjectResult]) -> (usize, f64, f64) {
    let occluders = brute_force::triangles_of(&box_mesh("box", BOX_MIN, BOX_MAX, 1, false, 1));
    let ground = &scene.objects[0];
    let (mut sq, mut sum, mut worst, mut count) = (0.0, 0.0, 0.0f64, 0);
    let mut corner = 0;
    for face in &ground.faces {
        for &v in face {
            let p = ground.vertices[v as usize];
            let value = results[0].corner_radiosity[corner][0] as f64;
            corner += 1;
            let (e_d, penumbra) = direct(p + DVec3::Z * 1e-9, &occluders);
            if !penumbra {
                continue;
            }
            let exact = RHO * e_d;
            sq += (value - exact).powi(2);
            sum += exact;
            worst = worst.max((value - exact).abs());
            count += 1;
        }
    }
    let mean = sum / count as f64;
    eprintln!(
        "{count} ground corners in the penumbra: relative RMS error {:.2}%, worst {:.2}% (of their mean B {mean:.4})",
        100.0 * (sq / count as f64).sqrt() / mean,
        100.0 * worst / mean
    );
    (count, (sq / count as f64).sqrt() / mean, worst / mean)
}

#[test]
fn ground_corners_in_a_penumbra_match_brute_force() {
    let scene = scene();
    let sys = brute_force::gathered(&scene);
    let (count, rms, worst) = penumbra_error(&scene, &sys.face_results(&scene, 1.0));
    assert!(count > 100, "the penumbra covers a good part of the ground: {count} corners");
    assert!(rms < 0.01, "relative RMS error {rms} in the penumbra");
    assert!(worst < 0.04, "worst corner {worst} in the penumbra");
}

/// The same through the hierarchy's corner gather, which casts the light as a far source.
#[test]
fn ground_corners_in_a_penumbra_match_brute_force_through_the_hierarchy() {
    let scene = scene();
    let settings = HierarchySettings { corner_gather: true, ..HierarchySettings::of(&scene.settings) };
    let h = solve_frame(&scene, 0.0, &settings, &no_progress).unwrap();
    let (count, rms, worst) = penumbra_error(&scene, &h.face_results(&scene, 0.0));
    assert!(count > 100, "the penumbra covers a good part of the ground: {count} corners");
    assert!(rms < 0.01, "relative RMS error {rms} in the penumbra");
    assert!(worst < 0.04, "worst corner {worst} in the penumbra");
}
