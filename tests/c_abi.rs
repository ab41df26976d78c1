//! The C ABI (issue 4): a C program compiled against the checked-in header and linked to the
//! cdylib, and Rust-side checks that call the exported functions directly (cancel, lengths,
//! validation, panics, busy sessions).

use std::ffi::{CStr, c_char, c_void};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::ptr::{null, null_mut};
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use galerkin_radiosity::ffi::*;
use galerkin_radiosity::scene::{Scene, Settings};
use galerkin_radiosity::scenes;

// ---------------------------------------------------------------------------------------------
// The C program.

/// The directory of the cdylib this test run built. `cargo test` builds the library (crate types
/// cdylib + rlib) into `target/<profile>/deps/`, next to this test binary, but copies it up to
/// `target/<profile>/` only on `cargo build`; so deps/ first (always this build), then the
/// profile directory (from the binary's place, so any CARGO_TARGET_DIR works; else the
/// manifest's target/ for this profile).
fn cdylib_dirs() -> Vec<PathBuf> {
    let exe = std::env::current_exe().expect("test binary path");
    let deps = exe.parent().map(Path::to_path_buf);
    let profile = deps.as_deref().and_then(Path::parent).map(Path::to_path_buf).unwrap_or_else(|| {
        let profile = if cfg!(debug_assertions) { "debug" } else { "release" };
        Path::new(env!("CARGO_MANIFEST_DIR")).join("target").join(profile)
    });
    deps.into_iter().chain([profile]).collect()
}

fn cdylib_name() -> &'static str {
    if cfg!(target_os = "macos") {
        "libgalerkin_radiosity.dylib"
    } else if cfg!(windows) {
        "galerkin_radiosity.dll"
    } else {
        "libgalerkin_radiosity.so"
    }
}

