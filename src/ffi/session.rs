//! `GrSession`: a baking session behind an opaque pointer.
//!
//! Soundness: exported functions only ever make shared references to a `GrSession`. The
//! `Session` sits in a `RwLock` that is only ever *tried*, never waited on, so an overlapping
//! call (from the progress callback or another thread) fails with a "busy" message instead of
//! deadlocking; `gr_session_cancel` only touches the atomic flag and works at any time. Counts are
//! fixed at creation and kept outside the lock.

use std::ffi::{CString, c_char, c_void};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock, RwLock, RwLockReadGuard, RwLockWriteGuard, TryLockError};

use glam::{DMat4, DVec3};

use super::error::{Failure, GrStatus};
use super::panic::{boundary, boundary_value};
use super::settings::{GrSettings, read_settings};
use crate::scene::json::ObjectResult;
use crate::scene::{Material, Object, Scene};
use crate::session::{FrameStats, Session};

/// An opaque baking session: a validated scene, its thread pool, and the solution of the last
/// completed frame. Create with `gr_session_new`, release with `gr_session_free`.
pub struct GrSession {
    state: RwLock<State>,
    cancel: Arc<AtomicBool>,
    /// Faces and face corners per object (fixed at creation).
    faces: Vec<u32>,
    corners: Vec<u32>,
}

pub(super) struct State {
    pub(super) session: Session,
    /// Statistics of the last completed frame.
    stats: Option<FrameStats>,
    /// Face and corner radiosity of the last completed frame, made on first read.
    results: OnceLock<Vec<ObjectResult>>,
}

/// Progress callback: `fraction` done in `[0,1]`, a short NUL-terminated `stage` name (valid only
/// during the call), and the `user` pointer given to `gr_session_solve_frame`. Return 0 to
/// cancel, non-zero to go on.
///
/// The callback may be called from the solver's worker threads, never from two threads at once
/// (calls are serialized by a lock). It must not call functions on the same session other than
/// `gr_session_cancel` (they would fail with `GR_STATUS_INVALID_ARGUMENT`, "session is busy").
pub type GrProgressFn =
    Option<unsafe extern "C" fn(fraction: f64, stage: *const c_char, user: *mut c_void) -> i32>;

fn busy() -> Failure {
    Failure::invalid(
        "session is busy: another call on it is running (only gr_session_cancel may overlap a solve)",
    )
}

impl GrSession {
    fn read(&self) -> Result<RwLockReadGuard<'_, State>, Failure> {
        match self.state.try_read() {
            Ok(g) => Ok(g),
            // A panic caught while the lock was held: `Session` only commits a frame at the end
            // of `solve_frame`, so the state is still the last consistent one.
            Err(TryLockError::Poisoned(p)) => Ok(p.into_inner()),
            Err(TryLockError::WouldBlock) => Err(busy()),
        }
    }

    pub(super) fn write(&self) -> Result<RwLockWriteGuard<'_, State>, Failure> {
        match self.state.try_write() {
            Ok(g) => Ok(g),
            Err(TryLockError::Poisoned(p)) => Ok(p.into_inner()),
            Err(TryLockError::WouldBlock) => Err(busy()),
        }
    }

    fn object(&self, object: u32) -> Result<usize, Failure> {
        let o = object as usize;
        if o >= self.faces.len() {
            return Err(Failure::invalid(format!("object {object} out of range (0..{})", self.faces.len())));
        }
        Ok(o)
    }
}

impl State {
    fn results(&self) -> Result<&[ObjectResult], Failure> {
        if self.session.frame().is_none() {
            return Err(Failure::new(GrStatus::NotSolved, "no frame has been solved yet"));
        }
        if let Some(r) = self.results.get() {
            return Ok(r);
        }
        let r = self.session.face_results()?;
        Ok(self.results.get_or_init(|| r))
    }
}

/// A shared reference to the session behind `s`.
///
/// # Safety
/// `s` is NULL or a live pointer from `gr_session_new`.
pub(super) unsafe fn session<'a>(s: *const GrSession) -> Result<&'a GrSession, Failure> {
    if s.is_null() {
        return Err(Failure::null("session"));
    }
    // SAFETY: per the contract, a live session; only shared references are ever made.
    Ok(unsafe { &*s })
}

