//! The corner gather on real meshes (issue 20, item 5): `cargo bench --bench gather [-- --quick]`.
//!
//! The scenes of tests/data/real at their own settings (order 2, the flat path the CLI and the
//! add-on take by default), one frame: the kernel, the solve and the corner gather timed apart,
//! with the gather's corner points and (point, source) moments. Each case runs in a child
//! process of this binary (`common/child.rs`), so that its peak RSS is its own.

use std::time::Instant;

use galerkin_radiosity::scene::json::read_scene;
use galerkin_radiosity::system::{System, no_progress};

#[path = "common/child.rs"]
mod common_child;
#[path = "common/rss.rs"]
mod rss;
use rss::peak_rss_mib;

/// One scene, in this (child) process: prints `faces kernel_s solve_s gather_s points moments`.
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

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--case") {
        run_case(&args[i + 1]);
        return;
    }
    let quick = args.iter().any(|a| a == "--quick");
    // The table after its caption: docs/benchmarks.md's "gather-real" block
    // (scripts/regenerate_docs.py).
    println!(
        "Real meshes (tests/data/real) at their own settings (order 2, flat), one frame, {} threads:\n",
        rayon::current_num_threads()
    );
    println!("| scene | faces | kernel s | solve s | gather s | corner points | moments | peak RSS MiB |");
    println!("|---|---|---|---|---|---|---|---|");
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/real");
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
