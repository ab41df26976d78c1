//! What a mesh says about its surface beyond its faces and materials (issue 22): per-corner
//! shading normals (smooth shading, custom split normals), per-face reflectance and a per-face
//! emission colour (each a texture's mean over the face). All are optional per object; without
//! them an object is what it was before, bit for bit.

use glam::{DMat3, DMat4, DVec3};

use super::Object;
use crate::error::{Result, invalid_scene};

/// One object's surface data.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Surface {
    /// Object-space shading normal per face corner, faces in order and corners in face order
    /// (as `Object::faces` lists them); empty: every corner takes its face's normal. A zero
    /// vector also means "the face's own normal" (a flat face of a partly smooth mesh).
    pub corner_normals: Vec<DVec3>,
    /// Diffuse reflectance per face, overriding the face's material's (an image texture's mean
    /// over the face); empty: the materials'.
    pub face_reflectance: Vec<[f64; 3]>,
    /// Emission colour per face, multiplying the face's material's emission (an Emission Color
    /// texture's mean over the face, the material's emission being strength x white); empty: 1.
    /// A scale rather than an exitance, so the material's animated strength keeps applying.
    pub face_emission: Vec<[f64; 3]>,
}

/// The largest per-face emission scale: an HDR texture's mean may exceed 1, but not by so much
/// that a material's emission (at most [`super::MAX_EMISSION`]) times it leaves the f32 range.
pub const MAX_FACE_EMISSION: f64 = 1e6;

impl Surface {
    pub fn is_empty(&self) -> bool {
        self.corner_normals.is_empty() && self.face_reflectance.is_empty() && self.face_emission.is_empty()
    }

    /// Checks the lengths against `obj` and every value; `place` names the object in messages.
    pub fn validate(&self, obj: &Object, place: &str) -> Result<()> {
        let corners: usize = obj.faces.iter().map(Vec::len).sum();
        if !self.corner_normals.is_empty() && self.corner_normals.len() != corners {
            return Err(invalid_scene!(
                "{place}: corner_normals has {} entries for {corners} face corners",
                self.corner_normals.len()
            ));
        }
        if let Some(k) = self.corner_normals.iter().position(|n| !n.is_finite()) {
            return Err(invalid_scene!("{place}: corner_normals[{k}] is not finite"));
        }
        per_face_rgb(
            &self.face_reflectance,
            "face_reflectance",
            obj,
            place,
            |r| (0.0..1.0).contains(&r),
            "is outside [0,1)",
        )?;
        let bound = format!("must be finite, >= 0 and at most {MAX_FACE_EMISSION:e}");
        per_face_rgb(
            &self.face_emission,
            "face_emission",
            obj,
            place,
            |x| (0.0..=MAX_FACE_EMISSION).contains(&x),
            &bound,
        )
    }
}

/// Checks a per-face RGB list `name`: empty, or one entry per face of `obj`, each channel finite
/// and `ok` (else the error says it `fails`).
fn per_face_rgb(
    values: &[[f64; 3]],
    name: &str,
    obj: &Object,
    place: &str,
    ok: impl Fn(f64) -> bool,
    fails: &str,
) -> Result<()> {
    if !values.is_empty() && values.len() != obj.faces.len() {
        return Err(invalid_scene!(
            "{place}: {name} has {} entries for {} faces",
            values.len(),
            obj.faces.len()
        ));
    }
    for (f, rgb) in values.iter().enumerate() {
        for (c, &x) in rgb.iter().enumerate() {
            if !(x.is_finite() && ok(x)) {
                return Err(invalid_scene!("{place}: {name}[{f}][{c}] = {x} {fails}"));
            }
        }
    }
    Ok(())
}

/// A shading normal placed by `world_from_object`: transformed by the inverse transpose (as
/// Blender's normal matrix, so a mirroring placement keeps the front side) and normalized;
/// `None` for the zero vector (the face's own normal) or a singular placement.
pub fn world_normal(world_from_object: &DMat4, n: DVec3) -> Option<DVec3> {
    if n == DVec3::ZERO {
        return None;
    }
    let linear = DMat3::from_mat4(*world_from_object);
    let w = linear.inverse().transpose() * n;
    let w = w.normalize_or_zero();
    (w != DVec3::ZERO && w.is_finite()).then_some(w)
}