/// Checks that `p` can be read as `len` values of `T`.
fn check_array<T>(p: *const T, len: usize, what: &str) -> Result<(), Failure> {
    if len == 0 {
        return Ok(());
    }
    if p.is_null() {
        return Err(Failure::null(what));
    }
    if !p.is_aligned() {
        return Err(Failure::invalid(format!("{what} is not aligned for its element type")));
    }
    if len.checked_mul(size_of::<T>()).is_none_or(|bytes| bytes > isize::MAX as usize) {
        return Err(Failure::invalid(format!("{what}: {len} elements is more than any buffer can hold")));
    }
    Ok(())
}

/// `len` values of `T` at `p` (NULL allowed when `len` is 0).
///
/// # Safety
/// When `len > 0`, `p` points to `len` readable values that are not written during `'a`.
pub(super) unsafe fn array<'a, T>(p: *const T, len: usize, what: &str) -> Result<&'a [T], Failure> {
    check_array(p, len, what)?;
    if len == 0 {
        return Ok(&[]);
    }
    // SAFETY: checked non-null, aligned and not too long; readable per the contract.
    Ok(unsafe { std::slice::from_raw_parts(p, len) })
}

/// Copies `values` to `out`, which holds `len` values (NULL allowed when nothing is copied).
///
/// # Safety
/// When `len > 0`, `out` points to `len` writable values.
unsafe fn write_out<T: Copy>(out: *mut T, len: usize, values: &[T], what: &str) -> Result<(), Failure> {
    if len < values.len() {
        return Err(Failure::invalid(format!("{what} holds {len} values, {} are needed", values.len())));
    }
    check_array(out.cast_const(), values.len(), what)?;
    if !values.is_empty() {
        // SAFETY: out holds at least values.len() writable values; values is our own memory.
        unsafe { std::ptr::copy_nonoverlapping(values.as_ptr(), out, values.len()) };
    }
    Ok(())
}

/// A row-major 4x4 of f32 as a world-from-object matrix.
pub(super) fn matrix_from_row_major(m: &[f32]) -> DMat4 {
    let mut a = [0.0f64; 16];
    for (d, s) in a.iter_mut().zip(m) {
        *d = f64::from(*s);
    }
    DMat4::from_cols_array(&a).transpose()
}

pub(super) fn rgb(v: &[f32]) -> [f64; 3] {
    [f64::from(v[0]), f64::from(v[1]), f64::from(v[2])]
}

/// The sum of `counts` (cannot overflow: at most 2^32 values below 2^32).
fn total(counts: &[u32]) -> u64 {
    counts.iter().map(|&c| u64::from(c)).sum()
}

fn to_usize(n: u64, what: &str) -> Result<usize, Failure> {
    usize::try_from(n).map_err(|_| Failure::invalid(format!("{what}: {n} is too large")))
}

/// Arrays of `gr_session_new`, already checked against each other.
struct Mesh<'a> {
    vertex_counts: &'a [u32],
    face_counts: &'a [u32],
    vertices: &'a [f32],
    face_vertex_counts: &'a [u32],
    face_indices: &'a [u32],
    face_materials: &'a [u32],
    matrices: Option<&'a [f32]>,
}

impl Mesh<'_> {
    fn objects(&self) -> Vec<Object> {
        let mut objects = Vec::with_capacity(self.vertex_counts.len());
        let (mut v0, mut f0, mut i0) = (0usize, 0usize, 0usize);
        for (o, (&nv, &nf)) in self.vertex_counts.iter().zip(self.face_counts).enumerate() {
            let (nv, nf) = (nv as usize, nf as usize);
            let vertices = self.vertices[3 * v0..3 * (v0 + nv)]
                .chunks_exact(3)
                .map(|p| DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])))
                .collect();
            let mut faces = Vec::with_capacity(nf);
            for &k in &self.face_vertex_counts[f0..f0 + nf] {
                let k = k as usize;
                faces.push(self.face_indices[i0..i0 + k].to_vec());
                i0 += k;
            }
            let matrix =
                self.matrices.map_or(DMat4::IDENTITY, |m| matrix_from_row_major(&m[16 * o..16 * o + 16]));
            objects.push(Object {
                name: format!("object {o}"),
                vertices,
                faces,
                face_materials: self.face_materials[f0..f0 + nf].to_vec(),
                matrix,
                animation: Vec::new(),
            });
            v0 += nv;
            f0 += nf;
        }
        objects
    }
}

