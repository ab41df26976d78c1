//! Seeded randomized differential test of the animation update (`animation::advance`).
//!
//! Each case builds a small random animated scene from its seed: a floor and some static walls
//! (one maybe twisted, as the Cornell box's left wall), one or two emitters, one to three
//! occluders (panels and boxes of `subdivided_quad`s); 20-100 patches (never over 150), 3-6
//! frames. Some objects
//! move: straight and curved translations, rotations and scalings (`KeyTransform::Matrix`), a move
//! that stops and reverses, an occluder passing between static surfaces, an object coming down
//! onto the floor or against a wall until it touches (or stops 2 mm short), a moving emitter;
//! some cases key an emission (a lamp's ramp, an occluder starting to glow). Settings vary: basis
//! order 1 or 2, visibility samples 2 or 3, adaptive quadrature on or off (off puts every pair on
//! the 4 x 4-point rule, where the series is used: `animation::pairs::MIN_SERIES_POINTS`), visibility
//! off in one case in ten; `corner_gather` off and tolerance 1e-6 throughout.
//!
//! Three chains run over each case: `Method::Full` (`System::build` and `System::solve` at every
//! frame, as `Session` does it), and from the first frame's system `advance` with
//! `AnimationState::new(n, false)` (`Method::Exact`) and with `AnimationState::new(n, true)`
//! (`Method::Incremental`, the default: series). Driving them directly rather than through
//! `Session` lets one fresh build serve both properties. At every frame after the first:
//!
//! 1. **The exact update keeps the link store of a fresh build, pair by pair**: both blocks of
//!    every pair within 1e-5 of the fresh build's peak block entry (as `tests/animation.rs`'s
//!    `exact_update_keeps_the_link_store_of_a_fresh_build`). Any pair the update failed to find
//!    or recompute (a static pair whose visibility a mover changed, a pair that started or
//!    stopped facing, a rotated or scaled element's pairs) fails it.
//! 2. **Both updates equal `Method::Full`**: every corner within 1% of the frame's peak corner
//!    (as `tests/animation.rs`'s `assert_matches_full`).
//!
//! and, stricter, in `random_animations_match_fresh_builds_strictly` (what the two properties let
//! through: 1% of a peak that the emitters make is a tenth of the reflected light, or more):
//!
//! 3. the exact chain's corners within 1e-4 of the peak of Full's: with property 1's links, only
//!    where the two solves stopped may differ;
//! 4. the series chain's links within 1e-5 of the fresh build's peak block entry, pair by pair
//!    (property 1 for the default method).
//!
//! Coverage is asserted over the fixed run, so that it cannot pass vacuously: static pairs
//! recomputed for visibility, series read and expanded, pairs recomputed for a non-translation,
//! a half-space crossing and off the expansion direction, cases with emission keys and with
//! visibility off. With `--nocapture` each case prints a line (seed, size, worst figures) and the
//! run its worst figures. Before session 12's fixes (commit 574c196), over 1,000 seeds, property
//! 1's worst was 0 (the exact update's blocks were the fresh build's bit for bit) and property 2's
//! 7.5e-3 of the peak; the stricter figures found the two defects pinned by the regression tests
//! at the end (the update added `Delta K b` where the solver's invariant needs `Delta K (b - u)`; a
//! series was read after its pair changed quadrature rule). The first breaks property 2 too in a
//! scene made for it (`panel_taken_out_of_a_box_lights_the_lamp_again`: 21% of the peak). With the
//! fixes the fixed run's worst figures are 0 (exact links), 3.3e-7 of the peak block entry (series
//! links) and 9.8e-7 of the peak corner (both chains).
//!
//! Runtime (release, 2 cores, measured): 20 s for the file's five tests (29 s on a busy machine),
//! nearly all of it the 96 fixed seeds, run once for the two random tests (322 updates of 20-98
//! patches). `ANIMATION_RANDOM_SEED=s` runs seed `s` alone and prints its scene;
//! `ANIMATION_RANDOM_CASES=n` runs seeds `1..=n` instead of the fixed ones (1,000 take about 5
//! minutes). A failing case prints its seed, its scene in words and how to rerun it.

use std::f64::consts::PI;

use galerkin_radiosity::animation::{self, AnimationState, Outcome, UpdateStats};
use galerkin_radiosity::scene::{EmissionKey, Key, KeyTransform, Material, Object, Scene, Settings};
use galerkin_radiosity::scenes;
use galerkin_radiosity::system::{System, no_progress};
use glam::{DMat4, DVec3};

mod common;
use common::{link_difference, worse};

#[path = "common/hierarchy_checks.rs"]
mod hierarchy_checks;

/// Seeds of the fixed run.
const CASES: u64 = 96;

/// Property 1's bound, as a fraction of the fresh build's peak block entry.
const LINK_TOLERANCE: f32 = 1e-5;

/// Property 2's bound, as a fraction of the frame's peak corner radiosity.
const CORNER_TOLERANCE: f32 = 0.01;

/// The solver's tolerance in every case: tight, so that the three chains' solutions differ by
/// their kernels rather than by where their shooting stopped.
const SOLVE_TOLERANCE: f64 = 1e-6;

/// Most patches a case may have (each case must stay well under two seconds).
const MAX_PATCHES: usize = 150;

/// SplitMix64: a small seeded generator, so that a seed names its case on every platform.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform in `lo..=hi`.
    fn int(&mut self, lo: usize, hi: usize) -> usize {
        lo + (self.next_u64() % (hi - lo + 1) as u64) as usize
    }

    fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }

    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.int(0, items.len() - 1)]
    }

    /// A uniformly distributed unit vector.
    fn direction(&mut self) -> DVec3 {
        let z = self.range(-1.0, 1.0);
        let a = self.range(0.0, 2.0 * PI);
        let r = (1.0 - z * z).sqrt();
        DVec3::new(r * a.cos(), r * a.sin(), z)
    }
}

/// One random case: the scene and what it is, in words (printed when the case fails).
struct Case {
    scene: Scene,
    description: Vec<String>,
}

/// An axis-aligned box `c +- h` of outward faces split `n x n`; without its bottom (it stands on
/// something, as the Cornell box's blocks do) unless `bottom`.
fn block(name: &str, c: DVec3, h: DVec3, n: usize, material: u32, bottom: bool) -> Object {
    let (x, y, z) = (DVec3::X * h.x, DVec3::Y * h.y, DVec3::Z * h.z);
    let mut faces = vec![
        scenes::panel("top", c + y, x, z, DVec3::Y, n, material),
        scenes::panel("side", c + x, y, z, DVec3::X, n, material),
        scenes::panel("side", c - x, y, z, -DVec3::X, n, material),
        scenes::panel("side", c + z, x, y, DVec3::Z, n, material),
        scenes::panel("side", c - z, x, y, -DVec3::Z, n, material),
    ];
    if bottom {
        faces.push(scenes::panel("bottom", c - y, x, z, -DVec3::Y, n, material));
    }
    scenes::merge(name, faces)
}

