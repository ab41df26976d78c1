//! Frames after the first on the hierarchy (issue 21): a frame updated from the one before keeps
//! only links that a fresh computation on its own geometry gives, its pairs still partition
//! every pair of leaves, its warm-started solve equals a cold one on the same links, and it
//! agrees with a frame solved from scratch.

use galerkin_radiosity::hierarchy::solve::State;
use galerkin_radiosity::hierarchy::update::update_frame;
use galerkin_radiosity::hierarchy::{HierarchicalFrame, HierarchySettings, Lighting, solve_frame};
use galerkin_radiosity::scene::{Scene, Settings};

use super::hierarchy_checks::{check_pair_tree, check_pairs, check_partition};
use galerkin_radiosity::scenes::{cornell_box_animated, cornell_box_moving_light, emission_ramp, seed_room};
use galerkin_radiosity::session::{Method, Session};
use galerkin_radiosity::system::no_progress;

fn settings() -> Settings {
    Settings { basis_order: 1, tolerance: 1e-6, ..Default::default() }
}

/// The demo animation (light and short block sliding) over 8 frames, 2x2 per wall.
fn animated() -> Scene {
    cornell_box_animated(2, 8, settings())
}

/// Settings that gather the corners and keep their values (and the pair tree) between frames,
/// as a session's animation does.
fn keeping_gather() -> HierarchySettings {
    HierarchySettings { keep_pair_tree: true, keep_gather: true, corner_gather: true, ..Default::default() }
}

/// The fast corner gather of `h`'s solution at `frame`, afresh (nothing kept).
fn fresh_gather(
    h: &HierarchicalFrame,
    scene: &Scene,
    frame: f64,
) -> galerkin_radiosity::hierarchy::gather::Gathered {
    use galerkin_radiosity::hierarchy::gather::{self, Mode};
    let lit = Lighting::new(scene, frame, &h.hierarchy.tree.faces);
    let inputs = gather::Inputs::new(&h.hierarchy, &h.state, &lit);
    gather::corners_with(&inputs, scene, frame, &no_progress, Mode::Fast).unwrap()
}

fn face_means(h: &HierarchicalFrame) -> Vec<f64> {
    (0..h.hierarchy.tree.faces.len()).map(|f| h.face_mean(f)[0]).collect()
}

/// Relative RMS of `a - b` over the faces, against `b`'s mean.
fn relative_rms(a: &[f64], b: &[f64]) -> f64 {
    let mean = b.iter().sum::<f64>() / b.len() as f64;
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt() / mean
}

/// Over the demo animation, each frame updated from the one before holds only links a fresh
/// computation gives (bit for bit), its pairs still partition every pair of leaves, and only a
/// part of the links was computed again: with the pair tree kept (the update coarsens) and
/// without.
#[test]
fn an_updated_frame_holds_the_links_of_its_own_geometry() {
    let scene = animated();
    for keep_pair_tree in [false, true] {
        let hs = HierarchySettings { keep_pair_tree, ..Default::default() };
        let mut h = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
        check_partition(&h);
        check_pair_tree(&h);
        for frame in 2..=4 {
            let f = frame as f64;
            let next = update_frame(&mut h, &scene, f, &hs, &no_progress).unwrap();
            assert!(next.stats.updated && next.stats.moved_faces > 0, "frame {frame}: nothing moved");
            let (links, blocked, idle) = check_pairs(&next, &scene, f, &hs);
            assert!(links > 0 && idle > 0, "frame {frame}: {links} links, {blocked} blocked, {idle} idle");
            check_partition(&next);
            check_pair_tree(&next);
            h = next;
        }
    }
}

/// A still scene's hierarchy (`HierarchySettings::moves` off, as `Session` solves a scene of one
/// frame) stores no idle pairs and is otherwise the same; an update that finds something moved
/// all the same cannot find the idle pairs the move touched, so it solves the frame afresh.
#[test]
fn a_still_scenes_hierarchy_solves_a_move_afresh() {
    let scene = animated();
    let still = HierarchySettings { moves: false, ..Default::default() };
    let mut h = solve_frame(&scene, 1.0, &still, &no_progress).unwrap();
    let moving = solve_frame(&scene, 1.0, &HierarchySettings::default(), &no_progress).unwrap();
    assert!(h.hierarchy.idle.is_empty() && !h.hierarchy.stores_idle);
    assert!(!moving.hierarchy.idle.is_empty() && moving.hierarchy.stores_idle);
    assert_eq!(face_means(&h), face_means(&moving), "the idle pairs changed the solution");
    let next = update_frame(&mut h, &scene, 2.0, &still, &no_progress).unwrap();
    assert!(!next.stats.updated, "a move on a hierarchy without its idle pairs was updated");
    let fresh = solve_frame(&scene, 2.0, &still, &no_progress).unwrap();
    assert_eq!(face_means(&next), face_means(&fresh));
}

