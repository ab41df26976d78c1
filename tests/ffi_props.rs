//! Property test of the C ABI: arbitrary (mostly almost-valid, often broken) scenes and calls
//! never crash, every status is one of the defined codes, a failed call leaves its outputs
//! untouched and explains itself in `gr_last_error`, and no input reaches a panic (which would
//! come back as `GR_STATUS_INTERNAL`).
//!
//! Arrays whose length C cannot pass (the per-object and per-face arrays) are as long as the
//! counts say, as the ABI requires; the lengths the ABI does check (`vertices_len`,
//! `face_indices_len`), the counts, indices, numbers and NULLs are arbitrary.
//!
//! 256 cases by default (well under a second); `PROPTEST_CASES=50000 cargo test --test
//! ffi_props -- --nocapture` for more (it prints how many sessions, solves and reads the cases
//! reached); `FFI_PROPS_DEBUG=1` prints why each rejected scene was rejected, and each case
//! whose solve diverged.

use std::ffi::{CStr, c_void};
use std::ptr::{null, null_mut};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use galerkin_radiosity::ffi::*;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

/// `GrSettings` as C may fill it: `method` is any 32-bit value.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
struct RawSettings {
    struct_size: u32,
    basis_order: u32,
    quadrature_order: u32,
    visibility: u32,
    visibility_samples: u32,
    threads: u32,
    method: u32,
    corner_gather: u32,
    tolerance: f64,
    memory_budget_mb: u64,
    accuracy: f64,
    reflecting_backs: u32,
}

const _: () = assert!(size_of::<RawSettings>() == size_of::<GrSettings>());
const _: () = assert!(align_of::<RawSettings>() == align_of::<GrSettings>());

#[derive(Clone, Debug)]
struct Obj {
    vertices: Vec<[f32; 3]>,
    faces: Vec<(Vec<u32>, u32)>,
    matrix: [f32; 16],
}

#[derive(Clone, Debug)]
enum Op {
    SetMatrix(u32, [f32; 16]),
    SetEmission(u32, [f32; 3]),
    Solve(f64, u32),
    FaceRadiosity(u32, i64),
    CornerRadiosity(u32, i64),
    Eval(Vec<(u32, u32, f32, f32)>),
    Stats(usize),
    Counts(u32),
    Cancel,
    /// `gr_session_set_preview` on or off.
    Preview(bool),
    /// `gr_session_refine`, cancelled at progress call `.0` (`u32::MAX`: never).
    Refine(u32),
}

#[derive(Clone, Debug)]
struct Case {
    settings: RawSettings,
    materials: Vec<[f32; 6]>,
    objects: Vec<Obj>,
    with_matrices: bool,
    fault: Fault,
    /// Solve frame 1 before the ops.
    solve_first: bool,
    /// Previews on (`gr_session_set_preview`) before that solve.
    preview: bool,
    ops: Vec<Op>,
}

fn number() -> impl Strategy<Value = f32> {
    prop_oneof![
        300 => -2.0f32..2.0,
        1 => prop::sample::select(vec![
            f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0, f32::MAX, f32::MIN,
            f32::MIN_POSITIVE, 1e30, -1e30, 1e-30, f32::EPSILON,
        ]),
        1 => any::<f32>(),
    ]
}

fn unit() -> impl Strategy<Value = f32> {
    prop_oneof![
        150 => 0.0f32..1.0,
        1 => prop::sample::select(vec![f32::NAN, 1.0, -0.5, 2.0, f32::INFINITY, 0.999_999]),
    ]
}

fn index(n: u32) -> impl Strategy<Value = u32> {
    prop_oneof![
        150 => 0..n.max(1),
        1 => prop::sample::select(vec![n, n + 1, u32::MAX, u32::MAX / 2]),
    ]
}

fn matrix() -> impl Strategy<Value = [f32; 16]> {
    prop_oneof![
        3 => (-2.0f32..2.0, -2.0f32..2.0, -2.0f32..2.0).prop_map(|(x, y, z)| {
            [1., 0., 0., x, 0., 1., 0., y, 0., 0., 1., z, 0., 0., 0., 1.]
        }),
        1 => prop::array::uniform16(number()),
    ]
}