/// What a generated object is, for the motions that depend on it.
#[derive(Clone, Copy, PartialEq)]
enum Kind {
    CeilingLamp,
    WallLamp,
    /// A horizontal panel facing up (`true`) or down.
    HorizontalPanel(bool),
    VerticalPanel,
    /// A box standing on the floor (`true`) or floating.
    Box(bool),
}

/// A movable object as generated: its mesh at rest, centre, half extents and kind.
struct Thing {
    object: Object,
    centre: DVec3,
    half: DVec3,
    kind: Kind,
    what: String,
}

/// The static room: a floor and some of the walls (x = 0, x = 1, z = 1) and the ceiling of the
/// unit cube, each `n x n`; one wall may be twisted (not planar, as the Cornell box's left wall).
fn room(rng: &mut Rng, objects: &mut Vec<Object>, description: &mut Vec<String>) -> [bool; 4] {
    let p = DVec3::new;
    let inside = p(0.5, 0.5, 0.5);
    let n = rng.int(3, 5);
    let floor = [p(0., 0., 0.), p(1., 0., 0.), p(1., 0., 1.), p(0., 0., 1.)];
    objects.push(scenes::subdivided_quad("floor", scenes::facing(floor, inside, false), n, 0));
    let mut words = vec![format!("floor {n}x{n}")];
    let walls = [
        ("wall x=0", [p(0., 0., 0.), p(0., 1., 0.), p(0., 1., 1.), p(0., 0., 1.)], 1),
        ("wall x=1", [p(1., 0., 0.), p(1., 1., 0.), p(1., 1., 1.), p(1., 0., 1.)], 0),
        ("wall z=1", [p(0., 0., 1.), p(1., 0., 1.), p(1., 1., 1.), p(0., 1., 1.)], 0),
        ("ceiling", [p(0., 1., 0.), p(1., 1., 0.), p(1., 1., 1.), p(0., 1., 1.)], 0),
    ];
    let mut present = [false; 4];
    let mut twisted = false;
    for (k, (name, mut q, material)) in walls.into_iter().enumerate() {
        if !rng.chance(0.55) {
            continue;
        }
        present[k] = true;
        let m = rng.int(2, 4);
        if k < 3 && !twisted && rng.chance(0.2) {
            // One corner pushed outward by 2% of the wall: a twisted wall, as the Cornell box's.
            twisted = true;
            let out = (q[2] - inside).normalize() * 0.02;
            q[2] += DVec3::new(out.x, 0.0, out.z);
            words.push(format!("{name} {m}x{m} twisted"));
        } else {
            words.push(format!("{name} {m}x{m}"));
        }
        objects.push(scenes::subdivided_quad(name, scenes::facing(q, inside, false), m, material));
    }
    description.push(format!("room: {}", words.join(", ")));
    present
}

/// An emitter of material `material`: a ceiling lamp facing down or a wall lamp on x = 0 facing +x.
fn emitter(rng: &mut Rng, k: usize, material: u32) -> Thing {
    let n = rng.int(1, 2);
    let s = rng.range(0.06, 0.14);
    if rng.chance(0.6) {
        let c = DVec3::new(rng.range(0.3, 0.7), rng.range(0.85, 0.97), rng.range(0.3, 0.7));
        let object =
            scenes::panel(&format!("lamp{k}"), c, DVec3::X * s, DVec3::Z * s, -DVec3::Y, n, material);
        let what = format!("ceiling lamp{k} at {c:.3} half {s:.3} {n}x{n}, facing down");
        Thing { object, centre: c, half: DVec3::new(s, 0.0, s), kind: Kind::CeilingLamp, what }
    } else {
        let c = DVec3::new(rng.range(0.01, 0.03), rng.range(0.3, 0.7), rng.range(0.3, 0.7));
        let object = scenes::panel(&format!("lamp{k}"), c, DVec3::Y * s, DVec3::Z * s, DVec3::X, n, material);
        let what = format!("wall lamp{k} at {c:.3} half {s:.3} {n}x{n}, facing +x");
        Thing { object, centre: c, half: DVec3::new(0.0, s, s), kind: Kind::WallLamp, what }
    }
}

/// An occluder: a horizontal or vertical panel, or a box on the floor or floating.
fn occluder(rng: &mut Rng, k: usize, material: u32) -> Thing {
    let n = rng.int(1, 2);
    let name = format!("occluder{k}");
    let xz = DVec3::new(rng.range(0.3, 0.7), 0.0, rng.range(0.3, 0.7));
    match rng.int(0, 3) {
        0 => {
            let c = xz + DVec3::Y * rng.range(0.3, 0.65);
            let h = DVec3::new(rng.range(0.06, 0.2), 0.0, rng.range(0.06, 0.2));
            let up = rng.chance(0.5);
            let normal = if up { DVec3::Y } else { -DVec3::Y };
            let object = scenes::panel(&name, c, DVec3::X * h.x, DVec3::Z * h.z, normal, n, material);
            let what = format!(
                "horizontal panel {name} at {c:.3} half {h:.3} {n}x{n}, facing {}",
                if up { "up" } else { "down" }
            );
            Thing { object, centre: c, half: h, kind: Kind::HorizontalPanel(up), what }
        }
        1 => {
            let c = xz + DVec3::Y * rng.range(0.3, 0.6);
            let along_x = rng.chance(0.5);
            let (a, b) = (rng.range(0.06, 0.2), rng.range(0.08, 0.2));
            let (u, normal) = if along_x { (DVec3::X * a, DVec3::Z) } else { (DVec3::Z * a, DVec3::X) };
            let normal = if rng.chance(0.5) { normal } else { -normal };
            let object = scenes::panel(&name, c, u, DVec3::Y * b, normal, n, material);
            let what =
                format!("vertical panel {name} at {c:.3} facing {normal} half {a:.3} x {b:.3} {n}x{n}");
            Thing { object, centre: c, half: u.abs() + DVec3::Y * b, kind: Kind::VerticalPanel, what }
        }
        _ => {
            let h = DVec3::new(rng.range(0.05, 0.14), rng.range(0.05, 0.15), rng.range(0.05, 0.14));
            let on_floor = rng.chance(0.5);
            let y = if on_floor { h.y } else { rng.range(0.3, 0.6) };
            let c = xz + DVec3::Y * y;
            let object = block(&name, c, h, n, material, !on_floor);
            let what = format!(
                "box {name} at {c:.3} half {h:.3} {n}x{n} per face, {}",
                if on_floor { "on the floor, no bottom" } else { "floating, closed" }
            );
            Thing { object, centre: c, half: h, kind: Kind::Box(on_floor), what }
        }
    }
}

fn matrices(keys: &[(f64, DMat4)]) -> Vec<Key> {
    keys.iter().map(|&(frame, m)| Key { frame, transform: KeyTransform::Matrix(m) }).collect()
}

