//! Per-frame time of the animation methods (issue 3): `cargo bench --bench animation [-- --quick]`.
//!
//! For the seed's two scenes (Fig. 5a: a room, a ceiling light moving left and right, a blue
//! panel passing a wall light; Fig. 5b: a billiard table under a moving light) and the Cornell
//! box of ~1,000 patches with a moving light, all at basis order 2 with visibility: the first
//! frame (the one-time precomputation), and the mean of the following frames, for the default
//! method (series), `--exact` and `--full`, measured one after the other in one run. The paper's
//! Tables 1 and 2 report 65% and 61% per-frame savings over its Galerkin progressive method.
//!
//! The second table is the hierarchy's (issue 21): each frame updated from the one before
//! ([`galerkin_radiosity::hierarchy::update::update_frame`]) against the same frames solved from
//! scratch, and how far the updated frames' face means are from the fresh ones.
//! `-- --hierarchy` prints the hierarchy's tables alone (about 1 min). The last table measures
//! how an update finds the pairs a move touched: a scan of every stored pair against the walk
//! down the pair tree ([`galerkin_radiosity::hierarchy::touch`]). `-- --methods` prints the
//! moving-light box's frames on the flat path against the hierarchy, `-- --gather` the same with
//! the corner gather on.

use galerkin_radiosity::scene::{Scene, Settings};
use galerkin_radiosity::scenes;
use galerkin_radiosity::session::{FrameStats, Method, Session};
use galerkin_radiosity::system::no_progress;

struct Run {
    first: f64,
    mean: f64,
    series: f64,
    recomputed: f64,
}

fn run(scene: &Scene, method: Method) -> Run {
    let mut session = Session::new(scene.clone(), method).unwrap();
    let stats: Vec<FrameStats> = (scene.frames.0..=scene.frames.1)
        .map(|f| session.solve_frame(f as f64, &no_progress).unwrap())
        .collect();
    let rest = &stats[1..];
    let n = rest.len().max(1) as f64;
    Run {
        first: stats[0].seconds,
        mean: rest.iter().map(|s| s.seconds).sum::<f64>() / n,
        series: rest.iter().map(|s| s.links_series as f64).sum::<f64>() / n,
        recomputed: rest.iter().map(|s| s.links_recomputed as f64).sum::<f64>() / n,
    }
}

/// A hierarchical session over `scene`'s frames against each frame solved from scratch, one
/// after the other: per-frame means over frames 2.., the kept share of links, and the worst
/// relative RMS of the face means of an updated frame against the fresh one.
struct HierRun {
    first: f64,
    updated: f64,
    /// An updated frame's link seconds (and of them, computing couplings: what the seed's series
    /// could replace at most), solve seconds and Jacobi sweeps (means).
    link: f64,
    compute: f64,
    solve: f64,
    sweeps: f64,
    fresh: f64,
    fresh_sweeps: f64,
    kept: f64,
    touched: f64,
    links: f64,
    /// The last frame's links, updated and fresh.
    last_links: usize,
    last_fresh_links: usize,
    worst_rms: f64,
}

fn face_means(results: &[galerkin_radiosity::scene::json::ObjectResult]) -> Vec<f64> {
    results
        .iter()
        .flat_map(|o| o.face_radiosity.iter().map(|v| v.iter().copied().fold(0.0f32, f32::max) as f64))
        .collect()
}

