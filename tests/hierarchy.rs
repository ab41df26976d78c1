//! The hierarchical solve (issue 20): energy balance with clusters, the hierarchy on a fixed
//! element set equal to the flat system, and a real mesh against Cycles.

use galerkin_radiosity::hierarchy::coupling::NearRule;
use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
use galerkin_radiosity::scene::Settings;
use galerkin_radiosity::scene::json::read_scene;
use galerkin_radiosity::scenes::{closed_box, cornell_box};
use galerkin_radiosity::session::{Method, Session};
use galerkin_radiosity::system::{System, no_progress};

#[path = "common/hierarchy_checks.rs"]
mod hierarchy_checks;

#[path = "hierarchy/update.rs"]
mod update;

#[path = "hierarchy/gather_modes.rs"]
mod gather_modes;

/// A 4 x 3 x 4 m room of grey 0.7 (walls split `per_metre` a metre, y up) lit by a 1 x 1 m
/// panel 1 cm under its ceiling, with `more` objects of the grey (material 0), at `basis_order`,
/// the corner gather off.
fn room_under_a_fixture(
    per_metre: f64,
    basis_order: usize,
    more: Vec<galerkin_radiosity::scene::Object>,
) -> galerkin_radiosity::scene::Scene {
    use galerkin_radiosity::scene::{Material, Scene};
    use galerkin_radiosity::scenes::{panel, room};
    use glam::DVec3;
    let mut objects = room(4.0, 3.0, 4.0, per_metre, [0; 6]);
    objects.push(panel(
        "Fixture",
        DVec3::new(0.0, 2.99, 0.0),
        DVec3::X * 0.5,
        DVec3::Z * 0.5,
        -DVec3::Y,
        1,
        1,
    ));
    objects.extend(more);
    let materials = vec![
        Material { name: "grey".into(), reflectance: [0.7; 3], emission: [0.0; 3] },
        Material { name: "lamp".into(), reflectance: [0.0; 3], emission: [10.0; 3] },
    ];
    let settings = Settings { basis_order, corner_gather: false, ..Default::default() };
    Scene::new(settings, (0, 0), materials, vec![Vec::new(); 2], objects).unwrap()
}

/// A closed box that emits `E = 1` everywhere with `rho = 0.5` has `B = E / (1 - rho) = 2`
/// on every face, whatever the links: clusters must neither lose nor make light.
#[test]
fn closed_box_balances_with_clusters() {
    for (n, mean_tol, face_tol) in [(4, 0.005, 0.01), (8, 0.025, 0.06)] {
        let scene = closed_box(n, 0.5, 1.0, Settings { basis_order: 1, ..Default::default() });
        let h = solve_frame(&scene, 0.0, &HierarchySettings::default(), &no_progress).unwrap();
        assert!(h.stats.cluster_links > 0, "n = {n}: no cluster links, nothing tested");
        let b: Vec<f64> = h
            .face_results(&scene, 0.0)
            .iter()
            .flat_map(|o| o.face_radiosity.iter().map(|v| v[0] as f64))
            .collect();
        let mean = b.iter().sum::<f64>() / b.len() as f64;
        assert!((mean / 2.0 - 1.0).abs() < mean_tol, "n = {n}: mean B {mean}, want 2");
        for (f, v) in b.iter().enumerate() {
            assert!((v / 2.0 - 1.0).abs() < face_tol, "n = {n}: face {f} B {v}, want 2");
        }
    }
}

