//! Per-corner shading normals and per-face reflectance (issue 22, items 3 and 4;
//! `galerkin_radiosity::scene::Surface`): what leaves them out changes nothing bit for bit, a
//! face's reflectance override is the same solve as a material of that reflectance, a smooth
//! vertex gets one value, and bad input is refused with a message naming the field.

use galerkin_radiosity::lights::{Light, LightKind};
use galerkin_radiosity::scene::json::{parse_scene, scene_to_json};
use galerkin_radiosity::scene::{Material, Object, Scene, Settings, Surface};
use galerkin_radiosity::scenes::{bumpy_sphere, cornell_box, subdivided_quad};
use galerkin_radiosity::session::{Method, Session};
use galerkin_radiosity::system::no_progress;
use glam::{DMat4, DVec3};

/// Per object: face means and corners.
type Results = Vec<(Vec<[f32; 3]>, Vec<[f32; 3]>)>;

fn solve(scene: Scene) -> Results {
    let mut s = Session::new(scene, Method::Full).unwrap();
    s.solve_frame(1.0, &no_progress).unwrap();
    s.face_results().unwrap().into_iter().map(|r| (r.face_radiosity, r.corner_radiosity)).collect()
}

fn box_scene() -> Scene {
    cornell_box(4, Settings { threads: 1, ..Settings::default() })
}

fn corners(o: &Object) -> usize {
    o.faces.iter().map(Vec::len).sum()
}

#[test]
fn zero_normals_material_reflectances_and_unit_emission_scales_change_nothing_bit_for_bit() {
    let plain = box_scene();
    let surfaces: Vec<Surface> = plain
        .objects
        .iter()
        .map(|o| Surface {
            corner_normals: vec![DVec3::ZERO; corners(o)],
            face_reflectance: o
                .face_materials
                .iter()
                .map(|&m| plain.materials[m as usize].reflectance)
                .collect(),
            face_emission: vec![[1.0; 3]; o.faces.len()],
        })
        .collect();
    let with = plain.clone().with_surfaces(surfaces).unwrap();
    assert!(!with.surfaces.is_empty());
    assert_eq!(solve(plain), solve(with));
}

#[test]
fn a_face_reflectance_is_the_solve_of_a_material_with_it() {
    // The floor's faces 0..8 take a red reflectance through the override, or through a new
    // material: the same system, so the same numbers.
    let red = [0.7, 0.1, 0.1];
    let plain = box_scene();
    let floor = plain.objects.iter().position(|o| o.name == "Floor").unwrap();
    let mut by_material = plain.clone();
    by_material.materials.push(Material { name: "red".into(), reflectance: red, emission: [0.0; 3] });
    by_material.emission_keys.push(Vec::new());
    let m = (by_material.materials.len() - 1) as u32;
    let mut rho: Vec<[f64; 3]> = plain.objects[floor]
        .face_materials
        .iter()
        .map(|&m| plain.materials[m as usize].reflectance)
        .collect();
    by_material.objects[floor].face_materials[..8].fill(m);
    rho[..8].fill(red);
    let mut surfaces = vec![Surface::default(); plain.objects.len()];
    surfaces[floor].face_reflectance = rho;
    let by_face = plain.clone().with_surfaces(surfaces).unwrap();
    let (a, b, p) = (solve(by_material), solve(by_face), solve(plain));
    assert_eq!(a, b);
    // And it did something: the red floor darkens the walls' green and blue.
    let wall = 2;
    let mean = |r: &Results, c: usize| r[wall].0.iter().map(|v| v[c] as f64).sum::<f64>();
    assert!(mean(&b, 1) < 0.99 * mean(&p, 1), "{} {}", mean(&b, 1), mean(&p, 1));
}

