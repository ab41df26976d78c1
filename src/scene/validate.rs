//! Checks every scene at the boundary, with messages that name the object, face or field.

use super::Scene;
use crate::basis::MAX_ORDER;
use crate::error::{Result, invalid_scene};

/// Faces whose area is below this fraction of the object's squared bounding-box diagonal are
/// degenerate: skipped with a warning rather than rejected (modelling tools leave them behind).
const DEGENERATE_AREA_FRACTION: f64 = 1e-12;

/// The largest emission per channel (W/m^2). Coefficients are stored in f32 (at most 3.4e38),
/// and a surface of reflectance `rho` reaches `E / (1 - rho)`: eight orders of magnitude of
/// headroom for that and the solver's sums.
pub const MAX_EMISSION: f64 = 1e30;

/// The largest world coordinate (scene units) a placed vertex may have. Squares of coordinates
/// (areas, distances) must stay far inside f64, and nothing real is 1e12 units from its origin.
pub const MAX_COORDINATE: f64 = 1e12;

/// A face must be at least this fraction of its distance from the origin across: f64 keeps
/// about 16 digits, so a smaller face's corners would round together (a 1 m face placed 1e17
/// from the origin has all its corners at one point).
const MIN_RELATIVE_SIZE: f64 = 1e-9;

/// The most worker threads a bake may ask for (0: one per core).
pub const MAX_THREADS: usize = 1024;

/// The most frames a scene or a bake may span (every frame's results are kept until written).
pub const MAX_FRAMES: i64 = 100_000;

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
    if !(s.accuracy.is_finite() && s.accuracy > 0.0 && s.accuracy < 1.0) {
        return Err(invalid_scene!("settings.accuracy {} is outside (0,1)", s.accuracy));
    }
    if !(s.tolerance.is_finite() && s.tolerance > 0.0 && s.tolerance < 1.0) {
        return Err(invalid_scene!("settings.tolerance {} is outside (0,1)", s.tolerance));
    }
    if !(1..=4).contains(&s.visibility_samples) {
        return Err(invalid_scene!("settings.visibility_samples {} is outside 1..=4", s.visibility_samples));
    }
    if s.threads > MAX_THREADS {
        return Err(invalid_scene!("settings.threads {} is above {MAX_THREADS}", s.threads));
    }
    check_frames(scene.frames).map_err(crate::Error::InvalidScene)?;
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

/// A span of frames, first to last inclusive: in order, at most [`MAX_FRAMES`] long. The message
/// is the caller's to wrap (a scene error, a usage error).
pub fn check_frames((first, last): (i64, i64)) -> std::result::Result<(), String> {
    if first > last {
        return Err(format!("frames [{first}, {last}]: the first frame is after the last"));
    }
    let span = i128::from(last) - i128::from(first) + 1;
    if span > i128::from(MAX_FRAMES) {
        return Err(format!(
            "frames [{first}, {last}]: {span} frames, more than the {MAX_FRAMES} one bake may span; \
             bake it in parts"
        ));
    }
    Ok(())
}

/// Checks the scene as placed at `frame` (keys and host overrides applied: what is built), in
/// world space: every vertex finite and within [`MAX_COORDINATE`], every face that has an area
/// in object space keeping one in world space (an object scaled to 0, or keyed to 0 at a frame,
/// or a singular matrix, would give elements of zero area and NaN radiosity), and every face
/// large enough for f64 to resolve where it is placed.
pub fn check_placed(scene: &Scene, frame: f64) -> Result<()> {
    (0..scene.objects.len()).try_for_each(|o| check_object(scene, o, frame))
}

/// [`check_placed`] of the animated objects at every frame of `first..=last` (the others are
/// placed the same at every frame): what a bake can check before it starts.
pub fn check_animation(scene: &Scene, (first, last): (i64, i64)) -> Result<()> {
    for (o, _) in scene.objects.iter().enumerate().filter(|(_, obj)| obj.is_animated()) {
        for frame in first..=last {
            check_object(scene, o, frame as f64)?;
        }
    }
    Ok(())
}

fn check_object(scene: &Scene, o: usize, frame: f64) -> Result<()> {
    let obj = &scene.objects[o];
    let place = format!("object \"{}\" at frame {frame}", obj.name);
    let m = obj.world_from_object(frame);
    if !m.is_finite() {
        return Err(invalid_scene!("{place}: its matrix is not finite"));
    }
    let world: Vec<glam::DVec3> = obj.vertices.iter().map(|v| m.transform_point3(*v)).collect();
    let (mut lo, mut hi) = (glam::DVec3::splat(f64::MAX), glam::DVec3::splat(f64::MIN));
    for (v, p) in world.iter().enumerate() {
        if !(p.is_finite() && p.abs().max_element() <= MAX_COORDINATE) {
            return Err(invalid_scene!(
                "{place}: vertex {v} is placed at ({:.3e}, {:.3e}, {:.3e}), beyond {MAX_COORDINATE:e} \
                 from the origin (check the object's translation and scale)",
                p.x,
                p.y,
                p.z
            ));
        }
        (lo, hi) = (lo.min(*p), hi.max(*p));
    }
    let diag2 = (hi - lo).length_squared();
    let start = scene.degenerate_faces.partition_point(|&d| d < (o, 0));
    let mut degenerate = scene.degenerate_faces[start..].iter().peekable();
    for (f, face) in obj.faces.iter().enumerate() {
        if degenerate.next_if(|&&d| d == (o, f)).is_some() {
            continue;
        }
        let corners: Vec<_> = face.iter().map(|&v| world[v as usize]).collect();
        let area = crate::geometry::Patch::from_corners(&corners).area();
        let far = corners.iter().map(|c| c.abs().max_element()).fold(0.0, f64::max);
        if area.is_nan() || area <= DEGENERATE_AREA_FRACTION * diag2 {
            return Err(invalid_scene!(
                "{place}: face {f} has no area in world space (the object is scaled to 0 or its \
                 matrix is singular)"
            ));
        }
        if area.sqrt() < MIN_RELATIVE_SIZE * far {
            return Err(invalid_scene!(
                "{place}: face {f} ({:.3e} across) is too small to resolve at {far:.3e} from the \
                 origin; move the scene nearer the origin",
                area.sqrt()
            ));
        }
    }
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
        if x > MAX_EMISSION {
            return Err(invalid_scene!(
                "{place}: emission[{c}] = {x:e} is above {MAX_EMISSION:e}, more than the solver's \
                 f32 coefficients can hold; scale the scene's emission down"
            ));
        }
    }
    Ok(())
}