/// A session on a scene of one frame whose object the caller moves (`set_object_matrix`, as the
/// add-on moves objects frame by frame) keeps what an update needs, so the frame after the move
/// is updated; promised still (`set_still`, as the CLI bakes one frame), its hierarchy keeps no
/// idle pairs, and the frame after a move is solved afresh.
#[test]
fn a_session_updates_a_moved_object_unless_promised_still() {
    let mut scene = animated();
    scene.frames = (1, 1);
    let o = scene.objects.iter().position(|o| o.is_animated()).expect("a moving object");
    let moved = scene.objects[o].world_from_object(3.0);
    for still in [false, true] {
        let mut session = Session::new(scene.clone(), Method::Hierarchical).unwrap();
        if still {
            session.set_still();
        }
        assert!(session.solve_frame(1.0, &no_progress).unwrap().full_rebuild);
        session.set_object_matrix(o, moved).unwrap();
        let stats = session.solve_frame(1.0, &no_progress).unwrap();
        assert_eq!(stats.full_rebuild, still, "promised still: {still}");
        let again = session.solve_frame(1.0, &no_progress).unwrap();
        assert!(!again.full_rebuild, "promised still: {still}: a moved session is updated after");
    }
}

/// A session told that frames follow (`set_animated`, as the add-on says for an animation's bake
/// and its live preview, whose scenes are of one frame) keeps the pair tree, as for a scene whose
/// own frames span more: over the demo animation its updates link coarser again where the block
/// and light have passed, so its last frame holds fewer links than a session not told.
#[test]
fn a_session_told_frames_follow_coarsens_its_updates() {
    let mut scene = cornell_box_animated(2, 16, settings());
    scene.frames = (0, 0);
    let last_links = |animated: bool| {
        let mut session = Session::new(scene.clone(), Method::Hierarchical).unwrap();
        session.set_animated(animated);
        let mut links = 0;
        for f in 0..=16 {
            let stats = session.solve_frame(f as f64, &no_progress).unwrap();
            assert_eq!(stats.full_rebuild, f == 0, "frame {f}, told frames follow: {animated}");
            links = stats.pairs;
        }
        links
    };
    let (told, not_told) = (last_links(true), last_links(false));
    println!("last frame's links: {told} told frames follow, {not_told} not");
    assert!(told < not_told, "{told} links told frames follow, {not_told} not");
}

/// Refined again from where they stood, touched pairs only get finer, and the links of wherever
/// the moving block and light passed pile up. With the pair tree kept, an update refines a
/// subtree touched everywhere, or touched and now linked whole by the oracle, from its top and
/// may link it coarser. Measured on the demo animation over 32 frames (order 1): 3,382 links at
/// the first frame; at the last, 5,562 without the pair tree, 3,999 with it (4,285 redoing only
/// subtrees touched everywhere), 3,583 in a fresh build of that frame.
#[test]
fn updates_coarsen_where_a_move_has_passed() {
    let scene = cornell_box_animated(2, 32, settings());
    let run = |keep_pair_tree: bool| {
        let hs = HierarchySettings { keep_pair_tree, ..Default::default() };
        let mut h = solve_frame(&scene, 0.0, &hs, &no_progress).unwrap();
        let mut refined_from = 0;
        for frame in 1..=32 {
            let next = update_frame(&mut h, &scene, frame as f64, &hs, &no_progress).unwrap();
            assert!(next.stats.updated, "frame {frame} was not updated");
            refined_from += next.stats.refined_from;
            h = next;
        }
        (h, refined_from)
    };
    let (only_finer, _) = run(false);
    let (coarsened, refined_from) = run(true);
    let fresh = solve_frame(&scene, 32.0, &HierarchySettings::default(), &no_progress).unwrap();
    let (a, b, f) = (only_finer.stats.links, coarsened.stats.links, fresh.stats.links);
    println!(
        "links at frame 32: {a} refined only, {b} coarsened, {f} fresh; refined from {refined_from} pairs"
    );
    assert!(refined_from > 0, "no update refined a pair");
    assert!(b < a, "coarsening kept {b} links against {a} without it");
    assert!((b as f64) < 1.2 * f as f64, "coarsening kept {b} links, a fresh build has {f}");
    check_pair_tree(&coarsened);
    check_partition(&coarsened);
    let err = relative_rms(&face_means(&coarsened), &face_means(&fresh));
    assert!(err < 0.01, "the coarsened frame is off the fresh one by {err} rms");
}

