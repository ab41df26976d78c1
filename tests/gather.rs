//! The corner gather (src/gather.rs): closed forms at corners, and corners hidden by contact.

use galerkin_radiosity::gather;
use galerkin_radiosity::scene::{Material, Object, Scene, Settings};
use galerkin_radiosity::scenes;
use galerkin_radiosity::session::{Method, Session};
use galerkin_radiosity::system::{System, no_progress};
use glam::DVec3;

fn solved(scene: &Scene) -> System {
    let mut sys = System::build(scene, 1.0, &no_progress).unwrap();
    sys.solve(scene.settings.tolerance, &|| false).unwrap();
    sys
}

fn gathered(scene: &Scene) -> (System, Vec<Vec<[f32; 3]>>) {
    let mut sys = solved(scene);
    let polynomial = sys.face_results(scene, 1.0).into_iter().map(|r| r.corner_radiosity).collect();
    sys.gather_corners(scene, 1.0, &no_progress).unwrap();
    (sys, polynomial)
}

fn materials(rho: f64, emission: f64) -> Vec<Material> {
    vec![
        Material { name: "grey".into(), reflectance: [rho; 3], emission: [0.0; 3] },
        Material { name: "emitter".into(), reflectance: [0.0; 3], emission: [emission; 3] },
    ]
}

/// Closed enclosure, uniform rho and E: B = E / (1 - rho) at every corner too, including the
/// room's edges and corners, where a perpendicular wall is nearly singular.
#[test]
fn furnace_corners_are_e_over_one_minus_rho() {
    for &(n, order, rho) in &[(2, 1, 0.5), (3, 2, 0.9)] {
        let scene = scenes::closed_box(
            n,
            rho,
            1.0,
            Settings { basis_order: order, tolerance: 1e-8, ..Settings::default() },
        );
        let (sys, _) = gathered(&scene);
        let want = 1.0 / (1.0 - rho);
        let mut worst: f64 = 0.0;
        for r in sys.face_results(&scene, 1.0) {
            for c in &r.corner_radiosity {
                worst = worst.max((c[0] as f64 - want).abs() / want);
            }
        }
        eprintln!("furnace n {n} order {order} rho {rho}: worst corner error {worst:.2e}");
        assert!(worst < 2e-3, "worst relative corner error {worst}");
    }
}

/// Differential area parallel to an `a x b` rectangle at distance `c`, under its corner
/// (references.md).
fn corner_rectangle(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * std::f64::consts::PI)
}

/// A differential area under the corner of a parallel 1 x 1 emitter at height 1 receives
/// F = 0.138532 (references.md): the floor corner is `rho Be F`, gathered at the corner moved
/// `INSET` into its face, where four rectangles superpose.
#[test]
fn corner_under_parallel_emitter_matches_closed_form() {
    let floor = scenes::subdivided_quad(
        "floor",
        [DVec3::ZERO, DVec3::new(2.0, 0.0, 0.0), DVec3::new(2.0, 2.0, 0.0), DVec3::new(0.0, 2.0, 0.0)],
        2,
        0,
    );
    // Emitter over [0,1]^2 at z = 1, facing down; its corner above the floor's corner (0,0).
    let e = [
        DVec3::new(0.0, 0.0, 1.0),
        DVec3::new(0.0, 1.0, 1.0),
        DVec3::new(1.0, 1.0, 1.0),
        DVec3::new(1.0, 0.0, 1.0),
    ];
    let emitter = scenes::subdivided_quad("emitter", e, 1, 1);
    let (rho, be) = (0.5, 10.0);
    let settings = Settings { basis_order: 2, tolerance: 1e-9, ..Settings::default() };
    let scene =
        Scene::new(settings, (1, 1), materials(rho, be), vec![vec![], vec![]], vec![floor, emitter]).unwrap();
    let (sys, polynomial) = gathered(&scene);
    let floor = &sys.face_results(&scene, 1.0)[0];
    // Face 0 spans [0,1]^2 of the floor; its corner 0 is (0,0), under the emitter's corner.
    let got = floor.corner_radiosity[0][0] as f64;
    assert!((corner_rectangle(1.0, 1.0, 1.0) - 0.138532).abs() < 1e-6);
    let d = gather::INSET;
    let f = corner_rectangle(d, d, 1.0)
        + 2.0 * corner_rectangle(1.0 - d, d, 1.0)
        + corner_rectangle(1.0 - d, 1.0 - d, 1.0);
    let want = rho * be * f;
    let rel = (got - want).abs() / want;
    let poly = polynomial[0][0][0] as f64;
    eprintln!("corner: gathered {got:.5}, polynomial {poly:.5}, closed form {want:.5} ({rel:.1e})");
    assert!(rel < 1e-4, "gathered {got} vs {want}");
}

