//! The last check before a frame becomes readable: every value a host will read (face means and
//! corners, as f32) is finite, and no face mean is negative beyond rounding.
//!
//! Validation ([`crate::scene::check_placed`], the emission range) keeps non-finite numbers out
//! of the solver; this check is the backstop for whatever still gets through, so a host never
//! receives NaN or infinity with a success status.

use crate::error::{Result, invalid_scene};
use crate::scene::Scene;
use crate::scene::json::ObjectResult;

/// A face mean above `-ROUNDING x peak` is rounding (the mean is a sum of f32 coefficient
/// products) and is clamped to 0 when read; below it, the face's polynomial undershoots for real.
pub const ROUNDING: f64 = 1e-6;

/// Checks `results` (one frame's, at `frame`, of `scene`'s objects in order): an error naming
/// the object, face and frame for a value that is not finite, or a face mean below
/// `-ROUNDING x` the frame's peak.
pub fn check_results(results: &[ObjectResult], scene: &Scene, frame: f64) -> Result<()> {
    let mut peak = 0.0f64;
    for (r, obj) in results.iter().zip(&scene.objects) {
        let corners = obj.faces.iter().enumerate().flat_map(|(f, face)| std::iter::repeat_n(f, face.len()));
        let means = r.face_radiosity.iter().enumerate().map(|(f, v)| (f, "mean", v));
        for (f, what, v) in means.chain(corners.zip(&r.corner_radiosity).map(|(f, v)| (f, "corner", v))) {
            if !v.iter().all(|x| x.is_finite()) {
                return Err(invalid_scene!(
                    "object \"{}\" face {f} at frame {frame}: {what} radiosity {v:?} is not finite \
                     (NaN, or above f32's 3.4e38)",
                    r.name
                ));
            }
            peak = v.iter().fold(peak, |p, &x| p.max(f64::from(x)));
        }
    }
    for r in results {
        for (f, v) in r.face_radiosity.iter().enumerate() {
            let low = v.iter().fold(f64::INFINITY, |m, &x| m.min(f64::from(x)));
            if low < -ROUNDING * peak {
                return Err(invalid_scene!(
                    "object \"{}\" face {f} at frame {frame}: mean radiosity {low:.3e} is negative \
                     ({:.1e} of the frame's peak): the face's polynomial undershoots, usually a face \
                     crossing another or a non-planar quad through an object; separate or split them",
                    r.name,
                    low / peak
                ));
            }
        }
    }
    Ok(())
}

/// Clamps to 0 the negative values that [`check_results`] let through as rounding.
pub fn clamp_rounding(results: &mut [ObjectResult]) {
    for r in results {
        for v in r.face_radiosity.iter_mut().chain(&mut r.corner_radiosity) {
            *v = v.map(|x| x.max(0.0));
        }
    }
}