/// A room lit by a panel 1 cm under its ceiling, through cluster links, against the flat solve:
/// each object's mean within 2.5%, and its faces' ratios, over the object's, within 3.8% RMS. A
/// cluster link's light is spread over a planar receiving cluster with the slope of `1 / r^2`
/// and the cosines at its centroid (`solve::sweep::slope_over_plane`), not evenly. Measured:
/// means 0.978-0.985 (the rest is the hemisphere bound's, docs/benchmarks.md "The hierarchy's
/// rooms"), faces 3.43% RMS; evenly, means 0.968-0.980 and 4.22%.
#[test]
fn a_room_lit_through_cluster_links_follows_the_flat_solve_face_by_face() {
    let scene = room_under_a_fixture(2.0, 2, Vec::new());
    let h = solve_frame(&scene, 0.0, &HierarchySettings::of(&scene.settings), &no_progress).unwrap();
    assert!(h.stats.cluster_links > 0, "no cluster links: nothing tested");
    let mut flat = System::build(&scene, 0.0, &no_progress).unwrap();
    flat.solve(scene.settings.tolerance, &|| false).unwrap();
    // Each face against the flat solve's, over its object's ratio of means: the spread within
    // an object, which the slope is for (the means are the hemisphere bound's, docs/benchmarks.md).
    let (mut lo, mut hi, mut sq, mut count) = (f64::INFINITY, 0.0f64, 0.0, 0);
    for (got, want) in h.face_results(&scene, 0.0).iter().zip(flat.face_results(&scene, 0.0).iter()) {
        if got.name == "Fixture" {
            continue;
        }
        let lum = |v: &[f32; 3]| v[0] as f64;
        let n = want.face_radiosity.len() as f64;
        let want_mean = want.face_radiosity.iter().map(lum).sum::<f64>() / n;
        let mean = got.face_radiosity.iter().map(lum).sum::<f64>() / n / want_mean;
        println!("{}: mean {mean:.4} of the flat solve's", got.name);
        assert!((mean - 1.0).abs() < 0.025, "{}: mean {mean} of the flat solve's", got.name);
        // (Not the ceiling's faces over the panel, which see almost nothing.)
        let (mut olo, mut ohi) = (f64::INFINITY, 0.0f64);
        for (a, b) in
            got.face_radiosity.iter().zip(&want.face_radiosity).filter(|(_, b)| lum(b) > 0.2 * want_mean)
        {
            let r = lum(a) / lum(b) / mean;
            (olo, ohi) = (olo.min(r), ohi.max(r));
            sq += (r - 1.0).powi(2);
            count += 1;
        }
        (lo, hi) = (lo.min(olo), hi.max(ohi));
    }
    let rms = (sq / count as f64).sqrt();
    println!(
        "faces {lo:.3} to {hi:.3} of the flat solve's over their object's mean ratio, {:.2}% RMS",
        100.0 * rms
    );
    assert!(rms < 0.038, "faces {:.2}% RMS from the flat solve's", 100.0 * rms);
}

/// With no element below a face, no cluster link and the flat system's near-pair integrator,
/// the hierarchy holds exactly the flat system's pairs, and its Jacobi sweeps with push-pull
/// (Anderson-mixed) converge to the flat solution (issue 20, item 4).
#[test]
fn on_the_faces_alone_the_hierarchy_is_the_flat_system() {
    let settings = Settings { basis_order: 2, tolerance: 1e-6, ..Default::default() };
    let scene = cornell_box(2, settings);
    let hs = HierarchySettings {
        max_depth: 0,
        clusters: false,
        near: NearRule::Adaptive,
        light_links: false,
        ..Default::default()
    };
    let h = solve_frame(&scene, 0.0, &hs, &no_progress).unwrap();
    let mut flat = System::build(&scene, 0.0, &no_progress).unwrap();
    flat.solve(1e-6, &|| false).unwrap();
    assert_eq!(h.stats.links, flat.stats.pairs, "the same pairs");
    assert_faces_agree(&h.face_results(&scene, 0.0), &flat.face_results(&scene, 0.0), "flat");
}

/// The Anderson-mixed sweeps (issue 21) reach the plain Jacobi sweeps' solution on the same
/// links in under two thirds of their sweeps: the Cornell box with clusters and quadtrees, one
/// link round (so that both solve one system), solved to 1e-6 of the source power.
#[test]
fn mixed_sweeps_reach_the_plain_sweeps_solution_in_fewer_sweeps() {
    let settings = Settings { basis_order: 2, tolerance: 1e-6, ..Default::default() };
    let scene = cornell_box(2, settings);
    let mixed = HierarchySettings { rounds: 1, ..Default::default() };
    let plain = HierarchySettings { anderson_depth: 0, ..mixed };
    let a = solve_frame(&scene, 0.0, &mixed, &no_progress).unwrap();
    let b = solve_frame(&scene, 0.0, &plain, &no_progress).unwrap();
    assert_eq!(a.stats.links, b.stats.links, "the same links");
    assert!(
        3 * a.stats.sweeps < 2 * b.stats.sweeps,
        "mixed {} sweeps, plain {}",
        a.stats.sweeps,
        b.stats.sweeps
    );
    assert_faces_agree(&a.face_results(&scene, 0.0), &b.face_results(&scene, 0.0), "plain");
}