fn settings() -> impl Strategy<Value = RawSettings> {
    let numbers =
        (0u32..=3, 1u32..=6, prop::sample::select(vec![1e-4, 1e-2, 0.5]), 0u32..=1, 1u32..=2, 0u32..=2);
    // Mostly a rule with more points than the basis order (fewer is rejected at validation).
    let enough_points = prop_oneof![7 => Just(true), 1 => Just(false)];
    (numbers, 0u32..=2, 0u32..=1, enough_points, 0u32..=1).prop_map(
        |((b, q, t, v, vs, th), m, g, enough, backs)| RawSettings {
            struct_size: size_of::<GrSettings>() as u32,
            basis_order: b,
            quadrature_order: if enough && q <= b { b + q } else { q },
            tolerance: t,
            visibility: v,
            visibility_samples: vs,
            threads: th,
            method: m,
            corner_gather: g,
            memory_budget_mb: 0,
            accuracy: 1e-3,
            reflecting_backs: backs,
        },
    )
}

/// One thing wrong with the call to `gr_session_new` (besides what the scene itself may get
/// wrong: non-finite numbers, bad indices, faces of other sizes).
#[derive(Clone, Debug)]
enum Fault {
    None,
    /// Setting `.0` (in declaration order) gets the raw value `.1`.
    Setting(usize, u64),
    VerticesLen(i64),
    FaceIndicesLen(i64),
    /// Object `.0 % objects`' vertex count (`.1 = false`) or face count becomes `.2`.
    Count(usize, bool, u32),
    /// Argument `.0` of `gr_session_new` that is a pointer is NULL.
    Null(u32),
}

fn fault() -> impl Strategy<Value = Fault> {
    let setting = prop_oneof![
        (0usize..10, prop_oneof![Just(0u64), 3u64..20, Just(u64::from(u32::MAX))]),
        Just(2usize).prop_flat_map(|k| {
            (
                Just(k),
                prop::sample::select(vec![0.0f64, 1.0, -1.0, f64::NAN, f64::INFINITY, 1e-300])
                    .prop_map(f64::to_bits),
            )
        }),
    ];
    prop_oneof![
        12 => Just(Fault::None),
        1 => setting.prop_map(|(k, v)| Fault::Setting(k, v)),
        1 => (-4i64..4).prop_map(Fault::VerticesLen),
        1 => (-4i64..4).prop_map(Fault::FaceIndicesLen),
        1 => (
            any::<usize>(),
            any::<bool>(),
            prop_oneof![0u32..10, Just(u32::MAX), 1_000_000u32..2_000_000],
        )
            .prop_map(|(o, f, n)| Fault::Count(o, f, n)),
        1 => (0u32..11).prop_map(Fault::Null),
    ]
}

fn object(materials: u32) -> impl Strategy<Value = Obj> {
    prop_oneof![20 => 3u32..7, 1 => 0u32..3].prop_flat_map(move |n| {
        let face = (prop_oneof![30 => 3usize..=4, 1 => 0usize..=6], index(materials))
            .prop_flat_map(move |(k, m)| (prop::collection::vec(index(n), k), Just(m)));
        (
            prop::collection::vec(prop::array::uniform3(number()), n as usize),
            prop::collection::vec(face, 0..4),
            matrix(),
        )
            .prop_map(|(vertices, faces, matrix)| Obj { vertices, faces, matrix })
    })
}

fn op(objects: u32, materials: u32) -> impl Strategy<Value = Op> {
    let st = prop_oneof![8 => 0.0f32..=1.0, 1 => number()];
    prop_oneof![
        (index(objects), matrix()).prop_map(|(o, m)| Op::SetMatrix(o, m)),
        (index(materials), prop::array::uniform3(number())).prop_map(|(m, e)| Op::SetEmission(m, e)),
        (
            prop_oneof![8 => -5.0f64..5.0, 1 => Just(f64::NAN), 1 => Just(f64::INFINITY)],
            prop_oneof![3 => Just(u32::MAX), 1 => 0u32..4],
        )
            .prop_map(|(f, c)| Op::Solve(f, c)),
        (index(objects), prop_oneof![3 => Just(0i64), 1 => -2i64..3])
            .prop_map(|(o, d)| Op::FaceRadiosity(o, d)),
        (index(objects), prop_oneof![3 => Just(0i64), 1 => -2i64..3])
            .prop_map(|(o, d)| Op::CornerRadiosity(o, d)),
        prop::collection::vec((index(objects), index(4), st.clone(), st), 0..4).prop_map(Op::Eval),
        (0usize..400).prop_map(Op::Stats),
        index(objects).prop_map(Op::Counts),
        Just(Op::Cancel),
        any::<bool>().prop_map(Op::Preview),
        prop_oneof![3 => Just(u32::MAX), 1 => 0u32..4].prop_map(Op::Refine),
    ]
}