/// Creates a session from a scene given as flat arrays and writes it to `*out`.
///
/// **Deprecated** since ABI version 2: use the scene builder (`gr_scene_builder_new`,
/// `gr_scene_builder_add_material`, `gr_scene_builder_add_mesh`, `gr_scene_builder_add_light`,
/// `gr_scene_builder_set_settings`, `gr_scene_builder_build`), which can take new kinds of input
/// without changing a signature. This function keeps working as documented here.
///
/// - `settings`: see `GrSettings`.
/// - `material_count` materials: `reflectance` and `emission` hold 3 floats (RGB) per material.
///   Emission is radiant exitance in W/m^2; reflectance is in [0,1).
/// - `object_count` objects: object `i` has `object_vertex_counts[i]` vertices and
///   `object_face_counts[i]` faces. `vertices` holds 3 floats per vertex (object space), the
///   objects one after another; `vertices_len` is its length in floats and must be 3 x the sum
///   of the vertex counts.
/// - `face_vertex_counts`: one entry per face (sum of the face counts), each 3 or 4.
///   `face_indices`: the vertex indices of every face in order, local to the face's object,
///   counter-clockwise seen from the lit (front) side; `face_indices_len` is its length and must
///   be the sum of `face_vertex_counts`. `face_materials`: one material index per face.
/// - `matrices`: 16 floats per object, row-major world-from-object (translation in elements 3,
///   7, 11), or NULL for identity.
///
/// An array may be NULL only when its length is 0. The arrays are read during the call only.
/// Objects are named "object 0", "object 1", ... in messages. Faces of zero area are kept but
/// skipped by the solver (they read back their own emission).
///
/// Returns `GR_STATUS_INVALID_ARGUMENT` when the lengths disagree with the counts or a setting's
/// enum value is unknown, `GR_STATUS_INVALID_SCENE` (with a message naming the object, face or
/// field) when the scene fails validation. `*out` is written only on success.
///
/// # Safety
/// Every non-NULL pointer points to at least as many readable elements as described above.
/// `out` points to a writable `GrSession *`.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn gr_session_new(
    settings: *const GrSettings,
    material_count: u32,
    reflectance: *const f32,
    emission: *const f32,
    object_count: u32,
    object_vertex_counts: *const u32,
    vertices: *const f32,
    object_face_counts: *const u32,
    face_vertex_counts: *const u32,
    face_indices: *const u32,
    face_materials: *const u32,
    matrices: *const f32,
    vertices_len: usize,
    face_indices_len: usize,
    out: *mut *mut GrSession,
) -> GrStatus {
    boundary("gr_session_new", || {
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        if !out.is_aligned() {
            return Err(Failure::invalid("out is not aligned for a pointer"));
        }
        // SAFETY (all `array` calls): lengths as in the contract above.
        let (settings, method) = unsafe { read_settings(settings) }?;
        let nm = material_count as usize;
        let reflectance = unsafe { array(reflectance, 3 * nm, "reflectance") }?;
        let emission = unsafe { array(emission, 3 * nm, "emission") }?;
        let no = object_count as usize;
        let vertex_counts = unsafe { array(object_vertex_counts, no, "object_vertex_counts") }?;
        let face_counts = unsafe { array(object_face_counts, no, "object_face_counts") }?;
        let nv = total(vertex_counts);
        if Some(vertices_len as u64) != nv.checked_mul(3) {
            return Err(Failure::invalid(format!(
                "vertices_len is {vertices_len} but the object vertex counts sum to {nv} \
                 vertices, which need {} floats",
                u128::from(nv) * 3
            )));
        }
        let nf = total(face_counts);
        // Each face has 3 or 4 vertices: check the face count against face_indices_len before
        // reading the per-face arrays, whose lengths C cannot tell us.
        let lo = u128::from(nf) * 3;
        let hi = u128::from(nf) * 4;
        if !(lo..=hi).contains(&(face_indices_len as u128)) {
            return Err(Failure::invalid(format!(
                "face_indices_len is {face_indices_len} but the object face counts sum to {nf} \
                 faces, which need {lo}..={hi} indices (3 or 4 per face)"
            )));
        }
        let nf = to_usize(nf, "face count")?;
        let vertices = unsafe { array(vertices, vertices_len, "vertices") }?;
        let fvc = unsafe { array(face_vertex_counts, nf, "face_vertex_counts") }?;
        let ni = total(fvc);
        if ni != face_indices_len as u64 {
            return Err(Failure::invalid(format!(
                "face_indices_len is {face_indices_len} but face_vertex_counts sum to {ni}"
            )));
        }
        let face_indices = unsafe { array(face_indices, face_indices_len, "face_indices") }?;
        let face_materials = unsafe { array(face_materials, nf, "face_materials") }?;
        let matrices =
            if matrices.is_null() { None } else { Some(unsafe { array(matrices, 16 * no, "matrices") }?) };
        let materials = (0..nm)
            .map(|m| Material {
                name: format!("material {m}"),
                reflectance: rgb(&reflectance[3 * m..]),
                emission: rgb(&emission[3 * m..]),
            })
            .collect();
        let mesh = Mesh {
            vertex_counts,
            face_counts,
            vertices,
            face_vertex_counts: fvc,
            face_indices,
            face_materials,
            matrices,
        };
        let objects = mesh.objects();
        let boxed = GrSession::create(settings, method, materials, objects, Vec::new())?;
        // SAFETY: out is non-null, aligned and writable.
        unsafe { out.write(Box::into_raw(boxed)) };
        Ok(())
    })
}

