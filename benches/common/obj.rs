//! Shared by the benches: a scene from an OBJ file (`v` and `f` lines) on a ground under a light.
//! (A copy of benches/hierarchy.rs's `obj_under_a_light`, with the corner gather a parameter.)

use galerkin_radiosity::scene::{Material, Object, Scene, Settings};
use galerkin_radiosity::scenes;
use glam::DVec3;

/// The OBJ at `path` (y-up, turned z-up) on a ground square 1.5 times its larger horizontal
/// extent, lit by an emissive square of a quarter of that size one model height above it;
/// order 1, `corner_gather` as given.
pub fn obj_under_a_light(path: &str, corner_gather: bool) -> Scene {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let (mut vertices, mut faces) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let p: Vec<f64> = it.take(3).map(|x| x.parse().unwrap()).collect();
                // OBJ is y-up; the library is z-up.
                vertices.push(DVec3::new(p[0], -p[2], p[1]));
            }
            Some("f") => {
                let idx: Vec<u32> =
                    it.map(|w| w.split('/').next().unwrap().parse::<i64>().unwrap() as u32 - 1).collect();
                for k in 1..idx.len() - 1 {
                    faces.push(vec![idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    let b = galerkin_radiosity::geometry::Aabb::from_points(&vertices);
    let (c, d) = (b.centre(), b.diagonal());
    let size = d.x.max(d.y) * 1.5;
    let ground = [
        DVec3::new(c.x - size, c.y - size, b.min.z),
        DVec3::new(c.x + size, c.y - size, b.min.z),
        DVec3::new(c.x + size, c.y + size, b.min.z),
        DVec3::new(c.x - size, c.y + size, b.min.z),
    ];
    let h = b.max.z + d.z;
    let l = 0.25 * size;
    let light = [
        DVec3::new(c.x - l, c.y + l, h),
        DVec3::new(c.x + l, c.y + l, h),
        DVec3::new(c.x + l, c.y - l, h),
        DVec3::new(c.x - l, c.y - l, h),
    ];
    let n = faces.len();
    let mesh = Object {
        name: "Mesh".into(),
        vertices,
        faces,
        face_materials: vec![0; n],
        matrix: glam::DMat4::IDENTITY,
        animation: Vec::new(),
    };
    let materials = vec![
        Material { name: "Grey".into(), reflectance: [0.7; 3], emission: [0.0; 3] },
        Material { name: "Light".into(), reflectance: [0.0; 3], emission: [30.0; 3] },
    ];
    let objects = vec![
        mesh,
        scenes::subdivided_quad("Ground", ground, 1, 0),
        scenes::subdivided_quad("Light", light, 1, 1),
    ];
    Scene::new(
        Settings { basis_order: 1, corner_gather, ..Default::default() },
        (0, 0),
        materials,
        vec![Vec::new(); 2],
        objects,
    )
    .unwrap()
}