/// `m` about the point `pivot`.
fn about(pivot: DVec3, m: DMat4) -> DMat4 {
    DMat4::from_translation(pivot) * m * DMat4::from_translation(-pivot)
}

/// Gives `thing` a random motion over frames `1..=last`; returns it in words. `walls` says which
/// of the room's walls (x = 0, x = 1, z = 1, ceiling) exist, for touching one.
fn animate(rng: &mut Rng, thing: &mut Thing, last: usize, walls: [bool; 4]) -> String {
    let l = last as f64;
    // Slow motions let the series apply (a pair is expanded only when the series would serve
    // `MIN_SERIES_FRAMES` frames at this speed); fast ones cross shadows and half-spaces.
    let slow = rng.chance(0.45);
    let speed = if slow { rng.range(0.0015, 0.004) } else { rng.range(0.01, 0.06) };
    let pace = if slow { "slow" } else { "fast" };
    let c = thing.centre;
    let lamp = matches!(thing.kind, Kind::CeilingLamp | Kind::WallLamp);
    // Lamps keep to their plane mostly (a ceiling lamp slides along the ceiling).
    let planar = |d: DVec3| match thing.kind {
        Kind::CeilingLamp => DVec3::new(d.x, 0.0, d.z).normalize_or(DVec3::X),
        Kind::WallLamp => DVec3::new(0.0, d.y, d.z).normalize_or(DVec3::Z),
        _ => d,
    };
    let choices: &[u32] = if lamp { &[0, 1, 2, 4] } else { &[0, 1, 2, 3, 4, 5, 6] };
    let (keys, what) = match rng.pick(choices) {
        0 => {
            let d = planar(rng.direction()) * speed * (l - 1.0);
            (
                scenes::translation_keys(&[(1.0, DVec3::ZERO), (l, d)]),
                format!("{pace} straight translation by {d:.4}"),
            )
        }
        1 => {
            // A circle of radius r through the rest position, in a random plane, keyed every frame.
            let r = rng.range(0.05, 0.2);
            let (a, b) = {
                let a = planar(rng.direction());
                let b = planar(rng.direction());
                let b = (b - a * a.dot(b)).normalize_or(a.any_orthonormal_vector());
                (a, b)
            };
            let step = speed / r;
            let keys: Vec<(f64, DVec3)> = (1..=last)
                .map(|f| {
                    let t = step * (f - 1) as f64;
                    (f as f64, r * ((t.cos() - 1.0) * a + t.sin() * b))
                })
                .collect();
            (
                scenes::translation_keys(&keys),
                format!("{pace} curve: circle radius {r:.3}, {step:.3} rad a frame"),
            )
        }
        2 => {
            // A move out and back: it stops for a frame at the far end when there are frames
            // enough, and the return overshoots the start.
            let d = planar(rng.direction()) * speed * (l - 1.0) * 0.5;
            let keys = if last >= 5 {
                let m = (1.0 + l) * 0.5;
                vec![(1.0, DVec3::ZERO), (m - 0.5, d), (m + 0.5, d), (l, -0.5 * d)]
            } else {
                vec![(1.0, DVec3::ZERO), (2.0, d), (l, -0.5 * d)]
            };
            let at: Vec<String> = keys.iter().map(|(f, _)| format!("{f}")).collect();
            (
                scenes::translation_keys(&keys),
                format!("{pace} move by {d:.4}, stop and reverse (keys at {})", at.join(", ")),
            )
        }
        3 => {
            // A pass across the room's middle: between the floor and the ceiling or lamps, and
            // between the walls, so that static pairs change visibility.
            let mut d = rng.direction();
            d.y *= 0.3;
            let d = d.normalize() * rng.range(0.15, 0.3);
            (
                scenes::translation_keys(&[(1.0, -d), (l, d)]),
                format!("pass from {:.3} to {:.3}", c - d, c + d),
            )
        }
        4 => {
            let axis =
                if rng.chance(0.6) { rng.pick(&[DVec3::X, DVec3::Y, DVec3::Z]) } else { rng.direction() };
            let degrees = rng.range(3.0, 40.0) * if rng.chance(0.5) { 1.0 } else { -1.0 };
            let shift =
                if rng.chance(0.4) { planar(rng.direction()) * speed * (l - 1.0) } else { DVec3::ZERO };
            let turn = |w: f64| {
                DMat4::from_translation(shift * w)
                    * about(c, DMat4::from_axis_angle(axis, (degrees * w).to_radians()))
            };
            // Keyed at the ends and the middle: matrices are blended linearly between keys.
            let keys = [(1.0, turn(0.0)), ((1.0 + l) * 0.5, turn(0.5)), (l, turn(1.0))];
            (
                matrices(&keys),
                format!("rotation by {degrees:.1} deg about {axis:.3} through the centre, shift {shift:.3}"),
            )
        }
        5 => {
            let s = if rng.chance(0.5) {
                DVec3::splat(rng.range(0.6, 1.4))
            } else {
                DVec3::new(rng.range(0.6, 1.4), rng.range(0.6, 1.4), rng.range(0.6, 1.4))
            };
            let keys = [(1.0, DMat4::IDENTITY), (l, about(c, DMat4::from_scale(s)))];
            (matrices(&keys), format!("scaling by {s:.3} about the centre"))
        }
        _ => {
            // Coming down onto the floor (or, standing on it, against a wall) until touching, or
            // stopping a hair short; reached a frame early and held.
            let gap = rng.pick(&[0.0, 0.002]);
            let reach = (l - 1.0).max(2.0);
            let (d, onto) = match thing.kind {
                Kind::Box(true) if walls[0] => {
                    (DVec3::new(-(c.x - thing.half.x - gap), 0.0, 0.0), "wall x=0")
                }
                Kind::Box(true) if walls[1] => {
                    (DVec3::new(1.0 - gap - c.x - thing.half.x, 0.0, 0.0), "wall x=1")
                }
                Kind::Box(true) => (DVec3::new(0.0, 0.0, 0.0), "nothing (no wall: held)"),
                _ => (DVec3::new(0.0, -(c.y - thing.half.y - gap), 0.0), "the floor"),
            };
            (
                scenes::translation_keys(&[(1.0, DVec3::ZERO), (reach, d), (l, d)]),
                format!("moves onto {onto}, gap {gap}, by {d:.3} by frame {reach}"),
            )
        }
    };
    thing.object.animation = keys;
    what
}

/// The case of `seed`.
fn generate(seed: u64) -> Case {
    let mut rng = Rng::new(seed);
    loop {
        if let Some(case) = try_generate(seed, &mut rng) {
            return case;
        }
    }
}

