//! Checks every scene at the boundary, with messages that name the object, face or field.

use super::Scene;
use crate::basis::MAX_ORDER;
use crate::error::{Result, invalid_scene};

/// Faces whose area is below this fraction of the object's squared bounding-box diagonal are
/// degenerate: skipped with a warning rather than rejected (modelling tools leave them behind).
const DEGENERATE_AREA_FRACTION: f64 = 1e-12;

pub(super) fn validate(scene: &mut Scene) -> Result<()> {
    let s = &scene.settings;
    if s.basis_order > MAX_ORDER {
        return Err(invalid_scene!("settings.basis_order {} is above {MAX_ORDER}", s.basis_order));
    }
    if !(1..=16).contains(&s.quadrature_order) {
        return Err(invalid_scene!("settings.quadrature_order {} is outside 1..=16", s.quadrature_order));
    }
    // A rule of n points integrates degree 2n - 1 exactly; the products of two basis functions
    // have degree 2 x basis_order per axis. With fewer points the projection is not a projection
    // (the basis is not orthonormal under the rule), and random scenes then made solves diverge.
    let (q, order) = (s.quadrature_order, s.basis_order);
    if q <= order {
        return Err(invalid_scene!(
            "settings.quadrature_order {q} must exceed settings.basis_order {order}: {q} Gauss \
             points per axis cannot integrate the products of basis functions of order {order}"
        ));
    }
    if !(s.tolerance.is_finite() && s.tolerance > 0.0 && s.tolerance < 1.0) {
        return Err(invalid_scene!("settings.tolerance {} is outside (0,1)", s.tolerance));
    }
    if !(1..=4).contains(&s.visibility_samples) {
        return Err(invalid_scene!("settings.visibility_samples {} is outside 1..=4", s.visibility_samples));
    }
    if s.threads > 1024 {
        return Err(invalid_scene!("settings.threads {} is above 1024", s.threads));
    }
    if scene.frames.0 > scene.frames.1 {
        return Err(invalid_scene!(
            "frames [{}, {}]: the first frame is after the last",
            scene.frames.0,
            scene.frames.1
        ));
    }
    if scene.emission_keys.len() != scene.materials.len() {
        return Err(invalid_scene!(
            "{} emission key lists for {} materials",
            scene.emission_keys.len(),
            scene.materials.len()
        ));
    }
    for (m, mat) in scene.materials.iter().enumerate() {
        let place = format!("material {m} \"{}\"", mat.name);
        check_reflectance(&place, mat.reflectance)?;
        check_emission(&place, mat.emission)?;
        for key in &scene.emission_keys[m] {
            if !key.frame.is_finite() {
                return Err(invalid_scene!("{place}: emission key frame {} is not finite", key.frame));
            }
            check_emission(&format!("{place} emission key at frame {}", key.frame), key.emission)?;
        }
    }
    let n_materials = scene.materials.len();
    let mut degenerate = Vec::new();
    for (o, obj) in scene.objects.iter().enumerate() {
        let place = format!("object {o} \"{}\"", obj.name);
        for (v, p) in obj.vertices.iter().enumerate() {
            if !p.is_finite() {
                return Err(invalid_scene!("{place} vertex {v}: coordinate {p} is not finite"));
            }
        }
        if !obj.matrix.is_finite() {
            return Err(invalid_scene!("{place}: matrix is not finite"));
        }
        if obj.face_materials.len() != obj.faces.len() {
            return Err(invalid_scene!(
                "{place}: {} face materials for {} faces",
                obj.face_materials.len(),
                obj.faces.len()
            ));
        }
        for key in &obj.animation {
            let finite = key.frame.is_finite()
                && match &key.transform {
                    super::KeyTransform::Translation(t) => t.is_finite(),
                    super::KeyTransform::Matrix(m) => m.is_finite(),
                };
            if !finite {
                return Err(invalid_scene!("{place}: animation key at frame {} is not finite", key.frame));
            }
        }
        let (lo, hi) = obj
            .vertices
            .iter()
            .fold((glam::DVec3::splat(f64::MAX), glam::DVec3::splat(f64::MIN)), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            });
        let diag2 = (hi - lo).length_squared();
        for (f, face) in obj.faces.iter().enumerate() {
            let fplace = format!("{place} face {f}");
            if face.len() < 3 {
                return Err(invalid_scene!("{fplace}: {} vertices; a face needs 3 or 4", face.len()));
            }
            if face.len() > 4 {
                return Err(invalid_scene!(
                    "{fplace}: {} vertices; n-gons must be split into triangles or quads before export",
                    face.len()
                ));
            }
            if let Some(&v) = face.iter().find(|&&v| v as usize >= obj.vertices.len()) {
                return Err(invalid_scene!(
                    "{fplace}: vertex index {v} out of range (0..{})",
                    obj.vertices.len()
                ));
            }
            let m = obj.face_materials[f];
            if m as usize >= n_materials {
                return Err(invalid_scene!("{fplace}: material {m} out of range (0..{n_materials})"));
            }
            let corners: Vec<_> = face.iter().map(|&v| obj.vertices[v as usize]).collect();
            let area = crate::geometry::Patch::from_corners(&corners).area();
            if area <= DEGENERATE_AREA_FRACTION * diag2 || !area.is_finite() {
                degenerate.push((o, f));
            }
        }
    }
    scene.degenerate_faces = degenerate;
    Ok(())
}

fn check_reflectance(place: &str, rho: [f64; 3]) -> Result<()> {
    for (c, &r) in rho.iter().enumerate() {
        if !(r.is_finite() && (0.0..1.0).contains(&r)) {
            return Err(invalid_scene!("{place}: reflectance[{c}] = {r} is outside [0,1)"));
        }
    }
    Ok(())
}

fn check_emission(place: &str, e: [f64; 3]) -> Result<()> {
    for (c, &x) in e.iter().enumerate() {
        if !(x.is_finite() && x >= 0.0) {
            return Err(invalid_scene!("{place}: emission[{c}] = {x} must be finite and >= 0"));
        }
    }
    Ok(())
}
