//! The corner gather on real meshes (issue 20, item 5): `cargo bench --bench gather [-- --quick]
//! [-- --hierarchy]`, with `GALERKIN_CROPS=a.obj,b.obj` (crops of the full monastery) and
//! `GALERKIN_MONASTERY=path/to/samurai_monastry.obj` the hierarchy's gather on larger meshes too.
//!
//! Two tables. The flat path's (the scenes of tests/data/real at their own settings, order 2,
//! the path the CLI and the add-on take by default), one frame: the kernel, the solve and the
//! corner gather timed apart, with the gather's corner points and (point, source) moments. Then
//! the hierarchy's gather alone (`src/hierarchy/gather/`) on meshes of growing size: the links
//! and solve first (not timed with it), then the gather, and where it takes minutes at most the
//! exhaustive gather (every source from the point with its own rays) on the same solution, with
//! the difference between the two. Each case runs in a child process of this binary
//! (`common/child.rs`), so that its peak RSS is its own. `--hierarchy` prints the second table
//! only. `GALERKIN_GATHER_DUMP=file` with `--hierarchy-case path fast|exhaustive` writes the fast
//! gather's corners (and the exhaustive one's to `file.exhaustive`), and `--diff a b` compares two such files (a change's corners against the old ones').

use std::time::Instant;

use galerkin_radiosity::gather::CornerValues;
use galerkin_radiosity::hierarchy::gather::{self, Mode};
use galerkin_radiosity::hierarchy::{HierarchySettings, Lighting, solve_frame};
use galerkin_radiosity::scene::Scene;
use galerkin_radiosity::scene::json::read_scene;
use galerkin_radiosity::system::{System, no_progress};

#[path = "common/child.rs"]
mod common_child;
#[path = "common/obj.rs"]
mod obj;
#[path = "common/rss.rs"]
mod rss;
use rss::peak_rss_mib;

/// One scene on the flat path, in this (child) process: prints `faces kernel_s solve_s gather_s
/// points moments`.
fn run_case(path: &str) {
    let scene = read_scene(std::path::Path::new(path)).unwrap();
    let t = Instant::now();
    let mut sys = System::build(&scene, 1.0, &no_progress).unwrap();
    let kernel = t.elapsed().as_secs_f64();
    let t = Instant::now();
    sys.solve(scene.settings.tolerance, &|| false).unwrap();
    let solve = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let g = sys.gather_corners(&scene, 1.0, &no_progress).unwrap();
    let gather = t.elapsed().as_secs_f64();
    println!("{} {kernel} {solve} {gather} {} {}", scene.face_count(), g.points, g.moments);
    eprintln!("peak {}", peak_rss_mib());
}

/// A hierarchy case's scene: a scene file of tests/data/real at order 1 (as the hierarchy
/// bench's real-mesh table runs them), or an OBJ under a light.
fn hierarchy_scene(path: &str) -> Scene {
    if path.ends_with(".obj") {
        return obj::obj_under_a_light(path, false);
    }
    let mut scene = read_scene(std::path::Path::new(path)).unwrap();
    scene.settings.basis_order = 1;
    scene.settings.corner_gather = false;
    scene
}