impl GrSession {
    /// Validates the scene and makes the session behind a handle (`gr_session_new` and
    /// `gr_scene_builder_build`).
    pub(super) fn create(
        settings: crate::scene::Settings,
        method: crate::session::Method,
        materials: Vec<Material>,
        objects: Vec<Object>,
        lights: Vec<crate::lights::Light>,
    ) -> Result<Box<GrSession>, Failure> {
        let count = |o: usize, n: usize, what: &str| {
            u32::try_from(n)
                .map_err(|_| Failure::invalid(format!("object {o} has {n} {what}, above 2^32 - 1")))
        };
        let mut faces = Vec::with_capacity(objects.len());
        let mut corners = Vec::with_capacity(objects.len());
        for (o, object) in objects.iter().enumerate() {
            faces.push(count(o, object.faces.len(), "faces")?);
            corners.push(count(o, object.faces.iter().map(Vec::len).sum(), "face corners")?);
        }
        let nm = materials.len();
        let scene = Scene::new(settings, (1, 1), materials, vec![Vec::new(); nm], objects)?;
        let mut session = Session::new(scene, method)?;
        if !lights.is_empty() {
            session.set_lights(lights)?;
        }
        Ok(Box::new(GrSession {
            state: RwLock::new(State { session, stats: None, results: OnceLock::new() }),
            cancel: Arc::new(AtomicBool::new(false)),
            faces,
            corners,
        }))
    }
}

/// Overrides object `object`'s world-from-object matrix (16 floats, row-major) from the next
/// solved frame on. `GR_STATUS_INVALID_ARGUMENT` when the object is out of range or the matrix
/// is not finite.
///
/// # Safety
/// `s` is NULL or a live session; `matrix` is NULL or points to 16 readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_object_matrix(
    s: *mut GrSession,
    object: u32,
    matrix: *const f32,
) -> GrStatus {
    boundary("gr_session_set_object_matrix", || {
        let s = unsafe { session(s) }?;
        let o = s.object(object)?;
        if matrix.is_null() {
            return Err(Failure::null("matrix"));
        }
        let m = unsafe { array(matrix, 16, "matrix") }?;
        let m = matrix_from_row_major(m);
        s.write()?.session.set_object_matrix(o, m)?;
        Ok(())
    })
}

/// Overrides material `material`'s emission (3 floats, RGB, W/m^2, finite and >= 0) from the
/// next solved frame on.
///
/// # Safety
/// `s` is NULL or a live session; `rgb` is NULL or points to 3 readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_material_emission(
    s: *mut GrSession,
    material: u32,
    rgb: *const f32,
) -> GrStatus {
    boundary("gr_session_set_material_emission", || {
        let s = unsafe { session(s) }?;
        if rgb.is_null() {
            return Err(Failure::null("rgb"));
        }
        let e = unsafe { array(rgb, 3, "rgb") }?;
        s.write()?.session.set_material_emission(material as usize, self::rgb(e))?;
        Ok(())
    })
}

/// The C callback and its user pointer, shared with the solver's worker threads.
struct Callback {
    f: GrProgressFn,
    user: *mut c_void,
    /// Serializes calls into C.
    lock: Mutex<()>,
    /// Set once the callback returned 0: it is not called again.
    stopped: AtomicBool,
}

// SAFETY: the C side is told that the callback and `user` are used from worker threads, one
// call at a time (`lock`).
unsafe impl Sync for Callback {}