#[test]
fn a_smooth_vertex_gets_one_value_and_json_keeps_the_normals() {
    // A sphere over a floor under a Point light, its corners given the sphere's normals: every
    // face corner at a vertex reads one value; flat, they differ.
    let centre = DVec3::new(0.0, 0.0, 0.8);
    let floor = subdivided_quad(
        "Floor",
        [
            DVec3::new(-2.0, -2.0, 0.0),
            DVec3::new(2.0, -2.0, 0.0),
            DVec3::new(2.0, 2.0, 0.0),
            DVec3::new(-2.0, 2.0, 0.0),
        ],
        6,
        0,
    );
    let materials = vec![Material { name: "grey".into(), reflectance: [0.6; 3], emission: [0.0; 3] }];
    let lamp =
        Light::new("Lamp", LightKind::Point, DMat4::from_translation(DVec3::new(1.0, -0.5, 2.5)), 200.0);
    let plain = Scene::new(
        Settings { threads: 1, ..Settings::default() },
        (1, 1),
        materials,
        vec![Vec::new()],
        vec![floor, bumpy_sphere("Sphere", centre, 0.5, 2, 0.0, 0)],
    )
    .unwrap()
    .with_lights(vec![lamp])
    .unwrap();
    let o = plain.objects.len() - 1;
    let obj = plain.objects[o].clone();
    let normals: Vec<DVec3> =
        obj.faces.iter().flatten().map(|&v| (obj.vertices[v as usize] - centre).normalize()).collect();
    let mut surfaces = vec![Surface::default(); plain.objects.len()];
    surfaces[o].corner_normals = normals;
    let smooth = plain.clone().with_surfaces(surfaces).unwrap();
    let back = parse_scene(&scene_to_json(&smooth)).unwrap();
    // The file keeps the normals (to the last ulp serde_json's float parsing allows).
    let (a, b) = (&back.surfaces[o].corner_normals, &smooth.surfaces[o].corner_normals);
    assert_eq!(a.len(), b.len());
    assert!(a.iter().zip(b).all(|(x, y)| (*x - *y).abs().max_element() < 1e-15));
    assert!(back.surfaces[..o].iter().all(Surface::is_empty));
    let (flat, values) = (solve(plain), solve(smooth));
    let spread = |corners: &[[f32; 3]]| {
        let mut by_vertex: std::collections::HashMap<u32, Vec<f32>> = Default::default();
        for (&v, b) in obj.faces.iter().flatten().zip(corners) {
            by_vertex.entry(v).or_default().push(b[0]);
        }
        by_vertex
            .values()
            .map(|l| l.iter().fold(f32::MIN, |m, &x| m.max(x)) - l.iter().fold(f32::MAX, |m, &x| m.min(x)))
            .fold(0.0, f32::max)
    };
    let mean = values[o].1.iter().map(|b| b[0]).sum::<f32>() / values[o].1.len() as f32;
    eprintln!(
        "vertex spread: flat {:.3}, smooth {:.3} of the mean",
        spread(&flat[o].1) / mean,
        spread(&values[o].1) / mean
    );
    assert_eq!(spread(&values[o].1), 0.0);
    assert!(spread(&flat[o].1) > 0.05 * mean);
    // The sphere's mean light barely changes (its faces' average normal is the same).
    let flat_mean = flat[o].1.iter().map(|b| b[0]).sum::<f32>() / flat[o].1.len() as f32;
    assert!((mean / flat_mean - 1.0).abs() < 0.03, "{mean} {flat_mean}");
}

#[test]
fn bad_surfaces_are_refused_with_the_field_named() {
    let plain = box_scene();
    let mut surfaces = vec![Surface::default(); plain.objects.len()];
    surfaces[0].corner_normals = vec![DVec3::Z; 3];
    let e = plain.clone().with_surfaces(surfaces).unwrap_err().to_string();
    assert!(e.contains("corner_normals has 3 entries"), "{e}");
    let mut surfaces = vec![Surface::default(); plain.objects.len()];
    surfaces[0].face_reflectance = vec![[1.5, 0.0, 0.0]; plain.objects[0].faces.len()];
    let e = plain.clone().with_surfaces(surfaces).unwrap_err().to_string();
    assert!(e.contains("face_reflectance[0][0] = 1.5"), "{e}");
    let mut surfaces = vec![Surface::default(); plain.objects.len()];
    surfaces[0].corner_normals = vec![DVec3::NAN; corners(&plain.objects[0])];
    let e = plain.with_surfaces(surfaces).unwrap_err().to_string();
    assert!(e.contains("not finite"), "{e}");
}