/// Compiles `tests/c/NAME.c` against the checked-in header and the cdylib; returns the program.
fn compile_c(name: &str) -> PathBuf {
    let dirs = cdylib_dirs();
    let Some(dir) = dirs.iter().find(|d| d.join(cdylib_name()).is_file()).cloned() else {
        panic!(
            "{} not found in {:?}. `cargo test` builds it with the library (crate-type cdylib); \
             if it was removed, run `cargo build --lib` (add --release for a release test run) \
             and retry.",
            cdylib_name(),
            dirs
        );
    };
    println!("linking {}", dir.join(cdylib_name()).display());
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let exe = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let out = Command::new(&cc)
        .args(["-Wall", "-Wextra", "-Werror", "-std=c11"])
        .arg("-I")
        .arg(root.join("include"))
        .arg(root.join(format!("tests/c/{name}.c")))
        .arg("-o")
        .arg(&exe)
        .arg(format!("-L{}", dir.display()))
        .arg("-lgalerkin_radiosity")
        .arg("-lm")
        .arg(format!("-Wl,-rpath,{}", dir.display()))
        .output()
        .unwrap_or_else(|e| panic!("cannot run the C compiler `{cc}`: {e}"));
    assert!(
        out.status.success(),
        "compiling tests/c/{name}.c failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

#[test]
fn c_program_solves_two_patches() {
    let exe = compile_c("two_patches");
    let run = Command::new(&exe).output().expect("run two_patches");
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    println!("{stdout}{stderr}");
    assert!(run.status.success(), "two_patches failed: {stdout}{stderr}");
    assert!(stdout.contains("all checks passed"));
}

/// Issue 23: an allocation the machine refuses past the estimate is `GR_STATUS_OUT_OF_MEMORY`,
/// not an abort of the host (tests/c/out_of_memory.c limits its own address space).
#[cfg(target_os = "linux")]
#[test]
fn c_program_gets_out_of_memory_as_a_status() {
    let exe = compile_c("out_of_memory");
    let run = Command::new(&exe).output().expect("run out_of_memory");
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    println!("{stdout}{stderr}");
    assert!(run.status.success(), "out_of_memory failed ({:?}): {stdout}{stderr}", run.status);
    assert!(stdout.contains("all checks passed"));
}

#[test]
fn header_compiles_as_cpp() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cxx = std::env::var("CXX").unwrap_or_else(|_| "c++".into());
    let Ok(out) = Command::new(&cxx)
        .args(["-x", "c++", "-std=c++17", "-fsyntax-only", "-Wall", "-Wextra", "-Werror"])
        .arg(root.join("include/galerkin_radiosity.h"))
        .output()
    else {
        eprintln!("no C++ compiler `{cxx}`; skipped");
        return;
    };
    assert!(
        out.status.success(),
        "the header does not compile as C++:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

// ---------------------------------------------------------------------------------------------
// Rust-side calls of the ABI.

/// A scene as the flat arrays of `gr_session_new`.
#[derive(Clone, Debug, Default)]
struct Flat {
    reflectance: Vec<f32>,
    emission: Vec<f32>,
    vertex_counts: Vec<u32>,
    vertices: Vec<f32>,
    face_counts: Vec<u32>,
    face_vertex_counts: Vec<u32>,
    face_indices: Vec<u32>,
    face_materials: Vec<u32>,
    matrices: Vec<f32>,
}

impl Flat {
    fn from_scene(scene: &Scene) -> Self {
        let mut f = Flat::default();
        for m in &scene.materials {
            f.reflectance.extend(m.reflectance.map(|x| x as f32));
            f.emission.extend(m.emission.map(|x| x as f32));
        }
        for o in &scene.objects {
            f.vertex_counts.push(o.vertices.len() as u32);
            f.vertices.extend(o.vertices.iter().flat_map(|v| v.to_array().map(|x| x as f32)));
            f.face_counts.push(o.faces.len() as u32);
            for face in &o.faces {
                f.face_vertex_counts.push(face.len() as u32);
                f.face_indices.extend(face);
            }
            f.face_materials.extend(&o.face_materials);
            f.matrices.extend(o.matrix.transpose().to_cols_array().map(|x| x as f32));
        }
        f
    }

    /// The two patches of tests/c/two_patches.c (receiver first, black emitter at z = 1).
    fn two_patches() -> Self {
        Flat {
            reflectance: vec![0.5, 0.5, 0.5, 0.0, 0.0, 0.0],
            emission: vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
            vertex_counts: vec![4, 4],
            vertices: vec![
                0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0., //
                0., 0., 1., 0., 1., 1., 1., 1., 1., 1., 0., 1.,
            ],
            face_counts: vec![1, 1],
            face_vertex_counts: vec![4, 4],
            face_indices: vec![0, 1, 2, 3, 0, 1, 2, 3],
            face_materials: vec![0, 1],
            matrices: Vec::new(),
        }
    }

    fn new_session(&self, settings: &GrSettings) -> Result<*mut GrSession, (GrStatus, String)> {
        self.new_session_with(settings, self.vertices.len(), self.face_indices.len())
    }

    fn new_session_with(
        &self,
        settings: &GrSettings,
        vertices_len: usize,
        face_indices_len: usize,
    ) -> Result<*mut GrSession, (GrStatus, String)> {
        let sentinel = 0x5e57 as *mut GrSession;
        let mut out = sentinel;
        let matrices = if self.matrices.is_empty() { null() } else { self.matrices.as_ptr() };
        let status = unsafe {
            gr_session_new(
                settings,
                (self.reflectance.len() / 3) as u32,
                self.reflectance.as_ptr(),
                self.emission.as_ptr(),
                self.vertex_counts.len() as u32,
                self.vertex_counts.as_ptr(),
                self.vertices.as_ptr(),
                self.face_counts.as_ptr(),
                self.face_vertex_counts.as_ptr(),
                self.face_indices.as_ptr(),
                self.face_materials.as_ptr(),
                matrices,
                vertices_len,
                face_indices_len,
                &mut out,
            )
        };
        if status == GrStatus::Ok {
            assert!(!out.is_null() && out != sentinel);
            Ok(out)
        } else {
            assert_eq!(out, sentinel, "out written on failure");
            Err((status, last_error()))
        }
    }
}

impl Flat {
    /// The same scene through the scene builder, `light` added when given.
    fn build(
        &self,
        settings: &GrSettings,
        light: Option<&GrLight>,
    ) -> Result<*mut GrSession, (GrStatus, String)> {
        self.build_with(settings, light.map(|l| l as *const GrLight))
    }

    /// [`Flat::build`] with the light as a pointer (a caller's struct of another layout).
    fn build_with(
        &self,
        settings: &GrSettings,
        light: Option<*const GrLight>,
    ) -> Result<*mut GrSession, (GrStatus, String)> {
        let fail = |st| Err((st, last_error()));
        let mut b = null_mut();
        assert_eq!(unsafe { gr_scene_builder_new(&mut b) }, GrStatus::Ok);
        let _free = Freed(b);
        let st = unsafe { gr_scene_builder_set_settings(b, settings) };
        if st != GrStatus::Ok {
            return fail(st);
        }
        for m in 0..self.reflectance.len() / 3 {
            let mut index = u32::MAX;
            let st = unsafe {
                gr_scene_builder_add_material(
                    b,
                    self.reflectance[3 * m..].as_ptr(),
                    self.emission[3 * m..].as_ptr(),
                    &mut index,
                )
            };
            assert_eq!((st, index), (GrStatus::Ok, m as u32));
        }
        let (mut v0, mut f0, mut i0) = (0usize, 0usize, 0usize);
        for (o, (&nv, &nf)) in self.vertex_counts.iter().zip(&self.face_counts).enumerate() {
            let (nv, nf) = (nv as usize, nf as usize);
            let ni: usize = self.face_vertex_counts[f0..f0 + nf].iter().map(|&c| c as usize).sum();
            let mut mesh = unsafe { std::mem::zeroed::<GrMesh>() };
            assert_eq!(unsafe { gr_mesh_default(&mut mesh) }, GrStatus::Ok);
            mesh.vertex_count = nv as u32;
            mesh.vertices = self.vertices[3 * v0..].as_ptr();
            mesh.face_count = nf as u32;
            mesh.face_vertex_counts = self.face_vertex_counts[f0..].as_ptr();
            mesh.face_materials = self.face_materials[f0..].as_ptr();
            mesh.face_indices = self.face_indices[i0..].as_ptr();
            mesh.face_indices_len = ni;
            if !self.matrices.is_empty() {
                mesh.matrix = self.matrices[16 * o..].as_ptr();
            }
            let mut index = u32::MAX;
            let st = unsafe { gr_scene_builder_add_mesh(b, &mesh, &mut index) };
            if st != GrStatus::Ok {
                return fail(st);
            }
            assert_eq!(index, o as u32);
            (v0, f0, i0) = (v0 + nv, f0 + nf, i0 + ni);
        }
        if let Some(light) = light {
            let st = unsafe { gr_scene_builder_add_light(b, light) };
            if st != GrStatus::Ok {
                return fail(st);
            }
        }
        let sentinel = 0x5e57 as *mut GrSession;
        let mut out = sentinel;
        match unsafe { gr_scene_builder_build(b, &mut out) } {
            GrStatus::Ok => Ok(out),
            st => {
                assert_eq!(out, sentinel, "out written on failure");
                fail(st)
            }
        }
    }
}

/// Frees a builder at the end of the scope.
struct Freed(*mut GrSceneBuilder);
impl Drop for Freed {
    fn drop(&mut self) {
        unsafe { gr_scene_builder_free(self.0) };
    }
}

fn last_error() -> String {
    let n = unsafe { gr_last_error(null_mut(), 0) };
    let mut buf = vec![0u8; n + 1];
    let m = unsafe { gr_last_error(buf.as_mut_ptr().cast(), buf.len()) };
    assert_eq!(m, n);
    CStr::from_bytes_until_nul(&buf).unwrap().to_str().unwrap().to_owned()
}

fn defaults() -> GrSettings {
    let mut s = GrSettings::default();
    assert_eq!(unsafe { gr_settings_default(&mut s) }, GrStatus::Ok);
    s
}

fn face_radiosity(s: *const GrSession, object: u32) -> Result<Vec<f32>, GrStatus> {
    let mut n = 0;
    assert_eq!(unsafe { gr_session_face_count(s, object, &mut n) }, GrStatus::Ok);
    let mut out = vec![f32::NAN; 3 * n as usize];
    match unsafe { gr_session_face_radiosity(s, object, out.as_mut_ptr(), out.len()) } {
        GrStatus::Ok => Ok(out),
        e => Err(e),
    }
}

fn stats_json(s: *const GrSession) -> Result<serde_json::Value, GrStatus> {
    let mut needed = 0;
    let st = unsafe { gr_session_frame_stats_json(s, null_mut(), 0, &mut needed) };
    if st != GrStatus::InvalidArgument {
        return Err(st);
    }
    let mut buf = vec![0u8; needed];
    let mut written = 0;
    let st = unsafe { gr_session_frame_stats_json(s, buf.as_mut_ptr().cast(), buf.len(), &mut written) };
    if st != GrStatus::Ok {
        return Err(st);
    }
    assert_eq!(written, needed);
    Ok(serde_json::from_str(CStr::from_bytes_with_nul(&buf).unwrap().to_str().unwrap()).unwrap())
}

/// A pointer that may cross threads (the ABI's sessions are used from several threads).
#[derive(Clone, Copy)]
struct Shared(*mut GrSession);
unsafe impl Send for Shared {}
unsafe impl Sync for Shared {}

impl Shared {
    /// The pointer (a method, so that closures capture the whole `Send` wrapper).
    fn get(self) -> *mut GrSession {
        self.0
    }
}

#[test]
fn versions_and_defaults() {
    assert_eq!(gr_abi_version(), 3);
    let v = unsafe { CStr::from_ptr(gr_version_string()) };
    assert_eq!(v.to_str().unwrap(), env!("CARGO_PKG_VERSION"));
    let s = defaults();
    let d = Settings::default();
    assert_eq!(s.basis_order as usize, d.basis_order);
    assert_eq!(s.quadrature_order as usize, d.quadrature_order);
    assert_eq!(s.tolerance, d.tolerance);
    assert_eq!(s.visibility, u32::from(d.visibility));
    assert_eq!(s.visibility_samples as usize, d.visibility_samples);
    assert_eq!(s.threads as usize, d.threads);
    assert_eq!(s.method, GrMethod::Incremental);
    assert_eq!(s.corner_gather, u32::from(d.corner_gather));
}

/// Issue 22, item 1: the scene builder makes the session `gr_session_new` makes (bit for bit),
/// with lights added up front; every misuse is a status with a message.
#[test]
fn the_scene_builder_builds_what_gr_session_new_builds() {
    let mut settings = defaults();
    settings.threads = 1;
    let room = Flat::from_scene(&scenes::cornell_box(3, Settings::default()));
    let solve = |s: *mut GrSession| {
        assert_eq!(
            unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) },
            GrStatus::Ok,
            "{}",
            last_error()
        );
        let values: Vec<Vec<f32>> =
            (0..room.vertex_counts.len() as u32).map(|o| face_radiosity(s, o).unwrap()).collect();
        unsafe { gr_session_free(s) };
        values
    };
    let positional = solve(room.new_session(&settings).unwrap());
    let built = solve(room.build(&settings, None).unwrap());
    assert_eq!(positional, built);
    assert!(built.iter().flatten().any(|&x| x > 0.0));

    // A light added to the builder equals the same light set on the session.
    let mut sun = unsafe { std::mem::zeroed::<GrLight>() };
    assert_eq!(unsafe { gr_light_default(&mut sun) }, GrStatus::Ok);
    sun.kind = GrLightKind::GrLightPoint as u32;
    sun.matrix[3] = 0.2; // row-major: the translation
    sun.matrix[7] = 0.1;
    sun.matrix[11] = 0.5;
    let with_light = solve(room.build(&settings, Some(&sun)).unwrap());
    let set_later = {
        let s = room.new_session(&settings).unwrap();
        assert_eq!(unsafe { gr_session_set_lights(s, &sun, 1) }, GrStatus::Ok, "{}", last_error());
        solve(s)
    };
    assert_eq!(with_light, set_later);
    assert_ne!(with_light, built);

    // Misuse: each a status and a message, nothing written.
    let mut newer = settings;
    newer.struct_size += 8;
    let (st, m) = room.build(&newer, None).unwrap_err();
    assert_eq!(st, GrStatus::InvalidArgument);
    assert!(m.contains("settings.struct_size is 72 but this library's struct has 64 bytes"), "{m}");
    let mut older = settings;
    older.struct_size = 40;
    let (st, m) = room.new_session(&older).unwrap_err();
    assert_eq!(st, GrStatus::InvalidArgument);
    assert!(m.contains("below the 48 bytes of its first version (fill it with gr_settings_default)"), "{m}");
    // A host built against version 2's header (48 bytes, no `accuracy`) still builds: the
    // fields past its size take the library's defaults.
    let mut v2 = settings;
    v2.struct_size = 48;
    assert!(room.build(&v2, None).is_ok(), "a version-2 GrSettings is refused");
    let mut bad_light = sun;
    bad_light.struct_size = 8;
    let (st, m) = room.build(&settings, Some(&bad_light)).unwrap_err();
    assert_eq!(st, GrStatus::InvalidArgument);
    assert!(m.contains("lights[0].struct_size is 8"), "{m}");
    let mut wrong_material = room.clone();
    wrong_material.face_materials[0] = 9;
    let (st, m) = wrong_material.build(&settings, None).unwrap_err();
    assert_eq!(st, GrStatus::InvalidScene);
    assert!(m.contains("object 0"), "{m}");

    let mut b = null_mut();
    assert_eq!(unsafe { gr_scene_builder_new(&mut b) }, GrStatus::Ok);
    let _free = Freed(b);
    let mut mesh = unsafe { std::mem::zeroed::<GrMesh>() };
    assert_eq!(unsafe { gr_mesh_default(&mut mesh) }, GrStatus::Ok);
    assert_eq!(mesh.struct_size as usize, size_of::<GrMesh>());
    let counts = [4u32];
    let indices = [0u32, 1, 2];
    mesh.face_count = 1;
    mesh.face_vertex_counts = counts.as_ptr();
    mesh.face_materials = counts.as_ptr();
    mesh.face_indices = indices.as_ptr();
    mesh.face_indices_len = 3;
    assert_eq!(unsafe { gr_scene_builder_add_mesh(b, &mesh, null_mut()) }, GrStatus::InvalidArgument);
    assert!(last_error().contains("mesh.face_indices_len is 3 but mesh.face_vertex_counts sum to 4"));
    mesh.struct_size = 4;
    assert_eq!(unsafe { gr_scene_builder_add_mesh(b, &mesh, null_mut()) }, GrStatus::InvalidArgument);
    assert!(last_error().contains("mesh.struct_size is 4"), "{}", last_error());
    assert_eq!(unsafe { gr_scene_builder_add_mesh(b, null(), null_mut()) }, GrStatus::NullPointer);
    assert_eq!(unsafe { gr_scene_builder_add_mesh(null_mut(), &mesh, null_mut()) }, GrStatus::NullPointer);
    assert_eq!(unsafe { gr_scene_builder_add_light(b, null()) }, GrStatus::NullPointer);
    assert_eq!(
        unsafe { gr_scene_builder_add_material(b, null(), null(), null_mut()) },
        GrStatus::NullPointer
    );
    assert_eq!(unsafe { gr_scene_builder_set_settings(b, null()) }, GrStatus::NullPointer);
    assert_eq!(unsafe { gr_scene_builder_build(b, null_mut()) }, GrStatus::NullPointer);
    assert_eq!(unsafe { gr_scene_builder_new(null_mut()) }, GrStatus::NullPointer);
    // Nothing was added by the failed calls: the builder makes an empty session.
    let mut out = null_mut();
    assert_eq!(unsafe { gr_scene_builder_build(b, &mut out) }, GrStatus::Ok);
    let mut n = u32::MAX;
    assert_eq!(unsafe { gr_session_object_count(out, &mut n) }, GrStatus::Ok);
    assert_eq!(n, 0);
    unsafe { gr_session_free(out) };
}

/// `reflecting_backs` (issue 19): a lamp facing up under a grey sheet whose front faces up too,
/// away from it. With backs the sheet's back returns the lamp's light, as two facing squares a
/// side apart do (Howell C-11, `F = 0.199825`): the lamp's radiosity is `E / (1 - rho^2 F^2)`
/// for constant radiosities, 1.0101; without, the lamp shows its own exitance exactly. The
/// sheet's front (what is read back) sees nothing either way. 2 is refused, and a host built
/// against the header before the field (56 bytes) gets the default, off.
#[test]
fn reflecting_backs_through_the_c_abi() {
    // The two patches, the first a reflecting lamp, the second turned to face up.
    let scene = Flat {
        reflectance: vec![0.5, 0.5, 0.5, 0.5, 0.5, 0.5],
        emission: vec![1.0, 1.0, 1.0, 0.0, 0.0, 0.0],
        vertices: vec![
            0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0., //
            0., 0., 1., 1., 0., 1., 1., 1., 1., 0., 1., 1.,
        ],
        ..Flat::two_patches()
    };
    let solved = |settings: &GrSettings| {
        let s = scene.new_session(settings).unwrap();
        assert_eq!(
            unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) },
            GrStatus::Ok,
            "{}",
            last_error()
        );
        let out = (face_radiosity(s, 0).unwrap()[0] as f64, face_radiosity(s, 1).unwrap()[0] as f64);
        unsafe { gr_session_free(s) };
        out
    };
    assert_eq!(defaults().reflecting_backs, 0, "backs are off by default");
    let (lamp, sheet) = solved(&defaults());
    assert!((lamp - 1.0).abs() < 1e-6 && sheet.abs() < 1e-6, "one-sided: lamp {lamp}, sheet {sheet}");
    let backs = GrSettings { reflecting_backs: 1, ..defaults() };
    let (lamp, sheet) = solved(&backs);
    let f2 = (0.5f64 * 0.199825).powi(2);
    let want = f2 / (1.0 - f2);
    assert!(((lamp - 1.0) - want).abs() < 0.1 * want, "two-sided: lamp gains {}, want {want}", lamp - 1.0);
    assert!(sheet.abs() < 1e-6, "two-sided: the sheet's front reads {sheet}");
    let bad = GrSettings { reflecting_backs: 2, ..defaults() };
    let (st, m) = scene.new_session(&bad).unwrap_err();
    assert_eq!(st, GrStatus::InvalidArgument);
    assert!(m.contains("settings.reflecting_backs 2 is neither 0 nor 1"), "{m}");
    let older = GrSettings { struct_size: 56, reflecting_backs: 1, ..defaults() };
    let (lamp, _) = solved(&older);
    assert!((lamp - 1.0).abs() < 1e-6, "a 56-byte GrSettings read a field past its size: lamp {lamp}");
}