fn case() -> impl Strategy<Value = Case> {
    (settings(), 0u32..4, 0u32..4).prop_flat_map(|(settings, nm, no)| {
        (
            Just(settings),
            prop::collection::vec(
                (prop::array::uniform3(unit()), prop::array::uniform3(number()))
                    .prop_map(|(r, e)| [r[0], r[1], r[2], e[0].abs(), e[1].abs(), e[2].abs()]),
                nm as usize,
            ),
            prop::collection::vec(object(nm), no as usize),
            any::<bool>(),
            fault(),
            (any::<bool>(), any::<bool>()),
            prop::collection::vec(op(no, nm), 0..8),
        )
            .prop_map(
                |(settings, materials, objects, with_matrices, fault, (solve_first, preview), ops)| Case {
                    settings,
                    materials,
                    objects,
                    with_matrices,
                    fault,
                    solve_first,
                    preview,
                    ops,
                },
            )
    })
}

fn last_error() -> String {
    let mut buf = vec![0u8; 4096];
    let n = unsafe { gr_last_error(buf.as_mut_ptr().cast(), buf.len()) };
    let s = CStr::from_bytes_until_nul(&buf).unwrap().to_str().unwrap().to_owned();
    assert_eq!(n.min(4095), s.len());
    s
}

/// The status is defined, not a caught panic, and the last error agrees with it.
fn check(what: &str, st: GrStatus) -> Result<GrStatus, TestCaseError> {
    let code = st as u32;
    prop_assert!(code <= 6, "{what}: status {code} is not a GrStatus");
    let msg = last_error();
    prop_assert!(st != GrStatus::Internal, "{what}: internal error: {msg}");
    if st == GrStatus::Ok {
        prop_assert!(msg.is_empty(), "{what}: OK with a message: {msg}");
    } else {
        prop_assert!(!msg.is_empty(), "{what}: {st:?} without a message");
    }
    Ok(st)
}

const SENTINEL: f32 = -12345.0;

/// What the cases reached: sessions made, frames solved, reads that returned values.
static RUNS: AtomicUsize = AtomicUsize::new(0);
static SESSIONS: AtomicUsize = AtomicUsize::new(0);
static SOLVED: AtomicUsize = AtomicUsize::new(0);
static CANCELLED: AtomicUsize = AtomicUsize::new(0);
static REFINED: AtomicUsize = AtomicUsize::new(0);
static READS: AtomicUsize = AtomicUsize::new(0);
static DIVERGED: AtomicUsize = AtomicUsize::new(0);

/// The case being run and since when, for [`watchdog`].
static CURRENT: Mutex<Option<(Instant, Case)>> = Mutex::new(None);

/// A case runs in milliseconds; one that has run for `limit` has hung (a solve that never
/// stopped hung CI for its whole 90 minutes once). Prints the case, so it can be replayed, and
/// ends the process: a failure with its input instead of a timeout without one.
fn watchdog(limit: Duration) {
    std::thread::spawn(move || {
        loop {
            std::thread::sleep(Duration::from_secs(1));
            if let Some((since, case)) = &*CURRENT.lock().unwrap()
                && since.elapsed() > limit
            {
                eprintln!("a case has run for over {limit:?}; it is:\n{case:#?}");
                std::process::exit(101);
            }
        }
    });
}

fn ptr<T>(v: &[T], null_it: bool) -> *const T {
    if null_it { null() } else { v.as_ptr() }
}

