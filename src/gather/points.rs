//! The corner points the gather evaluates: the face corners merged into distinct points
//! ([`corner_points`]), inset into their faces ([`INSET`]), the point and normal each is gathered
//! with ([`shading_point`]), and which of them lie buried inside another closed surface
//! ([`buried_points`]).

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::{Patch, Rect};
use crate::scene::Scene;
use crate::scene::surface::world_normal;
use crate::solids::Solids;
use crate::system::{System, corner_params};

/// Corners are gathered this far inside their face (in its parameter domain): exactly on an edge,
/// a perpendicular neighbour is seen edge-on and drops out, while a vertex bake and the eye see
/// the limit from inside.
pub const INSET: f64 = 1e-3;

/// A corner point: faces of one object meeting at a vertex with the same normal and material see
/// the same light there (4 faces per vertex of a grid), gathered once. A smooth-shaded corner
/// has the mesh's interpolated normal ([`crate::scene::Surface::corner_normals`]), so the faces
/// of a smooth vertex share one point and one value: no facets, as Cycles bakes them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CornerPoint {
    /// The element covering it and the local point (inset), or `None` for a skipped face.
    pub at: Option<(usize, f64, f64)>,
    pub material: u32,
    /// The object and face it was made for: a skipped face's point shows that face's exitance
    /// ([`Scene::emission_of`]).
    pub face: (u32, u32),
    /// The world-space shading normal, where it is not the face's own.
    pub normal: Option<DVec3>,
}

impl CornerPoint {
    /// The exitance of the face the point was made for at `frame`.
    pub fn exitance(&self, scene: &Scene, frame: f64) -> [f64; 3] {
        scene.emission_of(self.face.0 as usize, self.face.1 as usize, self.material, frame)
    }
}

/// The distinct corner points of the scene's faces, the point of each face corner, and the
/// number of face corners per object. `locate(o, f, s, t)` gives the element covering face `f`
/// of object `o` at its parameters `(s,t)` and the local point there (`None`: a skipped face),
/// `patch(e)` that element's patch: the flat system's elements, or the hierarchy's faces.
pub(crate) fn corner_points(
    scene: &Scene,
    frame: f64,
    locate: impl Fn(usize, usize, f64, f64) -> Option<(usize, f64, f64)>,
    patch: impl Fn(usize) -> Patch,
) -> (Vec<CornerPoint>, Vec<usize>, Vec<usize>) {
    let mut points = Vec::new();
    let mut point_of_corner = Vec::new();
    let mut per_object = Vec::with_capacity(scene.objects.len());
    let mut shared = std::collections::HashMap::new();
    for (o, obj) in scene.objects.iter().enumerate() {
        let before = point_of_corner.len();
        let shading = scene.corner_normals(o);
        let world_from_object = obj.world_from_object(frame);
        for (f, face) in obj.faces.iter().enumerate() {
            let first = point_of_corner.len() - before;
            for (k, (&v, (s, t))) in face.iter().zip(corner_params(face.len())).enumerate() {
                // A triangle's apex is the collapsed edge t = 1: the inset corner (1, 1) would lie
                // on the edge P1 P2 (INSET^2 inside), seeing the neighbour across it edge-on;
                // halfway along the collapsed edge it lies INSET inside along the median.
                let s = if face.len() == 3 && t == 1.0 { 0.5 } else { s };
                let (si, ti) = (s.clamp(INSET, 1.0 - INSET), t.clamp(INSET, 1.0 - INSET));
                let at = locate(o, f, si, ti);
                let material = obj.face_materials[f];
                let normal = shading.get(first + k).and_then(|&n| world_normal(&world_from_object, n));
                // Faces with their own reflectance or emission scale (a texture's means) share a
                // point only with faces of the same ones, as faces of one material do.
                let own = |pick: fn(&crate::scene::Surface) -> &Vec<[f64; 3]>| {
                    scene.surfaces.get(o).and_then(|s| pick(s).get(f)).map(|r| r.map(f64::to_bits))
                };
                let (rho, scale) = (own(|s| &s.face_reflectance), own(|s| &s.face_emission));
                let key = at.map(|(e, s, t)| {
                    let n = normal.unwrap_or_else(|| patch(e).area_vector(s, t).normalize_or_zero());
                    (o, v, material, rho, scale, (n * 1e6).round().as_i64vec3().to_array())
                });
                let k = match key.and_then(|k| shared.get(&k)) {
                    Some(&k) => k,
                    None => {
                        points.push(CornerPoint { at, material, face: (o as u32, f as u32), normal });
                        if let Some(key) = key {
                            shared.insert(key, points.len() - 1);
                        }
                        points.len() - 1
                    }
                };
                point_of_corner.push(k);
            }
        }
        per_object.push(point_of_corner.len() - before);
    }
    (points, point_of_corner, per_object)
}

/// A smooth-shaded point is lifted this far (times its element's bounding radius) along its
/// shading normal: the inset point lies below the planes of the other faces at a convex vertex
/// by about `INSET` of their size, and a shadow ray towards a light the shading normal faces but
/// the face does not would leave under them (measured on Suzanne under a Point light: dark
/// corners on the lit side, 0.33 relative RMSE against Cycles' smooth bake without the lift).
pub const SMOOTH_LIFT: f64 = 4.0 * INSET;

/// The point at `(s,t)` of `patch` and the normal it is gathered with: the face's own, or the
/// shading normal `normal` with the point lifted by [`SMOOTH_LIFT`] along it.
pub fn shading_point(patch: &Patch, s: f64, t: f64, normal: Option<DVec3>) -> (DVec3, DVec3) {
    let x = patch.point(s, t);
    match normal {
        Some(n) => (x + SMOOTH_LIFT * patch.bounding_sphere().1 * n, n),
        None => (x, patch.area_vector(s, t).normalize_or_zero()),
    }
}

/// Per point, whether it lies inside another closed surface of the scene
/// ([`Solids::buries_surface_point`]). The solids are made of the faces, not of the elements: a
/// face split into parts ([`crate::contact_split`]) leaves edges that only its own parts share.
/// (Without parts the elements are the faces: nothing more is allocated, which a bake near its
/// memory limit needs.)
pub(super) fn buried_points(
    sys: &System,
    scene: &Scene,
    frame: f64,
    patches: &[Patch],
    points: &[CornerPoint],
) -> Vec<bool> {
    let split = sys.elements.iter().any(|e| e.domain != Rect::UNIT);
    let faces = split.then(|| crate::system::build_elements(scene, frame, crate::basis::Basis::new(0)));
    let solids = Solids::new(faces.as_deref().unwrap_or(&sys.elements), scene.objects.len());
    if solids.is_empty() {
        return Vec::new();
    }
    points
        .par_iter()
        .map(|p| {
            p.at.is_some_and(|(e, s, t)| {
                let (centre, radius) = patches[e].bounding_sphere();
                let (x, n) = (patches[e].point(s, t), patches[e].area_vector(s, t).normalize_or_zero());
                solids.buries_surface_point(x, n, centre, radius)
            })
        })
        .collect()
}