impl Callback {
    fn call(&self, fraction: f64, stage: &str) -> bool {
        let Some(f) = self.f else { return true };
        let _serial = self.lock.lock().unwrap_or_else(|p| p.into_inner());
        if self.stopped.load(Ordering::Relaxed) {
            return false;
        }
        let stage = CString::new(stage).unwrap_or_default();
        // SAFETY: the host's callback, called as documented with a NUL-terminated stage.
        let go = unsafe { f(fraction, stage.as_ptr(), self.user) } != 0;
        if !go {
            self.stopped.store(true, Ordering::Relaxed);
        }
        go
    }
}

/// Runs `work` with the progress function a long call gives the session: the host's `progress`
/// (serialized, see [`Callback`]) and the session's cancel flag, which is cleared first.
fn with_progress<T>(
    s: &GrSession,
    progress: GrProgressFn,
    user: *mut c_void,
    work: impl FnOnce(crate::system::Progress) -> T,
) -> T {
    s.cancel.store(false, Ordering::SeqCst);
    let callback = Callback { f: progress, user, lock: Mutex::new(()), stopped: AtomicBool::new(false) };
    let cancel = &*s.cancel;
    let go_on = |fraction: f64, stage: &str| -> bool {
        !cancel.load(Ordering::Relaxed) && callback.call(fraction, stage) && !cancel.load(Ordering::Relaxed)
    };
    work(&go_on)
}

/// Solves `frame` (finite; object placements and emissions as overridden so far). Blocks until
/// the frame is solved, cancelled or fails. Clears the cancel flag when it starts.
///
/// `progress` may be NULL; see `GrProgressFn` (it may be called from worker threads).
/// Returns `GR_STATUS_CANCELLED` when `progress` returned 0 or `gr_session_cancel` was called;
/// then, as on any error, the last completed frame stays readable.
///
/// # Safety
/// `s` is NULL or a live session that no other thread frees during the call; `progress`, if not
/// NULL, may be called with `user` from any thread during the call.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_solve_frame(
    s: *mut GrSession,
    frame: f64,
    progress: GrProgressFn,
    user: *mut c_void,
) -> GrStatus {
    boundary("gr_session_solve_frame", || {
        let s = unsafe { session(s) }?;
        let mut state = s.write()?;
        let stats = with_progress(s, progress, user, |go_on| state.session.solve_frame(frame, go_on))?;
        state.stats = Some(stats);
        state.results = OnceLock::new();
        Ok(())
    })
}

/// While `on` is non-zero, `gr_session_solve_frame` solves previews: to a looser tolerance (ten
/// times the settings' `tolerance`, at most 1e-3 unless the tolerance is looser) and without the
/// corner gather (the corners are the face polynomials' values), until `gr_session_refine`
/// finishes the frame. For a host that previews while the user scrubs the timeline: such a frame
/// costs its kernel update and a shorter solve, and only the frame the user stops on is refined.
/// The frame statistics' `preview` says which a frame is. Starts at 0.
///
/// # Safety
/// `s` is NULL or a live session.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_preview(s: *mut GrSession, on: u32) -> GrStatus {
    boundary("gr_session_set_preview", || {
        let s = unsafe { session(s) }?;
        s.write()?.session.set_preview(on != 0);
        Ok(())
    })
}

/// Says whether frames will follow the next one (non-zero `on`): a host that bakes an animation,
/// or previews while the timeline is scrubbed, moving objects with
/// `gr_session_set_object_matrix`. With `GR_METHOD_HIERARCHICAL` the hierarchy then keeps the
/// record of its refinement (about 14 bytes per stored pair), so that a frame's update links
/// coarser again where a moving object has passed instead of only finer. Set it before the first
/// frame: a change after it solves the next frame afresh. Starts at 0; other methods ignore it.
///
/// # Safety
/// `s` is NULL or a live session.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_animated(s: *mut GrSession, on: u32) -> GrStatus {
    boundary("gr_session_set_animated", || {
        let s = unsafe { session(s) }?;
        s.write()?.session.set_animated(on != 0);
        Ok(())
    })
}

