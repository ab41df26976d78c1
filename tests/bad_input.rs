//! Bad scene files: a clear one-line error naming the object and face, exit code 1, no panic.

use std::process::Command;

fn bake(scene: &str) -> (i32, String) {
    let dir = std::env::temp_dir().join(format!("gr-bad-{}-{}", std::process::id(), scene.len()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("scene.json");
    std::fs::write(&input, scene).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_galerkin-radiosity"))
        .args(["bake", input.to_str().unwrap(), "-o", dir.join("out.json").to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn scene_with(object: &str, material: &str) -> String {
    format!(
        r#"{{"version": 1, "settings": {{"basis_order": 1}}, "frames": [1, 1],
            "materials": [{material}], "objects": [{object}]}}"#
    )
}

const MAT: &str = r#"{"name": "white", "reflectance": [0.5, 0.5, 0.5], "emission": [1, 1, 1]}"#;
const QUAD: &str =
    r#"{"name": "Floor", "vertices": [[0,0,0],[1,0,0],[1,1,0],[0,1,0]], "faces": [[0,1,2,3]]}"#;

#[test]
fn a_valid_scene_bakes() {
    let (code, err) = bake(&scene_with(QUAD, MAT));
    assert_eq!(code, 0, "{err}");
}

#[test]
fn each_bad_input_names_what_is_wrong() {
    let cases: Vec<(String, &str)> = vec![
        ("{not json".into(), "scene JSON"),
        (scene_with(&QUAD.replace("[1,1,0]", "[1,NaN,0]"), MAT), "scene JSON"),
        (
            scene_with(&QUAD.replace("[0,1,2,3]", "[0,1,2,9]"), MAT),
            "object \"Floor\" face 0: vertex index 9 out of range",
        ),
        (scene_with(&QUAD.replace("[0,1,2,3]", "[0,1]"), MAT), "object 0 \"Floor\" face 0: 2 vertices"),
        (
            scene_with(&QUAD.replace("}", r#", "material": 3}"#), MAT),
            "object \"Floor\": material 3 out of range",
        ),
        (
            scene_with(QUAD, &MAT.replace("[0.5, 0.5, 0.5]", "[0.5, 1.0, 0.5]")),
            "reflectance[1] = 1 is outside [0,1)",
        ),
        (scene_with(QUAD, &MAT.replace("[1, 1, 1]", "[1, -1, 1]")), "emission[1] = -1"),
        (scene_with(&QUAD.replace("[0,1,0]]", "[0,1e400,0]]"), MAT), "scene JSON"),
        (scene_with(QUAD, MAT).replace("\"basis_order\": 1", "\"basis_order\": 7"), "basis_order 7"),
        (
            scene_with(QUAD, MAT)
                .replace("\"basis_order\": 1", "\"basis_order\": 2, \"quadrature_order\": 2"),
            "settings.quadrature_order 2 must exceed settings.basis_order 2",
        ),
        (
            scene_with(QUAD, MAT).replace("\"basis_order\": 1", "\"basis_order\": 1, \"tolerence\": 1"),
            "unknown field `tolerence`",
        ),
    ];
    for (scene, want) in cases {
        let (code, err) = bake(&scene);
        assert_eq!(code, 1, "exit code for {want:?}: {err}");
        assert!(err.contains(want), "expected {want:?} in: {err}");
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn a_missing_file_is_an_error() {
    let out = Command::new(env!("CARGO_BIN_EXE_galerkin-radiosity"))
        .args(["bake", "/nonexistent/scene.json", "-o", "/tmp/x.json"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/scene.json"));
}

#[test]
fn zero_area_faces_are_skipped_with_a_warning() {
    let degenerate = r#"{"name": "Floor", "vertices": [[0,0,0],[1,0,0],[1,1,0],[0,1,0],[2,2,2]],
                         "faces": [[0,1,2,3],[4,4,4]]}"#;
    let (code, err) = bake(&scene_with(degenerate, MAT));
    assert_eq!(code, 0, "{err}");
    let (code, err) = {
        let dir = std::env::temp_dir().join(format!("gr-warn-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let input = dir.join("scene.json");
        std::fs::write(&input, scene_with(degenerate, MAT)).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_galerkin-radiosity"))
            .args(["bake", input.to_str().unwrap(), "-o", dir.join("out.json").to_str().unwrap()])
            .output()
            .unwrap();
        (out.status.code().unwrap(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    assert_eq!(code, 0);
    assert!(err.contains("1 zero-area face(s) skipped (first: object \"Floor\" face 1)"), "{err}");
}