/// Refining below faces and clustering above them moves the Cornell box's walls towards the
/// finely subdivided flat solution, not away: the unsubdivided box (16 faces) solved on the
/// hierarchy is closer per wall to the flat 8x8 solution than the flat 16-face solve is.
#[test]
fn the_hierarchy_refines_the_cornell_box_towards_the_fine_solution() {
    let settings = Settings { basis_order: 1, ..Default::default() };
    let coarse = cornell_box(1, settings.clone());
    let h = solve_frame(&coarse, 0.0, &HierarchySettings::default(), &no_progress).unwrap();
    let mut flat = System::build(&coarse, 0.0, &no_progress).unwrap();
    flat.solve(1e-4, &|| false).unwrap();
    let fine = cornell_box(8, settings);
    let mut reference = System::build(&fine, 0.0, &no_progress).unwrap();
    reference.solve(1e-4, &|| false).unwrap();
    // Per object, the area-weighted mean (objects are the same in both boxes).
    let power = |scene: &galerkin_radiosity::scene::Scene,
                 r: &[galerkin_radiosity::scene::json::ObjectResult]| {
        let sys = System::build(scene, 0.0, &no_progress).unwrap();
        let mut out = vec![(0.0, 0.0); r.len()];
        for e in &sys.elements {
            let v = r[e.object as usize].face_radiosity[e.face as usize][0] as f64;
            out[e.object as usize].0 += v * e.area;
            out[e.object as usize].1 += e.area;
        }
        out.into_iter().map(|(p, a)| p / a).collect::<Vec<f64>>()
    };
    let want = power(&fine, &reference.face_results(&fine, 0.0));
    let got = power(&coarse, &h.face_results(&coarse, 0.0));
    let before = power(&coarse, &flat.face_results(&coarse, 0.0));
    let rms = |x: &[f64]| {
        let s: f64 = x.iter().zip(&want).map(|(a, b)| ((a - b) / b).powi(2)).sum();
        (s / x.len() as f64).sqrt()
    };
    let (e_h, e_flat) = (rms(&got), rms(&before));
    assert!(e_h < e_flat, "hierarchy {e_h} vs flat on the same faces {e_flat}");
    assert!(e_h < 0.03, "hierarchy off the fine solution by {e_h} (rms over objects)");
}