/// Brings the last solved frame from a preview (see `gr_session_set_preview`) to what a solve
/// without previews gives: continues its solve down to the settings' tolerance, then gathers its
/// corners (with `corner_gather` on), reusing the last gather made where nothing that decides a
/// corner changed since. `GR_STATUS_OK` at once when the frame is no preview. Writes 1 to
/// `*refined` (if not NULL) when it refined, else 0. The frame statistics then describe the whole
/// frame (`preview` 0, its solve's time and shots included, the gather's fields this gather's).
/// After a cancelled `gr_session_solve_frame` the frame is built and solved afresh instead (its
/// links were the cancelled frame's; the statistics' `full_rebuild` true).
///
/// `progress` and cancelling as for `gr_session_solve_frame`. On `GR_STATUS_CANCELLED` or another
/// error the frame stays readable and a preview (refine it again later), solved as far as the
/// refinement came, with the polynomials' corners; after a cancel inside the gather the next
/// gather starts afresh. `GR_STATUS_NOT_SOLVED` before the first solved frame.
///
/// # Safety
/// `s` is NULL or a live session that no other thread frees during the call; `progress`, if not
/// NULL, may be called with `user` from any thread during the call; `refined` is NULL or points
/// to a writable `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_refine(
    s: *mut GrSession,
    progress: GrProgressFn,
    user: *mut c_void,
    refined: *mut u32,
) -> GrStatus {
    boundary("gr_session_refine", || {
        let s = unsafe { session(s) }?;
        let mut state = s.write()?;
        if state.session.frame().is_none() {
            return Err(Failure::new(GrStatus::NotSolved, "no frame has been solved yet"));
        }
        let outcome = with_progress(s, progress, user, |go_on| state.session.refine(go_on));
        // The solution and corners changed, refined or not (a cancel keeps the shots made).
        state.results = OnceLock::new();
        let done = outcome?;
        if let Some(r) = &done {
            state.stats = state.stats.take().map(|stats| stats.refined(r));
        }
        if !refined.is_null() {
            // SAFETY: non-NULL, writable per the contract.
            unsafe { *refined = u32::from(done.is_some()) };
        }
        Ok(())
    })
}

/// Asks the running solve on `s` to stop; it returns `GR_STATUS_CANCELLED` promptly. Safe to
/// call from any thread (and from the progress callback) at any time while `s` is alive. The
/// flag is cleared when the next solve starts, so a cancel with no solve running has no effect.
///
/// # Safety
/// `s` is NULL or a live session.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_cancel(s: *const GrSession) -> GrStatus {
    boundary("gr_session_cancel", || {
        let s = unsafe { session(s) }?;
        s.cancel.store(true, Ordering::SeqCst);
        Ok(())
    })
}

/// Writes the last solved frame's statistics (the library's `FrameStats`: `frame`, `seconds`,
/// `kernel_seconds`, `solve_seconds`, `elements`, `pairs`, `shots`, link recompute counts and
/// more; new fields may be added) as a NUL-terminated JSON object into `buf` of `len` bytes.
///
/// `*written` is set to the length needed including the NUL both on success and when `buf` is
/// too small (then `GR_STATUS_INVALID_ARGUMENT` and `buf` is untouched): call with `buf = NULL`,
/// `len = 0` to size the buffer. `GR_STATUS_NOT_SOLVED` before the first solved frame.
///
/// # Safety
/// `s` is NULL or a live session; `buf` is NULL or points to `len` writable bytes; `written` is
/// NULL or points to a writable `size_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_frame_stats_json(
    s: *const GrSession,
    buf: *mut c_char,
    len: usize,
    written: *mut usize,
) -> GrStatus {
    boundary("gr_session_frame_stats_json", || {
        let s = unsafe { session(s) }?;
        if written.is_null() {
            return Err(Failure::null("written"));
        }
        if !written.is_aligned() {
            return Err(Failure::invalid("written is not aligned for size_t"));
        }
        let json = {
            let state = s.read()?;
            let Some(stats) = &state.stats else {
                return Err(Failure::new(GrStatus::NotSolved, "no frame has been solved yet"));
            };
            serde_json::to_string(stats)
                .map_err(|e| Failure::new(GrStatus::Internal, format!("stats JSON: {e}")))?
        };
        let mut bytes = json.into_bytes();
        bytes.push(0);
        // SAFETY: written is non-null, aligned and writable.
        unsafe { written.write(bytes.len()) };
        unsafe { write_out(buf.cast::<u8>(), len, &bytes, "buf") }
    })
}

/// Writes the number of objects to `*out`.
///
/// # Safety
/// `s` is NULL or a live session; `out` is NULL or points to a writable `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_object_count(s: *const GrSession, out: *mut u32) -> GrStatus {
    boundary("gr_session_object_count", || {
        let s = unsafe { session(s) }?;
        unsafe { write_out(out, 1, &[s.faces.len() as u32], "out") }
    })
}

