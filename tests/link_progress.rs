//! The link phase's progress follows its work (`PairSpace` in src/hierarchy/refine/descent.rs):
//! on the decimated monastery's first link round, the share reported when half the chunks of
//! links are computed is near a half, a quarter's below a half. Not timed: the reports come one
//! before each chunk of links computed, in an order that is the same for every thread count.

use std::sync::Mutex;

use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
use galerkin_radiosity::scene::json::read_scene;

/// The first link round's reports, scaled so that its last is 1 (the session maps a round onto
/// its own part of the "links" stage), in the order they came: one before each chunk of links
/// computed.
fn first_round(scene: &str) -> Vec<f64> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    let mut scene = read_scene(&dir.join(scene)).unwrap();
    scene.settings.corner_gather = false;
    let seen = Mutex::new(Vec::<(f64, String)>::new());
    let progress = |f: f64, stage: &str| {
        seen.lock().unwrap().push((f, stage.to_owned()));
        true
    };
    solve_frame(&scene, 0.0, &HierarchySettings::of(&scene.settings), &progress).unwrap();
    let seen = seen.into_inner().unwrap();
    let round: Vec<f64> = seen.iter().take_while(|(_, s)| s == "links").map(|&(f, _)| f).collect();
    let last = *round.last().unwrap();
    assert!(round.len() > 20 && last > 0.0, "{} reports, the last {last}", round.len());
    assert!(round.windows(2).all(|w| w[0] <= w[1]), "the progress fell back");
    round.iter().map(|f| f / last).collect()
}

#[test]
fn the_link_rounds_progress_follows_the_links_computed() {
    let round = first_round("monastery_scene.json");
    let at = |share: f64| round[((round.len() - 1) as f64 * share).round() as usize];
    let (quarter, half) = (at(0.25), at(0.5));
    // (Counted in pairs of faces: 0.58 and 0.77; by the links expected, 0.36 and 0.64; with
    // the descents, each batch reported evenly over its chunks: 0.34 and 0.57.)
    assert!((0.3..=0.72).contains(&half), "half the links computed, the progress said {half:.3}");
    assert!(quarter <= 0.5, "a quarter of the links computed, the progress said {quarter:.3}");
}
