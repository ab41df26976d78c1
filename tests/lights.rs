//! Blender Light objects as sources (issue 22, item 1), mirrored placements (item 5) and
//! emitters that light nothing (item 6): closed forms on a single floor (no interreflection, so
//! `B = rho E_d` exactly), shadows, and animated lights' incremental frames against full solves;
//! the World (item 2) against closed forms, and two-sided emitters (item 6).

use std::f64::consts::PI;

use galerkin_radiosity::lights::{AreaShape, Environment, Light, LightKey, LightKind, World, WorldKey};
use galerkin_radiosity::scene::json::{parse_scene, scene_to_json};
use galerkin_radiosity::scene::{Material, Object, Scene, Settings};
use galerkin_radiosity::scenes::{box_mesh, panel, subdivided_quad};
use galerkin_radiosity::session::{Method, Session};
use galerkin_radiosity::system::no_progress;
use glam::{DMat4, DVec3};

const RHO: f64 = 0.5;

fn materials() -> Vec<Material> {
    vec![
        Material { name: "grey".into(), reflectance: [RHO; 3], emission: [0.0; 3] },
        Material { name: "glow".into(), reflectance: [0.0; 3], emission: [10.0; 3] },
    ]
}

/// A 4 m x 4 m floor at z = 0 facing up, split 8 x 8.
fn floor() -> Object {
    let p = [
        DVec3::new(-2.0, -2.0, 0.0),
        DVec3::new(2.0, -2.0, 0.0),
        DVec3::new(2.0, 2.0, 0.0),
        DVec3::new(-2.0, 2.0, 0.0),
    ];
    subdivided_quad("Floor", p, 8, 0)
}

fn scene(objects: Vec<Object>, lights: Vec<Light>, frames: (i64, i64)) -> Scene {
    let settings = Settings { tolerance: 1e-6, ..Settings::default() };
    Scene::new(settings, frames, materials(), vec![Vec::new(); 2], objects)
        .unwrap()
        .with_lights(lights)
        .unwrap()
}

/// Every corner of object `o` at `frame`: (world position, gathered `B`).
fn corners(session: &mut Session, frame: f64, o: usize) -> Vec<(DVec3, [f32; 3])> {
    session.solve_frame(frame, &no_progress).unwrap();
    let obj = &session.scene().objects[o];
    let m = obj.world_from_object(frame);
    let points: Vec<DVec3> =
        obj.faces.iter().flatten().map(|&v| m.transform_point3(obj.vertices[v as usize])).collect();
    let values = session.face_results().unwrap()[o].corner_radiosity.clone();
    points.into_iter().zip(values).collect()
}

/// The floor's corners at frame 1 lit by `light` alone (a full solve).
fn lit_floor(light: Light) -> Vec<(DVec3, [f32; 3])> {
    let mut s = Session::new(scene(vec![floor()], vec![light], (1, 1)), Method::Full).unwrap();
    corners(&mut s, 1.0, 0)
}

/// Worst corner error relative to the peak of `want`.
fn worst(got: &[(DVec3, [f32; 3])], want: impl Fn(DVec3) -> f64) -> f64 {
    let peak = got.iter().map(|(x, _)| want(*x)).fold(0.0, f64::max);
    got.iter().map(|(x, b)| (b[0] as f64 - want(*x)).abs()).fold(0.0, f64::max) / peak
}

fn at(position: DVec3, direction: DVec3) -> DMat4 {
    let z = -direction.normalize();
    let x = (if z.x.abs() < 0.9 { DVec3::X } else { DVec3::Y }).cross(z).normalize();
    DMat4::from_cols(x.extend(0.0), z.cross(x).extend(0.0), z.extend(0.0), position.extend(1.0))
}

#[test]
fn a_point_light_gives_the_inverse_square_cosine_law() {
    let p = DVec3::new(0.3, -0.2, 1.5);
    let light = Light::new("Point", LightKind::Point, DMat4::from_translation(p), 100.0);
    let got = lit_floor(light);
    let e = |x: DVec3| RHO * 100.0 / (4.0 * PI) * p.z / (p - x).length().powi(3);
    let w = worst(&got, e);
    eprintln!("point light: worst corner {w:.2e} of the peak");
    assert!(w < 5e-3, "{w}");
}

#[test]
fn a_sun_lights_a_floor_evenly_by_its_cosine() {
    let d = DVec3::new(1.0, 0.5, -2.0).normalize();
    let light = Light::new("Sun", LightKind::Sun, at(DVec3::new(9.0, 9.0, 9.0), d), 3.0);
    let got = lit_floor(light);
    let w = worst(&got, |_| RHO * 3.0 * -d.z);
    assert!(w < 1e-6, "{w}");
}

#[test]
fn a_spot_lights_its_cone_and_fades_at_its_edge() {
    let p = DVec3::new(0.0, 0.0, 1.0);
    let mut light = Light::new("Spot", LightKind::Spot, at(p, -DVec3::Z), 100.0);
    light.base.spot_size = 60f64.to_radians();
    light.base.spot_blend = 0.5;
    let got = lit_floor(light);
    let cos_half = 30f64.to_radians().cos();
    let smooth = (1.0 - cos_half) * 0.5;
    let e = |x: DVec3| {
        let d = p - x;
        let cos = d.z / d.length();
        let f = ((cos - cos_half) / smooth).clamp(0.0, 1.0);
        RHO * 100.0 / (4.0 * PI) * cos / d.length_squared() * (3.0 - 2.0 * f) * f * f
    };
    let w = worst(&got, e);
    assert!(w < 5e-3, "{w}");
    // Corners outside the cone (the floor's edge, 2 m out at 1 m height) get nothing.
    assert!(got.iter().filter(|(x, _)| x.x.abs() == 2.0).all(|(_, b)| b[0] < 1e-4));
}

#[test]
fn a_square_area_light_over_a_point_gives_the_rectangle_form_factor() {
    // A 1 m square at 1 m height facing down, power 10 W: exitance 10 W/m^2. Under its centre,
    // four corner rectangles of 0.5 x 0.5 at distance 1 (Howell C-11) make the form factor.
    let mut light = Light::new("Area", LightKind::Area, at(DVec3::new(0.0, 0.0, 1.0), -DVec3::Z), 10.0);
    light.shape = AreaShape::Square;
    light.base.size = [1.0, 1.0];
    let got = lit_floor(light);
    let (x, y) = (0.5f64, 0.5f64);
    let c11 = (x / (1.0 + x * x).sqrt() * (y / (1.0 + x * x).sqrt()).atan()
        + y / (1.0 + y * y).sqrt() * (x / (1.0 + y * y).sqrt()).atan())
        / (2.0 * PI);
    let centre = got.iter().find(|(p, _)| p.length() < 1e-9).unwrap().1[0] as f64;
    let want = RHO * 10.0 * 4.0 * c11;
    assert!((centre - want).abs() < 5e-3 * want, "{centre} vs {want}");
}

