//! Issue 23, item 3: a cancel arriving during the corner gather stops it and the frame returns
//! `GR_STATUS_CANCELLED` (it returned OK after the whole gather: the gather asked the host only
//! every 256 corners, so a 12-face scene was never asked again), and progress is reported from
//! inside the gather. The last completed frame stays readable, unchanged.
//!
//! The latency is printed, not asserted (`cargo test --release --test cancel_gather --
//! --nocapture`): timing depends on the machine.

use std::ffi::{CStr, c_char, c_void};
use std::ptr::null_mut;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::{Duration, Instant};

use galerkin_radiosity::ffi::*;
use galerkin_radiosity::scene::Scene;
use galerkin_radiosity::scene::json::parse_scene;

mod c_session;

/// Twelve faces whose gather is slow: eight slivers 1 mm tall standing on a floor, each corner
/// on the floor touching it, under a light, between two walls (0.5-0.7 s of gather on two cores).
fn slivers() -> Scene {
    let quad = |name: &str, v: [[f64; 3]; 4], m: u32| serde_json::json!({"name": name, "vertices": v, "faces": [[0, 1, 2, 3]], "material": m});
    let mut objects = vec![
        quad("Floor", [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]], 0),
        quad("Wall", [[0., 0., 0.], [0., 1., 0.], [0., 1., 1.], [0., 0., 1.]], 0),
        quad("Wall2", [[0., 0., 0.], [0., 0., 1.], [1., 0., 1.], [1., 0., 0.]], 0),
        quad("Light", [[0.2, 0.2, 0.99], [0.2, 0.8, 0.99], [0.8, 0.8, 0.99], [0.8, 0.2, 0.99]], 1),
    ];
    for k in 0..8 {
        let y = 0.1 + 0.8 * k as f64 / 7.0;
        let v = [[0.1, y, 0.0], [0.9, y, 0.0], [0.9, y, 1e-3], [0.1, y, 1e-3]];
        objects.push(quad(&format!("Sliver{k}"), v, 0));
    }
    let file = serde_json::json!({
        "version": 1, "settings": {"basis_order": 2}, "frames": [1, 2],
        "materials": [{"name": "white", "reflectance": [0.7, 0.7, 0.7]},
                      {"name": "light", "reflectance": [0.5, 0.5, 0.5], "emission": [10, 10, 10]}],
        "objects": objects,
    });
    parse_scene(&file.to_string()).unwrap()
}

/// A session of `scene` through `gr_session_new`, every frame from scratch (so the second
/// frame's gather is as slow as the first's).
fn new_session(scene: &Scene) -> *mut GrSession {
    let mut settings = GrSettings::default();
    assert_eq!(unsafe { gr_settings_default(&mut settings) }, GrStatus::Ok);
    settings.method = GrMethod::Full;
    let (status, out) = c_session::new_session(scene, &settings);
    assert_eq!(status, GrStatus::Ok);
    out
}

fn face_radiosity(s: *const GrSession, object: u32) -> Vec<f32> {
    let mut n = 0;
    assert_eq!(unsafe { gr_session_face_count(s, object, &mut n) }, GrStatus::Ok);
    let mut out = vec![f32::NAN; 3 * n as usize];
    assert_eq!(unsafe { gr_session_face_radiosity(s, object, out.as_mut_ptr(), out.len()) }, GrStatus::Ok);
    out
}

/// What the progress callback saw: that the gather started, and how many calls came from it.
#[derive(Default)]
struct Seen {
    gathering: AtomicBool,
    gather_calls: AtomicU32,
}

unsafe extern "C" fn watch(_f: f64, stage: *const c_char, user: *mut c_void) -> i32 {
    let seen = unsafe { &*(user as *const Seen) };
    if unsafe { CStr::from_ptr(stage) }.to_bytes() == b"corner gather" {
        seen.gathering.store(true, Ordering::SeqCst);
        seen.gather_calls.fetch_add(1, Ordering::SeqCst);
    }
    1
}

/// A pointer that may cross threads (the ABI's sessions are used from several threads).
#[derive(Clone, Copy)]
struct Shared(*mut GrSession);
unsafe impl Send for Shared {}
unsafe impl Sync for Shared {}

impl Shared {
    fn get(self) -> *mut GrSession {
        self.0
    }
}

#[test]
fn a_cancel_during_the_corner_gather_returns_cancelled_and_keeps_the_last_frame() {
    let scene = slivers();
    assert_eq!(scene.face_count(), 12);
    let s = Shared(new_session(&scene));
    // Frame 1 in full: the gather reports progress from inside (more than the one call at its
    // start: it is polled every 10 ms and takes hundreds).
    let first = Seen::default();
    let st =
        unsafe { gr_session_solve_frame(s.get(), 1.0, Some(watch), &first as *const Seen as *mut c_void) };
    assert_eq!(st, GrStatus::Ok);
    let calls = first.gather_calls.load(Ordering::SeqCst);
    assert!(calls > 1, "the gather reported progress {calls} time(s)");
    let before: Vec<Vec<f32>> = (0..scene.objects.len() as u32).map(|o| face_radiosity(s.0, o)).collect();

    // Frame 2, cancelled from this thread once its gather has begun.
    let seen = Seen::default();
    let (status, latency) = std::thread::scope(|scope| {
        let solver = scope.spawn(|| {
            let st = unsafe {
                gr_session_solve_frame(s.get(), 2.0, Some(watch), &seen as *const Seen as *mut c_void)
            };
            (st, Instant::now())
        });
        let wait = Instant::now();
        while !seen.gathering.load(Ordering::SeqCst) {
            assert!(wait.elapsed() < Duration::from_secs(120), "the gather never started");
            std::thread::sleep(Duration::from_millis(1));
        }
        let at = Instant::now();
        assert_eq!(unsafe { gr_session_cancel(s.0) }, GrStatus::Ok);
        let (st, finished) = solver.join().unwrap();
        (st, finished.saturating_duration_since(at))
    });
    println!(
        "cancel inside the corner gather: {:.1} ms from gr_session_cancel to the return ({} gather progress calls in frame 1)",
        latency.as_secs_f64() * 1e3,
        calls
    );
    assert_eq!(status, GrStatus::Cancelled);
    let after: Vec<Vec<f32>> = (0..scene.objects.len() as u32).map(|o| face_radiosity(s.0, o)).collect();
    assert_eq!(after, before, "the last completed frame changed");
    // The next frame solves.
    assert_eq!(unsafe { gr_session_solve_frame(s.get(), 2.0, None, null_mut()) }, GrStatus::Ok);
    unsafe { gr_session_free(s.0) };
}