/// An open-bottom box standing on the floor over the floor's corner: the corner sees nothing and
/// is black, as a vertex bake finds it; the face polynomial under the box edge leaks light there.
#[test]
fn corner_under_a_standing_box_is_dark() {
    let floor = scenes::subdivided_quad(
        "floor",
        [DVec3::ZERO, DVec3::new(1.0, 0.0, 0.0), DVec3::new(1.0, 1.0, 0.0), DVec3::new(0.0, 1.0, 0.0)],
        2,
        0,
    );
    let e = [
        DVec3::new(-1.0, -1.0, 2.0),
        DVec3::new(-1.0, 2.0, 2.0),
        DVec3::new(2.0, 2.0, 2.0),
        DVec3::new(2.0, -1.0, 2.0),
    ];
    let emitter = scenes::subdivided_quad("emitter", e, 1, 1);
    let scene = Scene::new(
        Settings { basis_order: 2, tolerance: 1e-8, ..Settings::default() },
        (1, 1),
        materials(0.5, 1.0),
        vec![vec![], vec![]],
        vec![floor, emitter, open_box(DVec3::new(-0.2, -0.2, 0.0), DVec3::new(0.3, 0.3, 0.5))],
    )
    .unwrap();
    let (sys, polynomial) = gathered(&scene);
    let floor = &sys.face_results(&scene, 1.0)[0];
    // Face 0 = [0,0.5]^2: corner 0 (0,0) under the box, corner 2 (0.5,0.5) in the open.
    let (hidden, open) = (floor.corner_radiosity[0][0], floor.corner_radiosity[2][0]);
    let leak = polynomial[0][0][0];
    eprintln!("hidden corner {hidden:.2e}, open corner {open:.4}, polynomial at the hidden corner {leak:.4}");
    assert!(open > 0.05, "the open corner is lit: {open}");
    assert!(hidden < 1e-6 * open, "the hidden corner is dark: {hidden}");
    // The face polynomial is far off at that corner (here it undershoots): else this test shows nothing.
    assert!(leak.abs() > 0.1 * open, "the polynomial is right at the hidden corner: {leak}");
}

/// Five outward faces (no bottom) of the axis-aligned box `lo..hi`.
fn open_box(lo: DVec3, hi: DVec3) -> Object {
    let p = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let (a, b) = (lo, hi);
    let faces = [
        [p(a.x, a.y, b.z), p(b.x, a.y, b.z), p(b.x, b.y, b.z), p(a.x, b.y, b.z)],
        [p(a.x, a.y, a.z), p(b.x, a.y, a.z), p(b.x, a.y, b.z), p(a.x, a.y, b.z)],
        [p(b.x, a.y, a.z), p(b.x, b.y, a.z), p(b.x, b.y, b.z), p(b.x, a.y, b.z)],
        [p(b.x, b.y, a.z), p(a.x, b.y, a.z), p(a.x, b.y, b.z), p(b.x, b.y, b.z)],
        [p(a.x, b.y, a.z), p(a.x, a.y, a.z), p(a.x, a.y, b.z), p(a.x, b.y, b.z)],
    ];
    scenes::merge("box", faces.iter().map(|q| scenes::subdivided_quad("side", *q, 1, 0)).collect())
}