fn run_hierarchy(scene: &Scene) -> HierRun {
    use galerkin_radiosity::hierarchy::update::update_frame;
    use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
    // As `Session` solves an animation: the pair tree kept, each frame updated from the last.
    let hs = HierarchySettings { keep_pair_tree: true, ..HierarchySettings::of(&scene.settings) };
    let fresh_hs = HierarchySettings::of(&scene.settings);
    let (mut first, mut updated, mut fresh, mut worst) = (0.0, 0.0, 0.0, 0.0f64);
    let (mut kept, mut touched, mut links) = (0.0, 0.0, 0.0);
    let (mut link, mut compute, mut solve, mut sweeps, mut fresh_sweeps) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut last_links, mut last_fresh_links) = (0, 0);
    let frames: Vec<i64> = (scene.frames.0..=scene.frames.1).collect();
    let mut h = None;
    for (k, &f) in frames.iter().enumerate() {
        let t = std::time::Instant::now();
        let next = match h.as_mut() {
            None => solve_frame(scene, f as f64, &hs, &no_progress).unwrap(),
            Some(previous) => update_frame(previous, scene, f as f64, &hs, &no_progress).unwrap(),
        };
        let seconds = t.elapsed().as_secs_f64();
        let stats = next.stats.clone();
        let got = face_means(&next.face_results(scene, f as f64));
        h = Some(next);
        if k == 0 {
            first = seconds;
            continue;
        }
        assert!(stats.updated, "frame {f} was not updated");
        updated += seconds;
        link += stats.link_seconds;
        compute += stats.compute_seconds;
        solve += stats.solve_seconds;
        sweeps += stats.sweeps as f64;
        links += stats.links as f64;
        kept += stats.kept_links as f64;
        touched += (stats.links - stats.kept_links) as f64;
        let t = std::time::Instant::now();
        let from_scratch = solve_frame(scene, f as f64, &fresh_hs, &no_progress).unwrap();
        fresh += t.elapsed().as_secs_f64();
        fresh_sweeps += from_scratch.stats.sweeps as f64;
        (last_links, last_fresh_links) = (stats.links, from_scratch.stats.links);
        let want = face_means(&from_scratch.face_results(scene, f as f64));
        let peak = want.iter().copied().fold(0.0, f64::max);
        let rms =
            (got.iter().zip(&want).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / want.len() as f64).sqrt();
        worst = worst.max(rms / peak);
    }
    let n = (frames.len() - 1).max(1) as f64;
    HierRun {
        first,
        updated: updated / n,
        link: link / n,
        compute: compute / n,
        solve: solve / n,
        sweeps: sweeps / n,
        fresh: fresh / n,
        fresh_sweeps: fresh_sweeps / n,
        kept: kept / n,
        touched: touched / n,
        links: links / n,
        last_links,
        last_fresh_links,
        worst_rms: worst,
    }
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let hierarchy_only = std::env::args().any(|a| a == "--hierarchy");
    if std::env::args().any(|a| a == "--gather") {
        gather_table(quick);
        return;
    }
    if std::env::args().any(|a| a == "--methods") {
        let settings = Settings { basis_order: 2, corner_gather: false, ..Settings::default() };
        methods_table(&settings, quick);
        return;
    }
    // The solver's methods side by side; the corner gather (the same work for every method) is
    // off here and reported by `gather_seconds` in a bake's frame stats.
    let settings = Settings { basis_order: 2, corner_gather: false, ..Settings::default() };
    if !hierarchy_only {
        flat_table(&settings, quick);
    }
    hierarchy_table(&settings, quick);
    mixing_table(&settings, quick);
    touch_table(quick);
}

