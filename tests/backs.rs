//! The backs of open surfaces (issue 19, `galerkin_radiosity::backs`): a sheet reflects from both
//! sides, as Cycles' diffuse surfaces do, and closed surfaces get no back.
//!
//! A lamp (a reflecting emitter facing up) under a grey sheet. Turned away from the lamp, the
//! one-sided sheet returned nothing to it; with its back it must return exactly what the same
//! sheet facing the lamp returns: the back is the same surface with its winding reversed. The
//! reference is the one-sided solver on the sheet turned over, which the form-factor, furnace and
//! Cornell tests validate.

use galerkin_radiosity::scene::{Key, KeyTransform, Material, Scene, Settings};
use galerkin_radiosity::scenes::{closed_box, facing, merge, subdivided_quad};
use galerkin_radiosity::session::{Method, Session};
use galerkin_radiosity::system::{System, no_progress};
use glam::{DMat4, DVec3};

const LAMP_EXITANCE: f64 = 1.0;

/// The lamp (1 m, facing up, reflectance 0.6) at z = 0 and a 1 m grey sheet (0.8) `height` above
/// it, in `n x n` faces, its front up (`up`) or down; `frames` frames, the sheet moving by `step`
/// each.
fn lamp_and_sheet(up: bool, backs: bool, frames: i64, step: DVec3) -> Scene {
    let p = |x, y, z| DVec3::new(x, y, z);
    let lamp_corners =
        facing([p(0., 0., 0.), p(1., 0., 0.), p(1., 1., 0.), p(0., 1., 0.)], p(0.5, 0.5, 1.), false);
    let h = 0.3;
    let sheet_corners = facing([p(0., 0., h), p(1., 0., h), p(1., 1., h), p(0., 1., h)], p(0.5, 0.5, 0.), up);
    let lamp = subdivided_quad("lamp", lamp_corners, 2, 0);
    let mut sheet = subdivided_quad("sheet", sheet_corners, 3, 1);
    if frames > 1 {
        sheet.animation = (0..frames)
            .map(|k| Key {
                frame: (1 + k) as f64,
                transform: KeyTransform::Matrix(DMat4::from_translation(step * k as f64)),
            })
            .collect();
    }
    let materials = vec![
        Material { name: "lamp".into(), reflectance: [0.6; 3], emission: [LAMP_EXITANCE; 3] },
        Material { name: "grey".into(), reflectance: [0.8; 3], emission: [0.0; 3] },
    ];
    let settings =
        Settings { basis_order: 2, tolerance: 1e-7, reflecting_backs: backs, ..Settings::default() };
    Scene::new(settings, (1, frames), materials, vec![Vec::new(); 2], vec![lamp, sheet]).unwrap()
}

fn solved(scene: &Scene) -> System {
    let mut sys = System::build(scene, 1.0, &no_progress).unwrap();
    sys.solve(scene.settings.tolerance, &|| false).unwrap();
    sys.gather_corners(scene, 1.0, &no_progress).unwrap();
    sys
}

/// The lamp's face means and gathered corners.
fn lamp_values(scene: &Scene, sys: &System) -> Vec<[f32; 3]> {
    let lamp = &sys.face_results(scene, 1.0)[0];
    lamp.face_radiosity.iter().chain(&lamp.corner_radiosity).copied().collect()
}

fn worst_relative(a: &[[f32; 3]], b: &[[f32; 3]]) -> f32 {
    a.iter().zip(b).map(|(x, y)| ((x[0] - y[0]) / y[0]).abs()).fold(0.0, f32::max)
}

#[test]
fn a_sheet_returns_light_from_its_back_as_from_its_front() {
    let turned_over = lamp_and_sheet(false, true, 1, DVec3::ZERO);
    let want = lamp_values(&turned_over, &solved(&turned_over));
    let away = lamp_and_sheet(true, true, 1, DVec3::ZERO);
    let sys = solved(&away);
    assert_eq!(sys.elements.iter().filter(|e| e.back).count(), 9, "the sheet's 9 faces get backs");
    let got = lamp_values(&away, &sys);
    let mean = |v: &[[f32; 3]]| v[..4].iter().map(|c| c[0] as f64).sum::<f64>() / 4.0;
    eprintln!("lamp mean: back {:.6}, front {:.6}", mean(&got), mean(&want));
    // The sheet sends a fifth or more of the lamp's light back to it.
    assert!(mean(&want) > 1.2 * LAMP_EXITANCE, "the reference returns light: {}", mean(&want));
    let worst = worst_relative(&got, &want);
    assert!(worst < 1e-4, "the back against the turned sheet: worst {worst:e} of the lamp's values");

    // Without backs nothing comes back: the lamp shows its own exitance alone.
    let one_sided = lamp_and_sheet(true, false, 1, DVec3::ZERO);
    let sys = solved(&one_sided);
    assert_eq!(sys.elements.iter().filter(|e| e.back).count(), 0);
    for v in lamp_values(&one_sided, &sys) {
        assert!((v[0] as f64 - LAMP_EXITANCE).abs() < 1e-6, "{v:?}");
    }
}