/// Gathered corners of the incremental update equal those of a from-scratch solve of the same
/// frame (the gather reads only the solution), within 1% of the peak as in tests/animation.rs.
#[test]
fn gathered_corners_of_incremental_frames_match_full() {
    use galerkin_radiosity::session::{Method, Session};
    let scene = scenes::cornell_box_animated(
        4,
        3,
        Settings { basis_order: 1, tolerance: 1e-5, ..Settings::default() },
    );
    let corners = |method| {
        let mut session = Session::new(scene.clone(), method).unwrap();
        (1..=3)
            .map(|f| {
                let stats = session.solve_frame(f as f64, &no_progress).unwrap();
                assert!(stats.gather_seconds > 0.0);
                session
                    .face_results()
                    .unwrap()
                    .into_iter()
                    .flat_map(|r| r.corner_radiosity)
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    let (inc, full) = (corners(Method::Incremental), corners(Method::Full));
    for (f, (a, b)) in inc.iter().zip(&full).enumerate() {
        let peak = b.iter().flatten().fold(0.0f32, |m, x| m.max(*x));
        let worst =
            a.iter().zip(b).flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs())).fold(0.0, f32::max);
        eprintln!("frame {}: worst gathered corner difference {:.2e} of peak", f + 1, worst / peak);
        assert!(worst <= 0.01 * peak, "frame {}: {worst} vs peak {peak}", f + 1);
    }
}

/// Advances `sys` (`state` its animation) to frame `f`, gathers its corners keeping the last
/// gather's values, and gathers them afresh: the kept gather's counts, the fresh one's, and the
/// worst difference of a kept corner from the fresh one, relative (the kept gather's corners are
/// read back as f32).
fn kept_and_fresh_gather(
    sys: &mut System,
    state: &mut galerkin_radiosity::animation::AnimationState,
    scene: &Scene,
    f: f64,
) -> (gather::GatherStats, gather::GatherStats, f64) {
    use galerkin_radiosity::animation::{Outcome, advance};
    use galerkin_radiosity::visibility::Occluders;
    assert!(matches!(advance(sys, state, scene, f, &no_progress).unwrap(), Outcome::Updated(_)));
    let kept = sys.gather_corners(scene, f, &no_progress).unwrap();
    let patches: Vec<_> = sys.elements.iter().map(|e| e.patch).collect();
    let occluders = Occluders::new(&patches, scene.settings.visibility_samples);
    let (fresh, _, all) =
        gather::CornerGather::run(sys, scene, f, Some(&occluders), None, None, &no_progress).unwrap();
    let mut worst: f64 = 0.0;
    for (r, want) in sys.face_results(scene, f).iter().zip(&fresh) {
        for (a, b) in r.corner_radiosity.iter().zip(want) {
            let d = (0..3).map(|c| (a[c] as f64 - b[c]).abs() / b[c].abs().max(1e-3)).fold(0.0, f64::max);
            worst = worst.max(d);
        }
    }
    (kept, all, worst)
}

/// The gather kept from frame to frame (moments reused where neither the corner, the source nor
/// anything in the shaft between them moved, rows whose sources cannot have changed not
/// re-derived) gives what a fresh gather of the same frame gives: on the demo animation (a light
/// and a block moving) and on the moving light of issue 3, whose links' masks change as it
/// passes the blocks, over 6 frames each.
#[test]
fn kept_gather_equals_fresh_gather() {
    use galerkin_radiosity::animation::AnimationState;
    let settings = |order| Settings { basis_order: order, tolerance: 1e-6, ..Settings::default() };
    for scene in
        [scenes::cornell_box_animated(4, 6, settings(1)), scenes::cornell_box_moving_light(4, 6, settings(2))]
    {
        let mut sys = System::build(&scene, 1.0, &no_progress).unwrap();
        sys.solve(scene.settings.tolerance, &|| false).unwrap();
        let first = sys.gather_corners(&scene, 1.0, &no_progress).unwrap();
        assert_eq!(first.recomputed, first.moments);
        let mut state = AnimationState::new(sys.elements.len(), true);
        for frame in 2..=6 {
            let (kept, all, worst) = kept_and_fresh_gather(&mut sys, &mut state, &scene, frame as f64);
            eprintln!(
                "frame {frame}: {} of {} moments recomputed, worst relative difference from a fresh gather {worst:.1e}",
                kept.recomputed, kept.moments
            );
            assert_eq!(kept.moments, all.moments);
            assert!(kept.recomputed < kept.moments / 2, "most moments are kept");
            assert!(worst <= 1e-6, "frame {frame}: {worst}");
        }
    }
}

/// The lights' direct light at the corners is kept too: a block sliding over a floor under a
/// World and a soft Point light (frames 1-3, then still; the light moving from frame 4 to 6), each
/// frame's kept gather equals a fresh gather of the same frame, once nothing moved every corner's
/// shadow ray is taken from the last gather's, and while the light moves all but its own.
#[test]
fn kept_direct_light_at_corners_equals_a_fresh_gathers() {
    use galerkin_radiosity::animation::AnimationState;
    use galerkin_radiosity::lights::{Light, LightKey, LightKind, World};
    let p = DVec3::new;
    let floor = scenes::subdivided_quad(
        "Floor",
        [p(-2., -2., 0.), p(2., -2., 0.), p(2., 2., 0.), p(-2., 2., 0.)],
        6,
        0,
    );
    let mut block = scenes::box_mesh("Block", p(-0.3, -0.3, 0.0), p(0.3, 0.3, 0.6), 2, false, 0);
    block.animation = scenes::translation_keys(&[(1.0, p(-0.8, 0.0, 0.0)), (3.0, p(0.8, 0.0, 0.0))]);
    let mut lamp =
        Light::new("Lamp", LightKind::Point, glam::DMat4::from_translation(p(0.4, -0.6, 1.5)), 60.0);
    lamp.base.radius = 0.1;
    // Still until frame 4, then moving over the still block: its rays are cast again, the
    // World's taken.
    lamp.animation = vec![
        LightKey { frame: 4.0, ..LightKey::default() },
        LightKey {
            frame: 6.0,
            matrix: Some(glam::DMat4::from_translation(p(-0.5, 0.3, 1.2))),
            ..LightKey::default()
        },
    ];
    let settings = Settings { basis_order: 1, tolerance: 1e-6, ..Settings::default() };
    let scene = Scene::new(settings, (1, 6), materials(0.6, 0.0), vec![vec![]; 2], vec![floor, block])
        .unwrap()
        .with_lights(vec![lamp])
        .unwrap()
        .with_world(Some(World::uniform([0.4, 0.5, 0.6], 1.0)))
        .unwrap();
    let mut sys = solved(&scene);
    sys.gather_corners(&scene, 1.0, &no_progress).unwrap();
    let mut state = AnimationState::new(sys.elements.len(), true);
    for frame in 2..=6 {
        let (kept, all, worst) = kept_and_fresh_gather(&mut sys, &mut state, &scene, frame as f64);
        eprintln!(
            "frame {frame}: corners' shadow rays {} traced, {} taken; worst relative difference {worst:.1e}",
            kept.direct_rays_traced, kept.direct_rays_taken
        );
        assert!(worst <= 1e-6, "frame {frame}: {worst}");
        assert_eq!(kept.direct_rays_traced + kept.direct_rays_taken, all.direct_rays_traced);
        if frame == 4 {
            assert!(kept.direct_rays_traced == 0 && kept.direct_rays_taken > 0, "nothing moved: {kept:?}");
        } else if frame > 4 {
            // The lamp's 64 rays a corner (Medium) cast again, the World's 289 and more taken.
            let (traced, taken) = (kept.direct_rays_traced, kept.direct_rays_taken);
            assert!(traced > 0 && taken > 2 * traced, "frame {frame}, the lamp moved: {kept:?}");
        } else {
            assert!(kept.direct_rays_taken > 0, "frame {frame}: no corner ray taken");
        }
    }
}

/// A bake cancelled while its corners are being gathered leaves the last frame readable, and the
/// next frame solves as if nothing had happened.
#[test]
fn cancel_during_the_gather_keeps_the_last_frame() {
    use galerkin_radiosity::error::Error;
    use galerkin_radiosity::session::{Method, Session};
    let scene = scenes::cornell_box_animated(
        4,
        3,
        Settings { basis_order: 1, tolerance: 1e-6, ..Settings::default() },
    );
    let corners = |s: &Session| {
        s.face_results().unwrap().into_iter().flat_map(|r| r.corner_radiosity).collect::<Vec<_>>()
    };
    let mut session = Session::new(scene.clone(), Method::Incremental).unwrap();
    session.solve_frame(1.0, &no_progress).unwrap();
    let frame1 = corners(&session);
    let stop_at_gather = |_: f64, stage: &str| stage != "corner gather";
    assert!(matches!(session.solve_frame(2.0, &stop_at_gather), Err(Error::Cancelled)));
    assert_eq!(session.frame(), Some(1.0));
    assert_eq!(corners(&session), frame1, "the cancelled frame left frame 1's corners");
    session.solve_frame(2.0, &no_progress).unwrap();
    let mut full = Session::new(scene, Method::Full).unwrap();
    full.solve_frame(2.0, &no_progress).unwrap();
    let (a, b) = (corners(&session), corners(&full));
    let peak = b.iter().flatten().fold(0.0f32, |m, x| m.max(*x));
    let worst =
        a.iter().zip(&b).flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs())).fold(0.0, f32::max);
    assert!(worst <= 1e-3 * peak, "after the cancel: {worst} vs peak {peak}");
}

