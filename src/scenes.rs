//! Procedural scenes for tests, benchmarks and the demo: a closed box and the Cornell box.
//!
//! Cornell box geometry: the Cornell Program of Computer Graphics' published data, in metres
//! (../shared/notes/references.md). Reflectances are those spectra integrated to linear sRGB
//! (D65): white (0.739, 0.736, 0.740), red (0.494, 0.049, 0.051), green (0.068, 0.398, 0.086).
//! The light has radiance (17, 12, 4) (Tungsten's), so exitance pi x that.

use glam::{DMat4, DVec3};

use crate::scene::{EmissionKey, Key, KeyTransform, Material, Object, Scene, Settings};

/// A quad `[p0,p1,p2,p3]` split into `n x n` bilinear sub-quads, faces counter-clockwise as given.
pub fn subdivided_quad(name: &str, p: [DVec3; 4], n: usize, material: u32) -> Object {
    let mut vertices = Vec::with_capacity((n + 1) * (n + 1));
    for a in 0..=n {
        for b in 0..=n {
            let (s, t) = (a as f64 / n as f64, b as f64 / n as f64);
            vertices.push(
                (1.0 - s) * (1.0 - t) * p[0] + s * (1.0 - t) * p[1] + s * t * p[2] + (1.0 - s) * t * p[3],
            );
        }
    }
    let id = |a: usize, b: usize| (a * (n + 1) + b) as u32;
    let mut faces = Vec::with_capacity(n * n);
    for a in 0..n {
        for b in 0..n {
            faces.push(vec![id(a, b), id(a + 1, b), id(a + 1, b + 1), id(a, b + 1)]);
        }
    }
    let face_materials = vec![material; faces.len()];
    Object {
        name: name.into(),
        vertices,
        faces,
        face_materials,
        matrix: DMat4::IDENTITY,
        animation: Vec::new(),
    }
}

/// Reorders a quad so that its front normal points toward `target` (or away when `away`).
pub fn facing(mut p: [DVec3; 4], target: DVec3, away: bool) -> [DVec3; 4] {
    let n = (p[1] - p[0]).cross(p[2] - p[0]);
    let centre = (p[0] + p[1] + p[2] + p[3]) / 4.0;
    if (n.dot(target - centre) < 0.0) != away {
        p.reverse();
    }
    p
}

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z) / 1000.0
}

/// A closed axis-aligned unit box of six inward-facing walls, each `n x n`, one material.
pub fn closed_box(n: usize, reflectance: f64, emission: f64, settings: Settings) -> Scene {
    let c = DVec3::splat(0.5);
    let p = |x, y, z| DVec3::new(x, y, z);
    let walls = [
        [p(0., 0., 0.), p(1., 0., 0.), p(1., 1., 0.), p(0., 1., 0.)],
        [p(0., 0., 1.), p(1., 0., 1.), p(1., 1., 1.), p(0., 1., 1.)],
        [p(0., 0., 0.), p(0., 1., 0.), p(0., 1., 1.), p(0., 0., 1.)],
        [p(1., 0., 0.), p(1., 1., 0.), p(1., 1., 1.), p(1., 0., 1.)],
        [p(0., 0., 0.), p(1., 0., 0.), p(1., 0., 1.), p(0., 0., 1.)],
        [p(0., 1., 0.), p(1., 1., 0.), p(1., 1., 1.), p(0., 1., 1.)],
    ];
    let objects = walls
        .iter()
        .enumerate()
        .map(|(k, w)| subdivided_quad(&format!("wall{k}"), facing(*w, c, false), n, 0))
        .collect();
    let materials =
        vec![Material { name: "grey".into(), reflectance: [reflectance; 3], emission: [emission; 3] }];
    Scene::new(settings, (1, 1), materials, vec![Vec::new()], objects).expect("closed box is valid")
}

/// Material indices of [`cornell_box`].
pub const WHITE: u32 = 0;
pub const RED: u32 = 1;
pub const GREEN: u32 = 2;
pub const LIGHT: u32 = 3;