/// Pairs none of whose sampled rays pass are split while they may carry a quarter of the
/// oracle's bar, as partly visible links are, not dropped whole: a few rays (a light link's
/// segments, a mask's cells) cannot show that a pair is hidden, and a dropped pair's light is
/// lost one way only. Before, 13 of the Cornell box's 15 lit faces came out too dark against the
/// flat 8 x 8 solve at order 2 (per-face RMS 1.58%, the faces' summed difference -1.85% of their
/// summed means); now 0.94% and -0.73%. The reference sees through 4 x 4 cells per element
/// (2 x 2 leak light under the blocks).
#[test]
fn hidden_pairs_are_refined_not_dropped() {
    let settings = Settings { basis_order: 1, ..Default::default() };
    let coarse = cornell_box(1, settings.clone());
    let h = solve_frame(&coarse, 0.0, &HierarchySettings::default(), &no_progress).unwrap();
    let fine = cornell_box(8, Settings { basis_order: 2, visibility_samples: 4, ..settings });
    let mut reference = System::build(&fine, 0.0, &no_progress).unwrap();
    reference.solve(1e-5, &|| false).unwrap();
    // Each fine element's mean into the coarse face it lies in: objects keep their faces'
    // order, each coarse face split into as many fine ones in a row (8 x 8 walls, 2 x 2 blocks).
    let faces = h.hierarchy.tree.faces.len();
    let mut want = vec![(0.0, 0.0); faces];
    for (i, e) in reference.elements.iter().enumerate() {
        let o = e.object as usize;
        let split = fine.objects[o].faces.len() / coarse.objects[o].faces.len();
        let k = coarse_face(&coarse, o, e.face as usize / split);
        let m = reference.mean(i).iter().copied().fold(0.0, f64::max);
        want[k].0 += m * e.area;
        want[k].1 += e.area;
    }
    let (mut num, mut den, mut signed, mut total) = (0.0, 0.0, 0.0, 0.0);
    for (f, face) in h.hierarchy.tree.faces.iter().enumerate() {
        if coarse.materials[face.material as usize].emission.iter().any(|&x| x > 0.0) {
            continue;
        }
        let (w, g) = (want[f].0 / want[f].1, h.face_mean(f).iter().copied().fold(0.0, f64::max));
        num += (g - w).powi(2);
        den += w * w;
        signed += g - w;
        total += w;
    }
    let (rms, bias) = ((num / den).sqrt(), signed / total);
    println!("per-face RMS {:.2}%, summed difference {:+.2}% of the summed means", rms * 100.0, bias * 100.0);
    assert!(rms < 0.012, "per-face RMS {rms}");
    assert!(bias.abs() < 0.01, "the faces are off one way: {bias}");
}

/// The index in the hierarchy's face list of face `face` of object `object`.
fn coarse_face(scene: &galerkin_radiosity::scene::Scene, object: usize, face: usize) -> usize {
    scene.objects[..object].iter().map(|o| o.faces.len()).sum::<usize>() + face
}

/// Light links (issue 20): a surface link that can carry only a small share of the accuracy's
/// power keeps `G^00` alone, from a 2 x 2 rule and the share of four segments that arrive
/// (`coupling::Coupling::Constants`). On the decimated monastery, where nearly every surface
/// link is light, the per-face means against a fine reference (every link in full, accuracy
/// 2e-5) are hardly further off than with every link in full at the same accuracy (measured:
/// 10.46% against 9.22% since the solve keeps the hemisphere bound, which takes both closer to
/// the reference and the full links more, `hierarchy::solve::bound::bound_of`; 11.27% against 10.41%
/// before it; 12.23% against 11.47% before hidden pairs were split,
/// `hidden_pairs_are_refined_not_dropped`; 12.27% against 12.06% before full near links kept
/// their sources' first moments, `kernel::pair::integrate_near_coarse`, which a light link's
/// `G^00` has no use for).
#[test]
fn light_links_are_as_accurate_as_full_links() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    let mut scene = read_scene(&dir.join("monastery_scene.json")).unwrap();
    scene.settings.basis_order = 1;
    scene.settings.corner_gather = false;
    let solve = |hs: HierarchySettings| solve_frame(&scene, 0.0, &hs, &no_progress).unwrap();
    let full = HierarchySettings { light_links: false, ..HierarchySettings::of(&scene.settings) };
    let light = solve(HierarchySettings { light_links: true, ..full });
    assert!(
        light.stats.constant_links > light.stats.surface_links,
        "{} light links, {} in full: nothing tested",
        light.stats.constant_links,
        light.stats.surface_links
    );
    let reference = face_means(&solve(HierarchySettings { accuracy: 2e-5, ..full }));
    // Over the lit faces: the light's own exitance would dominate the norm.
    let lit: Vec<bool> = light
        .hierarchy
        .tree
        .faces
        .iter()
        .map(|e| scene.materials[e.material as usize].emission.iter().all(|&x| x == 0.0))
        .collect();
    let off = |h: &galerkin_radiosity::hierarchy::HierarchicalFrame| {
        let (num, den) = face_means(h)
            .iter()
            .zip(&reference)
            .zip(&lit)
            .filter(|(_, l)| **l)
            .fold((0.0, 0.0), |(n, d), ((g, w), _)| (n + (g - w).powi(2), d + w * w));
        (num / den).sqrt()
    };
    let (e_light, e_full) = (off(&light), off(&solve(full)));
    println!("per-face error against the reference: light links {e_light:.4}, full {e_full:.4}");
    assert!(e_light < 1.15 * e_full, "light links {e_light} vs full {e_full}");
}