/// Writes the number of faces of object `object` to `*out`.
///
/// # Safety
/// `s` is NULL or a live session; `out` is NULL or points to a writable `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_face_count(s: *const GrSession, object: u32, out: *mut u32) -> GrStatus {
    boundary("gr_session_face_count", || {
        let s = unsafe { session(s) }?;
        let o = s.object(object)?;
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        unsafe { write_out(out, 1, &[s.faces[o]], "out") }
    })
}

/// Writes the number of face corners of object `object` (the sum of its faces' vertex counts)
/// to `*out`.
///
/// # Safety
/// `s` is NULL or a live session; `out` is NULL or points to a writable `uint32_t`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_corner_count(
    s: *const GrSession,
    object: u32,
    out: *mut u32,
) -> GrStatus {
    boundary("gr_session_corner_count", || {
        let s = unsafe { session(s) }?;
        let o = s.object(object)?;
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        unsafe { write_out(out, 1, &[s.corners[o]], "out") }
    })
}

/// Writes the area-mean radiosity (RGB, W/m^2) of each face of object `object` at the last
/// solved frame: 3 floats per face, faces in order. `out` holds `len` floats, at least 3 x the
/// face count (`GR_STATUS_INVALID_ARGUMENT` otherwise).
///
/// # Safety
/// `s` is NULL or a live session; `out` is NULL or points to `len` writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_face_radiosity(
    s: *const GrSession,
    object: u32,
    out: *mut f32,
    len: usize,
) -> GrStatus {
    boundary("gr_session_face_radiosity", || {
        let s = unsafe { session(s) }?;
        let o = s.object(object)?;
        let need = 3 * s.faces[o] as usize;
        if len < need {
            return Err(Failure::invalid(format!(
                "out holds {len} floats, object {object} needs {need} (3 per face)"
            )));
        }
        check_array(out.cast_const(), need, "out")?;
        let state = s.read()?;
        let r = &state.results()?[o];
        unsafe { write_out(out, len, r.face_radiosity.as_flattened(), "out") }
    })
}

/// Writes the radiosity (RGB, W/m^2) at each face corner of object `object` at the last solved
/// frame: 3 floats per corner, faces in order, corners in face order. `out` holds `len` floats,
/// at least 3 x the corner count. With `corner_gather` on (the default) these are gathered at
/// each corner with its own shadow rays, except on a preview frame (`gr_session_set_preview`)
/// until it is refined; otherwise each face's polynomial there.
///
/// # Safety
/// `s` is NULL or a live session; `out` is NULL or points to `len` writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_corner_radiosity(
    s: *const GrSession,
    object: u32,
    out: *mut f32,
    len: usize,
) -> GrStatus {
    boundary("gr_session_corner_radiosity", || unsafe {
        write_corners(s, object, out, len, |r| &r.corner_radiosity)
    })
}

/// Writes the irradiance `H` (RGB, W/m^2) at each face corner of object `object` at the last
/// solved frame, laid out as `gr_session_corner_radiosity`'s values: the light the surface
/// receives (the lights' direct light, the World, the other surfaces), without its own emission
/// `E` and reflectance `rho`, so that `B = E + rho H` at each corner. A host multiplies it with a
/// material's own (textured) reflectance. Gathered with the corners (by either method); where the
/// corners come from the face polynomials (corner gather off, a preview) it is `(B - E) / rho`
/// per channel, 0 where `rho` is below 1e-4.
///
/// # Safety
/// `s` is NULL or a live session; `out` is NULL or points to `len` writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_corner_irradiance(
    s: *const GrSession,
    object: u32,
    out: *mut f32,
    len: usize,
) -> GrStatus {
    boundary("gr_session_corner_irradiance", || unsafe {
        write_corners(s, object, out, len, |r| &r.corner_irradiance)
    })
}