/// The Cornell box with walls split `n x n`, blocks `max(n/4,1)` per side and face, light
/// `max(n/4,1)`; about `5 n^2 + ...` patches (n = 14 gives about 1,000).
pub fn cornell_box(n: usize, settings: Settings) -> Scene {
    let inside = v(278.0, 274.4, 279.6);
    let wall = |name: &str, p: [DVec3; 4], m| subdivided_quad(name, facing(p, inside, false), n, m);
    let mut objects = vec![
        wall("Floor", [v(552.8, 0., 0.), v(0., 0., 0.), v(0., 0., 559.2), v(549.6, 0., 559.2)], WHITE),
        wall(
            "Ceiling",
            [v(556., 548.8, 0.), v(556., 548.8, 559.2), v(0., 548.8, 559.2), v(0., 548.8, 0.)],
            WHITE,
        ),
        wall(
            "BackWall",
            [v(549.6, 0., 559.2), v(0., 0., 559.2), v(0., 548.8, 559.2), v(556., 548.8, 559.2)],
            WHITE,
        ),
        wall("RightWall", [v(0., 0., 559.2), v(0., 0., 0.), v(0., 548.8, 0.), v(0., 548.8, 559.2)], GREEN),
        wall(
            "LeftWall",
            [v(552.8, 0., 0.), v(549.6, 0., 559.2), v(556., 548.8, 559.2), v(556., 548.8, 0.)],
            RED,
        ),
    ];
    let m = (n / 4).max(1);
    objects.push(block(
        "ShortBlock",
        [v(130., 165., 65.), v(82., 165., 225.), v(240., 165., 272.), v(290., 165., 114.)],
        m,
    ));
    objects.push(block(
        "TallBlock",
        [v(423., 330., 247.), v(265., 330., 296.), v(314., 330., 456.), v(472., 330., 406.)],
        m,
    ));
    // The light, lowered to y = 548.0 so that it does not coincide with the ceiling; faces down.
    let light = [v(343., 548.0, 227.), v(343., 548.0, 332.), v(213., 548.0, 332.), v(213., 548.0, 227.)];
    objects.push(subdivided_quad("Light", facing(light, v(278., 0., 279.6), false), m, LIGHT));
    let pi = std::f64::consts::PI;
    let materials = vec![
        Material { name: "white".into(), reflectance: [0.739, 0.736, 0.740], emission: [0.0; 3] },
        Material { name: "red".into(), reflectance: [0.494, 0.049, 0.051], emission: [0.0; 3] },
        Material { name: "green".into(), reflectance: [0.068, 0.398, 0.086], emission: [0.0; 3] },
        Material {
            name: "light".into(),
            reflectance: [0.78, 0.78, 0.78],
            emission: [17.0 * pi, 12.0 * pi, 4.0 * pi],
        },
    ];
    Scene::new(settings, (1, 1), materials, vec![Vec::new(); 4], objects).expect("Cornell box is valid")
}

/// A block from its top quad down to the floor: top and four sides, faces outward, `m x m` each.
fn block(name: &str, top: [DVec3; 4], m: usize) -> Object {
    let centre = top.iter().copied().sum::<DVec3>() / 4.0 * DVec3::new(1.0, 0.5, 1.0);
    let mut parts = vec![subdivided_quad("top", facing(top, centre, true), m, WHITE)];
    for k in 0..4 {
        let (a, b) = (top[k], top[(k + 1) % 4]);
        let side = [a, b, DVec3::new(b.x, 0.0, b.z), DVec3::new(a.x, 0.0, a.z)];
        parts.push(subdivided_quad("side", facing(side, centre, true), m, WHITE));
    }
    merge(name, parts)
}

/// Concatenates objects into one (placements must be identity).
pub fn merge(name: &str, parts: Vec<Object>) -> Object {
    let mut out = Object {
        name: name.into(),
        vertices: Vec::new(),
        faces: Vec::new(),
        face_materials: Vec::new(),
        matrix: DMat4::IDENTITY,
        animation: Vec::new(),
    };
    for p in parts {
        let base = out.vertices.len() as u32;
        out.vertices.extend(p.vertices);
        out.faces.extend(p.faces.into_iter().map(|f| f.into_iter().map(|i| i + base).collect()));
        out.face_materials.extend(p.face_materials);
    }
    out
}

