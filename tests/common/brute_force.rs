//! Brute-force direct light for the differential tests: a light quad cut into `m x m` pieces,
//! each piece's exact point-to-polygon form factor counted when one shadow ray to its centre
//! passes every occluder triangle; and the scene the tests share (a grey receiver, black
//! occluders, a light quad), solved as the library does it.

use galerkin_radiosity::geometry::{Patch, Rect};
use galerkin_radiosity::kernel::point::point_to_polygon;
use galerkin_radiosity::scene::{Material, Object, Scene, Settings};
use galerkin_radiosity::scenes::facing;
use galerkin_radiosity::system::{System, no_progress};
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

/// The tests' scene: material 0 grey of reflectance `rho`, 1 black, 2 a light of exitance
/// `exitance`; basis order 2, tolerance 1e-6, one frame.
pub fn grey_black_light(rho: f64, exitance: f64, objects: Vec<Object>) -> Scene {
    let materials = vec![
        Material { name: "grey".into(), reflectance: [rho; 3], emission: [0.0; 3] },
        Material { name: "black".into(), reflectance: [0.0; 3], emission: [0.0; 3] },
        Material { name: "light".into(), reflectance: [0.0; 3], emission: [exitance; 3] },
    ];
    let settings = Settings { basis_order: 2, tolerance: 1e-6, ..Settings::default() };
    Scene::new(settings, (1, 1), materials, vec![Vec::new(); 3], objects).unwrap()
}

/// A square light quad of half-width `half`, `height` above the origin, facing down.
#[allow(dead_code)] // (not every test's light)
pub fn ceiling_light(half: f64, height: f64) -> [DVec3; 4] {
    let p = |x, y| DVec3::new(x, y, height);
    facing([p(-half, -half), p(half, -half), p(half, half), p(-half, half)], DVec3::ZERO, false)
}

/// `scene` solved on the flat path at frame 1, its corners gathered.
#[allow(dead_code)] // (not every test gathers)
pub fn gathered(scene: &Scene) -> System {
    let mut sys = System::build(scene, 1.0, &no_progress).unwrap();
    sys.solve(scene.settings.tolerance, &|| false).unwrap();
    sys.gather_corners(scene, 1.0, &no_progress).unwrap();
    sys
}
