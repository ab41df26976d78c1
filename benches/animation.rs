//! Per-frame time of the animation methods (issue 3): `cargo bench --bench animation [-- --quick]`.
//!
//! For the seed's two scenes (Fig. 5a: a room, a ceiling light moving left and right, a blue
//! panel passing a wall light; Fig. 5b: a billiard table under a moving light) and the Cornell
//! box of ~1,000 patches with a moving light, all at basis order 2 with visibility: the first
//! frame (the one-time precomputation), and the mean of the following frames, for the default
//! method (series), `--exact` and `--full`, measured one after the other in one run. The paper's
//! Tables 1 and 2 report 65% and 61% per-frame savings over its Galerkin progressive method.

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

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    // The solver's methods side by side; the corner gather (the same work for every method) is
    // off here and reported by `gather_seconds` in a bake's frame stats.
    let settings = Settings { basis_order: 2, corner_gather: false, ..Settings::default() };
    let frames = if quick { 4 } else { 48 };
    let cases: Vec<(&str, Scene, &str)> = vec![
        ("Fig. 5a room", scenes::seed_room(if quick { 2.0 } else { 3.0 }, frames, settings.clone()), "65%"),
        (
            "Fig. 5b billiard",
            scenes::billiard(if quick { 1.5 } else { 2.5 }, frames, settings.clone()),
            "61%",
        ),
        (
            "Cornell box, moving light",
            scenes::cornell_box_moving_light(if quick { 6 } else { 14 }, frames, settings.clone()),
            "",
        ),
    ];
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
    for (name, scene, paper) in cases {
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