/// A case from `rng`, or `None` when it came out over [`MAX_PATCHES`] or without a mover.
fn try_generate(seed: u64, rng: &mut Rng) -> Option<Case> {
    let mut description = Vec::new();
    let last = rng.int(3, 6);
    let settings = Settings {
        basis_order: rng.int(1, 2),
        tolerance: SOLVE_TOLERANCE,
        visibility: !rng.chance(0.1),
        visibility_samples: rng.int(2, 3),
        adaptive_quadrature: rng.chance(0.5),
        corner_gather: false,
        ..Settings::default()
    };
    description.push(format!(
        "seed {seed}: frames 1..={last}, basis order {}, visibility {} ({} samples), adaptive quadrature {}",
        settings.basis_order, settings.visibility, settings.visibility_samples, settings.adaptive_quadrature
    ));
    let mut objects = Vec::new();
    let walls = room(rng, &mut objects, &mut description);
    let mut materials = vec![
        Material { name: "white".into(), reflectance: [0.7; 3], emission: [0.0; 3] },
        Material { name: "red".into(), reflectance: [0.6, 0.1, 0.1], emission: [0.0; 3] },
    ];
    let mut things = Vec::new();
    for k in 0..rng.int(1, 2) {
        let e = rng.range(5.0, 20.0);
        let rho = rng.range(0.0, 0.6);
        materials.push(Material {
            name: format!("lamp{k}"),
            reflectance: [rho; 3],
            emission: [e, e, 0.8 * e],
        });
        things.push(emitter(rng, k, materials.len() as u32 - 1));
    }
    for k in 0..rng.int(1, 3) {
        let rho = [rng.range(0.1, 0.8), rng.range(0.1, 0.8), rng.range(0.1, 0.8)];
        materials.push(Material { name: format!("occluder{k}"), reflectance: rho, emission: [0.0; 3] });
        things.push(occluder(rng, k, materials.len() as u32 - 1));
    }
    // Some of the things move; at least one, and an occluder more often than a lamp.
    let mut movers = 0;
    for thing in &mut things {
        let lamp = matches!(thing.kind, Kind::CeilingLamp | Kind::WallLamp);
        let motion = if rng.chance(if lamp { 0.4 } else { 0.7 }) {
            movers += 1;
            animate(rng, thing, last, walls)
        } else {
            "static".into()
        };
        description.push(format!("{}: {motion}", thing.what));
    }
    if movers == 0 {
        return None;
    }
    let mut emission_keys = vec![Vec::new(); materials.len()];
    if rng.chance(0.35) {
        // An emitter's emission ramps between two frames.
        let lamps: Vec<usize> = (0..materials.len()).filter(|&m| materials[m].emission[0] > 0.0).collect();
        let m = rng.pick(&lamps);
        let (from, to) = (rng.int(1, last - 1) as f64, last as f64);
        let k = rng.range(0.2, 3.0);
        let e = materials[m].emission;
        emission_keys[m] = scenes::emission_ramp((from, e), (to, e.map(|x| x * k)));
        description.push(format!("emission of {} x{k:.2} from frame {from} to {to}", materials[m].name));
    } else if rng.chance(0.2) {
        // An occluder starts to glow.
        let m = materials.len() - 1;
        let at = rng.int(2, last) as f64;
        emission_keys[m] = vec![
            EmissionKey { frame: at - 1.0, emission: [0.0; 3] },
            EmissionKey { frame: at, emission: [3.0, 2.0, 1.0] },
        ];
        description.push(format!("{} glows from frame {at}", materials[m].name));
    }
    objects.extend(things.into_iter().map(|t| t.object));
    let patches: usize = objects.iter().map(|o| o.faces.len()).sum();
    if patches > MAX_PATCHES {
        return None;
    }
    description[0] += &format!(", {patches} patches");
    let scene = Scene::new(settings, (1, last as i64), materials, emission_keys, objects)
        .unwrap_or_else(|e| panic!("seed {seed}: invalid scene: {e}"));
    Some(Case { scene, description })
}

/// Whether `d` is within `bound` (a NaN is not).
fn within(d: f32, bound: f32) -> bool {
    d <= bound
}

/// Every corner's radiosity, clamped at 0 as `Session::face_results` reports it, and whether its
/// face emits at `frame`.
fn corners(sys: &System, scene: &Scene, frame: f64) -> Vec<([f32; 3], bool)> {
    let mut out = Vec::new();
    for (obj, res) in scene.objects.iter().zip(sys.face_results(scene, frame)) {
        let mut emits = obj.faces.iter().zip(&obj.face_materials).flat_map(|(face, &m)| {
            let e = scene.emission_at(m as usize, frame).iter().any(|&x| x > 0.0);
            std::iter::repeat_n(e, face.len())
        });
        out.extend(res.corner_radiosity.iter().map(|c| (c.map(|x| x.max(0.0)), emits.next().unwrap())));
    }
    out
}

/// The worst corner channel of `got` off `want`: relative to `want`'s peak corner (the measure of
/// property 2 and of `tests/animation.rs`), and, reported only, relative to the peak over the
/// faces that do not emit (the emitters' exitance makes the peak, so the first hides errors in
/// the reflected light by the ratio of the two).
fn corner_difference(got: &[([f32; 3], bool)], want: &[([f32; 3], bool)]) -> (f32, f32) {
    let peak =
        |lit: bool| want.iter().filter(|(_, e)| lit || !e).flat_map(|(c, _)| *c).fold(0.0f32, f32::max);
    let worst = got
        .iter()
        .zip(want)
        .flat_map(|((x, _), (y, _))| (0..3).map(move |c| (x[c] - y[c]).abs()))
        .fold(0.0f32, worse);
    (worst / peak(true).max(f32::MIN_POSITIVE), worst / peak(false).max(f32::MIN_POSITIVE))
}

/// The strict bound on the exact chain's corners, as a fraction of the frame's peak corner: its
/// links equal the fresh build's (property 1), so its solution must equal `Full`'s but for where
/// the two solves stopped, and both stop at `SOLVE_TOLERANCE` (this is 100 times that).
const STRICT_EXACT_CORNERS: f32 = 1e-4;

/// The strict bound on the series chain's blocks, as a fraction of the fresh build's peak block
/// entry (property 1's bound): a series is truncated where its dropped tail is 1e-6 of its largest
/// term (`series::SERIES_TAIL`), and is used only while it describes the pair.
const STRICT_SERIES_LINKS: f32 = 1e-5;

/// The sums of the update statistics over a run, for the coverage assertions.
#[derive(Default, Debug)]
struct Coverage {
    cases: usize,
    /// Exact chain: pairs recomputed because their visibility changed, and for a non-translation.
    visibility: usize,
    non_translation: usize,
    /// Series chain: pairs read from a series and expanded, and recomputed off the expansion
    /// direction and for a half-space crossing.
    series: usize,
    expanded: usize,
    direction: usize,
    half_space: usize,
    /// Cases with emission keys, and with visibility off.
    emission_keyed: usize,
    no_visibility: usize,
    /// Frames rebuilt because a move changed which faces cover a coplanar one.
    rebuilds: usize,
}

