//! Issue 23, item 1: a bake whose estimated memory is over the budget is refused at once, with
//! one line giving the estimate, the budget and what to change, through the CLI and the C ABI
//! (it used to abort in the allocator after 35-158 s, taking a host application with it).

use std::process::Command;

use galerkin_radiosity::budget;
use galerkin_radiosity::ffi::*;
use galerkin_radiosity::scene::{Material, Scene, Settings};
use galerkin_radiosity::scenes;

mod c_session;

/// Near the case (60,001 faces at order 2): a Cornell box of 100 x 100 patches per wall,
/// over 50,000 faces, whose links alone would take tens of terabytes.
fn huge() -> galerkin_radiosity::scene::Scene {
    scenes::cornell_box(100, Settings::default())
}

#[test]
fn the_cli_refuses_a_scene_over_the_default_budget() {
    let dir = std::env::temp_dir().join(format!("gr-budget-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("huge.json");
    let scene = huge();
    assert!(scene.face_count() >= 50_000);
    std::fs::write(&input, galerkin_radiosity::scene::json::scene_to_json(&scene)).unwrap();
    let out = dir.join("out.json");
    let run = |extra: &[&str]| {
        let mut args = vec!["bake", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "--quiet"];
        args.extend(extra);
        let o = Command::new(env!("CARGO_BIN_EXE_galerkin-radiosity")).args(&args).output().unwrap();
        (o.status.code().unwrap_or(-1), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    // Default budget (80% of MemAvailable): no machine has the terabytes the links would need.
    let (code, err) = run(&[]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("over the memory budget: this bake needs up to"), "{err}");
    assert!(err.contains("% of the memory available"), "{err}");
    assert!(err.contains("raise memory_budget_mb"), "{err}");
    // The hierarchy's own estimate fits where the flat one does not: the line names it.
    let planned = budget::hierarchical_estimate(&scene, 1).total().div_ceil(1 << 20);
    assert!(budget::check_hierarchical(&scene, 1).is_ok());
    assert!(err.contains(&format!("; or bake with --hierarchy, which plans for {planned} MB here")), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!out.exists());
    // An explicit budget is named as such; the hierarchy does not fit 64 MB, and is not named.
    let (code, err) = run(&["--memory-budget", "64"]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("but the budget is 64 MB (settings.memory_budget_mb)"), "{err}");
    assert!(!err.contains("--hierarchy"), "{err}");
    let (code, err) = run(&["--memory-budget", "lots"]);
    assert_eq!(code, 2, "{err}");
}

/// The hierarchical method has its own estimate (links per face, nodes), checked as the flat
/// one is: over the budget, refused in one line before anything is built (without the check the
/// CLI went on to link 60,000 faces).
#[test]
fn the_cli_refuses_a_hierarchical_bake_over_its_budget() {
    let dir = std::env::temp_dir().join(format!("gr-budget-h-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("huge.json");
    std::fs::write(&input, galerkin_radiosity::scene::json::scene_to_json(&huge())).unwrap();
    let out = dir.join("out.json");
    // Not --quiet: a bake that started would print its progress.
    let o = Command::new(env!("CARGO_BIN_EXE_galerkin-radiosity"))
        .args(["bake", input.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .args(["--hierarchy", "--memory-budget", "64"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("over the memory budget: this hierarchical bake may need up to"), "{err}");
    assert!(err.contains("but the budget is 64 MB (settings.memory_budget_mb)"), "{err}");
    assert!(err.contains("a larger settings.accuracy"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!out.exists());
    // A tighter accuracy plans for more links.
    let mut scene = huge();
    let loose = budget::hierarchical_estimate(&scene, 1);
    scene.settings.accuracy = 1e-4;
    let tight = budget::hierarchical_estimate(&scene, 1);
    assert!(tight.links > 5 * loose.links, "{loose:?} {tight:?}");
}

/// A flat bake that fits its budget but has many faces is told of `--hierarchy` once, on stderr,
/// and bakes; `--quiet` and the hierarchy itself say nothing.
#[test]
fn the_cli_warns_a_large_flat_bake_of_the_hierarchy() {
    let dir = std::env::temp_dir().join(format!("gr-budget-warn-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("large.json");
    // A floor of 45 x 45 faces under a light: over 2,000 faces, but only the light's pairs (the
    // floor's faces do not see each other), so each bake takes well under a second.
    let p = glam::DVec3::new;
    let floor =
        scenes::subdivided_quad("floor", [p(0., 0., 0.), p(1., 0., 0.), p(1., 1., 0.), p(0., 1., 0.)], 45, 0);
    let light = scenes::subdivided_quad(
        "light",
        [p(0.4, 0.4, 1.), p(0.4, 0.6, 1.), p(0.6, 0.6, 1.), p(0.6, 0.4, 1.)],
        1,
        1,
    );
    let materials = vec![
        Material { name: "grey".into(), reflectance: [0.5; 3], emission: [0.0; 3] },
        Material { name: "light".into(), reflectance: [0.0; 3], emission: [5.0; 3] },
    ];
    let settings = Settings { corner_gather: false, ..Settings::default() };
    let scene = Scene::new(settings, (1, 1), materials, vec![vec![]; 2], vec![floor, light]).unwrap();
    assert!(scene.face_count() >= 2000, "{}", scene.face_count());
    std::fs::write(&input, galerkin_radiosity::scene::json::scene_to_json(&scene)).unwrap();
    let out = dir.join("out.json");
    let run = |extra: &[&str]| {
        let mut args = vec!["bake", input.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend(extra);
        let o = Command::new(env!("CARGO_BIN_EXE_galerkin-radiosity")).args(&args).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let warning = format!(
        "warning: {} faces: the flat methods link every pair of faces, so their memory and time grow with the \
         square of the face count; --hierarchy grows about linearly",
        scene.face_count()
    );
    let err = run(&[]);
    assert_eq!(
        err.lines().filter(|l| l.starts_with("warning: ")).collect::<Vec<_>>(),
        [warning.as_str()],
        "{err}"
    );
    assert!(out.exists());
    assert!(!run(&["--quiet"]).contains("warning"));
    assert!(!run(&["--hierarchy"]).contains("--hierarchy grows"));
}

#[test]
fn the_c_abi_refuses_it_in_gr_session_new() {
    let scene = huge();
    let mut settings = GrSettings::default();
    assert_eq!(unsafe { gr_settings_default(&mut settings) }, GrStatus::Ok);
    assert_eq!(settings.memory_budget_mb, 0);
    settings.memory_budget_mb = 1024;
    let (status, out) = c_session::new_session(&scene, &settings);
    assert_eq!(status, GrStatus::InvalidScene);
    assert!(out.is_null());
    let mut buf = vec![0u8; 1024];
    let n = unsafe { gr_last_error(buf.as_mut_ptr().cast(), buf.len()) };
    let msg = String::from_utf8_lossy(&buf[..n.min(1023)]).into_owned();
    assert!(msg.contains("over the memory budget") && msg.contains("but the budget is 1024 MB"), "{msg}");
}

/// The estimate is an upper bound on what a real frame allocates (the links of a built Cornell
/// box are below half of it), and a bake inside its budget runs.
#[test]
fn a_scene_inside_its_budget_bakes() {
    let mut scene = scenes::cornell_box(3, Settings::default());
    let e = budget::estimate(&scene, 1);
    scene.settings.memory_budget_mb = e.total().div_ceil(1 << 20);
    budget::check(&scene, 1).unwrap();
    let mut session = galerkin_radiosity::session::Session::new(
        scene.clone(),
        galerkin_radiosity::session::Method::Incremental,
    )
    .unwrap();
    let stats = session.solve_frame(0.0, &galerkin_radiosity::system::no_progress).unwrap();
    assert!(stats.pairs as u64 <= (stats.elements as u64 * (stats.elements as u64 - 1)) / 2);
    // Keeping 10^5 frames' results does not fit in that budget.
    assert!(budget::check(&scene, 100_000).is_err());
}

/// The hierarchical estimate bounds what a real hierarchical frame's links hold (their records
/// and blocks, the incoming lists, the blocked and idle pairs), on a real mesh where nearly every
/// link is light and on a box where most are full, at orders 1 and 2.
#[test]
fn the_hierarchical_estimate_bounds_a_real_frames_links() {
    use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    let monastery = galerkin_radiosity::scene::json::read_scene(&dir.join("monastery_scene.json")).unwrap();
    let cornell = scenes::cornell_box(4, Settings::default());
    for mut scene in [monastery, cornell] {
        scene.settings.corner_gather = false;
        for order in [1, 2] {
            scene.settings.basis_order = order;
            let e = budget::hierarchical_estimate(&scene, 1);
            let hs = HierarchySettings::of(&scene.settings);
            let h = solve_frame(&scene, 0.0, &hs, &galerkin_radiosity::system::no_progress).unwrap();
            let kept = (h.hierarchy.blocked.len() + h.hierarchy.idle.len()) as u64 * 8;
            let held = h.stats.link_bytes as u64 + 16 * h.stats.links as u64 + kept;
            println!(
                "{} faces, order {order}: links hold {held} bytes, estimated {}",
                scene.face_count(),
                e.links
            );
            assert!(held <= e.links, "{} faces, order {order}: {held} > {}", scene.face_count(), e.links);
        }
    }
}

/// Past the estimate (a budget set far above what the process may have), the allocator's refusal
/// in the big arrays is an error with exit 1, not an abort: the CLI on a 1,456-face box at order 2
/// under a 300 MB address-space limit (`prlimit --as`; one thread, whose small allocations fit).
#[cfg(target_os = "linux")]
#[test]
fn an_allocation_refused_past_the_estimate_is_an_error_not_an_abort() {
    let dir = std::env::temp_dir().join(format!("gr-oom-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("box.json");
    let scene = scenes::cornell_box(16, Settings { basis_order: 2, ..Settings::default() });
    assert!(scene.face_count() >= 1400, "{}", scene.face_count());
    std::fs::write(&input, galerkin_radiosity::scene::json::scene_to_json(&scene)).unwrap();
    let out = dir.join("out.json");
    let o = Command::new("prlimit")
        .arg(format!("--as={}", 300_000_000))
        .arg(env!("CARGO_BIN_EXE_galerkin-radiosity"))
        .args(["bake", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "--quiet"])
        .args(["--threads", "1", "--memory-budget", "1000000"])
        .output()
        .expect("prlimit (util-linux) runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.starts_with("galerkin-radiosity: error: out of memory while building the "), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!out.exists());
}