#[test]
fn a_blocker_casts_a_shadow_from_a_point_light() {
    let p = DVec3::new(0.0, 0.0, 2.0);
    let light = Light::new("Point", LightKind::Point, DMat4::from_translation(p), 100.0);
    // A 0.6 m square at 1 m height facing up, black below (reflectance 0 on both materials'
    // receiving side does not matter: it faces the light).
    let blocker = panel("Blocker", DVec3::new(0.0, 0.0, 1.0), 0.3 * DVec3::X, 0.3 * DVec3::Y, DVec3::Z, 1, 0);
    let mut s = Session::new(scene(vec![floor(), blocker], vec![light], (1, 1)), Method::Full).unwrap();
    let got = corners(&mut s, 1.0, 0);
    let centre = got.iter().find(|(x, _)| x.length() < 1e-9).unwrap().1[0] as f64;
    let unshadowed = RHO * 100.0 / (4.0 * PI) / 4.0;
    assert!(centre < 0.02 * unshadowed, "{centre} vs {unshadowed}");
    // Beyond the shadow (0.6 m out, the shadow's edge at 0.3 x 2 = 0.6) the floor is lit.
    let far = got.iter().find(|(x, _)| (x.x - 1.0).abs() < 1e-9 && x.y.abs() < 1e-9).unwrap().1[0] as f64;
    assert!(far > 0.5 * unshadowed, "{far}");
}