impl Coverage {
    fn add(&mut self, exact: &UpdateStats, series: &UpdateStats) {
        self.visibility += exact.recomputed_visibility;
        self.non_translation += exact.recomputed_non_translation;
        self.series += series.links_series;
        self.expanded += series.series_expanded;
        self.direction += series.recomputed_direction;
        self.half_space += series.recomputed_half_space;
    }
}

/// A worst figure of a case and the frame where it is.
#[derive(Clone, Copy, Default)]
struct Worst {
    value: f32,
    frame: i64,
}

impl Worst {
    fn keep(&mut self, value: f32, frame: i64) {
        if worse(self.value, value) != self.value {
            *self = Worst { value, frame };
        }
    }
}

/// What one case measured (the worst figures over its frames) and which bounds it broke.
#[derive(Default)]
struct Report {
    /// Property 1, and the same measure for the series chain (strict check).
    exact_links: Worst,
    series_links: Worst,
    /// Property 2 for each chain; the exact chain's also against the strict bound.
    exact_corners: Worst,
    series_corners: Worst,
    /// Reported only: property 2's measure relative to the peak of the faces that do not emit.
    exact_corners_unlit: f32,
    series_corners_unlit: f32,
    /// Broken bounds of properties 1 and 2, and of the strict checks.
    failures: Vec<String>,
    strict_failures: Vec<String>,
}

/// Element `e` of `sys` by object name and face.
fn element_name(scene: &Scene, sys: &System, e: u32) -> String {
    let el = &sys.elements[e as usize];
    format!("{} face {}", scene.objects[el.object as usize].name, el.face)
}

/// Runs `scene`: the exact and the series chain from its first frame, against a fresh build and
/// solve at every later frame, recording the worst figures and every broken bound.
fn run(scene: &Scene, coverage: &mut Coverage) -> Report {
    let mut report = Report::default();
    if let Err(e) = run_frames(scene, coverage, &mut report) {
        report.failures.push(e);
    }
    report
}

/// The frames of [`run`]; an error (a failed build, solve or update) ends the case.
fn run_frames(scene: &Scene, coverage: &mut Coverage, report: &mut Report) -> Result<(), String> {
    let (first, last) = scene.frames;
    let solved = |frame: i64| -> Result<System, String> {
        let mut sys = System::build(scene, frame as f64, &no_progress)
            .map_err(|e| format!("frame {frame}: build: {e}"))?;
        sys.solve(SOLVE_TOLERANCE, &|| false).map_err(|e| format!("frame {frame}: solve: {e}"))?;
        Ok(sys)
    };
    let (mut exact, mut series) = (solved(first)?, solved(first)?);
    let mut exact_state = AnimationState::new(exact.elements.len(), false);
    let mut series_state = AnimationState::new(series.elements.len(), true);
    coverage.cases += 1;
    coverage.emission_keyed += scene.emission_keys.iter().any(|k| !k.is_empty()) as usize;
    coverage.no_visibility += !scene.settings.visibility as usize;
    for f in first + 1..=last {
        let frame = f as f64;
        let fresh = solved(f)?;
        // A panel brought flat onto the floor starts covering it: the floor's weight as a source
        // changes (crate::overlap) and the update asks for the rebuild the session then makes.
        let coverage_changed = fresh.source_weights != exact.source_weights;
        let update = |sys: &mut System, state: &mut AnimationState, what: &str| match animation::advance(
            sys,
            state,
            scene,
            frame,
            &no_progress,
        ) {
            Ok(Outcome::Updated(stats)) => Ok(Some(stats)),
            Ok(Outcome::NeedsRebuild) if coverage_changed => Ok(None),
            Ok(Outcome::NeedsRebuild) => Err(format!("frame {f}: the {what} update asked for a rebuild")),
            Err(e) => Err(format!("frame {f}: the {what} update failed: {e}")),
        };
        let exact_stats = update(&mut exact, &mut exact_state, "exact")?;
        let series_stats = update(&mut series, &mut series_state, "series")?;
        match (exact_stats, series_stats) {
            (Some(e), Some(s)) => coverage.add(&e, &s),
            _ => {
                coverage.rebuilds += 1;
                (exact, series) = (solved(f)?, solved(f)?);
                exact_state = AnimationState::new(exact.elements.len(), false);
                series_state = AnimationState::new(series.elements.len(), true);
            }
        }

        // Property 1, and the strict check of the series chain's links.
        for (sys, worst, bound, what) in [
            (&exact, &mut report.exact_links, LINK_TOLERANCE, "exact"),
            (&series, &mut report.series_links, STRICT_SERIES_LINKS, "series"),
        ] {
            let (d, (i, j)) = link_difference(&sys.links, &fresh.links);
            worst.keep(d, f);
            if !within(d, bound) {
                let (strict, property) =
                    if what == "exact" { (false, "property 1") } else { (true, "strict check") };
                let failure = format!(
                    "{property}, frame {f}: the {what} update's pair ({i}, {j}) ({} - {}) is {d:.3e} of \
                     the peak block entry off the fresh build's (bound {bound:e})",
                    element_name(scene, &fresh, i),
                    element_name(scene, &fresh, j),
                );
                if strict { &mut report.strict_failures } else { &mut report.failures }.push(failure);
            }
        }

        // Property 2, and the strict check of the exact chain's corners.
        let want = corners(&fresh, scene, frame);
        for (sys, worst, unlit, what) in [
            (&exact, &mut report.exact_corners, &mut report.exact_corners_unlit, "exact"),
            (&series, &mut report.series_corners, &mut report.series_corners_unlit, "series"),
        ] {
            let (d, d_unlit) = corner_difference(&corners(sys, scene, frame), &want);
            worst.keep(d, f);
            *unlit = worse(*unlit, d_unlit);
            let line = |bound: f32, name: &str| {
                format!(
                    "{name}, frame {f}: the {what} chain's worst corner is {d:.3e} of the frame's peak \
                     off Full's ({d_unlit:.3e} of the peak of the faces that do not emit; bound {bound:e})"
                )
            };
            if !within(d, CORNER_TOLERANCE) {
                report.failures.push(line(CORNER_TOLERANCE, "property 2"));
            } else if what == "exact" && !within(d, STRICT_EXACT_CORNERS) {
                report.strict_failures.push(line(STRICT_EXACT_CORNERS, "strict check"));
            }
        }
    }
    Ok(())
}

/// One case of a run: its seed, scene in words, size and report.
struct CaseResult {
    seed: u64,
    description: Vec<String>,
    patches: usize,
    frames: i64,
    report: Report,
}

/// The seeds to run: `ANIMATION_RANDOM_SEED` alone, or `1..=ANIMATION_RANDOM_CASES`, or the fixed
/// `1..=CASES`.
fn seeds() -> Vec<u64> {
    let var = |name: &str| std::env::var(name).ok().map(|v| v.parse::<u64>().expect(name));
    match (var("ANIMATION_RANDOM_SEED"), var("ANIMATION_RANDOM_CASES")) {
        (Some(seed), _) => vec![seed],
        (None, Some(n)) => (1..=n).collect(),
        (None, None) => (1..=CASES).collect(),
    }
}

