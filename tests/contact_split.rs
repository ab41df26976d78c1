//! Faces split where another object comes close (`contact_split`, issue 19): the differential
//! test that found the cause, against brute force.
//!
//! A black box stands on a grey ground under a light quad. The ground sees only the light and
//! the box (black; a plane does not see itself), so its exact radiosity is
//! `B(y) = rho E_d(y)`: the light's direct irradiance with the box's shadow, computed here by
//! brute force (the light cut into 24 x 24 pieces, each piece's exact point-to-polygon form
//! factor times one shadow ray to its centre, through every box triangle). The solved ground
//! polynomials are compared with it at points around and under the box. A ground face of 1 m
//! is one quadratic: it cannot follow the box's shadow and contact (it goes negative under the
//! box), which is what the corner gather then read at the corners of a model standing on it.

use galerkin_radiosity::geometry::Patch;
use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
use galerkin_radiosity::scene::{Key, KeyTransform, Object, Scene};
use galerkin_radiosity::scenes::{box_mesh, facing, merge, subdivided_quad};
use galerkin_radiosity::system::{System, no_progress};
use galerkin_radiosity::visibility::bvh::Triangle;
use glam::DVec3;

#[path = "common/brute_force.rs"]
mod brute_force;

const RHO: f64 = 0.7;
const EXITANCE: f64 = 10.0;
const LIGHT_HALF: f64 = 0.25;
const LIGHT_HEIGHT: f64 = 1.0;

fn ground() -> Object {
    let p = |x, y| DVec3::new(x, y, 0.0);
    subdivided_quad("ground", facing([p(-1., -1.), p(1., -1.), p(1., 1.), p(-1., 1.)], DVec3::Z, false), 2, 0)
}

/// A 0.3 m box standing on the ground with a corner on the ground faces' shared corner, its
/// sides 6 x 6.
fn black_box() -> Object {
    box_mesh("box", DVec3::new(0.0, 0.0, 0.0), DVec3::new(0.3, 0.3, 0.3), 6, false, 1)
}

fn light() -> Object {
    subdivided_quad("light", brute_force::ceiling_light(LIGHT_HALF, LIGHT_HEIGHT), 1, 2)
}

fn scene(objects: Vec<Object>) -> Scene {
    brute_force::grey_black_light(RHO, EXITANCE, objects)
}

/// `rho E_d(y)` at a ground point, by brute force.
fn ground_truth(y: DVec3, occluders: &[Triangle]) -> f64 {
    let m = 24;
    let light = Patch::from_corners(&brute_force::ceiling_light(LIGHT_HALF, LIGHT_HEIGHT));
    RHO * EXITANCE * brute_force::direct_light(&light, y, DVec3::Z, occluders, m).form_factor
}

/// The solved ground's `B` at world point `y` (on the ground plane).
fn solved_ground(sys: &System, scene: &Scene, ground: usize, y: DVec3) -> f64 {
    let (f, s, t) = ground_face_at(scene, ground, y);
    let (e, ls, lt) = sys.element_of_face(ground, f, s, t).expect("the ground has an element there");
    sys.eval(e, ls, lt)[0]
}

/// The box's triangles, for the brute force's shadow rays.
fn box_triangles() -> Vec<Triangle> {
    brute_force::triangles_of(&black_box())
}

/// Relative RMS error (of the brute-force mean) of `solved` on a 31 x 31 grid of ground points
/// within 0.35 m of the box, under it included; the lowest `B` there.
fn ground_error_of(solved: impl Fn(DVec3) -> f64) -> (f64, f64) {
    let occluders = box_triangles();
    let (mut sq, mut sum, mut min, mut n) = (0.0, 0.0, f64::INFINITY, 0);
    for i in 0..=30 {
        for j in 0..=30 {
            let y = DVec3::new(-0.35 + 1.0 * i as f64 / 30.0, -0.35 + 1.0 * j as f64 / 30.0, 0.0);
            let (ours, truth) = (solved(y), ground_truth(y, &occluders));
            sq += (ours - truth).powi(2);
            sum += truth;
            min = min.min(ours);
            n += 1;
        }
    }
    ((sq / n as f64).sqrt() / (sum / n as f64), min)
}

