//! Brute-force direct light for the differential tests: a light quad cut into `m x m` pieces,
//! each piece's exact point-to-polygon form factor counted when one shadow ray to its centre
//! passes every occluder triangle.

use galerkin_radiosity::geometry::{Patch, Rect};
use galerkin_radiosity::kernel::point::point_to_polygon;
use galerkin_radiosity::scene::Object;
use galerkin_radiosity::visibility::bvh::{Triangle, segment_hits};
use glam::DVec3;

/// What the point `y` receives from a light.
pub struct Direct {
    /// The form factor from `y` to the light's seen pieces (times the light's exitance: `E_d`).
    pub form_factor: f64,
    /// Pieces in front of `y` that its ray sees, and that it does not.
    pub seen: usize,
    pub hidden: usize,
}

/// The light `light` seen from `y` (normal `n`) through `occluders`, in `m x m` pieces.
pub fn direct_light(light: &Patch, y: DVec3, n: DVec3, occluders: &[Triangle], m: usize) -> Direct {
    let mut out = Direct { form_factor: 0.0, seen: 0, hidden: 0 };
    for i in 0..m {
        for j in 0..m {
            let r = Rect {
                s0: i as f64 / m as f64,
                s1: (i + 1) as f64 / m as f64,
                t0: j as f64 / m as f64,
                t1: (j + 1) as f64 / m as f64,
            };
            let piece = light.sub_patch(&r);
            let f = point_to_polygon(y, n, &piece.corners, piece.centre_normal());
            if f <= 0.0 {
                continue;
            }
            let (s, t) = r.map(0.5, 0.5);
            let d = light.point(s, t) - y;
            if occluders.iter().any(|tri| segment_hits(tri, y, d, 1e-9, 1.0 - 1e-9)) {
                out.hidden += 1;
            } else {
                out.form_factor += f;
                out.seen += 1;
            }
        }
    }
    out
}

/// An object's faces as triangles (its own coordinates), blocking every element.
pub fn triangles_of(object: &Object) -> Vec<Triangle> {
    object
        .faces
        .iter()
        .flat_map(|f| {
            let v: Vec<DVec3> = f.iter().map(|&k| object.vertices[k as usize]).collect();
            Patch::from_corners(&v).triangles()
        })
        .map(|v| Triangle { v, element: u32::MAX })
        .collect()
}