#[test]
fn two_patches_value_and_results() {
    let s = Flat::two_patches().new_session(&defaults()).unwrap();
    assert_eq!(face_radiosity(s, 0), Err(GrStatus::NotSolved));
    assert!(last_error().contains("no frame has been solved"));
    assert_eq!(stats_json(s).unwrap_err(), GrStatus::NotSolved);
    assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
    assert_eq!(last_error(), "");
    let b = face_radiosity(s, 0).unwrap();
    let want = 0.5 * 0.199825;
    for c in b {
        assert!(((c as f64) - want).abs() / want < 0.01, "B = {c}, want {want}");
    }
    let stats = stats_json(s).unwrap();
    assert_eq!(stats["frame"], 1.0);
    assert_eq!(stats["elements"], 2);
    let mut corners = vec![0f32; 12];
    assert_eq!(
        unsafe { gr_session_corner_radiosity(s, 0, corners.as_mut_ptr(), 11) },
        GrStatus::InvalidArgument
    );
    assert_eq!(corners, vec![0.0; 12], "nothing written on failure");
    assert_eq!(unsafe { gr_session_corner_radiosity(s, 0, corners.as_mut_ptr(), 12) }, GrStatus::Ok);
    // eval: a good point and a bad one; nothing is written unless all are good.
    let objects = [0u32, 0];
    let faces = [0u32, 3];
    let st = [0.5f32, 0.5, 0.5, 0.5];
    let mut out = [-1f32; 6];
    assert_eq!(
        unsafe { gr_session_eval(s, 2, objects.as_ptr(), faces.as_ptr(), st.as_ptr(), out.as_mut_ptr(),) },
        GrStatus::InvalidArgument
    );
    assert!(last_error().contains("point 1"), "{}", last_error());
    assert_eq!(out, [-1.0; 6]);
    assert_eq!(
        unsafe { gr_session_eval(s, 1, objects.as_ptr(), faces.as_ptr(), st.as_ptr(), out.as_mut_ptr(),) },
        GrStatus::Ok
    );
    assert!(out[0] > 0.1 && out[3] == -1.0);
    unsafe { gr_session_free(s) };
}

