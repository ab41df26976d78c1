//! Bad scene files: a clear one-line error naming the object and face, exit code 1, no panic.

use std::process::Command;

fn bake(scene: &str) -> (i32, String) {
    // A directory of its own per call: tests run in parallel, and two scenes of the same length
    // (a valid quad and one with a vertex index out of range) once shared one and raced.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("gr-bad-{}-{call}", std::process::id()));
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

/// A folder of its own for a test named `tag`, holding a valid one-quad scene file: the folder
/// and the file.
fn scene_in_temp_dir(tag: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("gr-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("scene.json");
    std::fs::write(&input, scene_with(QUAD, MAT)).unwrap();
    (dir, input)
}

/// Runs the CLI with `args`: exit code and stderr.
fn run(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_galerkin-radiosity")).args(args).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// Issue 23, item 4: spans and thread counts past their limits are usage errors (exit 2) or scene
/// errors (exit 1) at once, not a bake that runs forever or an internal error; an output into a
/// missing folder is refused before the bake, and a failed bake leaves an existing output as it
/// was.
#[test]
fn unbounded_work_and_bad_outputs_are_refused_before_baking() {
    let (dir, input) = scene_in_temp_dir("limits");
    let (input, out) = (input.to_str().unwrap().to_owned(), dir.join("out.json"));
    let out = out.to_str().unwrap();
    let cases: Vec<(Vec<&str>, i32, &str)> = vec![
        (vec!["--frames", "1:9223372036854775807"], 2, "more than the 100000 one bake may span"),
        (vec!["--frames", "-9223372036854775808:9223372036854775807"], 2, "100000"),
        (vec!["--frames", "5:1"], 2, "the first frame is after the last"),
        (vec!["--threads", "99999"], 2, "--threads 99999 is above 1024"),
    ];
    for (extra, code, want) in cases {
        let mut args = vec!["bake", &input, "-o", out, "--quiet"];
        args.extend(&extra);
        let (got, err) = run(&args);
        assert_eq!(got, code, "{extra:?}: {err}");
        assert!(err.contains(want), "{extra:?}: expected {want:?} in: {err}");
        assert!(!err.contains("internal"), "{err}");
    }
    // A scene file spanning 2^31 frames.
    let long = dir.join("long.json");
    std::fs::write(&long, scene_with(QUAD, MAT).replace("[1, 1]", "[1, 2147483648]")).unwrap();
    let (code, err) = run(&["bake", long.to_str().unwrap(), "-o", out, "--quiet"]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("frames [1, 2147483648]: 2147483648 frames, more than the 100000"), "{err}");
    // A missing folder.
    let missing = dir.join("no-such-folder").join("out.json");
    let (code, err) = run(&["bake", &input, "-o", missing.to_str().unwrap(), "--quiet"]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("no-such-folder does not exist"), "{err}");
    // A failed bake keeps what was there, and leaves no partial file.
    std::fs::write(out, "keep me").unwrap();
    std::fs::write(dir.join("bad.json"), scene_with(QUAD, &MAT.replace("[1, 1, 1]", "[1, -1, 1]"))).unwrap();
    let (code, err) = run(&["bake", dir.join("bad.json").to_str().unwrap(), "-o", out, "--quiet"]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(std::fs::read_to_string(out).unwrap(), "keep me");
    assert!(!dir.join("out.json.partial").exists());
    // And a good one replaces it.
    let (code, err) = run(&["bake", &input, "-o", out, "--quiet"]);
    assert_eq!(code, 0, "{err}");
    assert!(std::fs::read_to_string(out).unwrap().starts_with('{'));
}

/// An output that is not a regular file (`/dev/null`, a pipe) is written to as it is: the rename
/// that keeps a failed bake from touching a regular output would replace the pipe, or `/dev/null`
/// itself, with a file (it did, baking to `-o /dev/null` as root). Checked with a named pipe, read
/// while the bake writes it.
#[cfg(unix)]
#[test]
fn a_pipe_as_output_stays_a_pipe() {
    use std::os::unix::fs::FileTypeExt;
    let (dir, input) = scene_in_temp_dir("pipe");
    let pipe = dir.join("out.json");
    let _ = std::fs::remove_file(&pipe);
    let made = Command::new("mkfifo").arg(&pipe).status().expect("mkfifo runs");
    assert!(made.success());
    let reader = {
        let pipe = pipe.clone();
        std::thread::spawn(move || std::fs::read_to_string(pipe).unwrap())
    };
    let (code, err) = run(&["bake", input.to_str().unwrap(), "-o", pipe.to_str().unwrap(), "--quiet"]);
    assert_eq!(code, 0, "{err}");
    // Before the reader is joined: with the pipe replaced, it would wait on it for ever.
    assert!(std::fs::metadata(&pipe).unwrap().file_type().is_fifo(), "the pipe was replaced");
    let text = reader.join().unwrap();
    assert!(text.starts_with('{') && text.contains("\"frames\""), "{text}");
    assert!(!dir.join("out.json.partial").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