/// How an update finds the stored pairs a move touched: the scan of them all against the walk
/// down the pair tree, side by side on the same moves (docs/benchmarks.md's "touch-walk" block).
/// The decimated monastery of tests/data/real (order 1, its hierarchy at the default accuracy)
/// and a box the size of one of its pieces moved a small step at random places, `moves` times.
fn touch_table(quick: bool) {
    use galerkin_radiosity::geometry::Aabb;
    use galerkin_radiosity::hierarchy::touch::{self, Moves, Touch};
    use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
    use std::time::Instant;
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/real/monastery_scene.json");
    let mut scene = galerkin_radiosity::scene::json::read_scene(std::path::Path::new(path)).unwrap();
    scene.settings.basis_order = 1;
    scene.settings.corner_gather = false;
    let hs = HierarchySettings { keep_pair_tree: true, ..HierarchySettings::of(&scene.settings) };
    let h = solve_frame(&scene, 0.0, &hs, &no_progress).unwrap();
    let (hierarchy, tree) = (&h.hierarchy, &h.hierarchy.tree);
    // (Not stored with the pair tree kept: made here once, so that the scan scans every pair.)
    let idle = hierarchy.idle_pairs();
    let stored = hierarchy.links.len() + hierarchy.blocked.len() + idle.len();
    let moves_per_size = if quick { 20 } else { 200 };
    println!(
        "\nFinding the pairs a move touched: the decimated monastery (tests/data/real, {} faces, order 1, {} stored \
         pairs, {} inner pairs in its pair tree), a box of the given share of the scene's diagonal swept a tenth \
         of its size at {moves_per_size} random places; milliseconds per move (the scan tests every stored pair, \
         the walk enters the pair tree only where a shaft meets the box; both find the same pairs):\n",
        tree.faces.len(),
        stored,
        hierarchy.splits.len(),
    );
    println!(
        "| box / diagonal | touched pairs | scan ms | walk ms | x faster | then a lookup per stored pair ms |"
    );
    println!("|---|---|---|---|---|---|");
    let root = tree.bounds(tree.root);
    let size = root.diagonal();
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for share in [0.01, 0.05, 0.2] {
        let (mut scan_s, mut walk_s, mut lookup_s, mut touched) = (0.0, 0.0, 0.0, 0usize);
        for k in 0..moves_per_size {
            let c = root.min + size * glam::DVec3::new(next(), next(), next());
            let half = size * (0.5 * share) * glam::DVec3::ONE;
            let step = size * (0.1 * share) * glam::DVec3::X;
            let swept = Aabb { min: c - half, max: c + half + step };
            let moves = Moves { faces: vec![false; tree.faces.len()], swept: vec![swept] };
            let touch = Touch::new(tree, &moves);
            // Alternated, so that the machine's load falls on both alike.
            let (scan, walk) = if k % 2 == 0 {
                let t = Instant::now();
                let scan = touch::by_scan(hierarchy, &idle, &touch);
                scan_s += t.elapsed().as_secs_f64();
                let t = Instant::now();
                let walk = touch::by_walk(hierarchy, &touch).unwrap();
                walk_s += t.elapsed().as_secs_f64();
                (scan, walk)
            } else {
                let t = Instant::now();
                let walk = touch::by_walk(hierarchy, &touch).unwrap();
                walk_s += t.elapsed().as_secs_f64();
                let t = Instant::now();
                let scan = touch::by_scan(hierarchy, &idle, &touch);
                scan_s += t.elapsed().as_secs_f64();
                (scan, walk)
            };
            assert_eq!(scan.len(), walk.len(), "the walk and the scan disagree");
            touched += scan.len();
            // What taking the walk's pairs out of the stores costs: a lookup per stored pair
            // (`update::take_changed`), counted here without the removal.
            let t = Instant::now();
            let set: galerkin_radiosity::hierarchy::pair_tree::PairSet =
                walk.iter().map(|&(a, b)| galerkin_radiosity::hierarchy::pair_tree::key(a, b)).collect();
            let key = galerkin_radiosity::hierarchy::pair_tree::key;
            let found = hierarchy.links.iter().filter(|l| set.contains(&key(l.a, l.b))).count()
                + hierarchy.blocked.iter().chain(&idle).filter(|&&(a, b)| set.contains(&key(a, b))).count();
            lookup_s += t.elapsed().as_secs_f64();
            assert_eq!(found, walk.len());
        }
        let n = moves_per_size as f64;
        println!(
            "| {share} | {:.0} | {:.2} | {:.2} | {:.1}x | {:.2} |",
            touched as f64 / n,
            1e3 * scan_s / n,
            1e3 * walk_s / n,
            scan_s / walk_s,
            1e3 * lookup_s / n,
        );
    }
}