struct CancelAt {
    calls: AtomicU32,
    cancel_on_call: u32,
}

unsafe extern "C" fn cancel_at(_f: f64, stage: *const c_char, user: *mut c_void) -> i32 {
    let c = unsafe { &*(user as *const CancelAt) };
    let stage_ok = !stage.is_null() && !unsafe { CStr::from_ptr(stage) }.is_empty();
    let n = c.calls.fetch_add(1, Ordering::SeqCst) + 1;
    i32::from(stage_ok && n < c.cancel_on_call)
}

#[test]
fn progress_returning_zero_cancels_and_keeps_the_previous_frame() {
    let s = Flat::two_patches().new_session(&defaults()).unwrap();
    assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
    let before = face_radiosity(s, 0).unwrap();
    let red = [3.0f32, 0.0, 0.0];
    assert_eq!(unsafe { gr_session_set_material_emission(s, 1, red.as_ptr()) }, GrStatus::Ok);
    let cb = CancelAt { calls: AtomicU32::new(0), cancel_on_call: 1 };
    let st =
        unsafe { gr_session_solve_frame(s, 2.0, Some(cancel_at), &cb as *const CancelAt as *mut c_void) };
    assert_eq!(st, GrStatus::Cancelled);
    assert_eq!(last_error(), "cancelled");
    assert_eq!(cb.calls.load(Ordering::SeqCst), 1, "not called again once it said stop");
    assert_eq!(face_radiosity(s, 0).unwrap(), before);
    assert_eq!(stats_json(s).unwrap()["frame"], 1.0);
    // A cancel with no solve running does not affect the next solve.
    assert_eq!(unsafe { gr_session_cancel(s) }, GrStatus::Ok);
    assert_eq!(unsafe { gr_session_solve_frame(s, 2.0, None, null_mut()) }, GrStatus::Ok);
    let after = face_radiosity(s, 0).unwrap();
    assert!((after[0] / before[0] - 3.0).abs() < 0.01 && after[1] == 0.0);
    unsafe { gr_session_free(s) };
}

fn corner_radiosity(s: *const GrSession, object: u32) -> Vec<f32> {
    let mut n = 0;
    assert_eq!(unsafe { gr_session_corner_count(s, object, &mut n) }, GrStatus::Ok);
    let mut out = vec![f32::NAN; 3 * n as usize];
    assert_eq!(unsafe { gr_session_corner_radiosity(s, object, out.as_mut_ptr(), out.len()) }, GrStatus::Ok);
    out
}

