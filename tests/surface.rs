//! Per-corner shading normals, per-face reflectance and per-face emission scale (issue 22, items 3
//! and 4; `galerkin_radiosity::scene::Surface`): what leaves them out changes nothing bit for bit,
//! a face's reflectance override is the same solve as a material of that reflectance, a uniform
//! emission scale the same solve as a material of the scaled emission, a smooth vertex gets one
//! value, and bad input is refused with a message naming the field.

use galerkin_radiosity::lights::{Light, LightKind};
use galerkin_radiosity::scene::json::{parse_scene, scene_to_json};
use galerkin_radiosity::scene::{Material, Object, Scene, Settings, Surface};
use galerkin_radiosity::scenes::{LIGHT, bumpy_sphere, cornell_box, emission_ramp, subdivided_quad};
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

/// Solves every frame of `scene` with `method` in one session (later frames update the one
/// before); per frame, per object: face means and corners.
fn bake(scene: &Scene, method: Method) -> Vec<Results> {
    let mut s = Session::new(scene.clone(), method).unwrap();
    (scene.frames.0..=scene.frames.1)
        .map(|f| {
            s.solve_frame(f as f64, &no_progress).unwrap();
            s.face_results().unwrap().into_iter().map(|r| (r.face_radiosity, r.corner_radiosity)).collect()
        })
        .collect()
}

/// `scene` with object `o`'s emission scale per face set to `scale`.
fn with_face_emission(scene: &Scene, o: usize, scale: Vec<[f64; 3]>) -> Scene {
    let mut surfaces = vec![Surface::default(); scene.objects.len()];
    surfaces[o].face_emission = scale;
    scene.clone().with_surfaces(surfaces).unwrap()
}

fn light_object(scene: &Scene) -> usize {
    scene.objects.iter().position(|o| o.name == "Light").unwrap()
}

/// [`box_scene`] with its one-face light split into 4 x 4 faces (to scale them apart).
fn box_with_split_light() -> Scene {
    let mut scene = box_scene();
    let o = light_object(&scene);
    let light = &scene.objects[o];
    assert_eq!(light.faces.len(), 1);
    // `subdivided_quad`'s vertices run (a, b) = (0,0), (0,1), (1,0), (1,1).
    let v = &light.vertices;
    scene.objects[o] = subdivided_quad("Light", [v[0], v[2], v[3], v[1]], 4, LIGHT);
    scene
}

#[test]
fn a_uniform_emission_scale_is_the_solve_of_a_material_of_the_scaled_emission() {
    // The light's faces all scaled by c, or its material's emission times c: the same sources,
    // so the same numbers, flat and on the hierarchy.
    let c = [0.5, 0.25, 0.8];
    let plain = box_scene();
    let o = light_object(&plain);
    let by_face = with_face_emission(&plain, o, vec![c; plain.objects[o].faces.len()]);
    let mut by_material = plain.clone();
    let e = &mut by_material.materials[LIGHT as usize].emission;
    *e = std::array::from_fn(|k| e[k] * c[k]);
    for method in [Method::Full, Method::Hierarchical] {
        let (a, b) = (bake(&by_material, method), bake(&by_face, method));
        assert_eq!(a, b, "{method:?}");
        // And it did something: the scaled light's blue is 0.8 of the green's over 0.25.
        let p = bake(&plain, method);
        let sum = |r: &Results, k: usize| r[0].0.iter().map(|v| v[k] as f64).sum::<f64>();
        let ratio = |k: usize| sum(&b[0], k) / sum(&p[0], k);
        eprintln!("{method:?}: green x{:.6}, blue x{:.6}", ratio(1), ratio(2));
        // The hierarchy refines against the sources' power, which the scale changed.
        let close = if method == Method::Full { 1e-5 } else { 1e-2 };
        assert!((ratio(1) - 0.25).abs() < close && (ratio(2) - 0.8).abs() < close, "{method:?}");
    }
}