/// Runs `seeds`, printing a line per case and the worst figures of the run.
fn run_seeds(seeds: &[u64]) -> (Vec<CaseResult>, Coverage) {
    let start = std::time::Instant::now();
    let mut coverage = Coverage::default();
    let mut outcomes = Vec::new();
    for &seed in seeds {
        let case_start = std::time::Instant::now();
        let case = generate(seed);
        if seeds.len() == 1 {
            eprintln!("{}", case.description.join("\n  "));
        }
        let r = run(&case.scene, &mut coverage);
        let (patches, frames) = (case.scene.face_count(), case.scene.frames.1);
        eprintln!(
            "seed {seed:3}: {patches:3} patches, {frames} frames: links exact {:.1e}, series {:.1e} \
             (frame {}); corners exact {:.1e} (frame {}), series {:.1e} of the peak ({:.1e}, {:.1e} \
             of the unlit peak); {:.2} s",
            r.exact_links.value,
            r.series_links.value,
            r.series_links.frame,
            r.exact_corners.value,
            r.exact_corners.frame,
            r.series_corners.value,
            r.exact_corners_unlit,
            r.series_corners_unlit,
            case_start.elapsed().as_secs_f64()
        );
        outcomes.push(CaseResult { seed, description: case.description, patches, frames, report: r });
    }
    type Figure = fn(&Report) -> f32;
    let figures: [(&str, Figure); 6] = [
        ("links, exact (property 1)", |r| r.exact_links.value),
        ("links, series", |r| r.series_links.value),
        ("corners, exact (property 2)", |r| r.exact_corners.value),
        ("corners, series (property 2)", |r| r.series_corners.value),
        ("corners, exact, of the unlit peak", |r| r.exact_corners_unlit),
        ("corners, series, of the unlit peak", |r| r.series_corners_unlit),
    ];
    for (name, figure) in figures {
        let worst = outcomes.iter().max_by(|a, b| figure(&a.report).total_cmp(&figure(&b.report)));
        match worst {
            Some(o) if figure(&o.report) > 0.0 => {
                eprintln!("worst {name}: {:.2e} (seed {})", figure(&o.report), o.seed)
            }
            _ => eprintln!("worst {name}: 0 (every case)"),
        }
    }
    let patches: Vec<usize> = outcomes.iter().map(|o| o.patches).collect();
    let frames: i64 = outcomes.iter().map(|o| o.frames - 1).sum();
    eprintln!(
        "{} cases, {}-{} patches, {frames} updates, {:.1} s; {coverage:?}",
        outcomes.len(),
        patches.iter().min().unwrap_or(&0),
        patches.iter().max().unwrap_or(&0),
        start.elapsed().as_secs_f64()
    );
    (outcomes, coverage)
}

/// The run of [`seeds`], made once for the two tests that read it.
fn fixed_run() -> &'static (Vec<CaseResult>, Coverage) {
    static RUN: std::sync::OnceLock<(Vec<CaseResult>, Coverage)> = std::sync::OnceLock::new();
    RUN.get_or_init(|| run_seeds(&seeds()))
}

/// Panics listing every case of `outcomes` with failures (as `failures` picks them), with its
/// scene and how to rerun it.
fn assert_no_failures(outcomes: &[CaseResult], failures: fn(&Report) -> &Vec<String>, what: &str) {
    let failed: Vec<String> = outcomes
        .iter()
        .filter(|o| !failures(&o.report).is_empty())
        .map(|o| {
            format!(
                "{}\n  {}\n  rerun: ANIMATION_RANDOM_SEED={} cargo test --release --test animation_random \
                 -- --nocapture",
                o.description.join("\n  "),
                failures(&o.report).join("\n  "),
                o.seed
            )
        })
        .collect();
    assert!(
        failed.is_empty(),
        "{what}: {} of {} cases failed:\n{}",
        failed.len(),
        outcomes.len(),
        failed.join("\n\n")
    );
}

/// Properties 1 and 2 over the random cases (module docs), and the coverage that keeps the test
/// from passing vacuously: over the fixed run, static pairs were recomputed for visibility, series
/// were read and expanded, pairs were recomputed for a non-translation, for a half-space crossing
/// and off the expansion direction, and some cases had emission keys or visibility off.
#[test]
fn random_animations_match_fresh_builds() {
    let (outcomes, c) = fixed_run();
    assert_no_failures(outcomes, |r| &r.failures, "properties 1 and 2");
    if outcomes.len() < CASES as usize {
        return; // Fewer seeds than the fixed run: no coverage to expect.
    }
    // (With session 12's fixes the fixed run counts 22,655 / 5,499 / 5,621 / 30,552 / 23,706 /
    // 2,103, 41 and 10.)
    assert!(c.visibility > 5000, "{} pairs recomputed for visibility", c.visibility);
    assert!(c.series > 1000, "{} pairs read from a series", c.series);
    assert!(c.expanded > 1000, "{} pairs expanded", c.expanded);
    assert!(c.non_translation > 5000, "{} pairs recomputed for a non-translation", c.non_translation);
    assert!(c.half_space > 5000, "{} pairs recomputed for a half-space crossing", c.half_space);
    assert!(c.direction > 400, "{} series abandoned off their direction", c.direction);
    assert!(c.emission_keyed >= 10, "{} cases with emission keys", c.emission_keyed);
    assert!(c.no_visibility >= 3, "{} cases with visibility off", c.no_visibility);
}

/// The strict checks over the same cases: the exact chain's corners within
/// [`STRICT_EXACT_CORNERS`] of Full's (its links are the fresh build's, so only the solves'
/// stopping points may differ), and the series chain's links within [`STRICT_SERIES_LINKS`] of the
/// fresh build's, pair by pair (property 1's bound).
///
/// Failed before session 12's fixes (574c196) on 5 of the 96 fixed seeds, whose cases met the two
/// defects the regression tests below pin (`panel_taken_out_of_a_box_lights_the_lamp_again`,
/// `seed_239_...`, `seed_138_...`): seeds 20, 27, 65 and 77 by a series read across a change of
/// quadrature (up to 3.5e-3 of the peak block entry), seed 36 by `Delta K b` (exact chain 1.6e-4
/// of the peak off). With both fixes, 1,000 seeds stay within 1.6e-6 of the peak corner and 4.1e-7
/// of the peak block entry.
#[test]
fn random_animations_match_fresh_builds_strictly() {
    let (outcomes, _) = fixed_run();
    assert_no_failures(outcomes, |r| &r.strict_failures, "strict checks");
}

/// Runs seed `seed` alone, printing its scene, and returns its report.
fn seed_report(seed: u64) -> Report {
    let case = generate(seed);
    eprintln!("{}", case.description.join("\n  "));
    let r = run(&case.scene, &mut Coverage::default());
    for line in r.failures.iter().chain(&r.strict_failures) {
        eprintln!("  {line}");
    }
    r
}