/// Each face's mean radiosity (red channel; the scenes here are grey) of a hierarchical frame.
fn face_means(h: &galerkin_radiosity::hierarchy::HierarchicalFrame) -> Vec<f64> {
    (0..h.hierarchy.tree.faces.len()).map(|f| h.face_mean(f)[0]).collect()
}

/// The link phase decides the work stack in parallel (descents, filed in order by one thread)
/// and computes links in parallel: the decimated monastery's links, hidden pairs and face means
/// are bit for bit the same on one, two and three threads.
#[test]
fn the_links_are_the_same_for_every_thread_count() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    let mut scene = read_scene(&dir.join("monastery_scene.json")).unwrap();
    scene.settings.corner_gather = false;
    let settings = HierarchySettings::of(&scene.settings);
    let solve = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let h = pool.install(|| solve_frame(&scene, 0.0, &settings, &no_progress).unwrap());
        let links: Vec<String> =
            h.hierarchy.links.iter().map(|l| format!("{} {} {:?}", l.a, l.b, l.coupling)).collect();
        (links, h.hierarchy.blocked.clone(), face_means(&h))
    };
    let one = solve(1);
    assert!(one.0.len() > 10_000 && !one.1.is_empty(), "{} links, {} hidden pairs", one.0.len(), one.1.len());
    for threads in [2, 3] {
        let other = solve(threads);
        assert!(one.0 == other.0, "{threads} threads: other links");
        assert_eq!(one.1, other.1, "{threads} threads: other hidden pairs");
        assert_eq!(one.2, other.2, "{threads} threads: other face means");
    }
}

/// A real mesh in CI: the pybullet monastery decimated to 1,000 triangles on a ground, lit by
/// an emissive quad, baked through a session with the hierarchical method; its mean corner
/// radiosity per object within 8% of a converged Cycles bake of the same scene. (Corners from
/// the leaves: the gather, Ground 0.96 and Monastery 0.99 of Cycles' means, takes a minute on
/// two cores; the bunny test checks it per corner.)
#[test]
fn the_decimated_monastery_agrees_with_cycles_on_average() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    let mut scene = read_scene(&dir.join("monastery_scene.json")).unwrap();
    scene.settings.corner_gather = false;
    let cycles: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("monastery_cycles_means.json")).unwrap())
            .unwrap();
    let mut session = Session::new(scene, Method::Hierarchical).unwrap();
    session.solve_frame(0.0, &no_progress).unwrap();
    for o in session.face_results().unwrap() {
        let Some(want) = cycles["objects"][&o.name].as_f64() else { continue };
        let got =
            o.corner_radiosity.iter().map(|v| v[0] as f64).sum::<f64>() / o.corner_radiosity.len() as f64;
        assert!((got / want - 1.0).abs() < 0.08, "{}: mean corner B {got} vs Cycles {want}", o.name);
    }
}

/// The corner gather through the hierarchy (issue 20) keeps the closed box's balance: every
/// corner of a box that emits `E = 1` everywhere with `rho = 0.5` has `B = 2`, whether its light
/// comes through surface links, cluster links or both.
#[test]
fn gathered_corners_of_a_closed_box_balance() {
    let scene = closed_box(4, 0.5, 1.0, Settings { basis_order: 1, ..Default::default() });
    let hs = HierarchySettings { corner_gather: true, ..Default::default() };
    let h = solve_frame(&scene, 0.0, &hs, &no_progress).unwrap();
    assert!(h.stats.cluster_links > 0 && h.stats.gather_points > 0, "nothing tested");
    for o in h.face_results(&scene, 0.0) {
        for (k, v) in o.corner_radiosity.iter().enumerate() {
            assert!((v[0] / 2.0 - 1.0).abs() < 0.02, "{} corner {k}: B {}, want 2", o.name, v[0]);
        }
    }
}