/// In the seed's room (a ceiling light and a panel moving, a wall light still) a frame touches
/// the pairs of the moving objects and those whose shafts they cross: most links are kept.
#[test]
fn a_local_move_keeps_most_links() {
    let scene = seed_room(2.0, 60, settings());
    let hs = HierarchySettings { keep_pair_tree: true, ..Default::default() };
    let mut h = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
    for frame in 2..=3 {
        let f = frame as f64;
        let next = update_frame(&mut h, &scene, f, &hs, &no_progress).unwrap();
        let s = &next.stats;
        assert!(s.moved_faces > 0 && s.touched_pairs > 0, "frame {frame}: nothing moved");
        assert!(
            s.kept_links > s.touched_pairs,
            "frame {frame}: {} links kept, {} pairs touched: the update redid most of it",
            s.kept_links,
            s.touched_pairs
        );
        check_pairs(&next, &scene, f, &hs);
        h = next;
    }
}

/// The moving-light box's cluster links that the light's move touched only through their
/// shafts take the frame before's casts where no segment meets the light's swept box
/// (`coupling::Reuse`): some are taken, and every link, blocked and idle pair of the updated
/// frames is still what a fresh computation gives, bit for bit.
#[test]
fn casts_a_move_cannot_change_are_taken_from_the_frame_before() {
    let scene = cornell_box_moving_light(6, 8, settings());
    let hs = HierarchySettings { keep_pair_tree: true, ..Default::default() };
    let mut h = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
    assert_eq!(h.stats.reused_casts, 0, "a first frame has no frame before");
    for frame in 2..=4 {
        let f = frame as f64;
        let next = update_frame(&mut h, &scene, f, &hs, &no_progress).unwrap();
        let s = &next.stats;
        assert!(s.cluster_links > 0, "frame {frame}: no cluster links to test");
        // (Frame 2 has only frame 1's, which a first frame does not keep.)
        if frame > 2 {
            assert!(s.reused_casts > 0, "frame {frame}: no cast was taken from the frame before");
        } else {
            assert_eq!(s.reused_casts, 0);
        }
        check_pairs(&next, &scene, f, &hs);
        check_partition(&next);
        h = next;
    }
}

/// An updated frame's corner gather takes the last frame's values of the sources a move
/// cannot have changed (`gather::KeptGather`), and gathers exactly what a fresh gather of the
/// same solution gathers, bit for bit: on the moving-light box (the light under the ceiling
/// crosses the shafts of the ceiling's sources) and on the demo animation (a block sliding on
/// the floor, with the feet of its corners on it); and under a memory budget whose cap lets most
/// points keep nothing (they are gathered afresh).
#[test]
fn a_kept_gather_equals_a_fresh_gather() {
    use galerkin_radiosity::hierarchy::gather;
    let order2 = Settings { basis_order: 2, ..settings() };
    // A memory budget of 1 MB caps the kept values at 128 KiB: most points keep nothing.
    let capped = Settings { memory_budget_mb: 1, ..order2.clone() };
    // (In the small demo box both the light and the block move: most shafts meet a swept box.)
    for (name, scene, most) in [
        ("moving light", cornell_box_moving_light(4, 6, order2), true),
        ("demo", animated(), false),
        ("moving light, capped", cornell_box_moving_light(4, 6, capped), false),
    ] {
        let hs = keeping_gather();
        let mut h = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
        assert_eq!(h.stats.gather_kept, 0, "{name}: a first frame has no frame before");
        for frame in 2..=5 {
            let f = frame as f64;
            let next = update_frame(&mut h, &scene, f, &hs, &no_progress).unwrap();
            let s = &next.stats;
            assert!(s.moved_faces > 0);
            assert!(
                s.gather_kept > if most { s.gather_computed } else { 0 } && s.gather_computed > 0,
                "{name} frame {frame}: {} sources kept, {} computed",
                s.gather_kept,
                s.gather_computed
            );
            let budget = galerkin_radiosity::budget::budget_bytes(scene.settings.memory_budget_mb);
            let cap = gather::KeptGather::cap(budget);
            assert!(
                s.kept_gather_bytes > 0 && s.kept_gather_bytes <= cap,
                "{name}: {} bytes",
                s.kept_gather_bytes
            );
            let fresh = fresh_gather(&next, &scene, f);
            let (radiosity, irradiance) = next.corners.as_ref().expect("gathered");
            assert_eq!(radiosity, &fresh.radiosity, "{name} frame {frame}: B");
            assert_eq!(irradiance, &fresh.irradiance, "{name} frame {frame}: H");
            h = next;
        }
    }
}