/// Writes the per-corner values `pick` selects of object `object` at the last solved frame to
/// `out` (`len` floats, 3 per corner): the body of `gr_session_corner_radiosity` and
/// `gr_session_corner_irradiance`.
///
/// # Safety
/// As those functions.
unsafe fn write_corners(
    s: *const GrSession,
    object: u32,
    out: *mut f32,
    len: usize,
    pick: fn(&ObjectResult) -> &Vec<[f32; 3]>,
) -> Result<(), Failure> {
    let s = unsafe { session(s) }?;
    let o = s.object(object)?;
    let need = 3 * s.corners[o] as usize;
    if len < need {
        return Err(Failure::invalid(format!(
            "out holds {len} floats, object {object} needs {need} (3 per corner)"
        )));
    }
    check_array(out.cast_const(), need, "out")?;
    let state = s.read()?;
    let r = &state.results()?[o];
    unsafe { write_out(out, len, pick(r).as_flattened(), "out") }
}

/// Evaluates the radiosity (RGB, W/m^2) of the last solved frame at `count` points: point `i` is
/// face `faces[i]` of object `objects[i]` at face parameters `(st[2i], st[2i+1])` in `[0,1]^2`
/// (corner order of the face: (0,0), (1,0), (1,1), (0,1); a triangle's third corner is the
/// collapsed edge t = 1). Writes 3 floats per point to `out`, which must not overlap the inputs.
/// Nothing is written unless every point is valid. These are the face polynomials' values (the
/// Galerkin solution itself), never gathered: for display at vertices read the corners.
///
/// # Safety
/// `s` is NULL or a live session; `objects` and `faces` point to `count` readable `uint32_t`,
/// `st` to `2 count` readable floats, `out` to `3 count` writable floats (each may be NULL only
/// when `count` is 0).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_eval(
    s: *const GrSession,
    count: usize,
    objects: *const u32,
    faces: *const u32,
    st: *const f32,
    out: *mut f32,
) -> GrStatus {
    boundary("gr_session_eval", || unsafe { eval_points(s, count, (objects, faces, st), out, Session::eval) })
}

/// As `gr_session_eval`, the irradiance `H` (RGB, W/m^2) at the points: `(B - E) / rho` per
/// channel of the face polynomial's `B` there (0 where `rho` is below 1e-4, and on a skipped
/// zero-area face), clamped at 0. Same arguments and contract as `gr_session_eval`.
///
/// # Safety
/// As `gr_session_eval`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_eval_irradiance(
    s: *const GrSession,
    count: usize,
    objects: *const u32,
    faces: *const u32,
    st: *const f32,
    out: *mut f32,
) -> GrStatus {
    boundary("gr_session_eval_irradiance", || unsafe {
        eval_points(s, count, (objects, faces, st), out, Session::eval_irradiance)
    })
}

/// The body of `gr_session_eval` and `gr_session_eval_irradiance`: `eval` at each of the
/// `count` points, 3 floats per point to `out`.
///
/// # Safety
/// As those functions.
unsafe fn eval_points(
    s: *const GrSession,
    count: usize,
    (objects, faces, st): (*const u32, *const u32, *const f32),
    out: *mut f32,
    eval: fn(&Session, usize, usize, f64, f64) -> crate::error::Result<[f64; 3]>,
) -> Result<(), Failure> {
    let s = unsafe { session(s) }?;
    let n2 = count.checked_mul(2).ok_or_else(|| Failure::invalid("count is too large"))?;
    let n3 = count.checked_mul(3).ok_or_else(|| Failure::invalid("count is too large"))?;
    check_array(out.cast_const(), n3, "out")?;
    let values = {
        let objects = unsafe { array(objects, count, "objects") }?;
        let faces = unsafe { array(faces, count, "faces") }?;
        let st = unsafe { array(st, n2, "st") }?;
        let state = s.read()?;
        if state.session.frame().is_none() {
            return Err(Failure::new(GrStatus::NotSolved, "no frame has been solved yet"));
        }
        let mut values = Vec::with_capacity(n3);
        for i in 0..count {
            let (o, f) = (objects[i] as usize, faces[i] as usize);
            let v = eval(&state.session, o, f, f64::from(st[2 * i]), f64::from(st[2 * i + 1]))
                .map_err(|e| Failure::from(e).prefixed(&format!("point {i}: ")))?;
            values.extend(v.map(|x| x as f32));
        }
        values
    };
    unsafe { write_out(out, n3, &values, "out") }
}

/// Frees a session. NULL is ignored. No call on `s` may be running or follow.
///
/// # Safety
/// `s` is NULL or a live session from `gr_session_new`, not freed before.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_free(s: *mut GrSession) {
    if s.is_null() {
        return;
    }
    boundary_value((), || {
        // SAFETY: made by Box::into_raw in gr_session_new, freed once per the contract.
        drop(unsafe { Box::from_raw(s) });
    });
}