/// The demo animation (issue 6): the Cornell box over `frames` frames, the light sliding along
/// the ceiling and back, the short block sliding across the floor.
pub fn cornell_box_animated(n: usize, frames: i64, settings: Settings) -> Scene {
    let mut scene = cornell_box(n, settings);
    let last = frames as f64;
    for obj in &mut scene.objects {
        let keys: Option<Vec<(f64, DVec3)>> = match obj.name.as_str() {
            "Light" => Some(vec![
                (1.0, DVec3::ZERO),
                ((1.0 + last) * 0.5, DVec3::new(-0.15, 0.0, 0.1)),
                (last, DVec3::ZERO),
            ]),
            "ShortBlock" => Some(vec![(1.0, DVec3::ZERO), (last, DVec3::new(0.0, 0.0, 0.15))]),
            _ => None,
        };
        if let Some(keys) = keys {
            obj.animation = keys
                .into_iter()
                .map(|(frame, t)| Key { frame, transform: KeyTransform::Translation(t) })
                .collect();
        }
    }
    scene.frames = (1, frames);
    scene
}

/// The Cornell box with only its light moving, in a straight line along the ceiling (x), over
/// `frames` frames: the "moving light in the 1,000-patch box" (n = 14).
pub fn cornell_box_moving_light(n: usize, frames: i64, settings: Settings) -> Scene {
    let mut scene = cornell_box(n, settings);
    let light = scene.objects.iter_mut().find(|o| o.name == "Light").expect("Cornell box has a light");
    light.animation =
        translation_keys(&[(1.0, DVec3::new(0.08, 0.0, 0.0)), (frames as f64, DVec3::new(-0.08, 0.0, 0.0))]);
    scene.frames = (1, frames);
    scene
}

/// Keys translating an object by `t` at each `(frame, t)`.
pub fn translation_keys(keys: &[(f64, DVec3)]) -> Vec<Key> {
    keys.iter().map(|&(frame, t)| Key { frame, transform: KeyTransform::Translation(t) }).collect()
}

/// An axis-aligned room `w x h x d` (x, y up, z), walls split `n` per metre, faces inward.
pub fn room(w: f64, h: f64, d: f64, n: f64, materials: [u32; 6]) -> Vec<Object> {
    let c = DVec3::new(0.0, h / 2.0, 0.0);
    let (x, z) = (w / 2.0, d / 2.0);
    let p = DVec3::new;
    let walls = [
        ("Floor", [p(-x, 0., -z), p(x, 0., -z), p(x, 0., z), p(-x, 0., z)], w.max(d)),
        ("Ceiling", [p(-x, h, -z), p(x, h, -z), p(x, h, z), p(-x, h, z)], w.max(d)),
        ("WallLeft", [p(-x, 0., -z), p(-x, h, -z), p(-x, h, z), p(-x, 0., z)], d.max(h)),
        ("WallRight", [p(x, 0., -z), p(x, h, -z), p(x, h, z), p(x, 0., z)], d.max(h)),
        ("WallBack", [p(-x, 0., z), p(x, 0., z), p(x, h, z), p(-x, h, z)], w.max(h)),
        ("WallFront", [p(-x, 0., -z), p(x, 0., -z), p(x, h, -z), p(-x, h, -z)], w.max(h)),
    ];
    walls
        .iter()
        .zip(materials)
        .map(|((name, q, size), m)| {
            subdivided_quad(name, facing(*q, c, false), (size * n).ceil() as usize, m)
        })
        .collect()
}

/// A panel `u x v` (half extents) centred at `centre` facing `normal` (one quad split `k x k`).
pub fn panel(
    name: &str,
    centre: DVec3,
    u: DVec3,
    v: DVec3,
    normal: DVec3,
    k: usize,
    material: u32,
) -> Object {
    let q = [centre - u - v, centre + u - v, centre + u + v, centre - u + v];
    subdivided_quad(name, facing(q, centre + normal, false), k, material)
}