/// The hierarchy's gather of one scene, in this (child) process; `exhaustive` also runs the
/// exhaustive gather on the same solution. Prints `faces links link_and_solve_s points fast_s
/// fast_rays fast_shafts exhaustive_s exhaustive_rays rms max` (the exhaustive columns and the
/// difference NaN without it): rays and shaft queries summed over the points; the difference
/// of the fast corners from the exhaustive ones as a relative RMS (over every corner, against
/// their mean) and the largest (against the brightest corner), on the mean of the channels.
fn run_hierarchy_case(path: &str, exhaustive: bool) {
    let scene = hierarchy_scene(path);
    let t = Instant::now();
    let h = solve_frame(&scene, 0.0, &HierarchySettings::of(&scene.settings), &no_progress).unwrap();
    let solved = t.elapsed().as_secs_f64();
    let lit = Lighting::new(&scene, 0.0, &h.hierarchy.tree.faces);
    let inputs = gather::Inputs::new(&h.hierarchy, &h.state, &lit);
    let run = |mode| {
        let t = Instant::now();
        let g = gather::corners_with(&inputs, &scene, 0.0, &no_progress, mode).unwrap();
        (t.elapsed().as_secs_f64(), g)
    };
    let (fast_s, fast) = run(Mode::Fast);
    if let Ok(dump) = std::env::var("GALERKIN_GATHER_DUMP") {
        write_corners(&dump, &fast.radiosity);
    }
    let c = &fast.counts;
    let mut line =
        format!("{} {} {solved} {} {fast_s} {} {}", h.stats.faces, h.stats.links, c.points, c.rays, c.shafts);
    if exhaustive {
        let (slow_s, slow) = run(Mode::Exhaustive);
        if let Ok(dump) = std::env::var("GALERKIN_GATHER_DUMP") {
            write_corners(&format!("{dump}.exhaustive"), &slow.radiosity);
        }
        let (rms, max) = difference(&fast.radiosity, &slow.radiosity);
        line += &format!(" {slow_s} {} {rms} {max}", slow.counts.rays);
    } else {
        line += " NaN NaN NaN NaN";
    }
    println!("{line}");
    eprintln!("link s {:.1}, solve s {:.1}, {c:?}", h.stats.link_seconds, h.stats.solve_seconds);
    eprintln!("peak {}", peak_rss_mib());
}

/// The corners' `B` to `path` (little-endian `f64`s, object by object, corner by corner, `r g b`),
/// for `--diff` between two builds (`GALERKIN_GATHER_DUMP`).
fn write_corners(path: &str, values: &CornerValues) {
    let bytes: Vec<u8> = values.iter().flatten().flatten().flat_map(|x| x.to_le_bytes()).collect();
    std::fs::write(path, bytes).unwrap_or_else(|e| panic!("{path}: {e}"));
}

/// [`write_corners`]' file read back, as one object.
fn read_corners(path: &str) -> CornerValues {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let x: Vec<f64> = bytes.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap())).collect();
    vec![x.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()]
}

/// `got` against `want` per corner (the mean of the channels): the RMS difference over the mean
/// of `want`, and the largest difference over its largest value.
fn difference(got: &CornerValues, want: &CornerValues) -> (f64, f64) {
    let lum = |v: &[f64; 3]| (v[0] + v[1] + v[2]) / 3.0;
    let (mut sq, mut sum, mut peak, mut worst, mut n) = (0.0, 0.0, 0.0f64, 0.0f64, 0usize);
    for (g, w) in got.iter().flatten().zip(want.iter().flatten()) {
        let (g, w) = (lum(g), lum(w));
        sq += (g - w).powi(2);
        sum += w;
        peak = peak.max(w);
        worst = worst.max((g - w).abs());
        n += 1;
    }
    ((sq / n as f64).sqrt() / (sum / n as f64), worst / peak)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--case") {
        run_case(&args[i + 1]);
        return;
    }
    if let Some(i) = args.iter().position(|a| a == "--diff") {
        // `--diff got want`: two dumps of the same scene's fast corners (GALERKIN_GATHER_DUMP).
        let (rms, max) = difference(&read_corners(&args[i + 1]), &read_corners(&args[i + 2]));
        println!("difference: {:.3}% RMS, {:.3}% of the peak at worst", 100.0 * rms, 100.0 * max);
        return;
    }
    if let Some(i) = args.iter().position(|a| a == "--hierarchy-case") {
        run_hierarchy_case(&args[i + 1], args[i + 2] == "exhaustive");
        return;
    }
    let quick = args.iter().any(|a| a == "--quick");
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/real");
    if !args.iter().any(|a| a == "--hierarchy") {
        flat_table(dir, quick);
    }
    hierarchy_table(dir, quick);
}