/// A session previewing frames 2-6 (a host scrubbing the timeline) solves them to the preview
/// tolerance, in fewer shots, without gathers; refining frame 6 (the rest of its solve, then a
/// gather made from frame 1's) gives the corners of a session solving and gathering every frame,
/// on the demo animation (a light and a block moving).
#[test]
fn refined_preview_equals_solving_every_frame() {
    use galerkin_radiosity::session::{Method, Session, preview_tolerance};
    // Tight, so that two shooting paths to it agree far closer than the check below.
    let settings = Settings { basis_order: 1, tolerance: 1e-7, ..Settings::default() };
    assert_eq!(preview_tolerance(settings.tolerance), 1e-6);
    let scene = scenes::cornell_box_animated(4, 6, settings.clone());
    let corners = |s: &Session| -> Vec<[f32; 3]> {
        s.face_results().unwrap().into_iter().flat_map(|r| r.corner_radiosity).collect()
    };
    let mut every = Session::new(scene.clone(), Method::Incremental).unwrap();
    let mut preview = Session::new(scene, Method::Incremental).unwrap();
    every.solve_frame(1.0, &no_progress).unwrap();
    preview.solve_frame(1.0, &no_progress).unwrap();
    assert!(!preview.unrefined());
    preview.set_preview(true);
    let (mut shots_every, mut shots_preview) = (0, 0);
    for f in 2..=6 {
        shots_every += every.solve_frame(f as f64, &no_progress).unwrap().shots;
        let stats = preview.solve_frame(f as f64, &no_progress).unwrap();
        assert!(stats.preview && stats.gather_seconds == 0.0, "frame {f}: {stats:?}");
        assert!(preview.unrefined(), "frame {f}");
        shots_preview += stats.shots;
    }
    eprintln!("shots over frames 2-6: {shots_every} solving to the tolerance, {shots_preview} previewing");
    assert!(10 * shots_preview < 9 * shots_every, "{shots_preview} vs {shots_every}");
    let r = preview.refine(&no_progress).unwrap().expect("frame 6 is a preview");
    let (_, g) = r.gather.expect("corner_gather is on");
    assert!(r.shots > 0 && g.recomputed > 0 && g.recomputed < g.moments, "{r:?}");
    assert!(!preview.unrefined());
    assert!(preview.refine(&no_progress).unwrap().is_none(), "nothing left to refine");
    let (got, want) = (corners(&preview), corners(&every));
    let peak = want.iter().flatten().fold(0.0f32, |m, x| m.max(*x));
    let worst =
        got.iter().zip(&want).flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs())).fold(0.0, f32::max);
    eprintln!("refined frame 6: worst corner {:.2e} of peak", worst / peak);
    assert!(worst <= 1e-5 * peak, "{:.2e} of peak", worst / peak);
}