/// A 1 x 1 emitter of `n x n` faces (reflectance 0, exitance 10) 0.2 above the middle of a
/// 10 x 10 floor of 8 x 8 faces (reflectance 0.5), facing it: no light comes back to the
/// emitter, so the floor's `B` is 0.5 x the light it receives, in one bounce.
fn emitter_over_floor(n: usize) -> Scene {
    let v = DVec3::new;
    let floor =
        subdivided_quad("Floor", [v(-5., -5., 0.), v(5., -5., 0.), v(5., 5., 0.), v(-5., 5., 0.)], 8, 0);
    let h = 0.2;
    let corners = [v(-0.5, -0.5, h), v(-0.5, 0.5, h), v(0.5, 0.5, h), v(0.5, -0.5, h)];
    let emitter = subdivided_quad("Emitter", corners, n, 1);
    let materials = vec![
        Material { name: "floor".into(), reflectance: [0.5; 3], emission: [0.0; 3] },
        Material { name: "light".into(), reflectance: [0.0; 3], emission: [10.0; 3] },
    ];
    let settings = Settings { threads: 1, ..Settings::default() };
    Scene::new(settings, (1, 1), materials, vec![Vec::new(); 2], vec![floor, emitter]).unwrap()
}

/// The power the floor (object 0) of [`emitter_over_floor`] receives: `sum H A`, `H = B / 0.5`.
fn floor_power(r: &Results) -> f64 {
    let area = (10.0f64 / 8.0).powi(2);
    r[0].0.iter().map(|b| f64::from(b[0]) / 0.5 * area).sum()
}

#[test]
fn a_half_dark_emitter_emits_half_the_power() {
    let n = 4;
    let full = emitter_over_floor(n);
    let checker = |dark: usize| -> Vec<[f64; 3]> {
        (0..n * n).map(|f| if (f / n + f % n) % 2 == dark { [0.0; 3] } else { [1.0; 3] }).collect()
    };
    let (p_full, p_even, p_odd) = (
        floor_power(&solve(full.clone())),
        floor_power(&solve(with_face_emission(&full, 1, checker(0)))),
        floor_power(&solve(with_face_emission(&full, 1, checker(1)))),
    );
    // Energy balance: the full emitter's 10 W reaches the wide floor nearly all (the rest
    // leaves past its edges at grazing angles).
    let emitted = 10.0 * 1.0;
    eprintln!("floor receives {p_full:.4} W of {emitted} W; checkers {p_even:.4} + {p_odd:.4} W");
    assert!(p_full <= 1.01 * emitted && p_full > 0.9 * emitted, "{p_full}");
    // The two checkers are mirror images over the symmetric floor: half each, and together the
    // full emitter (the solve is linear in the emission).
    for p in [p_even, p_odd] {
        assert!((p / p_full - 0.5).abs() < 1e-3, "{p} of {p_full}");
    }
    assert!(((p_even + p_odd) / p_full - 1.0).abs() < 1e-5, "{p_even} + {p_odd} vs {p_full}");
}

#[test]
fn face_emission_survives_the_scene_file() {
    let plain = box_with_split_light();
    let o = light_object(&plain);
    let faces = plain.objects[o].faces.len();
    // Binary fractions: exact in the file's decimal digits.
    let scale: Vec<[f64; 3]> = (0..faces).map(|f| [f as f64 / 16.0, 0.5, 2.0]).collect();
    let scene = with_face_emission(&plain, o, scale.clone());
    let json = scene_to_json(&scene);
    assert!(json.contains("\"face_emission\""));
    let back = parse_scene(&json).unwrap();
    assert_eq!(back.surfaces[o].face_emission, scale);
    assert!(back.surfaces.iter().enumerate().all(|(k, s)| k == o || s.is_empty()));
    // The same solve, up to the file's rounding of the vertices (serde_json's float parsing).
    let corners = |r: Results| r.into_iter().flat_map(|o| o.1).collect::<Vec<_>>();
    let (a, b) = (corners(solve(back)), corners(solve(scene)));
    let peak = b.iter().flatten().fold(0.0f32, |m, &x| m.max(x));
    assert!(a.iter().zip(&b).all(|(x, y)| (0..3).all(|c| (x[c] - y[c]).abs() <= 1e-5 * peak)));
}