/// A closed box (six inward walls of 2 x 2 faces merged into one object) gets no backs; the
/// same walls as six open objects get their backs, which face out into nothing and change
/// nothing.
#[test]
fn only_open_surfaces_get_backs() {
    // The box's walls grey, but one emitting (an emitter gets no back).
    let settings = Settings { basis_order: 1, corner_gather: false, ..Settings::default() };
    let mut walls = closed_box(2, 0.5, 0.0, settings.clone()).objects;
    assert_eq!(walls.len(), 6, "the box's walls are six objects");
    walls[0].face_materials.fill(1);
    let faces: usize = walls.iter().map(|o| o.faces.len()).sum();
    let materials = vec![
        Material { name: "grey".into(), reflectance: [0.5; 3], emission: [0.0; 3] },
        Material { name: "lamp".into(), reflectance: [0.5; 3], emission: [1.0; 3] },
    ];
    let scene = |objects, backs| {
        let settings = Settings { reflecting_backs: backs, ..settings.clone() };
        Scene::new(settings, (1, 1), materials.clone(), vec![Vec::new(); 2], objects).unwrap()
    };
    let backs = |scene: &Scene| {
        let sys = System::build(scene, 1.0, &no_progress).unwrap();
        sys.elements.iter().filter(|e| e.back).count()
    };
    assert_eq!(backs(&scene(vec![merge("box", walls.clone())], true)), 0, "a closed box gets no backs");
    let (open, one_sided) = (scene(walls.clone(), true), scene(walls, false));
    assert_eq!(backs(&open), faces - 4, "every open face but the lamp's gets a back");
    let means = |scene: &Scene| -> Vec<f32> {
        let mut sys = System::build(scene, 1.0, &no_progress).unwrap();
        sys.solve(1e-7, &|| false).unwrap();
        sys.face_results(scene, 1.0).iter().flat_map(|o| o.face_radiosity.iter().map(|v| v[0])).collect()
    };
    for (x, y) in means(&open).iter().zip(&means(&one_sided)) {
        assert!((x - y).abs() <= 1e-6 * x, "{x} against {y}");
    }
}

/// The incremental updates keep the backs: a sheet sliding over the lamp, every frame's corners
/// within 1% of the peak of the same frame solved from scratch, on the flat path and on the
/// hierarchy.
#[test]
fn a_moving_sheet_updates_its_back() {
    let scene = lamp_and_sheet(true, true, 4, DVec3::new(0.07, 0.0, 0.0));
    let bake = |method| {
        let mut session = Session::new(scene.clone(), method).unwrap();
        (1..=4)
            .map(|f| {
                session.solve_frame(f as f64, &no_progress).unwrap();
                session.face_results().unwrap()[0].corner_radiosity.clone()
            })
            .collect::<Vec<_>>()
    };
    let (full, incremental) = (bake(Method::Full), bake(Method::Incremental));
    // The hierarchy updates each frame from the last (`hierarchy::update`), against each frame
    // solved on the hierarchy from scratch.
    let updated = bake(Method::Hierarchical);
    let fresh: Vec<_> = (1..=4)
        .map(|f| {
            use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
            let hs = HierarchySettings::of(&scene.settings);
            let h = solve_frame(&scene, f as f64, &hs, &no_progress).unwrap();
            h.face_results(&scene, f as f64)[0].corner_radiosity.clone()
        })
        .collect();
    for (got, want, what) in [(&incremental, &full, "flat"), (&updated, &fresh, "hierarchy")] {
        for (f, (a, b)) in got.iter().zip(want).enumerate() {
            let peak = b.iter().map(|c| c[0]).fold(0.0f32, f32::max);
            let worst = a.iter().zip(b).map(|(x, y)| (x[0] - y[0]).abs()).fold(0.0f32, f32::max);
            assert!(worst <= 0.01 * peak, "{what}, frame {f}: {worst} of peak {peak}");
            // The sheet's back lights the lamp in every frame.
            assert!(peak > 1.1 * LAMP_EXITANCE as f32, "{what}, frame {f}: peak {peak}");
        }
    }
}