/// Previews refined on request: a preview frame reads the polynomials' corners, refining it gives
/// what solving without previews gives, a cancelled refinement keeps the frame readable, and
/// misuse is an error, not a crash.
#[test]
fn previews_are_refined_on_request() {
    let mut refined = 7u32;
    assert_eq!(unsafe { gr_session_set_preview(null_mut(), 1) }, GrStatus::NullPointer);
    let st = unsafe { gr_session_refine(null_mut(), None, null_mut(), &mut refined) };
    assert_eq!(st, GrStatus::NullPointer);
    // Tight, so that the two shooting paths to it agree far closer than the checks below.
    let settings = GrSettings { tolerance: 1e-8, ..defaults() };
    let new = || Flat::two_patches().new_session(&settings).unwrap();
    let (s, at_once) = (new(), new());
    assert_eq!(unsafe { gr_session_refine(s, None, null_mut(), &mut refined) }, GrStatus::NotSolved);
    assert_eq!(refined, 7, "not written on error");
    let polynomial = {
        let p = Flat::two_patches().new_session(&GrSettings { corner_gather: 0, ..settings }).unwrap();
        assert_eq!(unsafe { gr_session_solve_frame(p, 1.0, None, null_mut()) }, GrStatus::Ok);
        let c = corner_radiosity(p, 0);
        unsafe { gr_session_free(p) };
        c
    };
    let close = |a: &[f32], b: &[f32], rel: f32| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= rel * y.abs());
    assert_eq!(unsafe { gr_session_solve_frame(at_once, 1.0, None, null_mut()) }, GrStatus::Ok);
    assert_eq!(unsafe { gr_session_set_preview(s, 1) }, GrStatus::Ok);
    assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
    let stats = stats_json(s).unwrap();
    assert_eq!((stats["preview"].as_bool(), stats["gather_seconds"].as_f64()), (Some(true), Some(0.0)));
    let preview_shots = stats["shots"].as_u64().unwrap();
    assert!(close(&corner_radiosity(s, 0), &polynomial, 1e-4), "the polynomials at the corners");
    assert!(
        !close(&corner_radiosity(at_once, 0), &polynomial, 1e-3),
        "the test needs corners the gather changes"
    );
    // Cancelled at its first progress call: the frame stays readable, with the polynomials' corners.
    let cb = CancelAt { calls: AtomicU32::new(0), cancel_on_call: 1 };
    let user = &cb as *const CancelAt as *mut c_void;
    assert_eq!(unsafe { gr_session_refine(s, Some(cancel_at), user, &mut refined) }, GrStatus::Cancelled);
    assert!(close(&corner_radiosity(s, 0), &polynomial, 1e-4));
    assert_eq!(unsafe { gr_session_refine(s, None, null_mut(), &mut refined) }, GrStatus::Ok);
    assert_eq!(refined, 1);
    assert!(close(&corner_radiosity(s, 0), &corner_radiosity(at_once, 0), 1e-6));
    let stats = stats_json(s).unwrap();
    assert_eq!(stats["preview"].as_bool(), Some(false));
    assert!(
        stats["gather_seconds"].as_f64().unwrap() > 0.0 && stats["shots"].as_u64().unwrap() >= preview_shots
    );
    assert_eq!(unsafe { gr_session_refine(s, None, null_mut(), &mut refined) }, GrStatus::Ok);
    assert_eq!(refined, 0, "nothing left to refine");
    unsafe { gr_session_free(s) };
    unsafe { gr_session_free(at_once) };
}

struct Watch {
    /// Fraction of the kernel done, as f64 bits.
    fraction: AtomicU64,
    calls: AtomicU32,
}

unsafe extern "C" fn watch(f: f64, _stage: *const c_char, user: *mut c_void) -> i32 {
    let w = unsafe { &*(user as *const Watch) };
    w.fraction.store(f.to_bits(), Ordering::SeqCst);
    w.calls.fetch_add(1, Ordering::SeqCst);
    1
}

#[test]
fn cancel_from_another_thread_stops_a_big_solve_promptly() {
    let scene = scenes::cornell_box(10, Settings::default());
    let flat = Flat::from_scene(&scene);
    let s = Shared(flat.new_session(&defaults()).unwrap());
    let w = Watch { fraction: AtomicU64::new(0), calls: AtomicU32::new(0) };
    let (status, finished, cancelled_at) = std::thread::scope(|scope| {
        let solver = scope.spawn(|| {
            let start = Instant::now();
            let st = unsafe {
                gr_session_solve_frame(s.get(), 1.0, Some(watch), &w as *const Watch as *mut c_void)
            };
            (st, Instant::now(), start)
        });
        // Cancel once the kernel is well under way.
        let wait = Instant::now();
        while f64::from_bits(w.fraction.load(Ordering::SeqCst)) < 0.05 {
            assert!(wait.elapsed() < Duration::from_secs(120), "no progress");
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(50));
        let at = Instant::now();
        assert_eq!(unsafe { gr_session_cancel(s.0) }, GrStatus::Ok);
        let (st, finished, _) = solver.join().unwrap();
        (st, finished, at)
    });
    let latency = finished.saturating_duration_since(cancelled_at);
    println!(
        "cancel latency: {:.1} ms (kernel at {:.1}% when cancelled, {} progress calls)",
        latency.as_secs_f64() * 1e3,
        100.0 * f64::from_bits(w.fraction.load(Ordering::SeqCst)),
        w.calls.load(Ordering::SeqCst)
    );
    assert_eq!(status, GrStatus::Cancelled);
    assert!(latency < Duration::from_secs(2), "cancel took {latency:?}");
    assert_eq!(face_radiosity(s.0, 0), Err(GrStatus::NotSolved));
    unsafe { gr_session_free(s.0) };
}

#[test]
fn lengths_that_disagree_with_the_counts() {
    let f = Flat::two_patches();
    let d = defaults();
    for (v, i) in [(23, 8), (25, 8), (0, 8), (24, 7), (24, 9), (24, 0)] {
        let (st, msg) = f.new_session_with(&d, v, i).unwrap_err();
        assert_eq!(st, GrStatus::InvalidArgument, "{v} {i}: {msg}");
        assert!(msg.contains("_len"), "{msg}");
    }
    // Face vertex counts that do not sum to face_indices_len (3 + 4 = 7 != 8).
    let mut g = f.clone();
    g.face_vertex_counts = vec![3, 4];
    let (st, msg) = g.new_session(&d).unwrap_err();
    assert_eq!(st, GrStatus::InvalidArgument);
    assert!(msg.contains("face_vertex_counts"), "{msg}");
    // A face count the index array cannot hold is caught before reading per-face arrays.
    let mut g = f.clone();
    g.face_counts = vec![1, 1_000_000];
    let (st, msg) = g.new_session(&d).unwrap_err();
    assert_eq!(st, GrStatus::InvalidArgument, "{msg}");
}