/// A moving, brightening Point light and a recoloured Sun over a floor with a block: the
/// incremental update's frames against full solves (the direct term changes as emission).
#[test]
fn animated_lights_incremental_frames_equal_full_solves() {
    let mut point =
        Light::new("Point", LightKind::Point, DMat4::from_translation(DVec3::new(-0.5, 0.0, 1.5)), 80.0);
    point.animation = vec![
        LightKey { frame: 1.0, ..LightKey::default() },
        LightKey {
            frame: 4.0,
            matrix: Some(DMat4::from_translation(DVec3::new(0.6, 0.2, 1.2))),
            color: Some([1.0, 0.6, 0.3]),
            power: Some(150.0),
            ..LightKey::default()
        },
    ];
    let mut sun = Light::new("Sun", LightKind::Sun, at(DVec3::ZERO, DVec3::new(0.3, 0.0, -1.0)), 1.0);
    sun.animation = vec![
        LightKey { frame: 1.0, ..LightKey::default() },
        LightKey { frame: 4.0, matrix: None, color: Some([0.2, 0.4, 1.0]), ..LightKey::default() },
    ];
    let block = galerkin_radiosity::scenes::merge(
        "Block",
        [DVec3::X, -DVec3::X, DVec3::Y, -DVec3::Y, DVec3::Z]
            .iter()
            .map(|&n| {
                let (u, v) = if n.z != 0.0 {
                    (DVec3::X, DVec3::Y)
                } else if n.x != 0.0 {
                    (DVec3::Y, DVec3::Z)
                } else {
                    (DVec3::X, DVec3::Z)
                };
                panel("side", DVec3::new(0.0, 0.0, 0.25) + 0.25 * n, 0.25 * u, 0.25 * v, n, 2, 0)
            })
            .collect(),
    );
    let sc = scene(vec![floor(), block], vec![point, sun], (1, 4));
    let bake = |method| {
        let mut s = Session::new(sc.clone(), method).unwrap();
        (1..=4)
            .map(|f| {
                s.solve_frame(f as f64, &no_progress).unwrap();
                s.face_results().unwrap().into_iter().flat_map(|o| o.corner_radiosity).collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    let (full, inc) = (bake(Method::Full), bake(Method::Incremental));
    assert_frames_agree(&inc, &full);
    // The light did change the picture.
    assert!(full[0].iter().zip(&full[3]).any(|(x, y)| (x[0] - y[0]).abs() > 0.1 * x[0].max(y[0])));
}

#[test]
fn lights_round_trip_through_the_scene_file() {
    let mut spot =
        Light::new("Spot", LightKind::Spot, at(DVec3::new(1.0, 2.0, 3.0), DVec3::new(0.0, 1.0, -1.0)), 40.0);
    spot.base.color = [1.0, 0.5, 0.25];
    spot.animation = vec![
        LightKey { frame: 3.0, power: Some(5.0), spot_size: Some(0.5), ..LightKey::default() },
        LightKey { frame: 5.0, radius: Some(0.3), soft_falloff: Some(false), ..LightKey::default() },
    ];
    let mut area = Light::new("Area", LightKind::Area, DMat4::IDENTITY, 12.0);
    area.shape = AreaShape::Ellipse;
    area.base.size = [0.5, 2.0];
    area.animation = vec![LightKey { frame: 2.0, size: Some([0.25, 1.5]), ..LightKey::default() }];
    let mut point = round_point(DVec3::new(0.0, 1.0, 2.0), 30.0, 0.25, false);
    point.name = "Bulb".into();
    let mut sun = Light::new("Sun", LightKind::Sun, DMat4::IDENTITY, 2.0);
    sun.base.angle = 0.2;
    sun.animation = vec![LightKey { frame: 2.0, angle: Some(0.05), ..LightKey::default() }];
    let sc = scene(vec![floor()], vec![spot, area, sun, point], (1, 3));
    let back = parse_scene(&scene_to_json(&sc)).unwrap();
    assert_eq!(back.lights, sc.lights);
    // position + direction: local -Z along the direction.
    let text = r#"{"version":1,"settings":{"basis_order":1},"materials":[{"reflectance":[0.5,0.5,0.5]}],
        "objects":[],"lights":[{"type":"point","position":[1,2,3],"direction":[0,0,-1],"power":10}]}"#;
    let l = &parse_scene(text).unwrap().lights[0];
    assert_eq!(l.base.matrix.w_axis.truncate(), DVec3::new(1.0, 2.0, 3.0));
    assert!((galerkin_radiosity::lights::direction(&l.base.matrix) + DVec3::Z).length() < 1e-12);
    assert!(l.base.soft_falloff, "Blender's default");
    let sphere =
        parse_scene(&text.replace(r#""power":10"#, r#""power":10,"radius":0.5,"soft_falloff":false"#))
            .unwrap();
    assert!(!sphere.lights[0].base.soft_falloff);
    assert_eq!(sphere.lights[0].base.radius, 0.5);
}

#[test]
fn bad_lights_are_named_in_one_line() {
    let base = r#"{"version":1,"settings":{"basis_order":1},"materials":[{"reflectance":[0.5,0.5,0.5]}],"objects":[],"lights":[LIGHT]}"#;
    for (light, says) in [
        (r#"{"name":"Lamp","type":"candle","power":1}"#, "light \"Lamp\": type \"candle\""),
        (r#"{"name":"Lamp","type":"sun","power":1,"strength":2}"#, "needs \"strength\""),
        (r#"{"name":"Lamp","type":"point"}"#, "needs \"power\""),
        (r#"{"name":"Lamp","type":"point","power":-1}"#, "power -1 must be finite and >= 0"),
        (r#"{"name":"Lamp","type":"spot","power":1,"spot_blend":2}"#, "spot_blend 2 is outside [0,1]"),
        (r#"{"name":"Lamp","type":"area","power":1,"size":[0,1]}"#, "size [0.0, 1.0] must be finite and > 0"),
        (
            r#"{"name":"Lamp","type":"point","power":1,"position":[0,0,0],"matrix":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}"#,
            "not both",
        ),
    ] {
        let err = parse_scene(&base.replace("LIGHT", light)).unwrap_err().to_string();
        assert!(err.contains(says), "{err}");
        assert!(!err.contains('\n'));
    }
}

#[test]
fn an_emitter_facing_away_from_everything_is_reported() {
    // An emissive panel above the floor facing up (away from it): it lights nothing.
    let up = panel("Sky lamp", DVec3::new(0.0, 0.0, 1.0), 0.3 * DVec3::X, 0.3 * DVec3::Y, DVec3::Z, 1, 1);
    let down = panel("Lamp", DVec3::new(0.0, 0.0, 1.0), 0.3 * DVec3::X, 0.3 * DVec3::Y, -DVec3::Z, 1, 1);
    let mut s = Session::new(scene(vec![floor(), up.clone()], vec![], (1, 1)), Method::Full).unwrap();
    let stats = s.solve_frame(1.0, &no_progress).unwrap();
    assert_eq!(
        stats.warnings,
        vec![
            "emitter \"Sky lamp\" lights nothing: its emitting faces face away from all geometry (flip its \
             normals, or turn on Two-Sided in its Radiosity object panel)"
        ]
    );
    let mut s = Session::new(scene(vec![floor(), down], vec![], (1, 1)), Method::Full).unwrap();
    assert!(s.solve_frame(1.0, &no_progress).unwrap().warnings.is_empty());
}

/// A mirroring placement (scale x = -1) lights the object as the mirror image built by hand
/// (vertices mirrored, winding reversed) is lit.
#[test]
fn a_mirroring_key_keeps_the_front_side() {
    let p = DVec3::new(0.0, 0.0, 2.0);
    let light = Light::new("Point", LightKind::Point, DMat4::from_translation(p), 100.0);
    let mut tile = panel("Tile", DVec3::new(0.5, 0.2, 0.5), 0.2 * DVec3::X, 0.3 * DVec3::Y, DVec3::Z, 2, 0);
    let plain = tile.clone();
    // Mirror in x about the origin: the tile lands at x = -0.5, still facing up.
    tile.matrix = DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0));
    let mut by_hand = plain.clone();
    for v in &mut by_hand.vertices {
        v.x = -v.x;
    }
    for f in &mut by_hand.faces {
        f.swap(0, 1);
        f.swap(2, 3);
    }
    let value = |o: Object| {
        let mut s = Session::new(scene(vec![floor(), o], vec![light.clone()], (1, 1)), Method::Full).unwrap();
        corners(&mut s, 1.0, 1).into_iter().map(|(_, b)| b[0]).collect::<Vec<_>>()
    };
    let (a, b) = (value(tile), value(by_hand));
    assert!(a.iter().all(|&x| x > 0.5), "the mirrored tile faces the light: {a:?}");
    // By hand, a face's corner k is the mirrored face's corner [1, 0, 3, 2][k].
    for (fa, fb) in a.chunks(4).zip(b.chunks(4)) {
        for (k, &x) in fa.iter().enumerate() {
            let y = fb[[1, 0, 3, 2][k]];
            assert!((x - y).abs() < 1e-4 * y, "{x} vs {y}");
        }
    }
}

/// An Area light and the emissive mesh it stands for (a one-sided, black quad of exitance
/// `P / A` in the same place) light a floor, a wall standing on it and a block alike: the
/// lights' path (direct term, its projection, the gather's corners and their feet at the
/// concave junctions) against the emitter path validated against Cycles (README).
#[test]
fn an_area_light_lights_like_the_emissive_quad_it_stands_for() {
    let wall = panel("Wall", DVec3::new(0.0, 2.0, 1.0), 2.0 * DVec3::X, 1.0 * DVec3::Z, -DVec3::Y, 6, 0);
    let block = panel("Block", DVec3::new(0.3, 0.0, 0.4), 0.3 * DVec3::X, 0.3 * DVec3::Y, DVec3::Z, 2, 0);
    let receivers = vec![floor(), wall, block];
    let centre = DVec3::new(-0.2, 0.4, 1.6);
    // Unrotated, a light looks down -Z with its size along X and Y.
    let mut light = Light::new("Area", LightKind::Area, DMat4::from_translation(centre), 20.0);
    light.shape = AreaShape::Rectangle;
    light.base.size = [0.6, 0.4];
    let lit = scene(receivers.clone(), vec![light], (1, 1));
    let mut materials = materials();
    materials[1].emission = [20.0 / (0.6 * 0.4); 3];
    let quad = panel("Quad", centre, 0.3 * DVec3::X, 0.2 * DVec3::Y, -DVec3::Z, 4, 1);
    let mut objects = receivers;
    objects.push(quad);
    let meshed = Scene::new(lit.settings.clone(), (1, 1), materials, vec![Vec::new(); 2], objects).unwrap();
    let values = |sc: Scene| {
        let mut s = Session::new(sc, Method::Full).unwrap();
        s.solve_frame(1.0, &no_progress).unwrap();
        s.face_results().unwrap().into_iter().take(3).flat_map(|o| o.corner_radiosity).collect::<Vec<_>>()
    };
    let (a, b) = (values(lit), values(meshed));
    let peak = b.iter().map(|x| x[0]).fold(0.0f32, f32::max);
    let worst = a.iter().zip(&b).map(|(x, y)| (x[0] - y[0]).abs()).fold(0.0f32, f32::max);
    let mean = |v: &[[f32; 3]]| v.iter().map(|x| x[0] as f64).sum::<f64>() / v.len() as f64;
    eprintln!(
        "area light vs emissive quad: worst corner {:.2e} of the peak, means {} vs {}",
        worst / peak,
        mean(&a),
        mean(&b)
    );
    // Measured: 3.9% of the peak at the worst corner (the block's penumbra on the floor: 16
    // shadow rays against the emitter's own quadrature; 3.1% with 64), means 0.4% apart.
    assert!(worst < 0.05 * peak, "{worst} vs peak {peak}");
    assert!((mean(&a) - mean(&b)).abs() < 5e-3 * mean(&b));
}

// ---------------------------------------------------------------------------------------------
// The World (issue 22, item 2) and two-sided emitters (item 6)

/// Grey floor, black (reflecting nothing, emitting nothing) and glowing materials.
fn world_materials() -> Vec<Material> {
    vec![
        Material { name: "grey".into(), reflectance: [RHO; 3], emission: [0.0; 3] },
        Material { name: "black".into(), reflectance: [0.0; 3], emission: [0.0; 3] },
        Material { name: "glow".into(), reflectance: [0.0; 3], emission: [10.0; 3] },
    ]
}

fn world_scene(objects: Vec<Object>, world: Option<World>, frames: (i64, i64)) -> Scene {
    let settings = Settings { tolerance: 1e-6, ..Settings::default() };
    Scene::new(settings, frames, world_materials(), vec![Vec::new(); 3], objects)
        .unwrap()
        .with_world(world)
        .unwrap()
}

/// Howell's corner formula: a differential area parallel to an `a x b` rectangle at distance
/// `c`, its normal through a corner (references.md); 0 for an empty rectangle.
fn corner_form_factor(a: f64, b: f64, c: f64) -> f64 {
    if a <= 0.0 || b <= 0.0 {
        return 0.0;
    }
    let (x, y) = (a / c, b / c);
    (x / (1.0 + x * x).sqrt() * (y / (1.0 + x * x).sqrt()).atan()
        + y / (1.0 + y * y).sqrt() * (x / (1.0 + y * y).sqrt()).atan())
        / (2.0 * PI)
}

const SKY: [f64; 3] = [0.4, 0.6, 0.8];

#[test]
fn an_open_floor_under_a_uniform_world_gets_pi_l() {
    // B = rho E = rho pi L at every corner and on every face, whatever the rays (each sees L).
    let world = World::uniform(SKY, 2.5);
    let mut s = Session::new(world_scene(vec![floor()], Some(world), (1, 1)), Method::Full).unwrap();
    let got = corners(&mut s, 1.0, 0);
    for (_, b) in &got {
        for c in 0..3 {
            let want = RHO * PI * 2.5 * SKY[c];
            assert!((b[c] as f64 - want).abs() < 1e-5 * want, "{b:?}");
        }
    }
    let faces = &s.face_results().unwrap()[0].face_radiosity;
    assert!(faces.iter().all(|f| (f[1] as f64 - RHO * PI * 2.5 * SKY[1]).abs() < 1e-4));
}

#[test]
fn a_floor_inside_a_closed_box_sees_no_world() {
    let room = box_mesh("Room", DVec3::splat(-2.5), DVec3::new(2.5, 2.5, 3.0), 2, true, 1);
    let mut inner = floor();
    inner.vertices.iter_mut().for_each(|v| v.z = -1.0);
    let mut s = Session::new(
        world_scene(vec![inner, room], Some(World::uniform([1.0; 3], 10.0)), (1, 1)),
        Method::Full,
    )
    .unwrap();
    let got = corners(&mut s, 1.0, 0);
    assert!(got.iter().all(|(_, b)| b.iter().all(|&c| c == 0.0)), "{:?}", &got[..4]);
}

/// An open-top box (floor 4 x 4 m, black walls 1 m high): each floor corner sees the World
/// through the opening only, `B = rho pi L F(x -> opening)` with `F` four corner rectangles.
#[test]
fn an_open_top_box_floor_gets_the_form_factor_to_the_opening() {
    let h = 1.0;
    let walls = |name: &str, c: DVec3, u: DVec3, n: DVec3| panel(name, c, u, 0.5 * h * DVec3::Z, n, 4, 1);
    let objects = vec![
        floor(),
        walls("N", DVec3::new(0.0, 2.0, 0.5 * h), 2.0 * DVec3::X, -DVec3::Y),
        walls("S", DVec3::new(0.0, -2.0, 0.5 * h), 2.0 * DVec3::X, DVec3::Y),
        walls("E", DVec3::new(2.0, 0.0, 0.5 * h), 2.0 * DVec3::Y, -DVec3::X),
        walls("W", DVec3::new(-2.0, 0.0, 0.5 * h), 2.0 * DVec3::Y, DVec3::X),
    ];
    let l = 3.0;
    let mut s =
        Session::new(world_scene(objects, Some(World::uniform([1.0; 3], l)), (1, 1)), Method::Full).unwrap();
    let got = corners(&mut s, 1.0, 0);
    let want = |x: DVec3| {
        let f: f64 =
            [(2.0 - x.x, 2.0 - x.y), (2.0 + x.x, 2.0 - x.y), (2.0 - x.x, 2.0 + x.y), (2.0 + x.x, 2.0 + x.y)]
                .iter()
                .map(|&(a, b)| corner_form_factor(a, b, h))
                .sum();
        RHO * PI * l * f
    };
    let w = worst(&got, want);
    let rms =
        (got.iter().map(|(x, b)| (b[0] as f64 - want(*x)).powi(2)).sum::<f64>() / got.len() as f64).sqrt();
    let mean = got.iter().map(|(x, _)| want(*x)).sum::<f64>() / got.len() as f64;
    eprintln!("open-top box: relative RMSE {:.2e}", rms / mean);
    let mean_error =
        got.iter().map(|(x, b)| (b[0] as f64 - want(*x)) / want(*x)).sum::<f64>() / got.len() as f64;
    eprintln!("open-top box: worst corner {w:.2e} of the peak, mean relative error {mean_error:.2e}");
    // Medium: 16 x 16 strata per corner, refined on the sky's edges. Measured: RMSE 0.48%,
    // worst corner 0.71% of the peak, mean +0.22%.
    assert!(rms < 0.01 * mean, "{rms} vs mean {mean}");
    assert!(w < 0.015, "{w}");
    assert!(mean_error.abs() < 5e-3, "{mean_error}");
}

#[test]
fn a_constant_image_lights_as_its_colour_does() {
    let blocker = panel("Blocker", DVec3::new(0.3, 0.0, 0.8), 0.5 * DVec3::X, 0.4 * DVec3::Y, DVec3::Z, 2, 1);
    let values = |world: World| {
        let mut s =
            Session::new(world_scene(vec![floor(), blocker.clone()], Some(world), (1, 1)), Method::Full)
                .unwrap();
        corners(&mut s, 1.0, 0)
    };
    let colour = values(World::uniform(SKY, 2.0));
    let mut textured = World::uniform([1.0; 3], 2.0);
    let texel = SKY.map(|c| c as f32);
    textured.image = Some(std::sync::Arc::new(Environment { width: 8, height: 4, pixels: vec![texel; 32] }));
    let image = values(textured);
    assert!(colour.iter().any(|(_, b)| b[0] < 0.9 * (RHO * PI * 2.0 * SKY[0]) as f32), "the blocker shades");
    for ((_, a), (_, b)) in colour.iter().zip(&image) {
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() <= 1e-6 * a[c].max(1e-3), "{a:?} vs {b:?}");
        }
    }
}

/// An image bright (2) in its upper half, the sky above the horizon, and dark below: an
/// up-facing floor sees the bright half, a wall facing +X half of each.
#[test]
fn a_half_bright_sky_lights_up_facing_and_side_facing_faces_by_their_share() {
    let pixels: Vec<[f32; 3]> = (0..16 * 8).map(|k| if k / 16 >= 4 { [2.0; 3] } else { [0.0; 3] }).collect();
    let mut world = World::uniform([1.0; 3], 1.0);
    world.image = Some(std::sync::Arc::new(Environment { width: 16, height: 8, pixels }));
    let wall = panel("Wall", DVec3::new(5.0, 0.0, 1.0), 0.5 * DVec3::Y, 0.5 * DVec3::Z, DVec3::X, 2, 0);
    let mut s = Session::new(world_scene(vec![floor(), wall], Some(world), (1, 1)), Method::Full).unwrap();
    let floor_values = corners(&mut s, 1.0, 0);
    let wall_values = corners(&mut s, 1.0, 1);
    // The texels next to the horizon blend bright and dark over half a texel (11.25 degrees
    // of a 22.5-degree row): the floor's cosine weights that band by sin(2 theta); its exact
    // share below follows from integrating the bilinear ramp.
    let ramp = |elevation: f64| (0.5 + elevation / (PI / 8.0)).clamp(0.0, 1.0); // v over texel rows
    let (mut floor_e, mut wall_e) = (0.0, 0.0);
    let n = 4000;
    for i in 0..n {
        let th = (i as f64 + 0.5) / n as f64 * PI; // polar angle from the zenith
        let l = 2.0 * ramp(PI / 2.0 - th);
        let dth = PI / n as f64;
        if th < PI / 2.0 {
            floor_e += l * th.cos() * th.sin() * dth * 2.0 * PI;
        }
        // A +X-facing wall: integral over azimuth of max(0, sin th cos phi) = 2 sin th.
        wall_e += l * 2.0 * th.sin() * th.sin() * dth;
    }
    let f = floor_values.iter().map(|(_, b)| b[0] as f64).sum::<f64>() / floor_values.len() as f64;
    let w = wall_values.iter().map(|(_, b)| b[0] as f64).sum::<f64>() / wall_values.len() as f64;
    eprintln!("half sky: floor {f} vs {}, wall {w} vs {}", RHO * floor_e, RHO * wall_e);
    // Measured: floor +0.34% (the ramp's strata averaged over their sub-strata), wall exact.
    assert!((f - RHO * floor_e).abs() < 5e-3 * RHO * floor_e, "{f} vs {}", RHO * floor_e);
    assert!((w - RHO * wall_e).abs() < 5e-3 * RHO * wall_e, "{w} vs {}", RHO * wall_e);
}

#[test]
fn an_animated_world_strength_incremental_frames_equal_full_solves() {
    let block = box_mesh("Block", DVec3::new(-0.3, -0.3, 0.0), DVec3::new(0.3, 0.3, 0.6), 2, false, 0);
    let mut world = World::uniform(SKY, 1.0);
    world.animation = vec![
        WorldKey { frame: 1.0, color: None, strength: Some(1.0) },
        WorldKey { frame: 3.0, color: Some([1.0, 0.5, 0.2]), strength: Some(4.0) },
    ];
    let sc = world_scene(vec![floor(), block], Some(world), (1, 3));
    let run = |method| {
        let mut s = Session::new(sc.clone(), method).unwrap();
        (1..=3)
            .map(|f| {
                s.solve_frame(f as f64, &no_progress).unwrap();
                s.face_results().unwrap().into_iter().flat_map(|o| o.corner_radiosity).collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    let (inc, full) = (run(Method::Incremental), run(Method::Full));
    for (a, b) in inc.iter().zip(&full) {
        let peak = b.iter().map(|x| x[0]).fold(0.0f32, f32::max);
        let worst = a.iter().zip(b).map(|(x, y)| (x[0] - y[0]).abs()).fold(0.0f32, f32::max);
        assert!(worst < 2e-3 * peak, "{worst} vs {peak}");
    }
    assert!(full[2][0][0] > 3.0 * full[0][0][0]);
}

#[test]
fn the_world_and_two_sided_round_trip_through_the_scene_file() {
    let mut world = World::uniform(SKY, 2.0);
    world.image =
        Some(std::sync::Arc::new(Environment { width: 2, height: 1, pixels: vec![[0.5; 3], [1.0; 3]] }));
    world.animation = vec![WorldKey { frame: 2.0, color: None, strength: Some(0.5) }];
    let lamp = panel("Lamp", DVec3::new(0.0, 0.0, 1.0), 0.3 * DVec3::X, 0.3 * DVec3::Y, DVec3::Z, 1, 2);
    let sc = world_scene(vec![floor(), lamp], Some(world), (1, 3)).with_two_sided(&[1]).unwrap();
    let back = parse_scene(&scene_to_json(&sc)).unwrap();
    assert_eq!(back.world, sc.world);
    assert_eq!(back.two_sided, vec![false, true]);
    let base = r#"{"version":1,"settings":{"basis_order":1},"materials":[{"reflectance":[0.5,0.5,0.5]}],"objects":[],"world":WORLD}"#;
    for (world, says) in [
        (r#"{"strength":-1}"#, "world: strength -1 must be finite and >= 0"),
        (r#"{"color":[1,-1,0]}"#, "world: color [1.0, -1.0, 0.0] must be"),
        (r#"{"image":{"width":2,"height":2,"pixels":[[1,1,1]]}}"#, "world image: 1 pixels for 2 x 2"),
        (r#"{"animation":[{"frame":2,"strength":-3}]}"#, "world key at frame 2: strength -3"),
    ] {
        let err = parse_scene(&base.replace("WORLD", world)).unwrap_err().to_string();
        assert!(err.contains(says), "{err}");
        assert!(!err.contains('\n'));
    }
}

/// A two-sided emissive panel facing up (away from the floor) lights the floor from its back as
/// the same panel facing down does from its front, and is not reported as lighting nothing.
#[test]
fn a_two_sided_emitter_lights_from_its_back() {
    // The wall stops below the lamp: facing up, the lamp's front sees nothing.
    let wall = panel("Wall", DVec3::new(0.0, 2.0, 0.5), 2.0 * DVec3::X, 0.5 * DVec3::Z, -DVec3::Y, 4, 0);
    let lamp = |n: DVec3| panel("Lamp", DVec3::new(0.2, 0.3, 1.2), 0.3 * DVec3::X, 0.25 * DVec3::Y, n, 2, 2);
    let values = |sc: Scene| {
        let mut s = Session::new(sc, Method::Full).unwrap();
        let stats = s.solve_frame(1.0, &no_progress).unwrap();
        let v = s
            .face_results()
            .unwrap()
            .into_iter()
            .take(2)
            .flat_map(|o| o.corner_radiosity)
            .collect::<Vec<_>>();
        (v, stats.warnings)
    };
    let (down, _) = values(world_scene(vec![floor(), wall.clone(), lamp(-DVec3::Z)], None, (1, 1)));
    let up_scene = world_scene(vec![floor(), wall.clone(), lamp(DVec3::Z)], None, (1, 1));
    let (dark, warned) = values(up_scene.clone());
    assert!(dark.iter().all(|b| b[0] < 1e-6) && warned.len() == 1);
    let (up, warnings) = values(up_scene.with_two_sided(&[2]).unwrap());
    assert!(warnings.is_empty(), "{warnings:?}");
    let peak = down.iter().map(|x| x[0]).fold(0.0f32, f32::max);
    let worst = up.iter().zip(&down).map(|(x, y)| (x[0] - y[0]).abs()).fold(0.0f32, f32::max);
    let mean = |v: &[[f32; 3]]| v.iter().map(|x| x[0] as f64).sum::<f64>() / v.len() as f64;
    eprintln!(
        "two-sided back vs front: worst corner {:.2e} of the peak, means {} vs {}",
        worst / peak,
        mean(&up),
        mean(&down)
    );
    assert!(worst < 0.03 * peak, "{worst} vs {peak}");
    assert!((mean(&up) - mean(&down)).abs() < 5e-3 * mean(&down));
}

// ---------------------------------------------------------------------------------------------
// Soft shadows: Point and Spot of radius > 0 (a disk facing the receiver with Soft Falloff, a
// sphere without), Sun of angle > 0 (a cone)

/// A Point light of `power` W and radius `r` at `p`, Soft Falloff `soft`.
fn round_point(p: DVec3, power: f64, r: f64, soft: bool) -> Light {
    let mut light = Light::new("Round", LightKind::Point, DMat4::from_translation(p), power);
    light.base.radius = r;
    light.base.soft_falloff = soft;
    light
}

/// The unoccluded irradiance at `x` (unit normal `n`, facing +Z here) of a Lambertian disk of
/// radiance `radiance` about `centre` of radius `rho` facing `x`, by a fine polar rule over
/// the disk (the reference for a disk or sphere across the receiver's horizon).
fn disk_irradiance(x: DVec3, n: DVec3, centre: DVec3, rho: f64, radiance: f64) -> f64 {
    let a = (centre - x).normalize();
    let (b1, b2) = a.any_orthonormal_pair();
    let (nr, nt) = (400, 800);
    let mut sum = 0.0;
    for i in 0..nr {
        let s = rho * (i as f64 + 0.5) / nr as f64;
        for j in 0..nt {
            let th = 2.0 * PI * (j as f64 + 0.5) / nt as f64;
            let y = centre + (b1 * th.cos() + b2 * th.sin()) * s;
            let d = y - x;
            let t2 = d.length_squared();
            let w = n.dot(d).max(0.0) * a.dot(d) / (t2 * t2);
            sum += w * s * (rho / nr as f64) * (2.0 * PI / nt as f64);
        }
    }
    radiance * sum
}

#[test]
fn a_soft_falloff_point_light_is_a_disk_facing_the_receiver() {
    // Radius 0.5 at 2 m: P cos / (4 pi (d^2 + r^2)), 1 - 4 / 4.25 = 5.9% below the point
    // light straight under it (Cycles' disk of radiance P / (4 pi^2 r^2)).
    let (p, r, power) = (DVec3::new(0.3, -0.2, 2.0), 0.5, 100.0);
    let got = lit_floor(round_point(p, power, r, true));
    let e = |x: DVec3| {
        let d = p - x;
        RHO * power / (4.0 * PI) * (d.z / d.length()) / (d.length_squared() + r * r)
    };
    let w = worst(&got, e);
    eprintln!("soft-falloff point: worst corner {w:.2e} of the peak");
    assert!(w < 5e-3, "{w}");
    let under = got.iter().find(|(x, _)| (x.x - 0.5).abs() < 1e-9 && x.y.abs() < 1e-9).unwrap();
    let point = RHO * power / (4.0 * PI) * p.z / (p - under.0).length().powi(3);
    let ratio = under.1[0] as f64 / point;
    eprintln!("soft-falloff point: {ratio:.4} of the point light 0.2 m off its foot");
    assert!(ratio < 0.95 && ratio > 0.93, "{ratio}");
}

#[test]
fn a_sphere_light_lights_as_its_point_does_while_seen_whole() {
    // Soft Falloff off: a sphere of radiance P / (4 pi^2 r^2) subtends sin^2(alpha) = r^2 / d^2,
    // so E = pi L sin^2(alpha) cos = P cos / (4 pi d^2), the point light's.
    let (p, r, power) = (DVec3::new(0.3, -0.2, 1.5), 0.5, 100.0);
    let got = lit_floor(round_point(p, power, r, false));
    let e = |x: DVec3| RHO * power / (4.0 * PI) * p.z / (p - x).length().powi(3);
    let w = worst(&got, e);
    eprintln!("sphere light: worst corner {w:.2e} of the peak");
    assert!(w < 5e-3, "{w}");
}

#[test]
fn round_lights_across_the_horizon_match_the_disk_integral() {
    // Low lights whose disk (or sphere's tangent circle) the floor's far corners see cut by
    // their horizon: the clipped 32-gon's form factor against a fine integral over the disk.
    let (r, power) = (0.4, 100.0);
    let p = DVec3::new(0.0, 0.0, 0.3);
    for soft in [true, false] {
        let got = lit_floor(round_point(p, power, r, soft));
        let radiance = power / (4.0 * PI * PI * r * r);
        let want = |x: DVec3| {
            let d2 = (x - p).length_squared();
            if !soft && d2 <= r * r {
                return RHO * PI * radiance;
            }
            let (c, rho) =
                if soft { (p, r) } else { (p + (x - p) * (r * r / d2), r * (1.0 - r * r / d2).sqrt()) };
            RHO * disk_irradiance(x, DVec3::Z, c, rho, radiance)
        };
        // The corners whose horizon cuts the disk.
        let cut: Vec<_> = got
            .iter()
            .filter(|(x, _)| {
                let d = p - *x;
                let dist2 = if soft { d.length_squared() } else { d.length_squared() - r * r };
                let rho2 = if soft { r * r } else { r * r * dist2 / d.length_squared() };
                dist2 > 0.0 && (d.z * d.z / d.length_squared()) < rho2 / (dist2 + rho2)
            })
            .copied()
            .collect();
        assert!(cut.len() > 10, "{}", cut.len());
        let w = worst(&got, want);
        let wc = worst(&cut, want);
        eprintln!(
            "low {} light: worst corner {w:.2e}, across the horizon {wc:.2e} of the peak ({} corners)",
            if soft { "disk" } else { "sphere" },
            cut.len()
        );
        assert!(w < 5e-3 && wc < 5e-3, "{w} {wc}");
    }
}

/// A 1.5 m square blocker at height 1 facing up covering `x < edge` (its other sides far out).
fn half_blocker(edge: f64) -> Object {
    panel("Blocker", DVec3::new(edge - 0.75, 0.0, 1.0), 0.75 * DVec3::X, 1.5 * DVec3::Y, DVec3::Z, 2, 0)
}

#[test]
fn a_blocker_edge_across_a_round_light_leaves_half_its_light() {
    // A light 2 m over the floor's centre, a blocker's edge 1 m up right under it: the centre
    // of the floor sees half the disk (or the sphere's tangent circle), the rays' points being
    // symmetric about the disk's centre.
    let p = DVec3::new(0.0, 0.0, 2.0);
    for soft in [true, false] {
        let light = round_point(p, 100.0, 0.5, soft);
        let open = |objects| {
            let mut s = Session::new(scene(objects, vec![light.clone()], (1, 1)), Method::Full).unwrap();
            corners(&mut s, 1.0, 0).into_iter().find(|(x, _)| x.length() < 1e-9).unwrap().1[0] as f64
        };
        let (lit, half) = (open(vec![floor()]), open(vec![floor(), half_blocker(0.0)]));
        eprintln!(
            "{}: half-blocked centre {:.4} of the unblocked",
            if soft { "disk" } else { "sphere" },
            half / lit
        );
        assert!((half / lit - 0.5).abs() < 0.02, "{half} vs {lit}");
    }
}

#[test]
fn a_vanishing_radius_converges_to_the_point_light() {
    let p = DVec3::new(0.3, -0.2, 1.5);
    let point = lit_floor(round_point(p, 100.0, 0.0, true));
    for soft in [true, false] {
        let mut last = f64::INFINITY;
        for r in [0.3, 0.1, 0.01, 1e-3] {
            let got = lit_floor(round_point(p, 100.0, r, soft));
            let w =
                worst(&got, |x| point.iter().find(|(y, _)| (*y - x).length() < 1e-12).unwrap().1[0] as f64);
            eprintln!(
                "{} radius {r}: worst corner {w:.2e} of the point's peak",
                if soft { "disk" } else { "sphere" }
            );
            assert!(w <= last * 1.01 + 1e-6, "radius {r}: {w} after {last}");
            last = w;
        }
        assert!(last < 1e-5, "{last}");
    }
}

#[test]
fn a_spot_with_a_radius_keeps_its_cone() {
    // Inside the cone (well inside its blend) a spot of radius r lights as its disk; outside
    // it, nothing; at the cone's edge the rays' points fade by their own directions.
    let p = DVec3::new(0.0, 0.0, 1.0);
    let mut spot = Light::new("Spot", LightKind::Spot, at(p, -DVec3::Z), 100.0);
    spot.base.spot_size = 90f64.to_radians();
    spot.base.spot_blend = 0.2;
    spot.base.radius = 0.2;
    let got = lit_floor(spot);
    let disk = |x: DVec3| {
        let d = p - x;
        RHO * 100.0 / (4.0 * PI) * (d.z / d.length()) / (d.length_squared() + 0.04)
    };
    let inner: Vec<_> = got.iter().filter(|(x, _)| x.truncate().length() <= 0.5).copied().collect();
    let w = worst(&inner, disk);
    assert!(w < 5e-3, "{w}");
    assert!(got.iter().filter(|(x, _)| x.truncate().length() >= 1.6).all(|(_, b)| b[0] < 1e-4));
    let edge: Vec<_> = got
        .iter()
        .filter(|(x, _)| (0.9..1.1).contains(&x.truncate().length()))
        .map(|(x, b)| b[0] as f64 / disk(*x))
        .collect();
    eprintln!("spot edge: {edge:?} of the disk");
    assert!(edge.iter().all(|&f| f > 0.0 && f < 1.0));
}

#[test]
fn a_sun_of_an_angle_lights_an_open_floor_by_its_cosine_exactly() {
    let d = DVec3::new(1.0, 0.5, -2.0).normalize();
    let mut light = Light::new("Sun", LightKind::Sun, at(DVec3::new(9.0, 9.0, 9.0), d), 3.0);
    light.base.angle = 10f64.to_radians();
    let got = lit_floor(light);
    let w = worst(&got, |_| RHO * 3.0 * -d.z);
    assert!(w < 1e-6, "{w}");
}

#[test]
fn a_sun_of_an_angle_casts_a_smooth_penumbra() {
    // A 20 degree sun straight overhead, a blocker's edge 1 m up over x = 0: the penumbra is
    // 2 tan(10 deg) = 0.35 m wide, half the light under the edge, rising monotonically across.
    let strip = subdivided_quad(
        "Strip",
        [
            DVec3::new(-0.5, -0.5, 0.0),
            DVec3::new(0.5, -0.5, 0.0),
            DVec3::new(0.5, 0.5, 0.0),
            DVec3::new(-0.5, 0.5, 0.0),
        ],
        40,
        0,
    );
    let mut sun = Light::new("Sun", LightKind::Sun, at(DVec3::ZERO, -DVec3::Z), 2.0);
    sun.base.angle = 20f64.to_radians();
    let mut s = Session::new(scene(vec![strip, half_blocker(0.0)], vec![sun], (1, 1)), Method::Full).unwrap();
    let mut line: Vec<(f64, f64)> = corners(&mut s, 1.0, 0)
        .into_iter()
        .filter(|(x, _)| x.y.abs() < 1e-9)
        .map(|(x, b)| (x.x, b[0] as f64 / (RHO * 2.0)))
        .collect();
    line.sort_by(|a, b| a.0.total_cmp(&b.0));
    line.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-9);
    eprintln!("sun penumbra: {line:?}");
    let mid = line.iter().find(|(x, _)| x.abs() < 1e-9).unwrap().1;
    assert!((mid - 0.5).abs() < 0.02, "{mid}");
    assert!(line.windows(2).all(|w| w[1].1 >= w[0].1 - 1e-6), "not monotonic");
    let half_width = 10f64.to_radians().tan();
    for &(x, v) in &line {
        if x < -half_width - 0.03 {
            assert!(v < 1e-4, "{x}: {v}");
        } else if x > half_width + 0.03 {
            assert!((v - 1.0).abs() < 1e-4, "{x}: {v}");
        }
    }
    let inside = line.iter().filter(|(_, v)| *v > 0.05 && *v < 0.95).count();
    let steepest = line.windows(2).map(|w| w[1].1 - w[0].1).fold(0.0, f64::max);
    eprintln!("sun penumbra: {inside} corners inside, steepest step {steepest:.3}");
    assert!(inside >= 8, "{inside}");
    assert!(steepest < 0.2, "{steepest}");
}

/// A radius and Soft Falloff changed from frame to frame, a sun's angle and an area light's
/// size: set per frame through `Session::set_lights` (as the add-on and the C ABI set them),
/// incremental frames against full solves; and the same changes keyed in the scene's own
/// animation (as a scene file holds them) give the same frames.
#[test]
fn changing_radius_angle_and_size_incremental_frames_equal_full_solves() {
    let blocker = panel("Blocker", DVec3::new(0.2, 0.1, 0.6), 0.3 * DVec3::X, 0.3 * DVec3::Y, DVec3::Z, 2, 0);
    let radius = [0.0, 0.2, 0.5, 0.5];
    let angle = [0.0f64, 5.0, 15.0, 30.0].map(f64::to_radians);
    let size = [[0.4, 0.4], [0.4, 0.8], [1.0, 0.8], [0.2, 0.2]];
    let point_at = |f: usize| {
        let mut point = round_point(DVec3::new(-0.3, 0.0, 1.6), 120.0, radius[f - 1], f != 4);
        point.base.color = [1.0, 0.8, 0.6];
        point
    };
    let sun_at = |f: usize| {
        let mut sun = Light::new("Sun", LightKind::Sun, at(DVec3::ZERO, DVec3::new(0.4, 0.1, -1.0)), 1.5);
        sun.base.angle = angle[f - 1];
        sun
    };
    let area_at = |f: usize| {
        let mut area = Light::new("Area", LightKind::Area, at(DVec3::new(0.8, -0.5, 1.2), -DVec3::Z), 60.0);
        area.shape = AreaShape::Rectangle;
        area.base.size = size[f - 1];
        area
    };
    let lights = |f: usize| vec![point_at(f), sun_at(f), area_at(f)];
    let bake = |sc: &Scene, method, set: bool| {
        let mut s = Session::new(sc.clone(), method).unwrap();
        (1..=4)
            .map(|f| {
                if set {
                    s.set_lights(lights(f)).unwrap();
                }
                s.solve_frame(f as f64, &no_progress).unwrap();
                s.face_results().unwrap().into_iter().flat_map(|o| o.corner_radiosity).collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    let sc = scene(vec![floor(), blocker.clone()], Vec::new(), (1, 4));
    let (full, inc) = (bake(&sc, Method::Full, true), bake(&sc, Method::Incremental, true));
    assert_frames_agree(&inc, &full);
    for f in 1..4 {
        assert!(
            full[f - 1].iter().zip(&full[f]).any(|(x, y)| (x[0] - y[0]).abs() > 0.02 * x[0].max(y[0])),
            "frame {} did not change the picture",
            f + 1
        );
    }
    // Keyed: every value of frame f in a key at f.
    let keyed = |light: Light, key: &dyn Fn(usize, &Light) -> LightKey| {
        let mut l = light;
        l.animation = (1..=4).map(|f| key(f, &l)).collect();
        l
    };
    let point = keyed(point_at(1), &|f, _| LightKey {
        frame: f as f64,
        radius: Some(radius[f - 1]),
        soft_falloff: Some(f != 4),
        ..LightKey::default()
    });
    // Soft Falloff holds the earlier key's value between keys; the radius is linear.
    let between = point.state_at(3.5);
    assert!(between.soft_falloff && (between.radius - 0.5).abs() < 1e-15);
    assert!((point.state_at(1.5).radius - 0.1).abs() < 1e-15);
    let sun = keyed(sun_at(1), &|f, _| LightKey {
        frame: f as f64,
        angle: Some(angle[f - 1]),
        ..LightKey::default()
    });
    let area = keyed(area_at(1), &|f, _| LightKey {
        frame: f as f64,
        size: Some(size[f - 1]),
        ..LightKey::default()
    });
    let sc = scene(vec![floor(), blocker], vec![point, sun, area], (1, 4));
    let sc = parse_scene(&scene_to_json(&sc)).unwrap(); // through the scene file
    assert_frames_agree(&bake(&sc, Method::Incremental, false), &full);
}

/// Each frame's corners (RGB) of `inc` within 1e-3 of that frame's peak of `full`, frames from 1.
fn assert_frames_agree(inc: &[Vec<[f32; 3]>], full: &[Vec<[f32; 3]>]) {
    for (f, (a, b)) in inc.iter().zip(full).enumerate() {
        let peak = b.iter().flatten().fold(0.0f32, |m, x| m.max(*x));
        let w = a
            .iter()
            .zip(b)
            .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs()))
            .fold(0.0f32, f32::max);
        eprintln!("frame {}: worst {:.2e} of the peak", f + 1, w / peak);
        assert!(w <= 1e-3 * peak, "frame {}: {w} vs {peak}", f + 1);
    }
}

/// A live preview projects lights that moved on a coarser rule (3 x 3 points an element instead
/// of 6 x 6: a quarter of the shadow rays), and refining the frame projects them again in full:
/// the refined frame equals a session's that never previewed. Lights placed as in the frame
/// before keep the full rule, and take that frame's rays where no move changed them.
#[test]
fn previews_project_moving_lights_coarsely_and_refining_projects_them_in_full() {
    use galerkin_radiosity::scene::{Key, KeyTransform};
    use galerkin_radiosity::session::preview_tolerance;
    let block = |keys: Vec<Key>| {
        let mut b = box_mesh("Block", DVec3::new(-0.3, -0.3, 0.0), DVec3::new(0.3, 0.3, 0.6), 2, false, 0);
        b.animation = keys;
        b
    };
    let slide =
        |frame: f64, x: f64| Key { frame, transform: KeyTransform::Translation(DVec3::new(x, 0.0, 0.0)) };
    let mut moving =
        Light::new("Point", LightKind::Point, DMat4::from_translation(DVec3::new(-0.8, 0.2, 1.5)), 120.0);
    moving.animation = vec![
        LightKey { frame: 1.0, ..LightKey::default() },
        LightKey {
            frame: 4.0,
            matrix: Some(DMat4::from_translation(DVec3::new(0.9, -0.1, 1.3))),
            ..LightKey::default()
        },
    ];
    let still =
        Light::new("Point", LightKind::Point, DMat4::from_translation(DVec3::new(0.2, 0.4, 1.6)), 120.0);
    // (The light moving over a still block; then a still light over a block sliding.)
    // (The light moving over a still block, alone, then under a still World; a still light over
    // a block sliding. Coarse only where every source moved: a World's rays are taken instead.)
    let sky = Some(World::uniform([0.3, 0.4, 0.5], 1.0));
    let cases = [
        (vec![floor(), block(Vec::new())], moving.clone(), None, true),
        (vec![floor(), block(Vec::new())], moving, sky, false),
        (vec![floor(), block(vec![slide(1.0, -0.6), slide(4.0, 0.7)])], still, None, false),
    ];
    for (objects, light, world, coarse) in cases {
        let mut sc = scene(objects, vec![light], (1, 4)).with_world(world).unwrap();
        // Tight, so that the two sessions' shooting paths agree far closer than the check below.
        sc.settings.tolerance = 1e-7;
        assert_eq!(preview_tolerance(sc.settings.tolerance), 1e-6);
        let mut every = Session::new(sc.clone(), Method::Incremental).unwrap();
        let mut preview = Session::new(sc, Method::Incremental).unwrap();
        every.solve_frame(1.0, &no_progress).unwrap();
        preview.solve_frame(1.0, &no_progress).unwrap();
        preview.set_preview(true);
        for f in 2..=4 {
            let full = every.solve_frame(f as f64, &no_progress).unwrap();
            let quick = preview.solve_frame(f as f64, &no_progress).unwrap();
            assert!(quick.preview, "frame {f}");
            let (traced, taken) = (quick.direct_rays_traced, quick.direct_rays_taken);
            if coarse {
                // Every source moved: every ray is cast again, on a quarter of the points.
                assert_eq!((full.direct_rays_taken, taken), (0, 0), "frame {f}");
                assert!(
                    3 * traced < full.direct_rays_traced,
                    "frame {f}: {traced} vs {}",
                    full.direct_rays_traced
                );
            } else {
                // Some source kept its place: the full rule, and the same rays as the session
                // that never previews.
                assert!(taken > 0, "frame {f}: {quick:?}");
                assert_eq!((traced, taken), (full.direct_rays_traced, full.direct_rays_taken), "frame {f}");
            }
        }
        assert!(preview.refine(&no_progress).unwrap().is_some());
        let corners = |s: &Session| -> Vec<[f32; 3]> {
            s.face_results().unwrap().into_iter().flat_map(|r| r.corner_radiosity).collect()
        };
        // The gathered corners (whose direct light is the lights' own at the corner) and the
        // faces' polynomials at their centres (whose direct light is the projection).
        let centres = |s: &Session| -> Vec<[f32; 3]> {
            (0..2)
                .flat_map(|o| (0..s.scene().objects[o].faces.len()).map(move |f| (o, f)))
                .map(|(o, f)| s.eval(o, f, 0.5, 0.5).unwrap().map(|x| x as f32))
                .collect()
        };
        for (what, got, want) in
            [("corners", corners(&preview), corners(&every)), ("centres", centres(&preview), centres(&every))]
        {
            let peak = want.iter().flatten().fold(0.0f32, |m, x| m.max(*x));
            let worst = got
                .iter()
                .zip(&want)
                .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs()))
                .fold(0.0, f32::max);
            eprintln!("light moving {coarse}: refined frame 4's {what} {:.2e} of the peak off", worst / peak);
            assert!(worst <= 1e-5 * peak, "{what}: {:.2e} of the peak", worst / peak);
        }
    }
}