/// The hierarchical solve with and without the Anderson mixer over the same frames, each chain
/// of frames updated from its own last one, the two chains alternated frame by frame (which
/// goes first swaps each frame): docs/benchmarks.md's "solve-mixing" block.
fn mixing_table(settings: &Settings, quick: bool) {
    use galerkin_radiosity::hierarchy::update::update_frame;
    use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
    let frames = if quick { 3 } else { 8 };
    let cases = bench_scenes(settings, quick, frames);
    println!(
        "\nThe hierarchical solve's sweeps plain (Jacobi with push-pull) and mixed (Anderson, depth {}): the same \
         scenes over {frames} frames, the first fresh, the others updated; solve seconds and sweeps per frame \
         (means over the updated frames; the fresh frame's sweeps in brackets), and the two chains' face means \
         apart, worst frame, of the peak:\n",
        HierarchySettings::default().anderson_depth
    );
    println!(
        "| scene | plain sweeps (fresh) | mixed sweeps (fresh) | plain solve s | mixed solve s | x faster solve | apart |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (name, scene) in cases {
        let mixed = HierarchySettings::of(&scene.settings);
        let plain = HierarchySettings { anderson_depth: 0, ..mixed };
        let settings = [plain, mixed];
        let mut chains: Vec<Option<galerkin_radiosity::hierarchy::HierarchicalFrame>> = vec![None, None];
        let (mut sweeps, mut fresh, mut seconds, mut apart) = ([0.0; 2], [0usize; 2], [0.0; 2], 0.0f64);
        for (k, f) in (scene.frames.0..=scene.frames.1).enumerate() {
            let order = if k % 2 == 0 { [0, 1] } else { [1, 0] };
            for i in order {
                let next = match chains[i].as_mut() {
                    None => solve_frame(&scene, f as f64, &settings[i], &no_progress).unwrap(),
                    Some(previous) => {
                        update_frame(previous, &scene, f as f64, &settings[i], &no_progress).unwrap()
                    }
                };
                if k == 0 {
                    fresh[i] = next.stats.sweeps;
                } else {
                    sweeps[i] += next.stats.sweeps as f64;
                    seconds[i] += next.stats.solve_seconds;
                }
                chains[i] = Some(next);
            }
            let means: Vec<Vec<f64>> = chains
                .iter()
                .map(|c| face_means(&c.as_ref().unwrap().face_results(&scene, f as f64)))
                .collect();
            let peak = means[0].iter().copied().fold(0.0, f64::max);
            let worst = means[0].iter().zip(&means[1]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            apart = apart.max(worst / peak);
        }
        let n = (frames - 1).max(1) as f64;
        println!(
            "| {name} | {:.1} ({}) | {:.1} ({}) | {:.3} | {:.3} | {:.2}x | {:.4}% |",
            sweeps[0] / n,
            fresh[0],
            sweeps[1] / n,
            fresh[1],
            seconds[0] / n,
            seconds[1] / n,
            seconds[0] / seconds[1],
            100.0 * apart,
        );
    }
}

/// The decimated monastery of tests/data/real (1,065 faces) at order 1, corner gather off, its
/// light quad moving 40 units (two thirds of its width) along x over `frames` frames: the
/// hierarchy's table's real-mesh row (issue 21's "monastery with a light moving along it").
fn monastery_moving_light(frames: i64) -> Scene {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/real/monastery_scene.json");
    let mut scene = galerkin_radiosity::scene::json::read_scene(std::path::Path::new(path)).unwrap();
    scene.settings.basis_order = 1;
    scene.settings.corner_gather = false;
    scene.frames = (0, frames - 1);
    let light = scene.objects.iter_mut().find(|o| o.name == "Light").expect("the scene's light");
    light.animation = scenes::translation_keys(&[
        (0.0, glam::DVec3::new(-20.0, 0.0, 0.0)),
        ((frames - 1) as f64, glam::DVec3::new(20.0, 0.0, 0.0)),
    ]);
    scene
}

/// The three scenes every table of this bench runs, over `frames` frames: the seed's room and
/// billiard (its Fig. 5) and the Cornell box with a moving light, smaller with `quick`.
fn bench_scenes(settings: &Settings, quick: bool, frames: i64) -> Vec<(&'static str, Scene)> {
    vec![
        ("Fig. 5a room", scenes::seed_room(if quick { 2.0 } else { 3.0 }, frames, settings.clone())),
        ("Fig. 5b billiard", scenes::billiard(if quick { 1.5 } else { 2.5 }, frames, settings.clone())),
        (
            "Cornell box, moving light",
            scenes::cornell_box_moving_light(if quick { 6 } else { 14 }, frames, settings.clone()),
        ),
    ]
}

/// Per-frame seconds of every updated frame of `scene` solved by `method` through a session, as
/// the CLI bakes it (the first frame left out; none of the others may have been built afresh).
fn frame_seconds(scene: &Scene, method: Method) -> Vec<f64> {
    let mut session = Session::new(scene.clone(), method).unwrap();
    let stats: Vec<FrameStats> = (scene.frames.0..=scene.frames.1)
        .map(|f| session.solve_frame(f as f64, &no_progress).unwrap())
        .collect();
    for s in &stats[1..] {
        assert!(!s.full_rebuild, "{method:?}: frame {} was built afresh", s.frame);
    }
    stats[1..].iter().map(|s| s.seconds).collect()
}

/// The `q`-quantile of `x` (sorted in place), by the nearest rank.
fn quantile(x: &mut [f64], q: f64) -> f64 {
    x.sort_by(f64::total_cmp);
    x[((q * x.len() as f64).ceil() as usize).clamp(1, x.len()) - 1]
}

/// Issue 20's moving-light row: the box's frames on the flat path's default method and on the
/// hierarchy, the two alternated run by run so that the machine's drift falls on both
/// (docs/benchmarks.md's "box-methods" block; `-- --methods`).
fn methods_table(settings: &Settings, quick: bool) {
    let (frames, runs) = if quick { (4, 1) } else { (48, 5) };
    let scene = scenes::cornell_box_moving_light(if quick { 6 } else { 14 }, frames, settings.clone());
    let methods = [("flat, the default method", Method::Incremental), ("hierarchy", Method::Hierarchical)];
    let mut seconds = vec![Vec::new(); methods.len()];
    // Each method first in every other run, so that what a run leaves (caches, the allocator's
    // pages) falls on both.
    for run in 0..runs {
        for k in 0..methods.len() {
            let k = if run % 2 == 0 { k } else { methods.len() - 1 - k };
            seconds[k].extend(frame_seconds(&scene, methods[k].1));
        }
    }
    println!(
        "\nThe moving-light box ({} patches, order 2, corner gather off), {frames} frames per run, the methods \
         alternated over {runs} runs (each first in every other); seconds per updated frame through a session (as the CLI bakes), over every \
         run's frames 2..{frames}, {} threads:\n",
        scene.face_count(),
        rayon::current_num_threads()
    );
    println!("| method | median s/frame | p25 | p75 | x the flat median |");
    println!("|---|---|---|---|---|");
    let quartiles: Vec<[f64; 3]> =
        seconds.iter_mut().map(|x| [0.25, 0.5, 0.75].map(|q| quantile(x, q))).collect();
    let flat = quartiles[0][1];
    for ((name, _), [p25, median, p75]) in methods.iter().zip(quartiles) {
        println!("| {name} | {median:.4} | {p25:.4} | {p75:.4} | {:.2}x |", median / flat);
    }
    hierarchy_phases(&scene, runs);
}

/// Where the hierarchy's updated frames of `scene` go (`HierarchyStats`' phases), as `Session`
/// updates them (the pair tree kept), with the last frame's cluster-link casts taken where a
/// move cannot have changed them (the default) and without: means over frames 2.. of `runs`
/// runs each, the two alternated (each first in every other run).
fn hierarchy_phases(scene: &Scene, runs: usize) {
    use galerkin_radiosity::hierarchy::update::update_frame;
    use galerkin_radiosity::hierarchy::{HierarchySettings, HierarchyStats, solve_frame};
    type Phase = (&'static str, fn(&HierarchyStats) -> f64);
    let phases: [Phase; 7] = [
        ("the set-up: faces placed, lights and occluders, the last frame's tree and solution copied", |s| {
            s.setup_seconds
        }),
        ("finding the touched pairs (the walk down the pair tree) and taking them out", |s| s.touch_seconds),
        ("linking them again (of it, computing couplings: next row)", |s| s.first_link_seconds),
        ("relinking after each solve", |s| s.relink_seconds),
        ("packing the links for the solve", |s| s.pack_seconds),
        ("the hemisphere bound's furnaces", |s| s.furnace_seconds),
        ("the sweeps", |s| s.sweep_seconds),
    ];
    /// Per phase, then computing couplings, the whole frame, sweeps and casts taken: sums.
    #[derive(Default, Clone, Copy)]
    struct Sums {
        phases: [f64; 7],
        compute: f64,
        whole: f64,
        sweeps: f64,
        reused: f64,
        frames: f64,
    }
    let frames: Vec<i64> = (scene.frames.0..=scene.frames.1).collect();
    let mut sums = [Sums::default(); 2];
    for run in 0..runs {
        for k in 0..2 {
            let k = if run % 2 == 0 { k } else { 1 - k };
            let hs = HierarchySettings {
                keep_pair_tree: true,
                reuse_casts: k == 0,
                ..HierarchySettings::of(&scene.settings)
            };
            let sum = &mut sums[k];
            let mut h = solve_frame(scene, frames[0] as f64, &hs, &no_progress).unwrap();
            for &f in &frames[1..] {
                let t = std::time::Instant::now();
                let next = update_frame(&mut h, scene, f as f64, &hs, &no_progress).unwrap();
                sum.whole += t.elapsed().as_secs_f64();
                let s = &next.stats;
                assert!(s.updated, "frame {f} was not updated");
                for (x, (_, of)) in sum.phases.iter_mut().zip(&phases) {
                    *x += of(s);
                }
                sum.compute += s.compute_seconds;
                sum.sweeps += s.sweeps as f64;
                sum.reused += s.reused_casts as f64;
                sum.frames += 1.0;
                h = next;
            }
        }
    }
    let [on, off] = sums;
    println!(
        "\nThe hierarchy's updated frames of the same box through `update_frame` (the pair tree kept, as a session \
         updates), milliseconds per frame, means over frames 2..{} of {runs} runs each, with the last frame's \
         cluster-link casts taken where a move cannot have changed them (the default; {:.0} a frame) and without, \
         alternated ({:.1} sweeps a frame):\n",
        frames.len(),
        on.reused / on.frames,
        on.sweeps / on.frames,
    );
    println!("| phase | ms per frame | without the casts |");
    println!("|---|---|---|");
    let ms = |x: f64, s: &Sums| 1e3 * x / s.frames;
    for (i, (name, _)) in phases.iter().enumerate() {
        println!("| {name} | {:.1} | {:.1} |", ms(on.phases[i], &on), ms(off.phases[i], &off));
        if i == 2 {
            println!(
                "| (of which computing the couplings) | ({:.1}) | ({:.1}) |",
                ms(on.compute, &on),
                ms(off.compute, &off)
            );
        }
    }
    let rest = |s: &Sums| ms(s.whole - s.phases.iter().sum::<f64>(), s);
    println!("| the rest (counts, the read-back) | {:.1} | {:.1} |", rest(&on), rest(&off));
    println!("| the whole frame | {:.1} | {:.1} |", ms(on.whole, &on), ms(off.whole, &off));
}

/// Issue 21's first row, a frame with its corner gather: the moving-light box's updated frames
/// with the corner gather on, on the flat path (a session, the default method) and on the
/// hierarchy (`update_frame`, as a session updates) with its gather keeping each point's source
/// values for the next frame (`HierarchySettings::keep_gather`, the default for animations) and
/// without, the three alternated run by run (docs/benchmarks.md's "box-gather" block;
/// `-- --gather`).
fn gather_table(quick: bool) {
    use galerkin_radiosity::hierarchy::update::update_frame;
    use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
    let (frames, runs) = if quick { (4, 1) } else { (24, 3) };
    let settings = Settings { basis_order: 2, corner_gather: true, ..Settings::default() };
    let scene = scenes::cornell_box_moving_light(if quick { 6 } else { 14 }, frames, settings);
    let names = [
        "flat, the default method",
        "hierarchy, the gather kept (the default)",
        "hierarchy, gathered afresh",
    ];
    // Per method: each updated frame's seconds and its gather's, and the sources kept and computed.
    let mut frame_s = vec![Vec::new(); 3];
    let mut gather_s = vec![Vec::new(); 3];
    let mut sources = [[0u64; 2]; 3];
    for run in 0..runs {
        for k in 0..3 {
            let k = (k + run) % 3;
            if k == 0 {
                let mut session = Session::new(scene.clone(), Method::Incremental).unwrap();
                for f in scene.frames.0..=scene.frames.1 {
                    let s = session.solve_frame(f as f64, &no_progress).unwrap();
                    if f > scene.frames.0 {
                        assert!(!s.full_rebuild, "flat frame {f} was built afresh");
                        frame_s[0].push(s.seconds);
                        gather_s[0].push(s.gather_seconds);
                    }
                }
                continue;
            }
            let hs = HierarchySettings {
                keep_pair_tree: true,
                keep_gather: k == 1,
                ..HierarchySettings::of(&scene.settings)
            };
            let mut h = solve_frame(&scene, scene.frames.0 as f64, &hs, &no_progress).unwrap();
            for f in scene.frames.0 + 1..=scene.frames.1 {
                let t = std::time::Instant::now();
                let next = update_frame(&mut h, &scene, f as f64, &hs, &no_progress).unwrap();
                frame_s[k].push(t.elapsed().as_secs_f64());
                let st = &next.stats;
                assert!(st.updated, "frame {f} was not updated");
                gather_s[k].push(st.gather_seconds);
                sources[k][0] += st.gather_kept;
                sources[k][1] += st.gather_computed;
                h = next;
            }
        }
    }
    println!(
        "\nThe moving-light box ({} patches, order 2, the corner gather on), {frames} frames per run, the three \
         alternated over {runs} runs; seconds per updated frame over every run's frames 2..{frames}, {} threads:\n",
        scene.face_count(),
        rayon::current_num_threads()
    );
    println!(
        "| method | median s/frame | p25 | p75 | of it the gather (median) | sources taken from the frame before |"
    );
    println!("|---|---|---|---|---|---|");
    for k in 0..3 {
        let [p25, median, p75] = [0.25, 0.5, 0.75].map(|q| quantile(&mut frame_s[k], q));
        let g = quantile(&mut gather_s[k], 0.5);
        let [kept, computed] = sources[k];
        let share = match k {
            0 => "-".to_owned(),
            _ => format!("{:.0}%", 100.0 * kept as f64 / (kept + computed).max(1) as f64),
        };
        println!("| {} | {median:.4} | {p25:.4} | {p75:.4} | {g:.4} | {share} |", names[k]);
    }
}

/// The flat methods side by side: docs/benchmarks.md's "animation" block.
fn flat_table(settings: &Settings, quick: bool) {
    let frames = if quick { 4 } else { 48 };
    // The seed's savings for its two scenes (its Fig. 5), beside ours.
    let papers = ["65%", "61%", ""];
    // The caption, then the table: docs/benchmarks.md's "animation" block (scripts/regenerate_docs.py).
    println!(
        "The seed's scenes and the moving-light box: {frames} frames, order 2, visibility on, corner gather \
         off, the three methods one after the other, means over frames 2..{frames}, {} threads:\n",
        rayon::current_num_threads()
    );
    println!(
        "| scene | patches | first frame s | series s/frame | exact s/frame | full s/frame | saving vs full | x full | x exact | links/frame by series / recomputed | paper's saving |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for ((name, scene), paper) in bench_scenes(settings, quick, frames).into_iter().zip(papers) {
        let inc = run(&scene, Method::Incremental);
        let exact = run(&scene, Method::Exact);
        let full = run(&scene, Method::Full);
        println!(
            "| {name} | {} | {:.2} | {:.3} | {:.3} | {:.3} | {:.0}% | {:.1}x | {:.1}x | {:.0} / {:.0} | {paper} |",
            scene.face_count(),
            inc.first,
            inc.mean,
            exact.mean,
            full.mean,
            100.0 * (1.0 - inc.mean / full.mean),
            full.mean / inc.mean,
            exact.mean / inc.mean,
            inc.series,
            inc.recomputed,
        );
    }
}

/// The hierarchy's frames: docs/benchmarks.md's "animation-hierarchy" block.
fn hierarchy_table(settings: &Settings, quick: bool) {
    let hframes = if quick { 4 } else { 16 };
    let mut hcases = bench_scenes(settings, quick, hframes);
    hcases.push(("monastery decimated, moving light (order 1)", monastery_moving_light(hframes)));
    println!(
        "\nThe hierarchy (issue 21): the same scenes over {hframes} frames, order 2, corner gather off, each frame \
         updated from the one before, then solved from scratch, means over frames 2..{hframes}; rms is the worst \
         frame's face means against the fresh frame's, of their peak; an updated frame's time split into linking \
         (of it, computing the couplings: the most the seed's series could save) and the Jacobi solve, with its \
         sweeps against a fresh frame's; the last frame's links, updated (the pair tree kept, so updates \
         coarsen) and fresh:\n"
    );
    println!(
        "| scene | patches | first frame s | updated s/frame | link s (couplings) | solve s | sweeps (fresh) | from scratch s/frame | x faster | links kept / relinked | last frame's links (fresh) | worst rms vs fresh |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, scene) in hcases {
        let h = run_hierarchy(&scene);
        println!(
            "| {name} | {} | {:.2} | {:.3} | {:.3} ({:.3}) | {:.3} | {:.1} ({:.1}) | {:.3} | {:.1}x | {:.0} / {:.0} of {:.0} | {} ({}) | {:.2}% |",
            scene.face_count(),
            h.first,
            h.updated,
            h.link,
            h.compute,
            h.solve,
            h.sweeps,
            h.fresh_sweeps,
            h.fresh,
            h.fresh / h.updated,
            h.kept,
            h.touched,
            h.links,
            h.last_links,
            h.last_fresh_links,
            100.0 * h.worst_rms,
        );
    }
}