#[test]
fn invalid_scenes_name_the_object_and_face() {
    let d = defaults();
    let f = Flat::two_patches();
    let mut g = f.clone();
    g.vertices[13] = f32::NAN;
    let (st, msg) = g.new_session(&d).unwrap_err();
    assert_eq!(st, GrStatus::InvalidScene);
    assert!(msg.contains("object 1") && msg.contains("vertex 0"), "{msg}");

    let mut g = f.clone();
    g.vertices[0] = f32::INFINITY;
    assert_eq!(g.new_session(&d).unwrap_err().0, GrStatus::InvalidScene);

    let mut g = f.clone();
    g.face_indices[6] = 7;
    let (st, msg) = g.new_session(&d).unwrap_err();
    assert_eq!(st, GrStatus::InvalidScene);
    assert!(msg.contains("object 1") && msg.contains("face 0"), "{msg}");

    let mut g = f.clone();
    g.face_vertex_counts = vec![5, 3];
    let (st, msg) = g.new_session(&d).unwrap_err();
    assert_eq!(st, GrStatus::InvalidScene);
    assert!(msg.contains("object 0") && msg.contains("face 0"), "{msg}");

    let mut g = f.clone();
    g.face_materials[1] = 2;
    let (st, msg) = g.new_session(&d).unwrap_err();
    assert_eq!(st, GrStatus::InvalidScene);
    assert!(msg.contains("material 2"), "{msg}");

    let mut g = f.clone();
    g.matrices = vec![0.0; 32];
    g.matrices[16 + 5] = f32::NAN;
    let (st, msg) = g.new_session(&d).unwrap_err();
    assert_eq!(st, GrStatus::InvalidScene);
    assert!(msg.contains("matrix"), "{msg}");

    let mut g = f.clone();
    g.reflectance[0] = 1.5;
    assert_eq!(g.new_session(&d).unwrap_err().0, GrStatus::InvalidScene);

    let mut bad = d;
    bad.basis_order = 9;
    let (st, msg) = f.new_session(&bad).unwrap_err();
    assert_eq!(st, GrStatus::InvalidScene);
    assert!(msg.contains("basis_order"), "{msg}");
}

#[test]
fn unknown_enum_values_and_nulls() {
    let f = Flat::two_patches();
    let d = defaults();
    // GrSettings with `method` = 9, which is not a GrMethod: written as C would, via raw bytes.
    let mut raw = d;
    unsafe { (&raw mut raw.method).cast::<u32>().write(9) };
    let (st, msg) = f.new_session(&raw).unwrap_err();
    assert_eq!(st, GrStatus::InvalidArgument);
    assert!(msg.contains("method"), "{msg}");
    let mut vis = d;
    vis.visibility = 2;
    assert_eq!(f.new_session(&vis).unwrap_err().0, GrStatus::InvalidArgument);
    let mut gather = d;
    gather.corner_gather = 3;
    let (st, msg) = f.new_session(&gather).unwrap_err();
    assert_eq!(st, GrStatus::InvalidArgument);
    assert!(msg.contains("corner_gather"), "{msg}");

    let mut out = null_mut();
    let st = unsafe {
        gr_session_new(
            null(),
            0,
            null(),
            null(),
            0,
            null(),
            null(),
            null(),
            null(),
            null(),
            null(),
            null(),
            0,
            0,
            &mut out,
        )
    };
    assert_eq!(st, GrStatus::NullPointer);
    assert_eq!(last_error(), "settings is NULL");
    let st = unsafe {
        gr_session_new(
            &d,
            2,
            null(),
            null(),
            0,
            null(),
            null(),
            null(),
            null(),
            null(),
            null(),
            null(),
            0,
            0,
            &mut out,
        )
    };
    assert_eq!(st, GrStatus::NullPointer);
    assert_eq!(last_error(), "reflectance is NULL");
    // Empty arrays may be NULL: an empty scene is valid.
    let st = unsafe {
        gr_session_new(
            &d,
            0,
            null(),
            null(),
            0,
            null(),
            null(),
            null(),
            null(),
            null(),
            null(),
            null(),
            0,
            0,
            &mut out,
        )
    };
    assert_eq!(st, GrStatus::Ok, "{}", last_error());
    let mut n = 7;
    assert_eq!(unsafe { gr_session_object_count(out, &mut n) }, GrStatus::Ok);
    assert_eq!(n, 0);
    assert_eq!(unsafe { gr_session_solve_frame(out, f64::NAN, None, null_mut()) }, GrStatus::InvalidArgument);
    assert_eq!(unsafe { gr_session_solve_frame(out, 1.0, None, null_mut()) }, GrStatus::Ok);
    assert_eq!(unsafe { gr_session_object_count(out, null_mut()) }, GrStatus::NullPointer);
    assert_eq!(unsafe { gr_session_face_count(out, 0, &mut n) }, GrStatus::InvalidArgument);
    unsafe { gr_session_free(out) };
    unsafe { gr_session_free(null_mut()) };
}

#[test]
fn last_error_is_per_thread_and_truncates_safely() {
    let f = Flat::two_patches();
    let mut g = f.clone();
    g.face_indices[6] = 7;
    assert!(g.new_session(&defaults()).is_err());
    let full = last_error();
    let n = unsafe { gr_last_error(null_mut(), 0) };
    assert_eq!(n, full.len());
    let mut small = [0x7fu8; 6];
    assert_eq!(unsafe { gr_last_error(small.as_mut_ptr().cast(), 5) }, n);
    assert_eq!(&small[..5], &full.as_bytes()[..4].iter().copied().chain([0]).collect::<Vec<_>>()[..]);
    assert_eq!(small[5], 0x7f, "wrote past len");
    let other = std::thread::spawn(|| unsafe { gr_last_error(null_mut(), 0) }).join().unwrap();
    assert_eq!(other, 0, "another thread has its own last error");
    // A successful call clears it.
    let mut settings = GrSettings::default();
    assert_eq!(unsafe { gr_settings_default(&mut settings) }, GrStatus::Ok);
    assert_eq!(unsafe { gr_last_error(null_mut(), 0) }, 0);
}

#[test]
fn panics_become_internal_errors() {
    let st = run_in_boundary("gr_test", || panic!("boom {}", 42));
    assert_eq!(st, GrStatus::Internal);
    let msg = last_error();
    assert!(msg.contains("gr_test") && msg.contains("boom 42"), "{msg}");
    // A panic in a rayon worker is re-raised on the calling thread and caught there too.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let st = run_in_boundary("gr_test_workers", || {
        use rayon::prelude::*;
        pool.install(|| {
            (0..64).into_par_iter().for_each(|i| {
                if i == 37 {
                    panic!("worker {i} failed");
                }
            })
        })
    });
    assert_eq!(st, GrStatus::Internal);
    assert!(last_error().contains("worker 37 failed"), "{}", last_error());
    assert_eq!(run_in_boundary("gr_test", || ()), GrStatus::Ok);
    assert_eq!(last_error(), "");
}

struct Reentry {
    session: Shared,
    face_radiosity: AtomicU32,
    face_count: AtomicU32,
    cancel: AtomicU32,
}

unsafe extern "C" fn reenter(_f: f64, _stage: *const c_char, user: *mut c_void) -> i32 {
    let r = unsafe { &*(user as *const Reentry) };
    let s = r.session.0;
    let mut out = [0f32; 3];
    let mut n = 0;
    let st = unsafe { gr_session_face_radiosity(s, 0, out.as_mut_ptr(), 3) };
    r.face_radiosity.store(st as u32, Ordering::SeqCst);
    let st = unsafe { gr_session_face_count(s, 0, &mut n) };
    r.face_count.store(st as u32, Ordering::SeqCst);
    let st = unsafe { gr_session_cancel(s) };
    r.cancel.store(st as u32, Ordering::SeqCst);
    1
}