/// The hierarchy (`Method::Hierarchical`) takes the backs as faces of its tree: the lamp under
/// the sheet turned away gets what the sheet facing it returns, within the hierarchy's own
/// refinement (the two trees are parametrised differently, so refined alike only roughly).
#[test]
fn the_hierarchy_reflects_from_backs_too() {
    use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
    let lamp_means = |scene: &Scene| -> Vec<f64> {
        let hs = HierarchySettings::of(&scene.settings);
        let h = solve_frame(scene, 1.0, &hs, &no_progress).unwrap();
        h.face_results(scene, 1.0)[0].face_radiosity.iter().map(|v| v[0] as f64).collect()
    };
    let want = lamp_means(&lamp_and_sheet(false, true, 1, DVec3::ZERO));
    let got = lamp_means(&lamp_and_sheet(true, true, 1, DVec3::ZERO));
    let one_sided = lamp_means(&lamp_and_sheet(true, false, 1, DVec3::ZERO));
    eprintln!("hierarchy lamp means: back {got:?}, front {want:?}, one-sided {one_sided:?}");
    for ((g, w), o) in got.iter().zip(&want).zip(&one_sided) {
        assert!(*w > 1.2 * LAMP_EXITANCE, "the sheet returns light: {w}");
        assert!((g - w).abs() < 0.01 * w, "the back {g} against the turned sheet {w}");
        assert!((o - LAMP_EXITANCE).abs() < 1e-6, "one-sided: nothing returns, {o}");
    }
}

/// The CLI's `--reflecting-backs` turns backs on for a scene file that has them off, and the
/// setting round-trips through the scene file.
#[test]
fn the_cli_flag_turns_backs_on() {
    use galerkin_radiosity::scene::json::{parse_scene, scene_to_json};
    let scene = lamp_and_sheet(true, false, 1, DVec3::ZERO);
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("backs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("scene.json");
    std::fs::write(&input, scene_to_json(&scene)).unwrap();
    let lamp_mean = |flags: &[&str]| -> f64 {
        let out = dir.join("out.json");
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_galerkin-radiosity"))
            .arg("bake")
            .arg(&input)
            .arg("-o")
            .arg(&out)
            .args(["--quiet", "--no-corner-gather"])
            .args(flags)
            .output()
            .unwrap();
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
        let result: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        let faces = result["frames"][0]["objects"][0]["face_radiosity"].as_array().unwrap().clone();
        faces.iter().map(|v| v[0].as_f64().unwrap()).sum::<f64>() / faces.len() as f64
    };
    let (off, on) = (lamp_mean(&[]), lamp_mean(&["--reflecting-backs"]));
    assert!((off - LAMP_EXITANCE).abs() < 1e-6, "one-sided: {off}");
    assert!(on > 1.2 * LAMP_EXITANCE, "with backs the sheet returns light: {on}");
    let with_backs =
        Scene { settings: Settings { reflecting_backs: true, ..scene.settings.clone() }, ..scene };
    let parsed = parse_scene(&scene_to_json(&with_backs)).unwrap();
    assert!(parsed.settings.reflecting_backs);
}

/// A mirrored placement (negative scale; Blender keeps the object-space front side): the sheet's
/// vertices mirrored in x about 0.5 and placed with a mirror in x, the same world positions. The
/// vertex mirror turned the object-space front over, so its front faces the lamp and its back
/// faces up, where the plain sheet's front faces up: each back is opposite its front, and a sheet
/// with backs returns the same light to the lamp whichever side is its front.
#[test]
fn a_mirrored_sheet_has_its_back_opposite_its_front() {
    let plain = lamp_and_sheet(true, true, 1, DVec3::ZERO);
    let mut mirrored = plain.clone();
    let sheet = &mut mirrored.objects[1];
    for v in &mut sheet.vertices {
        v.x = 1.0 - v.x;
    }
    sheet.matrix =
        DMat4::from_translation(DVec3::new(1.0, 0.0, 0.0)) * DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0));
    assert!(mirrored.objects[1].mirrored_at(1.0));
    let (a, b) = (solved(&plain), solved(&mirrored));
    // Front normals' z: up in the plain sheet, down in the mirrored one; backs the other way.
    for (sys, front_z) in [(&a, 1.0), (&b, -1.0)] {
        let sheet: Vec<_> = sys.elements.iter().filter(|e| e.object == 1).collect();
        assert_eq!(sheet.iter().filter(|e| e.back).count(), 9);
        for e in sheet {
            let z = e.patch.centre_normal().z;
            let want = if e.back { -front_z } else { front_z };
            assert!((z - want).abs() < 1e-9, "back {}: normal z {z}, want {want}", e.back);
        }
    }
    let worst = worst_relative(&lamp_values(&mirrored, &b), &lamp_values(&plain, &a));
    assert!(worst < 1e-4, "mirrored against plain: worst {worst:e}");
}