/// Corners of `s`'s readable frame, and their worst difference from `want`'s relative to its peak.
fn corner_error(
    s: &galerkin_radiosity::session::Session,
    want: &galerkin_radiosity::session::Session,
) -> f32 {
    let corners = |s: &galerkin_radiosity::session::Session| -> Vec<[f32; 3]> {
        s.face_results().unwrap().into_iter().flat_map(|r| r.corner_radiosity).collect()
    };
    let (got, want) = (corners(s), corners(want));
    let peak = want.iter().flatten().fold(0.0f32, |m, x| m.max(*x));
    got.iter().zip(&want).flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs())).fold(0.0, f32::max)
        / peak
}

/// Frames solved in full after unrefined previews (a bake started after scrubbing) equal those
/// of a session that never previewed. And a preview whose next frame was cancelled inside its
/// solve (its links updated, its solution put back) refines by a rebuild: the refined frame
/// equals that frame solved in full (shooting on through the cancelled frame's links, as
/// before, left it 8.2e-3 of the peak off).
#[test]
fn frames_after_previews_and_after_a_cancel_equal_solving_in_full() {
    use galerkin_radiosity::error::Error;
    use galerkin_radiosity::session::{Method, Session};
    let settings = Settings { basis_order: 1, tolerance: 1e-7, ..Settings::default() };
    let scene = scenes::cornell_box_animated(4, 6, settings);
    let mut every = Session::new(scene.clone(), Method::Incremental).unwrap();
    let mut preview = Session::new(scene.clone(), Method::Incremental).unwrap();
    for f in 1..=6 {
        every.solve_frame(f as f64, &no_progress).unwrap();
        preview.set_preview((2..=4).contains(&f));
        let stats = preview.solve_frame(f as f64, &no_progress).unwrap();
        assert_eq!(stats.preview, (2..=4).contains(&f));
        if f >= 5 {
            let worst = corner_error(&preview, &every);
            eprintln!("frame {f} after previews: worst corner {worst:.2e} of peak");
            assert!(worst <= 1e-5, "frame {f}: {worst:.2e} of peak");
        }
    }

    let mut preview = Session::new(scene.clone(), Method::Incremental).unwrap();
    let mut full = Session::new(scene, Method::Incremental).unwrap();
    preview.solve_frame(1.0, &no_progress).unwrap();
    preview.set_preview(true);
    for f in 2..=3 {
        preview.solve_frame(f as f64, &no_progress).unwrap();
    }
    let in_solve = |_: f64, stage: &str| stage != "solve";
    assert!(matches!(preview.solve_frame(4.0, &in_solve), Err(Error::Cancelled)));
    assert_eq!(preview.frame(), Some(3.0));
    assert!(preview.unrefined());
    let r = preview.refine(&no_progress).unwrap().expect("frame 3 is a preview");
    assert!(!preview.unrefined() && r.gather.is_some() && r.rebuilt.is_some(), "{r:?}");
    full.solve_frame(3.0, &no_progress).unwrap();
    let worst = corner_error(&preview, &full);
    eprintln!("frame 3 refined after a cancelled frame 4: worst corner {worst:.2e} of peak");
    assert!(worst <= 1e-5, "{worst:.2e} of peak");
}