/// Frames that do not gather (a session's previews, while the timeline is scrubbed) pass the
/// last gathered frame's values on with what moved since: the next gathered frame takes those
/// that all the moves since spared, and still gathers what a fresh gather of its solution gives,
/// bit for bit (taking them against the last move alone would not: the light moved over three
/// frames).
#[test]
fn a_kept_gather_outlasts_frames_without_a_gather() {
    let scene = cornell_box_moving_light(4, 8, Settings { basis_order: 2, ..settings() });
    let gathering = keeping_gather();
    let preview = HierarchySettings { corner_gather: false, ..gathering };
    let mut h = solve_frame(&scene, 1.0, &gathering, &no_progress).unwrap();
    for frame in [2, 3] {
        h = update_frame(&mut h, &scene, frame as f64, &preview, &no_progress).unwrap();
        assert!(h.corners.is_none() && h.kept_gather.is_some() && h.moved_since_gather.is_some());
    }
    // The frame before's, then a refinement of it (nothing moves): both gather.
    for frame in [4, 4] {
        let f = frame as f64;
        let next = update_frame(&mut h, &scene, f, &gathering, &no_progress).unwrap();
        let s = &next.stats;
        assert!(s.gather_kept > 0 && s.gather_computed > 0 || s.moved_faces == 0, "{} kept", s.gather_kept);
        let fresh = fresh_gather(&next, &scene, f);
        let (radiosity, _) = next.corners.as_ref().expect("gathered");
        assert_eq!(radiosity, &fresh.radiosity, "frame {frame}");
        assert!(next.moved_since_gather.is_none());
        h = next;
    }
    assert_eq!(h.stats.gather_computed, 0, "a refinement with nothing moved computes nothing");
}

/// The update's warm start changes only where the solve begins: the same links solved from the
/// sources alone give the same solution.
#[test]
fn an_updated_frame_solves_as_a_cold_start_on_its_links() {
    let scene = animated();
    let hs = HierarchySettings::default();
    let mut h = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
    let next = update_frame(&mut h, &scene, 3.0, &hs, &no_progress).unwrap();
    let tree = &next.hierarchy.tree;
    let lit = Lighting::new(&scene, 3.0, &tree.faces);
    let mut cold = State::new(tree);
    cold.add_sources(tree, &lit.emission, lit.lights.as_ref());
    cold.start_from_sources(tree);
    let stop = 1e-9 * cold.source_power(tree);
    let many = HierarchySettings { max_sweeps: 2000, ..hs };
    cold.solve(tree, &next.hierarchy.links, stop, &many, &|| false).unwrap();
    let warm = face_means(&next);
    let cold: Vec<f64> = (0..tree.faces.len()).map(|f| cold.mean[f][0]).collect();
    let peak = cold.iter().copied().fold(0.0, f64::max);
    for (f, (w, c)) in warm.iter().zip(&cold).enumerate() {
        // The settings' tolerance 1e-6 of the power against the cold solve's 1e-9.
        assert!((w - c).abs() < 1e-4 * peak, "face {f}: updated {w}, cold start {c}");
    }
}