#[test]
fn calls_from_the_progress_callback_do_not_deadlock() {
    let s = Flat::two_patches().new_session(&defaults()).unwrap();
    let r = Reentry {
        session: Shared(s),
        face_radiosity: AtomicU32::new(99),
        face_count: AtomicU32::new(99),
        cancel: AtomicU32::new(99),
    };
    let st = unsafe { gr_session_solve_frame(s, 1.0, Some(reenter), &r as *const Reentry as *mut c_void) };
    // The callback asked to cancel through gr_session_cancel, so the solve stops.
    assert_eq!(st, GrStatus::Cancelled);
    assert_eq!(r.face_radiosity.load(Ordering::SeqCst), GrStatus::InvalidArgument as u32);
    assert_eq!(r.face_count.load(Ordering::SeqCst), GrStatus::Ok as u32);
    assert_eq!(r.cancel.load(Ordering::SeqCst), GrStatus::Ok as u32);
    unsafe { gr_session_free(s) };
}

fn corner_irradiance(s: *const GrSession, object: u32) -> Vec<f32> {
    let mut n = 0;
    assert_eq!(unsafe { gr_session_corner_count(s, object, &mut n) }, GrStatus::Ok);
    let mut out = vec![f32::NAN; 3 * n as usize];
    assert_eq!(unsafe { gr_session_corner_irradiance(s, object, out.as_mut_ptr(), out.len()) }, GrStatus::Ok);
    out
}

/// Per corner of every object, `B - (E + rho H)` relative to `B`'s peak, the worst: the
/// definition of the irradiance `H` (issue 22, item 7), with `rho` and `E` per face from `flat`.
fn worst_identity_error(s: *const GrSession, flat: &Flat) -> f64 {
    let (mut worst, mut peak, mut face) = (0.0f64, 0.0f64, 0usize);
    for (o, &nf) in flat.face_counts.iter().enumerate() {
        let (b, h) = (corner_radiosity(s, o as u32), corner_irradiance(s, o as u32));
        assert_eq!(b.len(), h.len());
        let mut k = 0;
        for f in face..face + nf as usize {
            let m = flat.face_materials[f] as usize;
            for _ in 0..flat.face_vertex_counts[f] {
                for c in 0..3 {
                    let (rho, e) = (flat.reflectance[3 * m + c] as f64, flat.emission[3 * m + c] as f64);
                    let (b, h) = (b[3 * k + c] as f64, h[3 * k + c] as f64);
                    assert!(h >= 0.0 && h.is_finite(), "H = {h}");
                    peak = peak.max(b);
                    if rho >= 1e-4 {
                        worst = worst.max((b - (e + rho * h)).abs());
                    }
                }
                k += 1;
            }
        }
        face += nf as usize;
    }
    worst / peak
}

/// The irradiance at the corners (issue 22, item 7): a closed box of rho 0.5 and E 1 receives
/// `H = B = E / (1 - rho) = 2` everywhere, gathered or from the polynomials; on a lit Cornell box
/// `B = E + rho H` at every corner with the corner gather on and off; a black emitter's gathered
/// irradiance is what it receives, its polynomial one 0 (rho below 1e-4); and
/// `gr_session_eval_irradiance` at a face's corner is the polynomial corner's value.
#[test]
fn corner_irradiance_is_the_light_received() {
    for gather in [1, 0] {
        let settings = GrSettings { corner_gather: gather, tolerance: 1e-7, ..defaults() };
        let flat = Flat::from_scene(&scenes::closed_box(2, 0.5, 1.0, Settings::default()));
        let s = flat.new_session(&settings).unwrap();
        assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
        for o in 0..6 {
            for h in corner_irradiance(s, o) {
                assert!((h as f64 - 2.0).abs() < 0.01 * 2.0, "gather {gather}: H = {h}, want 2");
            }
        }
        assert!(worst_identity_error(s, &flat) < 1e-6);
        unsafe { gr_session_free(s) };

        let flat = Flat::from_scene(&scenes::cornell_box(2, Settings::default()));
        let mut light = unsafe { std::mem::zeroed::<GrLight>() };
        assert_eq!(unsafe { gr_light_default(&mut light) }, GrStatus::Ok);
        light.matrix =
            glam::DMat4::from_translation(glam::DVec3::new(0.3, 0.35, 0.25)).transpose().to_cols_array();
        light.power = 20.0;
        let s = flat.build(&settings, Some(&light)).unwrap();
        assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
        let worst = worst_identity_error(s, &flat);
        assert!(worst < 1e-6, "gather {gather}: |B - E - rho H| up to {worst:.2e} of the peak");
        unsafe { gr_session_free(s) };
    }
    // The hierarchy's corners are its leaf polynomials': H derived, the identity still holds.
    let settings = GrSettings { method: GrMethod::Hierarchical, ..defaults() };
    let flat = Flat::from_scene(&scenes::cornell_box(2, Settings::default()));
    let s = flat.new_session(&settings).unwrap();
    assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
    let worst = worst_identity_error(s, &flat);
    assert!(worst < 1e-6, "hierarchical: |B - E - rho H| up to {worst:.2e} of the peak");
    assert!(corner_irradiance(s, 0).iter().any(|&h| h > 0.0));
    unsafe { gr_session_free(s) };
    // Two patches: the receiver (rho 0.5) and a black emitter facing it.
    for gather in [1, 0] {
        let s = Flat::two_patches().new_session(&GrSettings { corner_gather: gather, ..defaults() }).unwrap();
        assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
        let emitter = corner_irradiance(s, 1);
        if gather == 1 {
            // It sees the receiver's B = 0.5 H_receiver, about 0.1 W/m^2, over a form factor of 0.2.
            assert!(emitter.iter().all(|&h| h > 0.005 && h < 0.05), "{emitter:?}");
        } else {
            assert_eq!(emitter, vec![0.0; 12], "rho 0: not derived");
        }
        let receiver = corner_irradiance(s, 0);
        let (objects, faces, st) = ([0u32], [0u32], [0.0f32, 0.0]);
        let mut out = [-1f32; 3];
        let status = unsafe {
            gr_session_eval_irradiance(s, 1, objects.as_ptr(), faces.as_ptr(), st.as_ptr(), out.as_mut_ptr())
        };
        assert_eq!(status, GrStatus::Ok);
        if gather == 0 {
            for c in 0..3 {
                assert!((out[c] - receiver[c]).abs() <= 1e-6 * receiver[c], "{out:?} {receiver:?}");
            }
        }
        assert!(out[0] > 0.1, "H at the receiver's corner {out:?}");
        unsafe { gr_session_free(s) };
    }
}

