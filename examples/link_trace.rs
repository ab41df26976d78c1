//! The progress a hierarchical first frame's first link round reports against its time: `cargo run
//! --release --example link_trace SCENE.json` (the corner gather off; `TRACE=1` prints every report
//! on stderr). The round's share is its reports scaled by its last (the session maps the round onto
//! a part of the "links" stage); a report comes before each chunk of links computed.
use galerkin_radiosity::scene::json::read_scene;
use galerkin_radiosity::session::{Method, Session};
use std::sync::Mutex;
use std::time::Instant;

fn main() {
    let path = std::env::args().nth(1).expect("SCENE.json");
    let mut scene = read_scene(std::path::Path::new(&path)).unwrap();
    scene.settings.corner_gather = false;
    let first = scene.frames.0;
    let mut session = Session::new(scene, Method::Hierarchical).unwrap();
    session.set_still();
    let log = Mutex::new(Vec::<(f64, f64, String)>::new());
    let t0 = Instant::now();
    let progress = |f: f64, stage: &str| {
        log.lock().unwrap().push((t0.elapsed().as_secs_f64(), f, stage.to_string()));
        true
    };
    let stats = session.solve_frame(first as f64, &progress).unwrap();
    let total = t0.elapsed().as_secs_f64();
    let log = log.into_inner().unwrap();
    // The first round of links: "links" reports before the first "hierarchy" one.
    let end = log.iter().position(|(_, _, s)| s == "hierarchy").unwrap_or(log.len());
    let round: Vec<_> = log[..end].iter().filter(|(_, _, s)| s == "links").collect();
    let (ts, te) = (round.first().unwrap().0, round.last().unwrap().0);
    println!(
        "frame {total:.1} s, pairs {}; first link round {:.1}-{:.1} s, {} reports",
        stats.pairs,
        ts,
        te,
        round.len()
    );
    let last = round.last().unwrap().1;
    println!("| time share of the round | chunks of links computed | round fraction said |");
    println!("|---|---|---|");
    for share in [0.1, 0.25, 0.5, 0.75, 0.9, 0.99] {
        let t = ts + share * (te - ts);
        let i = round.iter().rposition(|r| r.0 <= t).unwrap();
        let r = round[i];
        println!(
            "| {:.0}% ({:.1} s) | {:.1}% | {:.1}% |",
            share * 100.0,
            r.0 - ts,
            100.0 * i as f64 / round.len() as f64,
            100.0 * r.1 / last
        );
    }
    let worst = round
        .iter()
        .enumerate()
        .map(|(i, r)| (100.0 * r.1 / last - i as f64 / round.len() as f64 * 100.0).abs())
        .fold(0.0, f64::max);
    let worst_t =
        round.iter().map(|r| (100.0 * r.1 / last - (r.0 - ts) / (te - ts) * 100.0).abs()).fold(0.0, f64::max);
    println!(
        "largest gap between the fraction and the chunks' share {worst:.1} points, the time's share {worst_t:.1}"
    );
    if std::env::var("TRACE").is_ok() {
        for (t, f, s) in &log {
            eprintln!("{t:.3} {f:.5} {s}");
        }
    }
}