/// Frame by frame through a session, the updated frames agree with frames solved from scratch
/// as closely as two hierarchies of the same accuracy can (their links differ where brightness
/// refined them), and an emission change alone touches no pair.
#[test]
fn updated_frames_agree_with_frames_solved_from_scratch() {
    let mut scene = animated();
    // The light also dims over the animation.
    let light = scene.materials.iter().position(|m| m.emission[0] > 0.0).unwrap();
    let e = scene.materials[light].emission;
    scene.emission_keys[light] = emission_ramp((1.0, e), (8.0, e.map(|x| 0.5 * x)));
    let hs = HierarchySettings::of(&scene.settings);
    let mut session = Session::new(scene.clone(), Method::Hierarchical).unwrap();
    let mut worst: f64 = 0.0;
    for frame in 1..=8 {
        let f = frame as f64;
        let stats = session.solve_frame(f, &no_progress).unwrap();
        assert_eq!(stats.full_rebuild, frame == 1, "frame {frame}");
        let fresh = solve_frame(&scene, f, &hs, &no_progress).unwrap();
        let got: Vec<f64> = session
            .face_results()
            .unwrap()
            .iter()
            .flat_map(|o| o.face_radiosity.iter().map(|v| v[0] as f64))
            .collect();
        let want: Vec<f64> = fresh
            .face_results(&scene, f)
            .iter()
            .flat_map(|o| o.face_radiosity.iter().map(|v| v[0] as f64))
            .collect();
        let err = relative_rms(&got, &want);
        println!(
            "frame {frame}: updated vs from scratch {:.3}% rms, {} links recomputed of {}",
            100.0 * err,
            stats.links_recomputed,
            stats.pairs
        );
        worst = worst.max(err);
    }
    assert!(worst < 0.01, "updated frames off the fresh ones by {worst} rms");

    // The light's emission alone: nothing moves, no pair is linked again.
    let mut still = scene.clone();
    for o in &mut still.objects {
        o.animation.clear();
    }
    let mut h = solve_frame(&still, 1.0, &hs, &no_progress).unwrap();
    let next = update_frame(&mut h, &still, 5.0, &hs, &no_progress).unwrap();
    assert_eq!((next.stats.moved_faces, next.stats.touched_pairs), (0, 0));
    let fresh = solve_frame(&still, 5.0, &hs, &no_progress).unwrap();
    let err = relative_rms(&face_means(&next), &face_means(&fresh));
    assert!(err < 0.01, "dimmed light: updated off the fresh frame by {err} rms");
}

/// The relink rounds test again only links and blocked pairs whose recorded load, times their
/// ends' growth in brightness since, passes 1 (`Hierarchy::decided_at`, `Hierarchy::link_load`),
/// and a round after which no node grew much reads only the loads, leaving the untested ones as
/// they were (`RefineStats::quick`): over the demo animation with the light dimming and
/// brightening, the frames are the same, link for link and bit for bit, as when every pair is
/// tested (the records cleared before each update), with fewer pairs tested.
#[test]
fn relinking_tests_only_what_may_fail() {
    let (mut tested_filtered, mut tested_every, mut quick) = (0, 0, 0);
    // A steep ramp, whose relinks mostly find nodes much brighter, and a gentle one.
    for (from, to) in [(0.3, 2.0), (1.0, 1.3)] {
        let mut scene = animated();
        let light = scene.materials.iter().position(|m| m.emission[0] > 0.0).unwrap();
        let e = scene.materials[light].emission;
        scene.emission_keys[light] = emission_ramp((1.0, e.map(|x| from * x)), (8.0, e.map(|x| to * x)));
        let hs = HierarchySettings { keep_pair_tree: true, ..Default::default() };
        let mut filtered = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
        let mut every = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
        for frame in 2..=8 {
            let f = frame as f64;
            every.hierarchy.decided_at.clear();
            every.hierarchy.blocked_load.clear();
            let a = update_frame(&mut filtered, &scene, f, &hs, &no_progress).unwrap();
            let b = update_frame(&mut every, &scene, f, &hs, &no_progress).unwrap();
            let pairs = |h: &HierarchicalFrame| {
                let mut p: Vec<_> = h.hierarchy.links.iter().map(|l| (l.a, l.b)).collect();
                p.sort_unstable();
                (p, h.hierarchy.blocked.len(), h.hierarchy.idle_pairs().len())
            };
            assert_eq!(pairs(&a), pairs(&b), "ramp {from}-{to}, frame {frame}: the links differ");
            assert_eq!(
                face_means(&a),
                face_means(&b),
                "ramp {from}-{to}, frame {frame}: the solutions differ"
            );
            check_loads_bound(&a, &format!("ramp {from}-{to}, frame {frame}"));
            tested_filtered += a.stats.retested;
            tested_every += b.stats.retested;
            quick += a.stats.quick_relinks;
            (filtered, every) = (a, b);
        }
    }
    println!(
        "pairs tested again: {tested_filtered} with the records, {tested_every} without; {quick} quick relinks"
    );
    assert!(tested_every > 0 && tested_filtered * 4 < tested_every);
    assert!(quick > 0, "no relink read only the loads");
}

