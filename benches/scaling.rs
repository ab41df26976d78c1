//! Benchmark tables (issue 2 and 3): `cargo bench --bench scaling [-- --quick]`.
//!
//! 1. Kernel build and solve of the Cornell box against patch count and basis order.
//! 2. Per-frame time of the demo animation: incremental (exact update) vs full recompute,
//!    measured side by side in one run.
//!
//! Prints markdown tables; the README quotes them with this command.

use std::time::Instant;

use galerkin_radiosity::scene::Settings;
use galerkin_radiosity::scenes;
use galerkin_radiosity::session::{Method, Session};
use galerkin_radiosity::system::{System, no_progress};

#[path = "common/rss.rs"]
mod rss;
use rss::peak_rss_mib;

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let threads = rayon::current_num_threads();
    println!("## Static Cornell box: kernel (with visibility) and solve, {threads} threads\n");
    println!(
        "| walls n x n | patches | order | pairs | link MiB | kernel s | solve s | total s | peak RSS MiB |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let sizes: &[usize] = if quick { &[4, 8] } else { &[4, 8, 14, 16] };
    for &n in sizes {
        let orders: &[usize] = if n >= 32 {
            &[0]
        } else if n >= 16 {
            &[0, 1]
        } else {
            &[0, 1, 2, 3]
        };
        let orders: Vec<usize> = if n == 14 { vec![2] } else { orders.to_vec() };
        for &order in &orders {
            let scene = scenes::cornell_box(n, Settings { basis_order: order, ..Settings::default() });
            let start = Instant::now();
            let mut sys = System::build(&scene, 1.0, &no_progress).unwrap();
            sys.solve(scene.settings.tolerance, &|| false).unwrap();
            println!(
                "| {n} | {} | {order} | {} | {:.1} | {:.2} | {:.2} | {:.2} | {:.0} |",
                sys.stats.elements,
                sys.stats.pairs,
                sys.stats.link_bytes as f64 / (1 << 20) as f64,
                sys.stats.kernel_seconds,
                sys.stats.solve_seconds,
                start.elapsed().as_secs_f64(),
                peak_rss_mib()
            );
        }
    }

    let (n, frames) = if quick { (6, 4) } else { (14, 8) };
    // The solver's methods; the corner gather (the same for both) is off, as in benches/animation.rs.
    let scene =
        scenes::cornell_box_animated(n, frames, Settings { corner_gather: false, ..Settings::default() });
    println!(
        "\n## Demo animation ({} patches, order 2, light and block moving): seconds per frame\n",
        scene.face_count()
    );
    println!("| frame | incremental (exact update) | links recomputed | full | speed-up |");
    println!("|---|---|---|---|---|");
    let mut inc = Session::new(scene.clone(), Method::Exact).unwrap();
    let mut full = Session::new(scene.clone(), Method::Full).unwrap();
    let (mut ti, mut tf) = (0.0, 0.0);
    for f in 1..=frames {
        let a = inc.solve_frame(f as f64, &no_progress).unwrap();
        let b = full.solve_frame(f as f64, &no_progress).unwrap();
        if f > 1 {
            ti += a.seconds;
            tf += b.seconds;
        }
        println!(
            "| {f} | {:.2} | {} | {:.2} | {:.1}x |",
            a.seconds,
            a.links_recomputed,
            b.seconds,
            b.seconds / a.seconds
        );
    }
    println!(
        "| mean of frames 2..{frames} | {:.2} | | {:.2} | {:.1}x |",
        ti / (frames - 1) as f64,
        tf / (frames - 1) as f64,
        tf / ti
    );
}