/// A small emitter hovering just above a large floor (one face): its corners' light from the
/// floor comes from the floor's contact light right under them, which no polynomial over the
/// floor holds and the foot's ball takes (`B` gathered at the foot). The ball, four times the
/// height across, is a coaxial disk of form factor `1 - 1/16`; the floor at the foot is `rho`
/// times the emitter's form factor from there (four rectangles superposed); the rest of the
/// floor is dark. Both methods' gathers. Until the ball's edge was split below the twelfth
/// level, a ball smaller than a twelfth-level part of the floor was lost and the corners took
/// the floor's polynomial instead: `B` = 1.000 against 1.174.
#[test]
fn a_small_emitter_over_a_large_floor_takes_the_contact_light_at_its_foot() {
    let (size, height, half_floor) = (0.01, 1e-5, 100.0);
    let floor = scenes::subdivided_quad(
        "floor",
        [
            DVec3::new(-half_floor, -half_floor, 0.0),
            DVec3::new(half_floor, -half_floor, 0.0),
            DVec3::new(half_floor, half_floor, 0.0),
            DVec3::new(-half_floor, half_floor, 0.0),
        ],
        1,
        0,
    );
    // Facing down over [0, size]^2.
    let e = [
        DVec3::new(0.0, 0.0, height),
        DVec3::new(0.0, size, height),
        DVec3::new(size, size, height),
        DVec3::new(size, 0.0, height),
    ];
    let emitter = scenes::subdivided_quad("emitter", e, 1, 1);
    let (rho, be) = (0.5, 1.0);
    let materials = vec![
        Material { name: "grey".into(), reflectance: [rho; 3], emission: [0.0; 3] },
        Material { name: "emitter".into(), reflectance: [rho; 3], emission: [be; 3] },
    ];
    let settings = Settings { basis_order: 2, tolerance: 1e-9, ..Settings::default() };
    let scene = Scene::new(settings, (1, 1), materials, vec![vec![], vec![]], vec![floor, emitter]).unwrap();
    let d = gather::INSET * size;
    // The foot lies `d` in from two edges of the emitter, `height` below it.
    let f = corner_rectangle(d, d, height)
        + 2.0 * corner_rectangle(size - d, d, height)
        + corner_rectangle(size - d, size - d, height);
    let ball = 1.0 - 1.0 / 16.0;
    let want = be + rho * ball * rho * be * f;
    for method in [Method::Full, Method::Hierarchical] {
        let mut session = Session::new(scene.clone(), method).unwrap();
        session.solve_frame(0.0, &no_progress).unwrap();
        let results = session.face_results().unwrap();
        for (k, got) in results[1].corner_radiosity.iter().enumerate() {
            let got = got[0] as f64;
            let rel = (got - want).abs() / (want - be);
            eprintln!(
                "{method:?}: emitter corner {k}: gathered {got:.5}, closed form {want:.5} ({rel:.1e} of the floor's part)"
            );
            assert!(rel < 2e-3, "{method:?}: corner {k}: gathered {got} vs {want}");
        }
    }
}
