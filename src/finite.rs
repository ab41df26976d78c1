//! The last check before a frame becomes readable: every value a host will read (face means and
//! corners, as f32) is finite, and no face mean is negative beyond what the method's polynomials
//! undershoot by.
//!
//! Validation ([`crate::scene::check_placed`], the emission range) keeps non-finite numbers out
//! of the solver; this check is the backstop for whatever still gets through, so a host never
//! receives NaN or infinity with a success status.

use crate::error::{Result, invalid_scene};
use crate::scene::Scene;
use crate::scene::json::ObjectResult;

/// A face mean above `-UNDERSHOOT x peak` is clamped to 0 when read; below it, it is an error.
/// Within it are the f32 rounding of the mean and the undershoot of a Galerkin polynomial next to
/// a contact or crossing (its projection of a function with a jump rings): measured on real
/// meshes at -1.2e-5 (the teddy's crossing convex hulls) and -1.3e-5 (the monastery) of the
/// peak, on fuzzed scenes down to -2.6e-4. One percent of the peak is invisible and far past
/// all of these, so what fails is a frame that is wrong, not a mesh that is awkward.
pub const UNDERSHOOT: f64 = 1e-2;

/// Checks `results` (one frame's, at `frame`, of `scene`'s objects in order): an error naming
/// the object, face and frame for a value that is not finite, or a face mean below
/// `-UNDERSHOOT x` the frame's peak.
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
        let corners = obj.faces.iter().enumerate().flat_map(|(f, face)| std::iter::repeat_n(f, face.len()));
        if let Some((f, v)) =
            corners.zip(&r.corner_irradiance).find(|(_, v)| !v.iter().all(|x| x.is_finite()))
        {
            return Err(invalid_scene!(
                "object \"{}\" face {f} at frame {frame}: corner irradiance {v:?} is not finite \
                 (NaN, or above f32's 3.4e38)",
                r.name
            ));
        }
    }
    for r in results {
        for (f, v) in r.face_radiosity.iter().enumerate() {
            let low = v.iter().fold(f64::INFINITY, |m, &x| m.min(f64::from(x)));
            if low < -UNDERSHOOT * peak {
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

/// Clamps to 0 the negative values that [`check_results`] let through.
pub fn clamp_rounding(results: &mut [ObjectResult]) {
    for r in results {
        for v in r.face_radiosity.iter_mut().chain(&mut r.corner_radiosity).chain(&mut r.corner_irradiance) {
            *v = v.map(|x| x.max(0.0));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Settings;

    /// A closed box's six one-face walls with these face means (corners at the mean).
    fn results(means: [f32; 6]) -> (Vec<ObjectResult>, Scene) {
        let scene = crate::scenes::closed_box(1, 0.5, 1.0, Settings::default());
        let results = scene
            .objects
            .iter()
            .zip(means)
            .map(|(o, m)| ObjectResult {
                name: o.name.clone(),
                face_radiosity: vec![[m; 3]],
                corner_radiosity: vec![[m; 3]; 4],
                corner_irradiance: vec![[m; 3]; 4],
            })
            .collect();
        (results, scene)
    }

    #[test]
    fn undershoot_is_clamped_and_a_wrong_frame_refused() {
        let (mut r, scene) = results([1.0, 1.0, -1e-3, 1.0, 1.0, 1.0]);
        check_results(&r, &scene, 1.0).unwrap();
        clamp_rounding(&mut r);
        assert_eq!(r[2].face_radiosity[0], [0.0; 3]);
        let (r, scene) = results([1.0, 1.0, -2e-2, 1.0, 1.0, 1.0]);
        let e = check_results(&r, &scene, 1.0).unwrap_err().to_string();
        assert!(e.contains("wall2") && e.contains("is negative"), "{e}");
        let (r, scene) = results([1.0, f32::NAN, 1.0, 1.0, 1.0, 1.0]);
        assert!(check_results(&r, &scene, 1.0).unwrap_err().to_string().contains("not finite"));
        let (mut r, scene) = results([1.0; 6]);
        r[4].corner_irradiance[1][2] = f32::INFINITY;
        let e = check_results(&r, &scene, 1.0).unwrap_err().to_string();
        assert!(e.contains("wall4") && e.contains("irradiance"), "{e}");
    }
}