/// The seed's Fig. 5a scene: a room, a ceiling light moving left and right, and a blue panel
/// passing in front of a wall light. `n` patches per metre of wall.
pub fn seed_room(n: f64, frames: i64, settings: Settings) -> Scene {
    const WHITE: u32 = 0;
    const RED: u32 = 1;
    const BLUE: u32 = 2;
    const LAMP: u32 = 3;
    let mut objects = room(4.0, 2.5, 4.0, n, [WHITE, WHITE, RED, WHITE, WHITE, WHITE]);
    let last = frames as f64;
    let mut ceiling_light =
        panel("CeilingLight", DVec3::new(0.0, 2.49, 0.0), DVec3::X * 0.3, DVec3::Z * 0.3, -DVec3::Y, 2, LAMP);
    ceiling_light.animation = translation_keys(&[
        (1.0, DVec3::new(-1.0, 0.0, 0.0)),
        ((1.0 + last) * 0.5, DVec3::new(1.0, 0.0, 0.0)),
        (last, DVec3::new(-1.0, 0.0, 0.0)),
    ]);
    objects.push(ceiling_light);
    objects.push(panel(
        "WallLight",
        DVec3::new(1.99, 1.2, 0.0),
        DVec3::Z * 0.25,
        DVec3::Y * 0.25,
        -DVec3::X,
        2,
        LAMP,
    ));
    let mut blue =
        panel("BluePanel", DVec3::new(1.6, 1.2, 0.0), DVec3::Z * 0.3, DVec3::Y * 0.4, DVec3::X, 2, BLUE);
    blue.animation =
        translation_keys(&[(1.0, DVec3::new(0.0, 0.0, -1.5)), (last, DVec3::new(0.0, 0.0, 1.5))]);
    objects.push(blue);
    let materials = vec![
        Material { name: "white".into(), reflectance: [0.7, 0.7, 0.7], emission: [0.0; 3] },
        Material { name: "red".into(), reflectance: [0.6, 0.1, 0.1], emission: [0.0; 3] },
        Material { name: "blue".into(), reflectance: [0.1, 0.15, 0.7], emission: [0.0; 3] },
        Material { name: "lamp".into(), reflectance: [0.0; 3], emission: [30.0, 30.0, 28.0] },
    ];
    let mut scene =
        Scene::new(settings, (1, frames), materials, vec![Vec::new(); 4], objects).expect("valid");
    scene.frames = (1, frames);
    scene
}

/// The seed's Fig. 5b scene: a billiard table in a room with a light moving above it.
pub fn billiard(n: f64, frames: i64, settings: Settings) -> Scene {
    const WHITE: u32 = 0;
    const GREEN: u32 = 1;
    const WOOD: u32 = 2;
    const LAMP: u32 = 3;
    let mut objects = room(6.0, 3.0, 4.0, n, [WOOD, WHITE, WHITE, WHITE, WHITE, WHITE]);
    // The table: a green top 2.6 x 1.4 at 0.8 m and four wooden sides down to the floor.
    let (x, z, h) = (1.3, 0.7, 0.8);
    let k = ((2.6 * n).ceil() as usize).max(2);
    let mut parts =
        vec![panel("top", DVec3::new(0.0, h, 0.0), DVec3::X * x, DVec3::Z * z, DVec3::Y, k, GREEN)];
    for (c, u, nrm) in [
        (DVec3::new(0.0, h / 2.0, z), DVec3::X * x, DVec3::Z),
        (DVec3::new(0.0, h / 2.0, -z), DVec3::X * x, -DVec3::Z),
        (DVec3::new(x, h / 2.0, 0.0), DVec3::Z * z, DVec3::X),
        (DVec3::new(-x, h / 2.0, 0.0), DVec3::Z * z, -DVec3::X),
    ] {
        parts.push(panel("side", c, u, DVec3::Y * (h / 2.0), nrm, (k / 2).max(1), WOOD));
    }
    objects.push(merge("Table", parts));
    let last = frames as f64;
    let mut light =
        panel("Light", DVec3::new(0.0, 2.2, 0.0), DVec3::X * 0.25, DVec3::Z * 0.25, -DVec3::Y, 2, LAMP);
    light.animation =
        translation_keys(&[(1.0, DVec3::new(-1.2, 0.0, 0.0)), (last, DVec3::new(1.2, 0.0, 0.0))]);
    objects.push(light);
    let materials = vec![
        Material { name: "white".into(), reflectance: [0.7, 0.7, 0.7], emission: [0.0; 3] },
        Material { name: "green".into(), reflectance: [0.1, 0.5, 0.15], emission: [0.0; 3] },
        Material { name: "wood".into(), reflectance: [0.45, 0.3, 0.15], emission: [0.0; 3] },
        Material { name: "lamp".into(), reflectance: [0.0; 3], emission: [40.0, 38.0, 33.0] },
    ];
    Scene::new(settings, (1, frames), materials, vec![Vec::new(); 4], objects).expect("valid")
}

