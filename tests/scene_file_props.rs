//! Property test of the scene file through the whole bake (issue 23's fuzz item): random small
//! rooms with random placements (scaled to 0, singular, translated or scaled past what f64
//! resolves, keyed to any of those at a frame) and emissions (up to past f32), parsed and baked
//! over three frames. Every case either bakes with every value finite and >= 0, or fails with a
//! one-line message; none panics.
//!
//! 64 cases by default (a few seconds); `PROPTEST_CASES=2000 cargo test --release --test
//! scene_file_props -- --nocapture` for more; it prints how many baked, how many were refused and
//! how many gave a non-finite or negative value (must be 0).

use std::sync::atomic::{AtomicUsize, Ordering};

use galerkin_radiosity::scene::json::parse_scene;
use galerkin_radiosity::session::{Method, Session};
use galerkin_radiosity::system::no_progress;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

static BAKED: AtomicUsize = AtomicUsize::new(0);
static REFUSED: AtomicUsize = AtomicUsize::new(0);

/// A row-major 4x4 placement: mostly near identity, sometimes degenerate or extreme.
fn matrix() -> impl Strategy<Value = [f64; 16]> {
    let extreme = prop::sample::select(vec![0.0, 1e-300, 1e-9, 1e9, 1e13, 1e17, 1e300, -1e300]);
    prop_oneof![
        6 => (-0.5f64..0.5, -0.5f64..0.5, -0.5f64..0.5, 0.5f64..1.5).prop_map(|(x, y, z, s)| {
            [s, 0., 0., x, 0., s, 0., y, 0., 0., s, z, 0., 0., 0., 1.]
        }),
        1 => extreme.clone().prop_map(|s| [s, 0., 0., 0., 0., s, 0., 0., 0., 0., s, 0., 0., 0., 0., 1.]),
        1 => extreme.prop_map(|t| [1., 0., 0., t, 0., 1., 0., t, 0., 0., 1., t, 0., 0., 0., 1.]),
        1 => prop::array::uniform16(-2.0f64..2.0),
    ]
}

fn emission() -> impl Strategy<Value = f64> {
    prop_oneof![8 => 0.0f64..20.0, 1 => prop::sample::select(vec![1e29, 1e30, 1e31, 1e39, 3.4e38])]
}

/// A quad inside the unit box, sometimes non-planar.
fn quad() -> impl Strategy<Value = [[f64; 3]; 4]> {
    prop::array::uniform4(prop::array::uniform3(0.0f64..1.0))
}

/// A quad's vertices, its matrix, and the matrix it is keyed to at frame 3 (if animated).
type Quad = ([[f64; 3]; 4], [f64; 16], Option<[f64; 16]>);

#[derive(Clone, Debug)]
struct Case {
    order: usize,
    light: f64,
    quads: Vec<Quad>,
}

fn case() -> impl Strategy<Value = Case> {
    (0usize..=2, emission(), prop::collection::vec((quad(), matrix(), prop::option::of(matrix())), 1..4))
        .prop_map(|(order, light, quads)| Case { order, light, quads })
}

fn scene_json(c: &Case) -> String {
    let mut objects = vec![
        serde_json::json!({"name": "Floor", "vertices": [[0,0,0],[1,0,0],[1,1,0],[0,1,0]], "faces": [[0,1,2,3]]}),
        serde_json::json!({"name": "Light", "vertices": [[0,0,1],[0,1,1],[1,1,1],[1,0,1]], "faces": [[0,1,2,3]], "material": 1}),
    ];
    for (k, (v, m, key)) in c.quads.iter().enumerate() {
        let mut o =
            serde_json::json!({"name": format!("Quad{k}"), "vertices": v, "faces": [[0,1,2,3]], "matrix": m});
        if let Some(key) = key {
            o["animation"] = serde_json::json!([{"frame": 1, "matrix": m}, {"frame": 3, "matrix": key}]);
        }
        objects.push(o);
    }
    serde_json::json!({
        "version": 1, "settings": {"basis_order": c.order}, "frames": [1, 3],
        "materials": [{"name": "white", "reflectance": [0.6, 0.6, 0.6]},
                      {"name": "light", "reflectance": [0.5, 0.5, 0.5], "emission": [c.light, c.light, c.light]}],
        "objects": objects,
    })
    .to_string()
}

fn run(c: &Case) -> Result<(), TestCaseError> {
    let scene = match parse_scene(&scene_json(c)) {
        Ok(s) => s,
        Err(e) => {
            let m = e.to_string();
            prop_assert!(!m.is_empty() && !m.contains('\n'), "{m}");
            REFUSED.fetch_add(1, Ordering::Relaxed);
            return Ok(());
        }
    };
    let mut session =
        Session::new(scene, Method::Incremental).map_err(|e| TestCaseError::fail(e.to_string()))?;
    for frame in 1..=3 {
        match session.solve_frame(f64::from(frame), &no_progress) {
            Ok(_) => {
                for r in session.face_results().map_err(|e| TestCaseError::fail(e.to_string()))? {
                    for v in r.face_radiosity.iter().chain(&r.corner_radiosity).flatten() {
                        prop_assert!(v.is_finite() && *v >= 0.0, "frame {frame} {}: {v}", r.name);
                    }
                }
            }
            Err(e) => {
                let m = e.to_string();
                prop_assert!(!m.contains('\n') && !m.contains("internal"), "{m}");
                REFUSED.fetch_add(1, Ordering::Relaxed);
                return Ok(());
            }
        }
    }
    BAKED.fetch_add(1, Ordering::Relaxed);
    Ok(())
}

#[test]
fn random_scene_files_bake_finite_or_fail_in_one_line() {
    let cases = std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(64);
    let mut runner = TestRunner::new(Config { cases, failure_persistence: None, ..Config::default() });
    runner.run(&case(), |c| run(&c)).unwrap();
    println!(
        "scene file cases: {cases}, baked {}, refused {}, non-finite or negative values 0, panics 0",
        BAKED.load(Ordering::Relaxed),
        REFUSED.load(Ordering::Relaxed)
    );
}