/// Corners gathered through the hierarchy against Cycles, per corner: the 300-triangle bunny
/// standing on a ground under a light quad (tests/data/real/bunny_scene.json, Cycles' DIFFUSE
/// bake at 16384 spp in bunny_cycles.json). Measured: at accuracy 1e-4, Bunny 6.40% relative
/// RMSE, Ground 0.29% (6.49% before the gather took coarse clusters with the corner's own rays;
/// since cluster links pair 8 points an end, 5.36%, 0.28% before that: see
/// docs/benchmarks.md, "Cluster links' points"; 5.71%, 0.69% when written; the flat path's
/// corner gather now 3.27%, 0.15%; the hierarchy's leaf polynomials alone: 29%, 11%).
#[test]
fn the_bunny_gathered_through_the_hierarchy_agrees_with_cycles_per_corner() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    let mut scene = read_scene(&dir.join("bunny_scene.json")).unwrap();
    scene.settings.accuracy = 1e-4;
    let cycles: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("bunny_cycles.json")).unwrap()).unwrap();
    let mut session = Session::new(scene, Method::Hierarchical).unwrap();
    session.solve_frame(0.0, &no_progress).unwrap();
    let bounds = [("Bunny", 0.065), ("Ground", 0.015)];
    for o in session.face_results().unwrap() {
        let Some(&(_, bound)) = bounds.iter().find(|(n, _)| *n == o.name) else { continue };
        let want: Vec<f64> =
            cycles["objects"][&o.name].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!(want.len(), o.corner_radiosity.len(), "{}", o.name);
        let got: Vec<f64> = o.corner_radiosity.iter().map(|v| (v[0] + v[1] + v[2]) as f64 / 3.0).collect();
        let mean = want.iter().sum::<f64>() / want.len() as f64;
        let rmse = (got.iter().zip(&want).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / want.len() as f64)
            .sqrt()
            / mean;
        let ratio = got.iter().sum::<f64>() / got.len() as f64 / mean;
        println!("{}: relative RMSE {:.2}%, mean ratio {ratio:.4}", o.name, 100.0 * rmse);
        assert!(rmse < bound, "{}: relative RMSE {rmse} per corner against Cycles (bound {bound})", o.name);
        assert!((ratio - 1.0).abs() < 0.02, "{}: mean ratio {ratio}", o.name);
    }
}

/// A scene with nothing of area (no objects) bakes on the hierarchy as on the flat path: a frame
/// with no values, not an error (found by the C ABI fuzz, tests/ffi_props.rs).
#[test]
fn an_empty_scene_bakes_on_the_hierarchy_as_on_the_flat_path() {
    let mut scene = closed_box(1, 0.5, 1.0, Settings::default());
    scene.objects.clear();
    scene.surfaces.clear();
    for method in [Method::Full, Method::Hierarchical] {
        let mut session = Session::new(scene.clone(), method).unwrap();
        session.solve_frame(0.0, &no_progress).unwrap_or_else(|e| panic!("{method:?}: {e}"));
        assert!(session.face_results().unwrap().is_empty(), "{method:?}");
    }
}

/// A first frame's links are computed in chunks that report their progress and may cancel it
/// (issue 24 item 4, issue 23): on a large scene the link phase ran for minutes with no line and
/// no way to stop it.
#[test]
fn the_link_phase_reports_progress_and_cancels_between_chunks() {
    use std::sync::Mutex;
    let scene = cornell_box(10, Settings { basis_order: 1, ..Default::default() });
    let hs = HierarchySettings::default();
    let seen = Mutex::new(Vec::new());
    let record = |f: f64, stage: &str| {
        seen.lock().unwrap().push((f, stage.to_owned()));
        true
    };
    let h = solve_frame(&scene, 0.0, &hs, &record).unwrap();
    assert!(h.stats.links > 3 * 4096, "{} links: too few chunks to test", h.stats.links);
    let seen = seen.into_inner().unwrap();
    let first_round: Vec<f64> = seen
        .iter()
        .filter(|(f, s)| s == "links" && *f > 0.0 && *f < 1.0 / hs.rounds as f64)
        .map(|r| r.0)
        .collect();
    assert!(first_round.len() >= 2, "the first round's linking reported {first_round:?}");
    assert!(first_round.windows(2).all(|w| w[0] <= w[1]), "{first_round:?}");

    // Cancelled at the first chunk after the start: no sweep ran.
    let swept = Mutex::new(false);
    let cancel = |f: f64, stage: &str| {
        if stage == "hierarchy" {
            *swept.lock().unwrap() = true;
        }
        !(stage == "links" && f > 0.0)
    };
    let r = solve_frame(&scene, 0.0, &hs, &cancel);
    assert!(matches!(r, Err(galerkin_radiosity::Error::Cancelled)), "{:?}", r.err());
    assert!(!*swept.lock().unwrap(), "the solve began before the cancel was heard");
}