/// The flat path's table: docs/benchmarks.md's "gather-real" block.
fn flat_table(dir: &str, quick: bool) {
    // The table after its caption (scripts/regenerate_docs.py).
    println!(
        "Real meshes (tests/data/real) at their own settings (order 2, flat), one frame, {} threads:\n",
        rayon::current_num_threads()
    );
    println!("| scene | faces | kernel s | solve s | gather s | corner points | moments | peak RSS MiB |");
    println!("|---|---|---|---|---|---|---|---|");
    // The reduced case keeps the bunny only (a few seconds); the monastery's gather takes about a
    // minute.
    let real: &[(&str, &str)] = if quick {
        &[("bunny scene", "bunny_scene.json")]
    } else {
        &[("monastery decimated", "monastery_scene.json"), ("bunny scene", "bunny_scene.json")]
    };
    for &(name, file) in real {
        let case = format!("{dir}/{file}");
        let Some((v, peak)) = common_child::child(&["--case", &case]) else { continue };
        println!(
            "| {name} | {} | {:.2} | {:.2} | {:.2} | {} | {} | {peak:.0} |",
            v[0], v[1], v[2], v[3], v[4], v[5]
        );
    }
}

/// Crops with fewer faces than this also run the exhaustive gather (it took over 28 minutes on
/// the full monastery and about 5 on the 10k crop).
const EXHAUSTIVE_FACES: usize = 15_000;

/// The hierarchy's gather on meshes of growing size (not yet a generated block of
/// docs/benchmarks.md).
fn hierarchy_table(dir: &str, quick: bool) {
    println!(
        "\nThe hierarchy's corner gather alone (`src/hierarchy/gather/`), order 1, accuracy {:e}, {} \
         threads, after the links and solve; beside it the exhaustive gather (every source from \
         the point with its own rays) on the same solution where it takes minutes at most; \
         difference: the fast corners' from the exhaustive ones, RMS over their mean and largest \
         over the brightest; peak RSS of the whole case:\n",
        galerkin_radiosity::scene::Settings::default().accuracy,
        rayon::current_num_threads()
    );
    println!(
        "| scene | faces | links | corners | gather s | rays per corner | shafts per corner | exhaustive s \
         | exhaustive rays per corner | speed-up | difference RMS | difference max | peak RSS MiB |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut cases: Vec<(String, String, bool)> =
        vec![("bunny scene".into(), format!("{dir}/bunny_scene.json"), true)];
    if !quick {
        cases.push(("monastery decimated".into(), format!("{dir}/monastery_scene.json"), true));
        // Crops of the full monastery (the faces whose centroid lies in a centre box) and the
        // full model, under the OBJ light.
        let crops = std::env::var("GALERKIN_CROPS").unwrap_or_default();
        for path in crops.split(',').filter(|p| !p.is_empty()) {
            let faces = std::fs::read_to_string(path)
                .map_or(usize::MAX, |t| t.lines().filter(|l| l.starts_with("f ")).count());
            let name = std::path::Path::new(path).file_stem().unwrap().to_string_lossy().into_owned();
            cases.push((format!("monastery crop ({name}.obj)"), path.into(), faces < EXHAUSTIVE_FACES));
        }
        if let Ok(path) = std::env::var("GALERKIN_MONASTERY") {
            cases.push(("monastery, full".into(), path, false));
        }
    }
    for (name, path, exhaustive) in cases {
        let mode = if exhaustive { "exhaustive" } else { "fast" };
        let Some((v, peak)) = common_child::child(&["--hierarchy-case", &path, mode]) else { continue };
        let points = v[3];
        let per = |x: f64| x / points;
        let or_dash = |x: f64, f: &dyn Fn(f64) -> String| if x.is_nan() { "-".to_string() } else { f(x) };
        println!(
            "| {name} | {} | {} | {} | {:.2} | {:.0} | {:.1} | {} | {} | {} | {} | {} | {peak:.0} |",
            v[0],
            v[1],
            points,
            v[4],
            per(v[5]),
            per(v[6]),
            or_dash(v[7], &|x| format!("{x:.2}")),
            or_dash(v[8], &|x| format!("{:.0}", per(x))),
            or_dash(v[7], &|x| format!("{:.1}x", x / v[4])),
            or_dash(v[9], &|x| format!("{:.2}%", 100.0 * x)),
            or_dash(v[10], &|x| format!("{:.2}%", 100.0 * x)),
        );
    }
}