#[test]
fn bad_face_emission_is_refused_with_the_field_named() {
    let plain = box_with_split_light();
    let o = light_object(&plain);
    let faces = plain.objects[o].faces.len();
    let refused = |scale: Vec<[f64; 3]>| {
        let mut surfaces = vec![Surface::default(); plain.objects.len()];
        surfaces[o].face_emission = scale;
        plain.clone().with_surfaces(surfaces).unwrap_err().to_string()
    };
    let e = refused(vec![[1.0; 3]; faces + 1]);
    assert!(e.contains(&format!("face_emission has {} entries for {faces} faces", faces + 1)), "{e}");
    let mut bad = vec![[1.0; 3]; faces];
    bad[2] = [1.0, -0.5, 1.0];
    let e = refused(bad.clone());
    assert!(e.contains("face_emission[2][1] = -0.5 must be finite, >= 0"), "{e}");
    bad[2] = [f64::NAN, 1.0, 1.0];
    assert!(refused(bad.clone()).contains("face_emission[2][0] = NaN"));
    bad[2] = [1.0, 1.0, 2e6];
    assert!(refused(bad).contains("face_emission[2][2] = 2000000"));
    // The scene file and a session refuse them too, the session keeping what it had.
    let json = scene_to_json(&with_face_emission(&plain, o, vec![[1.0; 3]; faces]));
    let mut file: serde_json::Value = serde_json::from_str(&json).unwrap();
    file["objects"][o]["face_emission"][0][1] = serde_json::json!(-1.0);
    let e = parse_scene(&file.to_string()).unwrap_err().to_string();
    assert!(e.contains("face_emission[0][1] = -1"), "{e}");
    let mut s = Session::new(plain.clone(), Method::Full).unwrap();
    assert!(s.set_face_emission(o, vec![[1.0; 3]; 2]).is_err());
    assert!(s.set_face_emission(plain.objects.len(), Vec::new()).is_err());
    assert!(s.surface(o).is_empty());
}

#[test]
fn an_override_of_the_emission_keeps_the_face_scale() {
    // The host overrides the light's emission (as the add-on does each frame): the face scale
    // still multiplies it.
    let c = [0.5, 0.25, 1.0];
    let plain = box_scene();
    let o = light_object(&plain);
    let faces = plain.objects[o].faces.len();
    let mut s = Session::new(plain.clone(), Method::Full).unwrap();
    s.set_face_emission(o, vec![c; faces]).unwrap();
    s.set_material_emission(LIGHT as usize, [4.0, 8.0, 2.0]).unwrap();
    s.solve_frame(1.0, &no_progress).unwrap();
    let got: Results =
        s.face_results().unwrap().into_iter().map(|r| (r.face_radiosity, r.corner_radiosity)).collect();
    let mut by_material = plain.clone();
    by_material.materials[LIGHT as usize].emission = [2.0, 2.0, 2.0];
    assert_eq!(got, solve(by_material));
}

#[test]
fn an_animated_strength_with_a_face_scale_updates_as_from_scratch() {
    // The light's strength ramps over 4 frames while half its faces are dark: each updated frame
    // (flat incremental, and the hierarchy's update from the frame before) equals the frame
    // solved from scratch, within 1% of its peak.
    let mut plain = box_with_split_light();
    plain.frames = (1, 4);
    plain.emission_keys[LIGHT as usize] =
        emission_ramp((1.0, plain.materials[LIGHT as usize].emission), (4.0, [120.0, 80.0, 30.0]));
    let o = light_object(&plain);
    let faces = plain.objects[o].faces.len();
    let scale = (0..faces).map(|f| if f % 2 == 0 { [0.0; 3] } else { [1.0, 0.5, 1.0] }).collect();
    let scene = with_face_emission(&plain, o, scale);
    let alone = |method: Method, f: i64| {
        let mut one = scene.clone();
        one.frames = (f, f);
        bake(&one, method).remove(0)
    };
    for (updated, scratch) in
        [(Method::Incremental, Method::Full), (Method::Hierarchical, Method::Hierarchical)]
    {
        for (k, got) in bake(&scene, updated).iter().enumerate() {
            let want = alone(scratch, scene.frames.0 + k as i64);
            let corners = |r: &Results| r.iter().flat_map(|o| o.1.clone()).collect::<Vec<_>>();
            let (a, b) = (corners(got), corners(&want));
            let peak = b.iter().flatten().fold(0.0f32, |m, &x| m.max(x));
            let worst = a
                .iter()
                .zip(&b)
                .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs()))
                .fold(0.0, f32::max);
            eprintln!("{updated:?} frame {}: worst {:.2e} of the peak {peak}", k + 1, worst / peak);
            assert!(worst <= 0.01 * peak, "{updated:?} frame {}: {worst} vs peak {peak}", k + 1);
        }
    }
    // The ramp did something: the last frame is brighter than the first.
    let frames = bake(&scene, Method::Full);
    assert!(frames[3][0].0[0][0] > 1.5 * frames[0][0].0[0][0]);
}