/// Every stored load, times the growth of its ends' brightness since `decided_at`, bounds what
/// the oracle gives the pair at the frame's own brightness: what lets a relink leave a pair
/// untested (`Hierarchy::relink`).
fn check_loads_bound(h: &HierarchicalFrame, what: &str) {
    use galerkin_radiosity::hierarchy::coupling::Coupling;
    let hierarchy = &h.hierarchy;
    let (tree, oracle) = (&hierarchy.tree, &hierarchy.oracle);
    let radiosity = h.state.radiosity_estimate();
    let growth = |n: u32| {
        let (r, v) = (radiosity[n as usize], hierarchy.decided_at.get(n as usize).copied());
        match v {
            _ if r <= 0.0 => 0.0,
            Some(v) if v > 0.0 => r / oracle.threshold / v,
            _ => f64::INFINITY,
        }
    };
    let bound = |load: f32, a: u32, b: u32| load as f64 * growth(a).max(growth(b)) * (1.0 + 1e-4) + 1e-6;
    assert_eq!(hierarchy.link_load.len(), hierarchy.links.len(), "{what}: a load per link");
    for (l, &load) in hierarchy.links.iter().zip(&hierarchy.link_load) {
        let light = matches!(l.coupling, Coupling::Constants { .. });
        let now = oracle.load(tree, &radiosity, l.a, l.b, light) as f64;
        assert!(
            now <= bound(load, l.a, l.b),
            "{what}: link {:?} loads {now}, bound {}",
            (l.a, l.b),
            bound(load, l.a, l.b)
        );
    }
    for (&(a, b), &load) in hierarchy.blocked.iter().zip(&hierarchy.blocked_load) {
        let now = oracle.blocked_load(tree, &radiosity, a, b) as f64;
        assert!(
            now <= bound(load, a, b),
            "{what}: blocked pair {:?} loads {now}, bound {}",
            (a, b),
            bound(load, a, b)
        );
    }
}

/// A cancelled update leaves the last frame readable as it was, and the next frame is solved
/// from scratch (the cancelled update took the links).
#[test]
fn a_cancelled_update_keeps_the_last_frame() {
    let scene = animated();
    let mut session = Session::new(scene, Method::Hierarchical).unwrap();
    session.solve_frame(1.0, &no_progress).unwrap();
    let before = session.face_results().unwrap();
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let cancel_late = |_: f64, _: &str| calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed) < 3;
    let err = session.solve_frame(2.0, &cancel_late).unwrap_err();
    assert!(matches!(err, galerkin_radiosity::Error::Cancelled), "{err}");
    assert_eq!(session.face_results().unwrap(), before, "the readable frame changed");
    let stats = session.solve_frame(2.0, &no_progress).unwrap();
    assert!(stats.full_rebuild, "after a cancelled update the frame must be solved afresh");
    let stats = session.solve_frame(3.0, &no_progress).unwrap();
    assert!(!stats.full_rebuild, "and the one after updated again");
}