/// The ground's `(face, s, t)` at world point `y` (faces are axis-aligned squares in corner
/// order: `(s,t)` along the first two edges).
fn ground_face_at(scene: &Scene, ground: usize, y: DVec3) -> (usize, f64, f64) {
    let obj = &scene.objects[ground];
    for (f, face) in obj.faces.iter().enumerate() {
        let corners: Vec<DVec3> = face.iter().map(|&v| obj.vertices[v as usize]).collect();
        let (lo, hi) =
            corners.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(l, h), c| (l.min(*c), h.max(*c)));
        if y.x < lo.x || y.x > hi.x || y.y < lo.y || y.y > hi.y {
            continue;
        }
        let s = (y - corners[0]).dot(corners[1] - corners[0]) / (corners[1] - corners[0]).length_squared();
        let t = (y - corners[0]).dot(corners[3] - corners[0]) / (corners[3] - corners[0]).length_squared();
        return (f, s, t);
    }
    panic!("{y} is off the ground");
}

/// Relative RMS error (of the brute-force mean) of the solved ground on a 31 x 31 grid of points
/// within 0.35 m of the box, under it included; the lowest `B` there; the elements.
fn ground_error(scene: &Scene, ground: usize) -> (f64, f64, usize) {
    let mut sys = System::build(scene, 1.0, &no_progress).unwrap();
    sys.solve(scene.settings.tolerance, &|| false).unwrap();
    let (error, min) = ground_error_of(|y| solved_ground(&sys, scene, ground, y));
    (error, min, sys.elements.len())
}

/// As [`ground_error`], solved on the hierarchy (its leaves for the elements).
fn hierarchical_ground_error(scene: &Scene, ground: usize) -> (f64, f64, usize) {
    let h = solve_frame(scene, 0.0, &HierarchySettings::of(&scene.settings), &no_progress).unwrap();
    let (error, min) = ground_error_of(|y| {
        let (f, s, t) = ground_face_at(scene, ground, y);
        h.eval_face(h.face_index(ground, f).expect("a ground face"), s, t)[0]
    });
    (error, min, h.stats.leaves)
}

#[test]
fn ground_next_to_a_box_follows_its_shadow() {
    // The box and the ground as one object with a key that does not move it: an object with keys
    // neither splits nor is split (the ground as before the split).
    let mut keyed = merge("ground and box", vec![ground(), black_box()]);
    keyed.animation = vec![Key { frame: 1.0, transform: KeyTransform::Translation(DVec3::ZERO) }];
    let (before, min_before, n_before) = ground_error(&scene(vec![keyed, light()]), 0);
    // The same object without the key: its faces split each other where the box's sides meet
    // the ground at a concave crease (the crease rule), down to 4% of the scene's size only.
    let one = scene(vec![merge("ground and box", vec![ground(), black_box()]), light()]);
    let (crease, _, n_crease) = ground_error(&one, 0);
    let split = scene(vec![ground(), black_box(), light()]);
    let (after, min_after, n_after) = ground_error(&split, 0);
    eprintln!(
        "ground within 0.35 m of the box, relative RMS error against brute force: one face each \
         {:.1}% (lowest B {min_before:.3}, {n_before} elements), one object split at its creases \
         {:.1}% ({n_crease} elements), split {:.1}% (lowest B {min_after:.3}, {n_after} elements)",
        100.0 * before,
        100.0 * crease,
        100.0 * after
    );
    assert!(n_after > n_before, "the ground next to the box is split");
    assert!(crease < before, "the crease split lowers the error: {crease} against {before}");
    assert!(after < 0.12, "split ground {after} from brute force");
    // A quadratic over a face half in the box's shadow goes negative under the box; the parts
    // do not (B >= 0 up to the rounding of the fit).
    let peak = RHO * EXITANCE;
    assert!(min_after > -0.01 * peak, "split ground negative: {min_after}");
    assert!(after < 0.5 * before, "splitting halves the error at least: {after} against {before}");
}

/// The hierarchy splits the same faces ahead of linking (`Tree::split_for_contacts`). Its own
/// refinement already follows much of the shadow (it splits where the light's links carry
/// most), so the gain is smaller than the flat path's: measured 9.1% -> 7.1%.
#[test]
fn the_hierarchy_splits_the_ground_next_to_a_box_too() {
    let one = scene(vec![merge("ground and box", vec![ground(), black_box()]), light()]);
    let (before, min_before, n_before) = hierarchical_ground_error(&one, 0);
    let split = scene(vec![ground(), black_box(), light()]);
    let (after, min_after, n_after) = hierarchical_ground_error(&split, 0);
    eprintln!(
        "hierarchy, ground within 0.35 m of the box against brute force: one object {:.1}% (lowest \
         B {min_before:.3}, {n_before} leaves), split {:.1}% (lowest B {min_after:.3}, {n_after} leaves)",
        100.0 * before,
        100.0 * after
    );
    assert!(after < 0.12, "split ground {after} from brute force");
    let peak = RHO * EXITANCE;
    assert!(min_after > -0.01 * peak, "split ground negative: {min_after}");
    assert!(after < 0.85 * before, "the split lowers the error: {after} against {before}");
}