/// Every face's radiosity (RGB) of `got` within 1e-4 of the peak of `want` (`what` names `want`).
fn assert_faces_agree(
    got: &[galerkin_radiosity::scene::json::ObjectResult],
    want: &[galerkin_radiosity::scene::json::ObjectResult],
    what: &str,
) {
    let peak = want.iter().flat_map(|o| &o.face_radiosity).map(|v| v[0]).fold(0.0f32, f32::max);
    for (x, y) in got.iter().zip(want) {
        for (f, (u, v)) in x.face_radiosity.iter().zip(&y.face_radiosity).enumerate() {
            for c in 0..3 {
                assert!(
                    (u[c] - v[c]).abs() < 1e-4 * peak,
                    "{} face {f}: {} vs {what} {}",
                    x.name,
                    u[c],
                    v[c]
                );
            }
        }
    }
}

/// A hierarchical session previewing frames 2-4 (a host scrubbing the timeline: looser solves,
/// corners from the leaves) leaves each frame unrefined; refining frame 4 (an update in which
/// nothing moved, solved to the tolerance, then its corners gathered) gives the corners of a
/// session solving every frame in full (measured 7.9e-8 of the peak apart; the preview's own
/// corners, from the leaves, 2.0e-3).
#[test]
fn a_refined_hierarchical_preview_equals_solving_every_frame() {
    let settings = Settings { basis_order: 1, tolerance: 1e-5, ..Settings::default() };
    let scene = galerkin_radiosity::scenes::cornell_box_animated(2, 4, settings);
    let corners = |s: &Session| -> Vec<[f32; 3]> {
        s.face_results().unwrap().into_iter().flat_map(|r| r.corner_radiosity).collect()
    };
    let mut every = Session::new(scene.clone(), Method::Hierarchical).unwrap();
    let mut preview = Session::new(scene, Method::Hierarchical).unwrap();
    every.solve_frame(1.0, &no_progress).unwrap();
    preview.solve_frame(1.0, &no_progress).unwrap();
    assert!(!preview.unrefined());
    preview.set_preview(true);
    for f in 2..=4 {
        every.solve_frame(f as f64, &no_progress).unwrap();
        let stats = preview.solve_frame(f as f64, &no_progress).unwrap();
        assert!(stats.preview && stats.gather_seconds == 0.0, "frame {f}: {stats:?}");
        assert!(preview.unrefined(), "frame {f}");
    }
    let before = corners(&preview);
    let r = preview.refine(&no_progress).unwrap().expect("frame 4 is a preview");
    assert!(r.gather.is_some(), "corner_gather is on: {r:?}");
    assert!(!preview.unrefined());
    assert!(preview.refine(&no_progress).unwrap().is_none(), "nothing left to refine");
    let want = corners(&every);
    let peak = want.iter().flatten().fold(0.0f32, |m, x| m.max(*x));
    let off = |got: &[[f32; 3]]| {
        got.iter().zip(&want).flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs())).fold(0.0, f32::max)
            / peak
    };
    let (preview_off, refined_off) = (off(&before), off(&corners(&preview)));
    println!(
        "frame 4's corners off the full chain's, of the peak: preview {preview_off:.2e}, refined {refined_off:.2e}"
    );
    assert!(refined_off < 1e-5 && preview_off > 1e-4, "refined {refined_off}, preview {preview_off}");
}