/// Regression (failed before session 12's fix): unshot energy parked where it delivers nothing
/// came back wrong when the kernel changed.
///
/// A white panel (reflectance 0.9) 0.1 under a ceiling lamp (reflectance 0.8) is moved into a
/// closed box at frame 2 and put back at frame 3. Inside the box it sees nothing: its row and
/// column of the kernel vanish, so frame 2's `Delta K b` takes its radiosity `b = 6.77` away as
/// unshot `u = -6.77` that the solve never shoots (its transfer `T` is 0, so it counts for nothing
/// in the stopping test). At frame 3 the update forms `Delta K b` with the panel's `b = 0`, but
/// the solve keeps `b = e + K (b - u)` (`replay` module docs), whose change is `Delta K (b - u)`:
/// the panel's light on the lamp, `Delta K` times its `b - u = 6.77`, is never added. Both methods
/// then leave the lamp at 9.54 where `Full` has 12.15: 21% of the frame's peak (39% of the peak of
/// the faces that do not emit), while the links equal the fresh build's bit for bit.
///
/// Cause: `animation::advance` (then src/animation.rs; now src/animation/delta_k.rs), the apply step, called `delta_kb` with
/// `sys.solution.b`; the invariant needs `b - unshot` there (then `b` and `unshot` both take
/// `Delta e + Delta K (b - u)`, and `b = e + K' (b - u)` holds exactly), which it now uses. Eq.
/// (9) assumes a converged previous frame (`u = 0`); the error was `Delta K u`, negligible only
/// while every unshot coefficient is small, which the stopping test does not ensure for
/// coefficients whose transfer is (near) 0. The fix makes this test, seed 239 and the 15 of 1,000
/// seeds whose exact chain was off Full's by over 1e-4 of the peak agree to 1.6e-6 or better.
#[test]
fn panel_taken_out_of_a_box_lights_the_lamp_again() {
    let p = DVec3::new;
    let settings =
        Settings { basis_order: 1, tolerance: SOLVE_TOLERANCE, corner_gather: false, ..Settings::default() };
    let floor = [p(0., 0., 0.), p(1., 0., 0.), p(1., 0., 1.), p(0., 0., 1.)];
    let floor = scenes::subdivided_quad("floor", scenes::facing(floor, p(0.5, 1.0, 0.5), false), 4, 0);
    let lamp = scenes::panel("lamp", p(0.5, 0.9, 0.5), DVec3::X * 0.15, DVec3::Z * 0.15, -DVec3::Y, 1, 1);
    let mut shelf =
        scenes::panel("panel", p(0.5, 0.8, 0.5), DVec3::X * 0.12, DVec3::Z * 0.12, DVec3::Y, 1, 2);
    let into_box = p(0.2, 0.3, 0.8) - p(0.5, 0.8, 0.5);
    shelf.animation = scenes::translation_keys(&[(1.0, DVec3::ZERO), (2.0, into_box), (3.0, DVec3::ZERO)]);
    let closed = block("box", p(0.2, 0.3, 0.8), DVec3::splat(0.15), 1, 0, true);
    let materials = vec![
        Material { name: "white".into(), reflectance: [0.7; 3], emission: [0.0; 3] },
        Material { name: "lamp".into(), reflectance: [0.8; 3], emission: [10.0; 3] },
        Material { name: "panel".into(), reflectance: [0.9; 3], emission: [0.0; 3] },
    ];
    let scene = Scene::new(settings, (1, 3), materials, vec![vec![]; 3], vec![floor, lamp, shelf, closed])
        .expect("valid scene");
    let r = run(&scene, &mut Coverage::default());
    eprintln!(
        "links exact {:.1e}; corners exact {:.3e}, series {:.3e} of the peak (frame {})",
        r.exact_links.value, r.exact_corners.value, r.series_corners.value, r.exact_corners.frame
    );
    assert!(r.failures.is_empty() && r.strict_failures.is_empty(), "{:#?}", (r.failures, r.strict_failures));
}

/// Regression (failed before session 12's fix), the random case where the defect of
/// `panel_taken_out_of_a_box_lights_the_lamp_again` came to light: a panel facing up comes down
/// onto the floor through two boxes being scaled; at frame 2 it is inside one of them (unshot
/// -1.24 left on it, transfer 2e-19), at frame 3 below it (cutting through the other). From frame
/// 3 on the exact chain's solution breaks `b = e + K (b - u)` by exactly `rho Delta K u`
/// (1.68e-2, as computed from the two frames' link stores), and both methods are 7.3e-3 of the
/// peak corner off Full's at frame 3 (11% of the peak of the faces that do not emit), 3.0e-3 at
/// frame 5, while the links equal the fresh build's bit for bit. Within property 2's 1%; caught
/// by the strict check.
#[test]
fn seed_239_exact_update_matches_full_to_the_solver_tolerance() {
    let r = seed_report(239);
    assert!(r.failures.is_empty() && r.strict_failures.is_empty(), "seed 239 failed (above)");
}

/// Regression (failed before session 12's fix): a series kept serving a pair whose fresh kernel
/// would be integrated by another rule.
///
/// Seed 138: a panel facing down moves slowly over the floor, stops and reverses, while a box
/// beside it circles slowly (so the floor-panel pairs are partly hidden, a masked integrand).
/// Floor face 8 and the panel are 1.5006 radii-sums apart when the pair is expanded (frame 2),
/// just over `kernel::pair::SEPARATION` (1.5), so its series reproduces the whole-domain 4 x 4
/// Gauss kernel. The reversal takes them to 1.4983 at frame 5, within the displacement the series
/// allows (`0.2 r_min`) and on its line, so the series is still read; but a fresh build now
/// splits the pair (near-pair quadrature), whose kernel differs from the whole-domain rule's by
/// 2.0e-2 of the peak block entry (the pair's largest entry is 0.013; some of its others are off
/// by half), with the same visibility mask. The blocks stay that far off a fresh build's at frames
/// 5 and 6, and the series chain's solution 4.1e-4 of the peak off Full's (seed 829, which the
/// change below mends too: 3.6e-3, 4.8% of the peak of the faces that do not emit).
///
/// Cause: `animation::series_check` (now src/animation/pairs.rs) checked the epochs, the half-space, the
/// visibility, the direction and the bound, but not that the pair is still integrated as it was
/// at the expansion: separated beyond `SEPARATION` (`series::eligible` checks that at expansion
/// only) and, with adaptive quadrature, on the same `PairContext::points_for` rule (pairs crossing
/// `MID` or `FAR` change rules too). The fix: a series records its rule (`PairSeries::points`),
/// and `series_check` abandons it, as past its bound, when the pair's rule is no longer that one
/// (split, or another point count); 1,000 seeds then keep the series chain's links within 4.1e-7
/// of the peak block entry.
#[test]
fn seed_138_series_is_abandoned_when_the_pair_changes_quadrature() {
    let r = seed_report(138);
    assert!(r.failures.is_empty() && r.strict_failures.is_empty(), "seed 138 failed (above)");
}