/// The walks down the pair tree (`touch::by_walk`, and the one an update makes,
/// `Splits::coarsest_touched`) find exactly the stored pairs a scan of them all finds, for
/// random moves (random faces moved, random swept boxes in and around the scene) on the
/// hierarchies of the demo animation and of the seed's room, each after an update.
#[test]
fn the_pair_tree_walk_finds_what_the_scan_finds() {
    use galerkin_radiosity::geometry::Aabb;
    use galerkin_radiosity::hierarchy::touch::{self, Moves, Touch};
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for scene in [animated(), seed_room(2.0, 60, settings())] {
        let hs = HierarchySettings { keep_pair_tree: true, ..Default::default() };
        let mut first = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
        let h = update_frame(&mut first, &scene, 2.0, &hs, &no_progress).unwrap();
        let hierarchy = &h.hierarchy;
        let tree = &hierarchy.tree;
        let idle = hierarchy.idle_pairs();
        let stored = hierarchy.links.len() + hierarchy.blocked.len() + idle.len();
        let scene_box = tree.bounds(tree.root);
        let size = scene_box.diagonal();
        let (mut partial, mut none) = (0, 0);
        for case in 0..300 {
            let p = [0.0, 0.0, 0.002, 0.02][case % 4];
            let faces: Vec<bool> = (0..tree.faces.len()).map(|_| next() < p).collect();
            let swept: Vec<Aabb> = (0..1 + case % 3)
                .map(|_| {
                    let c = scene_box.min + size * glam::DVec3::new(next(), next(), next());
                    let h = size * (0.002 + 0.2 * next()) * glam::DVec3::new(next(), next(), next());
                    Aabb { min: c - h, max: c + h }
                })
                .collect();
            let moves = Moves { faces, swept };
            let touch = Touch::new(tree, &moves);
            let mut scan = touch::by_scan(hierarchy, &idle, &touch);
            let mut walk = touch::by_walk(hierarchy, &touch).expect("the pair tree is kept");
            // The walk an update makes (`update::take_changed`): the touched leaves it finds on
            // the way to the subtrees it redoes (on a copy: it forgets what it redoes).
            let mut splits = hierarchy.splits.clone();
            let mut update_walk = splits
                .coarsest_touched(
                    tree,
                    |a, b| touch.pair(a, b),
                    |a, b| touch.may_below(a, b),
                    |a, b| touch::neutral(tree, a, b),
                    |_, _| false,
                )
                .expect("the pair tree is kept")
                .touched;
            scan.sort_unstable();
            walk.sort_unstable();
            update_walk.sort_unstable();
            assert_eq!(walk, scan, "case {case}: the walk and the scan disagree");
            assert_eq!(update_walk, scan, "case {case}: the update's walk and the scan disagree");
            match scan.len() {
                0 => none += 1,
                n if n < stored => partial += 1,
                _ => {}
            }
        }
        assert!(
            partial > 100 && none > 0,
            "{partial} cases touched part of the pairs, {none} none: too few tested"
        );
    }
}

/// The hemisphere bound's furnace gathers again only the receivers whose links changed since it
/// last ran, keeping the other rows with the packing from solve to solve and frame to frame
/// (`State::bound_leaves`). Checked at every solve of every frame (`check_furnace` gathers them
/// all too and fails where a kept row differs): the demo animation with and without the pair
/// tree (updates that refine only, and that coarsen), and the seed's room, where a panel moves
/// past a still wall light.
#[test]
fn the_furnace_gathers_again_only_what_changed() {
    for (scene, frames) in [(animated(), 8), (seed_room(2.0, 6, settings()), 6)] {
        for keep_pair_tree in [false, true] {
            let hs = HierarchySettings { keep_pair_tree, check_furnace: true, ..Default::default() };
            let mut h = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
            let (mut rows, mut whole) = (h.stats.furnace_rows, h.stats.furnaces * h.stats.nodes);
            for frame in 2..=frames {
                let next = update_frame(&mut h, &scene, frame as f64, &hs, &no_progress)
                    .unwrap_or_else(|e| panic!("frame {frame} (pair tree kept: {keep_pair_tree}): {e}"));
                assert!(next.stats.updated, "frame {frame} was not updated");
                (rows, whole) =
                    (rows + next.stats.furnace_rows, whole + next.stats.furnaces * next.stats.nodes);
                h = next;
            }
            // (Not every row every time: the kept ones were checked.)
            assert!(2 * rows < whole, "the furnaces gathered {rows} rows of {whole}");
        }
    }
}