/// An emission key list for tests: material `m` ramps from `from` to `to` between two frames.
pub fn emission_ramp(from: (f64, [f64; 3]), to: (f64, [f64; 3])) -> Vec<EmissionKey> {
    vec![EmissionKey { frame: from.0, emission: from.1 }, EmissionKey { frame: to.0, emission: to.1 }]
}

/// A closed triangle mesh like a sculpted or scanned model: an icosphere of radius `radius`
/// subdivided `subdivisions` times (20 4^s faces), each vertex pushed out along its normal by
/// up to `bump` of the radius by a fixed pseudo-random field, so that neighbouring faces meet at
/// concave as well as convex edges. Faces outward.
pub fn bumpy_sphere(
    name: &str,
    centre: DVec3,
    radius: f64,
    subdivisions: u32,
    bump: f64,
    material: u32,
) -> Object {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut vertices: Vec<DVec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut mid = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, vertices: &mut Vec<DVec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                vertices.push(((vertices[a as usize] + vertices[b as usize]) / 2.0).normalize());
                vertices.len() as u32 - 1
            })
        };
        faces = faces
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = (
                    midpoint(a, b, &mut vertices),
                    midpoint(b, c, &mut vertices),
                    midpoint(c, a, &mut vertices),
                );
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    // A smooth deterministic field: a few products of sines of the direction.
    let field = |d: DVec3| {
        ((3.1 * d.x + 1.3).sin() * (2.7 * d.y - 0.4).sin() + (4.3 * d.z + 2.1).sin() * (3.7 * d.x).cos())
            * 0.5
    };
    let vertices = vertices.iter().map(|&d| centre + d * radius * (1.0 + bump * field(d))).collect();
    Object {
        name: name.into(),
        vertices,
        faces: faces.into_iter().map(|f| f.to_vec()).collect(),
        face_materials: vec![material; 20 * 4usize.pow(subdivisions)],
        matrix: DMat4::IDENTITY,
        animation: Vec::new(),
    }
}

/// A closed axis-aligned box from `min` to `max`, each side split `n x n`, faces outward (or
/// inward when `inward`).
pub fn box_mesh(name: &str, min: DVec3, max: DVec3, n: usize, inward: bool, material: u32) -> Object {
    let c = (min + max) / 2.0;
    let p = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    let (a, b) = (min, max);
    let sides = [
        [p(a.x, a.y, a.z), p(b.x, a.y, a.z), p(b.x, b.y, a.z), p(a.x, b.y, a.z)],
        [p(a.x, a.y, b.z), p(b.x, a.y, b.z), p(b.x, b.y, b.z), p(a.x, b.y, b.z)],
        [p(a.x, a.y, a.z), p(a.x, b.y, a.z), p(a.x, b.y, b.z), p(a.x, a.y, b.z)],
        [p(b.x, a.y, a.z), p(b.x, b.y, a.z), p(b.x, b.y, b.z), p(b.x, a.y, b.z)],
        [p(a.x, a.y, a.z), p(b.x, a.y, a.z), p(b.x, a.y, b.z), p(a.x, a.y, b.z)],
        [p(a.x, b.y, a.z), p(b.x, b.y, a.z), p(b.x, b.y, b.z), p(a.x, b.y, b.z)],
    ];
    let parts = sides.iter().map(|s| subdivided_quad(name, facing(*s, c, !inward), n, material)).collect();
    merge(name, parts)
}