#[test]
fn face_emission_scales_an_emitter_and_bad_lengths_are_refused() {
    // The two patches' emitter (object 1, one face) scaled per channel: the receiver, lit only
    // by it (the emitter is black, so nothing comes back), takes the same scale.
    let s = Flat::two_patches().new_session(&defaults()).unwrap();
    let solved = || {
        assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
        face_radiosity(s, 0).unwrap()
    };
    let plain = solved();
    let scale = [0.5f32, 0.25, 1.0];
    assert_eq!(unsafe { gr_session_set_object_face_emission(s, 1, scale.as_ptr(), 3) }, GrStatus::Ok);
    let scaled = solved();
    for c in 0..3 {
        let ratio = scaled[c] / plain[c];
        assert!((ratio - scale[c]).abs() < 1e-5, "channel {c}: {ratio} for {}", scale[c]);
    }
    // Setting the other surface data keeps the scale.
    let st = unsafe { gr_session_set_object_surface(s, 1, null(), 0, null(), 0) };
    assert_eq!(st, GrStatus::Ok);
    assert_eq!(solved(), scaled);
    // Refused, and nothing changes: lengths that are not 3 x the faces, an object out of
    // range, a NULL array with a length, a NULL session, values out of range.
    let six = [1.0f32; 6];
    for len in [2, 6] {
        let st = unsafe { gr_session_set_object_face_emission(s, 1, six.as_ptr(), len) };
        assert_eq!(st, GrStatus::InvalidArgument, "len {len}");
        assert!(last_error().contains(&format!("len {len} is not 3 x the 1 faces")), "{}", last_error());
    }
    let st = unsafe { gr_session_set_object_face_emission(s, 2, six.as_ptr(), 3) };
    assert_eq!(st, GrStatus::InvalidArgument);
    assert!(last_error().contains("object 2 out of range"), "{}", last_error());
    assert_eq!(unsafe { gr_session_set_object_face_emission(s, 1, null(), 3) }, GrStatus::NullPointer);
    let st = unsafe { gr_session_set_object_face_emission(null_mut(), 1, six.as_ptr(), 3) };
    assert_eq!(st, GrStatus::NullPointer);
    for bad in [[1.0f32, -0.5, 1.0], [f32::NAN, 1.0, 1.0], [1.0, 1.0, 1e7]] {
        let st = unsafe { gr_session_set_object_face_emission(s, 1, bad.as_ptr(), 3) };
        assert_eq!(st, GrStatus::InvalidScene, "{bad:?}");
        assert!(last_error().contains("face_emission[0]"), "{}", last_error());
    }
    assert_eq!(solved(), scaled);
    // Length 0 (NULL allowed) goes back to the materials' emission.
    assert_eq!(unsafe { gr_session_set_object_face_emission(s, 1, null(), 0) }, GrStatus::Ok);
    assert_eq!(solved(), plain);
    unsafe { gr_session_free(s) };
}

/// `GrLight` before `soft_falloff` was appended (224 bytes), as a host built against that header
/// lays it out.
#[repr(C)]
#[derive(Clone, Copy)]
struct GrLightV1 {
    struct_size: u32,
    kind: u32,
    shape: u32,
    matrix: [f64; 16],
    color: [f64; 3],
    power: f64,
    radius: f64,
    spot_size: f64,
    spot_blend: f64,
    angle: f64,
    area_size: [f64; 2],
}

#[test]
fn an_older_hosts_smaller_light_reads_with_the_new_fields_defaults() {
    assert_eq!(size_of::<GrLightV1>(), 224);
    assert_eq!(std::mem::offset_of!(GrLight, soft_falloff), 224);
    let mut light = unsafe { std::mem::zeroed::<GrLight>() };
    assert_eq!(unsafe { gr_light_default(&mut light) }, GrStatus::Ok);
    assert_eq!((light.struct_size as usize, light.soft_falloff), (size_of::<GrLight>(), 1));
    light.matrix =
        glam::DMat4::from_translation(glam::DVec3::new(0.3, 0.35, 0.25)).transpose().to_cols_array();
    light.power = 20.0;
    light.radius = 0.1;
    let mut second = light;
    second.kind = GrLightKind::GrLightSpot as u32;
    second.matrix[3] = -0.2;
    let old = |g: &GrLight| GrLightV1 {
        struct_size: 224,
        kind: g.kind,
        shape: g.shape,
        matrix: g.matrix,
        color: g.color,
        power: g.power,
        radius: g.radius,
        spot_size: g.spot_size,
        spot_blend: g.spot_blend,
        angle: g.angle,
        area_size: g.area_size,
    };
    let flat = Flat::from_scene(&scenes::cornell_box(2, Settings::default()));
    let settings = defaults();
    // The corners of every object with `count` lights at `lights` set on a fresh session.
    let solve = |lights: *const GrLight, count: usize| -> Result<Vec<f32>, String> {
        let s = flat.new_session(&settings).unwrap();
        let st = unsafe { gr_session_set_lights(s, lights, count) };
        if st != GrStatus::Ok {
            unsafe { gr_session_free(s) };
            return Err(last_error());
        }
        assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
        let v = (0..flat.vertex_counts.len() as u32).flat_map(|o| corner_radiosity(s, o)).collect();
        unsafe { gr_session_free(s) };
        Ok(v)
    };
    let new = [light, second];
    let olds = [old(&light), old(&second)];
    // Two old lights, 224 bytes apart: read at the caller's stride, Soft Falloff on (the default).
    let from_old = solve(olds.as_ptr().cast(), 2).unwrap();
    assert_eq!(from_old, solve(new.as_ptr(), 2).unwrap());
    // The builder reads an old light as the session does.
    let built = |g: *const GrLight| {
        let s = flat.build_with(&settings, Some(g)).unwrap();
        assert_eq!(unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) }, GrStatus::Ok);
        let v: Vec<f32> = (0..flat.vertex_counts.len() as u32).flat_map(|o| corner_radiosity(s, o)).collect();
        unsafe { gr_session_free(s) };
        v
    };
    assert_eq!(built((&olds[0] as *const GrLightV1).cast()), built(&new[0]));
    assert_eq!(built(&new[0]), solve(new.as_ptr(), 1).unwrap());
    let mut spheres = new;
    spheres.iter_mut().for_each(|g| g.soft_falloff = 0);
    assert_ne!(from_old, solve(spheres.as_ptr(), 2).unwrap(), "a sphere is not the disk");
    // Refused: a size between the layouts' or beyond, a bad flag, sizes that disagree.
    for (size, says) in [(220, "below the 224 bytes"), (240, "but this library's struct has 232 bytes")] {
        let mut bad = new;
        bad[0].struct_size = size;
        bad[1].struct_size = size;
        let m = solve(bad.as_ptr(), 2).unwrap_err();
        assert!(m.contains(says), "{m}");
    }
    let mut bad = new;
    bad[1].soft_falloff = 2;
    let m = solve(bad.as_ptr(), 2).unwrap_err();
    assert!(m.contains("lights[1].soft_falloff 2 is not 0 or 1"), "{m}");
    let mut mixed = new;
    mixed[1].struct_size = 224;
    let m = solve(mixed.as_ptr(), 2).unwrap_err();
    assert!(m.contains("lights[1].struct_size is 224 but lights[0]'s is 232"), "{m}");
}