/// The random cases the hierarchy's test runs (a third of the flat tests' fixed seeds: each case
/// checks every stored pair of every frame against a fresh computation, and the partition).
const HIERARCHY_CASES: u64 = 32;

/// The same random animations on the hierarchy (issue 21): from the first frame's
/// `hierarchy::solve_frame`, each frame `update_frame`d from the last with the pair tree kept (as
/// `Session` does for animations: touched pairs found by the walk, subtrees redone and coarsened),
/// against the frame solved from scratch. At every frame after the first:
///
/// 1. every link the update holds is, bit for bit, what a fresh computation on the frame's
///    geometry gives, every blocked pair is blocked and every idle pair carries nothing
///    (`hierarchy_checks::check_pairs`): nothing a move touched was kept;
/// 2. the links, blocked and idle pairs partition the pairs of leaves (links removed and made
///    again, none lost or doubled), and they are the pair tree's leaves;
/// 3. the face means are within 2% of the fresh frame's peak: the two hierarchies' links differ
///    where the brightness refined them (the update refines from the last frame's light), so
///    this is the accuracy knob's agreement, not the solver tolerance's;
/// 4. the corners, gathered with the last frame's kept values where the moves spared them
///    (`hierarchy::gather::KeptGather`), are exactly a fresh gather's of the same solution.
///
/// Coverage is asserted: updates that redid fewer pairs than they touched (coarsened), updates
/// that kept most links, and gathers that took kept values. Measured over the 32 fixed seeds: 99
/// updates (97 coarsened, 48 kept most links, 99 gathers took kept values), worst face 4.4e-3 of
/// the peak (2026-12-07); over seeds 1..=300
/// (`ANIMATION_RANDOM_CASES=300`, 105 s): 1,028 updates, worst face 1.2e-2 of the peak. That run
/// found seed 77 (a blocked pair that a recomputation found open: the BVH's blocker cache and
/// its slab test, `visibility::bvh`, both fixed). `ANIMATION_RANDOM_SEED` / `ANIMATION_RANDOM_CASES` pick the
/// seeds as for the flat tests.
#[test]
fn random_animations_on_the_hierarchy_match_fresh_builds() {
    let var = |name: &str| std::env::var(name).ok().map(|v| v.parse::<u64>().expect(name));
    let seeds: Vec<u64> = match (var("ANIMATION_RANDOM_SEED"), var("ANIMATION_RANDOM_CASES")) {
        (Some(seed), _) => vec![seed],
        (None, Some(n)) => (1..=n).collect(),
        (None, None) => (1..=HIERARCHY_CASES).collect(),
    };
    check_hierarchy_cases(&seeds);
}

/// Seed 42 (a static box starts to glow in its last frame) found the kept gather taking a
/// face's values from when it was dark: an emitter's rectangles are integrated with their
/// penumbrae split, so its values are not a dark face's (`Changes::lit_or_dimmed`).
#[test]
fn seed_42_a_face_that_starts_to_glow_is_gathered_again() {
    check_hierarchy_cases(&[42]);
}

/// [`random_animations_on_the_hierarchy_match_fresh_builds`]' checks on `seeds`.
fn check_hierarchy_cases(seeds: &[u64]) {
    use galerkin_radiosity::hierarchy::gather;
    use galerkin_radiosity::hierarchy::update::update_frame;
    use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
    let (mut updates, mut coarsened, mut mostly_kept, mut worst) = (0, 0, 0, 0.0f64);
    let mut gathers_kept = 0;
    for &seed in seeds {
        let case = generate(seed);
        let scene = &case.scene;
        let (first, last) = scene.frames;
        // Shown when a check below fails (the harness prints a failed test's output).
        println!("{}", case.description.join("; "));
        let fresh_hs = HierarchySettings::of(&scene.settings);
        // The corners gathered too, keeping their values from frame to frame (as `Session` gathers
        // an animation), each frame's against a fresh gather of its solution.
        let hs =
            HierarchySettings { keep_pair_tree: true, corner_gather: true, keep_gather: true, ..fresh_hs };
        let about = || {
            format!("seed {seed} ({}), rerun with ANIMATION_RANDOM_SEED={seed}", case.description.join("; "))
        };
        let mut h = solve_frame(scene, first as f64, &hs, &no_progress)
            .unwrap_or_else(|e| panic!("{e}: {}", about()));
        for f in first + 1..=last {
            let frame = f as f64;
            let next = update_frame(&mut h, scene, frame, &hs, &no_progress)
                .unwrap_or_else(|e| panic!("frame {f}: {e}: {}", about()));
            let s = &next.stats;
            if s.updated {
                updates += 1;
                coarsened += usize::from(s.refined_from < s.touched_pairs);
                mostly_kept += usize::from(s.kept_links > s.links / 2);
            }
            if s.updated && s.gather_kept > 0 {
                gathers_kept += 1;
            }
            let lit = galerkin_radiosity::hierarchy::Lighting::new(scene, frame, &next.hierarchy.tree.faces);
            let inputs = gather::Inputs::new(&next.hierarchy, &next.state, &lit);
            let fresh_corners =
                gather::corners_with(&inputs, scene, frame, &no_progress, gather::Mode::Fast).unwrap();
            let (radiosity, _) = next.corners.as_ref().expect("gathered");
            assert!(
                radiosity == &fresh_corners.radiosity,
                "frame {f}: the kept gather's corners are not a fresh gather's: {}",
                about()
            );
            hierarchy_checks::check_pairs(&next, scene, frame, &hs);
            hierarchy_checks::check_partition(&next);
            hierarchy_checks::check_pair_tree(&next);
            let fresh = solve_frame(scene, frame, &fresh_hs, &no_progress).unwrap();
            let means = |x: &galerkin_radiosity::hierarchy::HierarchicalFrame| -> Vec<f64> {
                (0..x.hierarchy.tree.faces.len())
                    .map(|i| x.face_mean(i).iter().copied().fold(0.0, f64::max))
                    .collect()
            };
            let (got, want) = (means(&next), means(&fresh));
            let peak = want.iter().copied().fold(0.0, f64::max);
            let d = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max) / peak.max(1e-300);
            worst = worst.max(d);
            assert!(
                d < 0.02,
                "frame {f}: a face mean {d:.3e} of the peak off the fresh frame's: {}",
                about()
            );
            h = next;
        }
    }
    println!(
        "{} cases, {updates} updates ({coarsened} coarsened, {mostly_kept} kept most links, {gathers_kept} gathers \
         took kept values); worst face {worst:.3e} of the peak",
        seeds.len()
    );
    if seeds.len() as u64 == HIERARCHY_CASES {
        assert!(
            updates > 60 && coarsened > 10 && mostly_kept > 10 && gathers_kept > 30,
            "coverage: {updates} updates, {coarsened} coarsened, {mostly_kept} kept most links, {gathers_kept} \
             gathers took kept values"
        );
    }
}
