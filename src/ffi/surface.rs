//! An object's surface beyond its faces through the C ABI ([`crate::scene::Surface`], issue 22):
//! smooth-shading normals per face corner, a reflectance per face and an emission colour scale per
//! face (each a texture's mean).

use glam::DVec3;

use super::error::{Failure, GrStatus};
use super::panic::boundary;
use super::session::{GrSession, array, session};
use crate::scene::Surface;

/// Sets object `object`'s shading normals and per-face reflectance; the next solved frame is
/// built afresh with them (set them before the first frame).
///
/// - `corner_normals`: 3 floats per face corner (faces in order, corners in face order as given
///   to `gr_session_new`), object space, a zero vector for "the face's own normal"; or NULL with
///   `corner_normals_len` 0 for flat faces everywhere. A corner with a normal is gathered with it
///   (smooth shading: the faces of a smooth vertex get one value).
/// - `face_reflectance`: 3 floats (RGB, each in [0,1)) per face, overriding the face's
///   material's reflectance; or NULL with `face_reflectance_len` 0 for the materials'.
///
/// The object's emission scale per face (`gr_session_set_object_face_emission`) stays as set.
///
/// The lengths are in floats. Returns `GR_STATUS_INVALID_ARGUMENT` for an object out of range
/// or a length that is not 3 x the corners or faces, `GR_STATUS_INVALID_SCENE` for a value out
/// of range; on error nothing changes.
///
/// # Safety
/// `s` is NULL or a live session; each non-NULL pointer points to its length of readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_object_surface(
    s: *mut GrSession,
    object: u32,
    corner_normals: *const f32,
    corner_normals_len: usize,
    face_reflectance: *const f32,
    face_reflectance_len: usize,
) -> GrStatus {
    boundary("gr_session_set_object_surface", || {
        let s = unsafe { session(s) }?;
        let normals = unsafe { array(corner_normals, corner_normals_len, "corner_normals") }?;
        let rho = unsafe { array(face_reflectance, face_reflectance_len, "face_reflectance") }?;
        for (what, len) in [("corner_normals_len", normals.len()), ("face_reflectance_len", rho.len())] {
            if len % 3 != 0 {
                return Err(
                    crate::Error::InvalidArgument(format!("{what} {len} is not a multiple of 3")).into()
                );
            }
        }
        let mut state = s.write()?;
        // The emission scale has its own function and stays as it was set.
        let surface = Surface {
            corner_normals: normals
                .chunks_exact(3)
                .map(|n| DVec3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2])))
                .collect(),
            face_reflectance: rgb_triples(rho),
            ..state.session.surface(object as usize)
        };
        state.session.set_surface(object as usize, surface)?;
        Ok(())
    })
}

/// Sets object `object`'s emission colour scale per face: 3 floats (RGB, finite, >= 0, at most
/// 1e6) per face, multiplying the face's material's emission, keys and
/// `gr_session_set_material_emission` overrides included (an Emission Color texture's mean over
/// the face, the material's emission then being its strength x white); or NULL with `len` 0 for
/// 1 everywhere. Keeps the object's other surface data (`gr_session_set_object_surface`); the
/// next solved frame is built afresh with it.
///
/// `len` is in floats. Returns `GR_STATUS_INVALID_ARGUMENT` for an object out of range or a
/// `len` that is not 3 x the object's faces, `GR_STATUS_INVALID_SCENE` for a value out of range;
/// on error nothing changes.
///
/// # Safety
/// `s` is NULL or a live session; a non-NULL `rgb` points to `len` readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_object_face_emission(
    s: *mut GrSession,
    object: u32,
    rgb: *const f32,
    len: usize,
) -> GrStatus {
    boundary("gr_session_set_object_face_emission", || {
        let s = unsafe { session(s) }?;
        let rgb = unsafe { array(rgb, len, "rgb") }?;
        let mut state = s.write()?;
        let faces = face_count(&state.session, object)?;
        if !(len == 0 || len == 3 * faces) {
            return Err(Failure::invalid(format!(
                "len {len} is not 3 x the {faces} faces of object {object} (or 0)"
            )));
        }
        state.session.set_face_emission(object as usize, rgb_triples(rgb))?;
        Ok(())
    })
}

/// The number of faces of `object`, or why there is no such object.
fn face_count(session: &crate::session::Session, object: u32) -> Result<usize, Failure> {
    let objects = &session.scene().objects;
    objects
        .get(object as usize)
        .map(|o| o.faces.len())
        .ok_or_else(|| Failure::invalid(format!("object {object} out of range (0..{})", objects.len())))
}

/// RGB triples of `floats` (a length the caller checked to be a multiple of 3).
fn rgb_triples(floats: &[f32]) -> Vec<[f64; 3]> {
    floats.chunks_exact(3).map(|r| [f64::from(r[0]), f64::from(r[1]), f64::from(r[2])]).collect()
}