/// Builds the arrays of `gr_session_new` from `c`, calls it, then runs the ops on the session.
fn run(c: &Case) -> Result<(), TestCaseError> {
    RUNS.fetch_add(1, Ordering::Relaxed);
    *CURRENT.lock().unwrap() = Some((Instant::now(), c.clone()));
    let nm = c.materials.len();
    let reflectance: Vec<f32> = c.materials.iter().flat_map(|m| m[..3].to_vec()).collect();
    let emission: Vec<f32> = c.materials.iter().flat_map(|m| m[3..].to_vec()).collect();
    let mut vertex_counts: Vec<u32> = c.objects.iter().map(|o| o.vertices.len() as u32).collect();
    let mut face_counts: Vec<u32> = c.objects.iter().map(|o| o.faces.len() as u32).collect();
    let mut vertices: Vec<f32> = c.objects.iter().flat_map(|o| o.vertices.concat()).collect();
    let mut face_vertex_counts = Vec::new();
    let mut face_indices = Vec::new();
    let mut face_materials = Vec::new();
    for o in &c.objects {
        for (idx, m) in &o.faces {
            face_vertex_counts.push(idx.len() as u32);
            face_indices.extend(idx);
            face_materials.push(*m);
        }
    }
    let matrices: Vec<f32> = c.objects.iter().flat_map(|o| o.matrix).collect();
    let (mut dv, mut di, mut nulls) = (0i64, 0i64, 0u32);
    let mut settings = c.settings;
    match c.fault {
        Fault::None => {}
        Fault::Setting(k, v) => {
            let v32 = v as u32;
            match k {
                0 => settings.basis_order = v32,
                1 => settings.quadrature_order = v32,
                2 => settings.tolerance = f64::from_bits(v),
                3 => settings.visibility = v32,
                4 => settings.visibility_samples = v32,
                5 => settings.threads = v32,
                6 => settings.corner_gather = v32,
                8 => settings.memory_budget_mb = v,
                9 => settings.reflecting_backs = v32,
                _ => settings.method = v32,
            }
        }
        Fault::VerticesLen(d) => dv = d,
        Fault::FaceIndicesLen(d) => di = d,
        Fault::Count(o, faces, n) => {
            if !c.objects.is_empty() {
                let o = o % c.objects.len();
                if faces {
                    face_counts[o] = n;
                } else {
                    vertex_counts[o] = n;
                }
            }
        }
        Fault::Null(k) => nulls = 1 << k,
    }
    let vertices_len = (vertices.len() as i64 + dv).max(0) as usize;
    let face_indices_len = (face_indices.len() as i64 + di).max(0) as usize;
    // The buffers hold at least what the lengths claim.
    vertices.resize(vertices.len().max(vertices_len), 0.5);
    face_indices.resize(face_indices.len().max(face_indices_len), 0);
    // Per-face arrays as long as the face counts say (when they can be allocated; a huge count
    // cannot fit face_indices_len, which the ABI checks before reading them).
    let nf: u64 = face_counts.iter().map(|&n| u64::from(n)).sum();
    if nf <= 10_000 {
        face_vertex_counts.resize(nf as usize, 3);
        face_materials.resize(nf as usize, 0);
    } else {
        prop_assert!(nf * 3 > face_indices_len as u64);
    }
    let is_null = |k: u32| nulls & (1 << k) != 0;
    let mut out: *mut GrSession = std::ptr::dangling_mut::<GrSession>();
    let st = unsafe {
        gr_session_new(
            if is_null(0) { null() } else { (&raw const settings).cast::<GrSettings>() },
            nm as u32,
            ptr(&reflectance, is_null(1)),
            ptr(&emission, is_null(2)),
            c.objects.len() as u32,
            ptr(&vertex_counts, is_null(3)),
            ptr(&vertices, is_null(4)),
            ptr(&face_counts, is_null(5)),
            ptr(&face_vertex_counts, is_null(6)),
            ptr(&face_indices, is_null(7)),
            ptr(&face_materials, is_null(8)),
            if c.with_matrices { ptr(&matrices, is_null(9)) } else { null() },
            vertices_len,
            face_indices_len,
            if is_null(10) { null_mut() } else { &mut out },
        )
    };
    check("gr_session_new", st)?;
    if st != GrStatus::Ok {
        if std::env::var_os("FFI_PROPS_DEBUG").is_some() {
            eprintln!("rejected: {}", last_error());
        }
        prop_assert_eq!(out, std::ptr::dangling_mut::<GrSession>(), "out written on failure");
        return Ok(());
    }
    prop_assert!(!out.is_null() && out != std::ptr::dangling_mut::<GrSession>());
    SESSIONS.fetch_add(1, Ordering::Relaxed);
    let s = out;
    let result = run_ops(s, c);
    unsafe { gr_session_free(s) };
    result
}