/// The leaves' and the corners' direct light is kept between frames: a block sliding over a floor
/// under a World, a soft Point light and a Sun (frames 1-3, then still; the light moving from frame
/// 4 to 6), each updated frame's leaf sources equal a fresh projection of the same leaves and its
/// corners a fresh gather's, bit for bit, once nothing moves every leaf takes its shadow rays from
/// the frame before, and while the light moves all but its own.
#[test]
fn kept_leaf_rays_give_the_sources_a_fresh_projection_gives() {
    use galerkin_radiosity::lights::direct::DirectLight;
    use galerkin_radiosity::lights::{Light, LightKey, LightKind, World};
    use galerkin_radiosity::scene::Material;
    use galerkin_radiosity::scenes::{box_mesh, subdivided_quad, translation_keys};
    use glam::{DMat4, DVec3};
    let p = DVec3::new;
    let floor =
        subdivided_quad("Floor", [p(-2., -2., 0.), p(2., -2., 0.), p(2., 2., 0.), p(-2., 2., 0.)], 4, 0);
    let mut block = box_mesh("Block", p(-0.3, -0.3, 0.0), p(0.3, 0.3, 0.6), 1, false, 0);
    block.animation = translation_keys(&[(1.0, p(-0.8, 0.0, 0.0)), (3.0, p(0.8, 0.0, 0.0))]);
    let mut lamp = Light::new("Lamp", LightKind::Point, DMat4::from_translation(p(0.4, -0.6, 1.5)), 60.0);
    lamp.base.radius = 0.1;
    // Still until frame 4, then moving over the still block: its rays are cast again, the World's
    // and the Sun's taken.
    lamp.animation = vec![
        LightKey { frame: 4.0, ..LightKey::default() },
        LightKey {
            frame: 6.0,
            matrix: Some(DMat4::from_translation(p(-0.5, 0.3, 1.2))),
            ..LightKey::default()
        },
    ];
    let sun = Light::new("Sun", LightKind::Sun, DMat4::from_rotation_x(0.3), 1.5);
    let grey = Material { name: "grey".into(), reflectance: [0.6; 3], emission: [0.0; 3] };
    let scene = Scene::new(settings(), (1, 6), vec![grey], vec![vec![]], vec![floor, block])
        .unwrap()
        .with_lights(vec![lamp, sun])
        .unwrap()
        .with_world(Some(World::uniform([0.4, 0.5, 0.6], 1.0)))
        .unwrap();
    let hs = keeping_gather();
    let mut h = solve_frame(&scene, 1.0, &hs, &no_progress).unwrap();
    for frame in 2..=6 {
        let f = frame as f64;
        let next = update_frame(&mut h, &scene, f, &hs, &no_progress).unwrap();
        let lights = next.direct.as_ref().expect("the frame keeps its lights");
        let tree = &next.hierarchy.tree;
        let (nb, rule) = (tree.basis.len(), DirectLight::projection_rule());
        let lit = Lighting::new(&scene, f, &tree.faces);
        let mut leaves = Vec::new();
        tree.leaves_below(tree.root, &mut leaves);
        let mut compared = 0;
        for &id in &leaves {
            let Some(s) = tree.nodes[id as usize].surface() else { continue };
            let fc = s.face as usize;
            let mut fresh = vec![[0.0; 3]; nb];
            fresh[0] = lit.emission[fc];
            lights.project_onto(&s.patch, s.face, tree.reflectance[fc], tree.basis, &rule, &mut fresh);
            let kept = &next.state.sources[id as usize * nb..(id as usize + 1) * nb];
            let bits = |v: &[[f64; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert!(
                bits(kept) == bits(&fresh),
                "frame {frame}, leaf {id}: kept sources differ from fresh ones"
            );
            compared += 1;
        }
        let fresh = fresh_gather(&next, &scene, f);
        let (radiosity, irradiance) = next.corners.as_ref().expect("gathered");
        assert_eq!(radiosity, &fresh.radiosity, "frame {frame}: B");
        assert_eq!(irradiance, &fresh.irradiance, "frame {frame}: H");
        let s = &next.stats;
        eprintln!(
            "frame {frame}: {compared} leaves, direct rays {} traced, {} taken",
            s.direct_rays_traced, s.direct_rays_taken
        );
        if frame == 4 {
            assert!(s.direct_rays_traced == 0 && s.direct_rays_taken > 0, "nothing moved: {s:?}");
        } else if frame > 4 {
            let (traced, taken) = (s.direct_rays_traced, s.direct_rays_taken);
            assert!(
                s.moved_faces == 0 && traced > 0 && taken > 2 * traced,
                "frame {frame}, the lamp moved: {s:?}"
            );
        } else {
            assert!(s.moved_faces > 0 && s.direct_rays_taken > 0, "frame {frame}: {s:?}");
        }
        h = next;
    }
}