unsafe extern "C" fn stop_after(_f: f64, _stage: *const std::ffi::c_char, user: *mut c_void) -> i32 {
    let left = unsafe { &mut *(user as *mut u32) };
    if *left == 0 {
        return 0;
    }
    *left -= 1;
    1
}

/// A solve of a valid scene fails only when its kernel makes the solution diverge (random faces
/// that cross or overlap, with visibility off or one visibility sample), and says so.
fn diverged(st: GrStatus) -> Result<(), TestCaseError> {
    let msg = last_error();
    // Or, since issue 23, when a placement has no area or is out of range at that frame, or a
    // face's mean comes out negative beyond rounding (random faces that cross).
    let refused = ["diverges", " at frame ", "is negative", "not finite"];
    prop_assert!(
        st == GrStatus::InvalidScene && refused.iter().any(|r| msg.contains(r)),
        "solve_frame: {st:?}: {msg}"
    );
    DIVERGED.fetch_add(1, Ordering::Relaxed);
    if std::env::var_os("FFI_PROPS_DEBUG").is_some()
        && let Some((_, case)) = &*CURRENT.lock().unwrap()
    {
        eprintln!("diverged: {msg}\n{case:#?}");
    }
    Ok(())
}

fn run_ops(s: *mut GrSession, c: &Case) -> Result<(), TestCaseError> {
    let mut solved = false;
    let mut n = 0u32;
    check("gr_session_object_count", unsafe { gr_session_object_count(s, &mut n) })?;
    prop_assert_eq!(n as usize, c.objects.len());
    if c.preview {
        prop_assert_eq!(check("set_preview", unsafe { gr_session_set_preview(s, 1) })?, GrStatus::Ok);
    }
    if c.solve_first {
        let st = check("solve_frame", unsafe { gr_session_solve_frame(s, 1.0, None, null_mut()) })?;
        if st == GrStatus::Ok {
            SOLVED.fetch_add(1, Ordering::Relaxed);
            solved = true;
        } else {
            diverged(st)?;
        }
    }
    for op in &c.ops {
        match op {
            Op::SetMatrix(o, m) => {
                check("set_object_matrix", unsafe { gr_session_set_object_matrix(s, *o, m.as_ptr()) })?;
            }
            Op::SetEmission(m, e) => {
                check("set_material_emission", unsafe {
                    gr_session_set_material_emission(s, *m, e.as_ptr())
                })?;
            }
            Op::Solve(frame, calls) => {
                let mut left = *calls;
                let st = check("solve_frame", unsafe {
                    gr_session_solve_frame(s, *frame, Some(stop_after), (&raw mut left).cast())
                })?;
                solved |= st == GrStatus::Ok;
                match st {
                    GrStatus::Ok => _ = SOLVED.fetch_add(1, Ordering::Relaxed),
                    GrStatus::Cancelled => _ = CANCELLED.fetch_add(1, Ordering::Relaxed),
                    GrStatus::InvalidArgument => {}
                    _ => diverged(st)?,
                }
            }
            Op::FaceRadiosity(o, d) | Op::CornerRadiosity(o, d) => {
                let corners = matches!(op, Op::CornerRadiosity(..));
                let mut count = 0u32;
                let st = check("count", unsafe {
                    if corners {
                        gr_session_corner_count(s, *o, &mut count)
                    } else {
                        gr_session_face_count(s, *o, &mut count)
                    }
                })?;
                let need = 3 * count as i64;
                let len = (need + d).max(0) as usize;
                let mut buf = vec![SENTINEL; len + 3];
                let st2 = check("radiosity", unsafe {
                    if corners {
                        gr_session_corner_radiosity(s, *o, buf.as_mut_ptr(), len)
                    } else {
                        gr_session_face_radiosity(s, *o, buf.as_mut_ptr(), len)
                    }
                })?;
                let ok = st == GrStatus::Ok && len as i64 >= need && solved;
                prop_assert_eq!(st2 == GrStatus::Ok, ok, "{:?}: {}", st2, last_error());
                if st2 == GrStatus::Ok {
                    READS.fetch_add(1, Ordering::Relaxed);
                    prop_assert!(buf[..need as usize].iter().all(|v| *v != SENTINEL));
                    prop_assert!(buf[need as usize..].iter().all(|v| *v == SENTINEL));
                } else {
                    prop_assert!(buf.iter().all(|v| *v == SENTINEL), "written on failure");
                }
                if !solved && st == GrStatus::Ok && len as i64 >= need {
                    prop_assert_eq!(st2, GrStatus::NotSolved);
                }
            }
            Op::Eval(points) => {
                let objects: Vec<u32> = points.iter().map(|p| p.0).collect();
                let faces: Vec<u32> = points.iter().map(|p| p.1).collect();
                let st: Vec<f32> = points.iter().flat_map(|p| [p.2, p.3]).collect();
                let mut out = vec![SENTINEL; 3 * points.len()];
                let r = check("eval", unsafe {
                    gr_session_eval(
                        s,
                        points.len(),
                        objects.as_ptr(),
                        faces.as_ptr(),
                        st.as_ptr(),
                        out.as_mut_ptr(),
                    )
                })?;
                if r != GrStatus::Ok {
                    prop_assert!(out.iter().all(|v| *v == SENTINEL), "written on failure");
                }
                if !solved {
                    prop_assert_eq!(r, GrStatus::NotSolved);
                }
            }
            Op::Stats(len) => {
                let mut buf = vec![0x55u8; *len];
                let mut written = 0usize;
                let r = check("frame_stats_json", unsafe {
                    gr_session_frame_stats_json(s, buf.as_mut_ptr().cast(), *len, &mut written)
                })?;
                if r == GrStatus::Ok {
                    let text = CStr::from_bytes_until_nul(&buf).unwrap().to_str().unwrap();
                    prop_assert_eq!(text.len() + 1, written);
                    let v: serde_json::Value = serde_json::from_str(text).unwrap();
                    prop_assert!(v.get("frame").is_some());
                } else {
                    prop_assert!(buf.iter().all(|b| *b == 0x55));
                }
                prop_assert_eq!(r == GrStatus::NotSolved, !solved);
            }
            Op::Counts(o) => {
                let mut f = u32::MAX;
                let mut k = u32::MAX;
                let a = check("face_count", unsafe { gr_session_face_count(s, *o, &mut f) })?;
                let b = check("corner_count", unsafe { gr_session_corner_count(s, *o, &mut k) })?;
                prop_assert_eq!(a, b);
                if a == GrStatus::Ok {
                    prop_assert!(3 * f <= k && k <= 4 * f);
                } else {
                    prop_assert!(f == u32::MAX && k == u32::MAX);
                }
            }
            Op::Cancel => {
                check("cancel", unsafe { gr_session_cancel(s) })?;
            }
            Op::Preview(on) => {
                let st = check("set_preview", unsafe { gr_session_set_preview(s, u32::from(*on)) })?;
                prop_assert_eq!(st, GrStatus::Ok);
            }
            Op::Refine(calls) => {
                let (mut left, mut refined) = (*calls, 7u32);
                let st = check("refine", unsafe {
                    gr_session_refine(s, Some(stop_after), (&raw mut left).cast(), &mut refined)
                })?;
                match st {
                    GrStatus::Ok => {
                        prop_assert!(refined <= 1, "refined = {refined}");
                        REFINED.fetch_add(refined as _, Ordering::Relaxed);
                    }
                    GrStatus::Cancelled => _ = CANCELLED.fetch_add(1, Ordering::Relaxed),
                    GrStatus::NotSolved => prop_assert!(!solved, "refine: no frame, after a solve"),
                    _ => diverged(st)?,
                }
            }
        }
    }
    Ok(())
}

fn config() -> Config {
    let cases = std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(256);
    Config { cases, failure_persistence: None, ..Config::default() }
}

#[test]
fn arbitrary_input_never_crashes() {
    let config = config();
    let cases = config.cases;
    watchdog(Duration::from_secs(60));
    let mut runner = TestRunner::new(config);
    let result = runner.run(&case(), |c| run(&c));
    eprintln!(
        "{cases} cases ({} runs): {} sessions made, {} frames solved, {} previews refined, {} \
         cancelled, {} diverged, {} radiosity reads",
        RUNS.load(Ordering::Relaxed),
        SESSIONS.load(Ordering::Relaxed),
        SOLVED.load(Ordering::Relaxed),
        REFINED.load(Ordering::Relaxed),
        CANCELLED.load(Ordering::Relaxed),
        DIVERGED.load(Ordering::Relaxed),
        READS.load(Ordering::Relaxed),
    );
    if let Err(e) = result {
        panic!("{e}");
    }
}
