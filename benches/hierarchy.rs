//! The hierarchy's bench table (issue 20): `cargo bench --bench hierarchy [-- --quick]`, and with
//! `GALERKIN_MONASTERY=path/to/samurai_monastry.obj` the full 124,789-triangle monastery too.
//! `GALERKIN_EXACT=clusters,light,near` turns the Cornell rows' approximations off (links between
//! surfaces only, every surface link in full, near links integrated adaptively), to see what each
//! costs in error and time.
//!
//! Each case runs in a child process of this binary, so that its peak RSS is its own. Errors are
//! the relative RMS of per-face mean radiosity (largest channel, lit faces) against the flat
//! solution of the box with every face subdivided 8 x 8 at order 2, visibility over 4 x 4 cells
//! per element (the reference the Cycles comparison stands in for here: within 0.21% of
//! the same solve on 12 x 12 faces).

use std::time::Instant;

use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
use galerkin_radiosity::scene::json::read_scene;
use galerkin_radiosity::scene::{Material, Object, Scene, Settings};
use galerkin_radiosity::scenes;
use galerkin_radiosity::system::{System, no_progress};

#[path = "common/child.rs"]
mod common_child;
#[path = "common/rss.rs"]
mod rss;
use rss::peak_rss_mib;

/// Per coarse face of `coarse`, the area-mean of `fine`'s solution over the fine faces whose
/// centre lies on it (same object, on its plane, inside its domain).
fn reference_means(coarse: &Scene, fine_sys: &System) -> Vec<f64> {
    let coarse_elems =
        galerkin_radiosity::system::build_elements(coarse, 0.0, galerkin_radiosity::basis::Basis::new(0));
    let mut acc = vec![(0.0, 0.0); coarse_elems.len()];
    for (i, e) in fine_sys.elements.iter().enumerate() {
        let c = e.patch.point(0.5, 0.5);
        let hit = coarse_elems.iter().position(|ce| {
            let (s, t) = ce.patch.locate(c);
            ce.object == e.object
                && (-1e-6..=1.0 + 1e-6).contains(&s)
                && (-1e-6..=1.0 + 1e-6).contains(&t)
                && ce.patch.point(s, t).distance(c) < 1e-6
        });
        if let Some(k) = hit {
            let m = fine_sys.mean(i);
            acc[k].0 += m.iter().copied().fold(0.0, f64::max) * e.area;
            acc[k].1 += e.area;
        }
    }
    acc.into_iter().map(|(p, a)| if a > 0.0 { p / a } else { f64::NAN }).collect()
}

/// Per face of `h`, its mean radiosity's largest channel.
fn face_means(h: &galerkin_radiosity::hierarchy::HierarchicalFrame) -> Vec<f64> {
    (0..h.hierarchy.tree.faces.len()).map(|f| h.face_mean(f).iter().copied().fold(0.0, f64::max)).collect()
}

fn relative_rms(got: &[f64], want: &[f64]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (g, w) in got.iter().zip(want) {
        if w.is_finite() && *w > 0.0 {
            num += (g - w).powi(2);
            den += w * w;
        }
    }
    (num / den).sqrt()
}

/// One case, in this (child) process: prints `seconds faces leaves links error` on one line.
fn run_case(case: &str, arg: &str) {
    match case {
        "cornell" => {
            // arg: accuracy
            let accuracy: f64 = arg.parse().unwrap();
            let settings = Settings { basis_order: 1, threads: 1, ..Default::default() };
            let coarse = scenes::cornell_box(1, settings.clone());
            let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            let hs = without_approximations(HierarchySettings { accuracy, ..Default::default() });
            let t = Instant::now();
            let h = pool.install(|| solve_frame(&coarse, 0.0, &hs, &no_progress).unwrap());
            let seconds = t.elapsed().as_secs_f64();
            let got = face_means(&h);
            // The solve's own peak, before the reference is built beside it.
            eprintln!("peak {}", peak_rss_mib());
            // Visibility over 4 x 4 cells per element: with 2 x 2 the reference leaks light under
            // the blocks (its floor 1.8% brighter); 8 x 8 faces with 4 x 4 cells are within
            // 0.21% of 12 x 12 faces with 4 x 4 (10 x 10: 0.14%).
            let fine = scenes::cornell_box(8, Settings { basis_order: 2, visibility_samples: 4, ..settings });
            let mut reference = System::build(&fine, 0.0, &no_progress).unwrap();
            reference.solve(1e-5, &|| false).unwrap();
            let mut want = reference_means(&coarse, &reference);
            // Lit faces only: the light's own exitance would dominate the norm.
            for (w, e) in want.iter_mut().zip(&h.hierarchy.tree.faces) {
                if coarse.materials[e.material as usize].emission.iter().any(|&x| x > 0.0) {
                    *w = f64::NAN;
                }
            }
            let error = relative_rms(&got, &want);
            println!("{seconds} {} {} {} {error}", h.stats.faces, h.stats.leaves, h.stats.links);
            return;
        }
        "presubdivided" => {
            let n: usize = arg.parse().unwrap();
            solve_and_report(&scenes::cornell_box(n, Settings { basis_order: 1, ..Default::default() }));
        }
        "scene" => {
            let mut scene = read_scene(std::path::Path::new(arg)).unwrap();
            scene.settings.basis_order = 1;
            solve_and_report(&scene);
        }
        "obj" => solve_and_report(&obj_under_a_light(arg)),
        "separation" => separation(arg.parse().unwrap()),
        "light" => light_links(arg),
        c => panic!("unknown case {c}"),
    }
    eprintln!("peak {}", peak_rss_mib());
}

/// `settings` with the approximations `GALERKIN_EXACT` names (comma-separated) turned off.
fn without_approximations(mut settings: HierarchySettings) -> HierarchySettings {
    let exact = std::env::var("GALERKIN_EXACT").unwrap_or_default();
    for name in exact.split(',').filter(|n| !n.is_empty()) {
        match name {
            "clusters" => settings.clusters = false,
            "light" => settings.light_links = false,
            "near" => settings.near = galerkin_radiosity::hierarchy::coupling::NearRule::Adaptive,
            other => panic!("GALERKIN_EXACT: unknown approximation {other} (clusters, light, near)"),
        }
    }
    settings
}

/// Solves `scene` on the hierarchy at its own settings and prints `seconds faces leaves links NaN`.
fn solve_and_report(scene: &Scene) {
    let t = Instant::now();
    let h = solve_frame(scene, 0.0, &HierarchySettings::of(&scene.settings), &no_progress).unwrap();
    let s = &h.stats;
    println!("{} {} {} {} NaN", t.elapsed().as_secs_f64(), s.faces, s.leaves, s.links);
    // Where the time went, for a run by hand (the table reads stdout only).
    eprintln!(
        "link s {:.1} (couplings {:.1}), solve s {:.1}, sweeps {}",
        s.link_seconds, s.compute_seconds, s.solve_seconds, s.sweeps
    );
}

/// How near a cluster may link (`HierarchySettings::cluster_separation = sep`): prints `seconds
/// links error box_mean box_worst`, with the decimated monastery's link-and-solve time (corner
/// gather off), its links and its per-face error against the same scene at separation 3 and
/// accuracy 2e-5, and a closed box's balance (`B = 2` on every face, rho 0.5, E 1): the mean
/// and the worst face's relative departure.
fn separation(sep: f64) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/real/monastery_scene.json");
    let mut scene = read_scene(std::path::Path::new(path)).unwrap();
    scene.settings.basis_order = 1;
    scene.settings.corner_gather = false;
    let hs = HierarchySettings { cluster_separation: sep, ..HierarchySettings::of(&scene.settings) };
    let t = Instant::now();
    let h = solve_frame(&scene, 0.0, &hs, &no_progress).unwrap();
    let seconds = t.elapsed().as_secs_f64();
    eprintln!("peak {}", peak_rss_mib());
    let fine = HierarchySettings { accuracy: 2e-5, cluster_separation: 3.0, light_links: false, ..hs };
    let reference = solve_frame(&scene, 0.0, &fine, &no_progress).unwrap();
    let mut want = face_means(&reference);
    for (w, e) in want.iter_mut().zip(&h.hierarchy.tree.faces) {
        if scene.materials[e.material as usize].emission.iter().any(|&x| x > 0.0) {
            *w = f64::NAN;
        }
    }
    let error = relative_rms(&face_means(&h), &want);
    let boxed = scenes::closed_box(4, 0.5, 1.0, Settings { basis_order: 1, ..Default::default() });
    let b = solve_frame(
        &boxed,
        0.0,
        &HierarchySettings { cluster_separation: sep, ..Default::default() },
        &no_progress,
    )
    .unwrap();
    let off: Vec<f64> = face_means(&b).iter().map(|v| v / 2.0 - 1.0).collect();
    let mean = off.iter().sum::<f64>() / off.len() as f64;
    let worst = off.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    println!("{seconds} {} {error} {mean} {worst}", h.stats.links);
}

/// Light links on or off (`arg`: `light:SOURCE` or `full:SOURCE`, SOURCE `decimated` for
/// tests/data/real's monastery or an OBJ as [`obj_under_a_light`] takes it): prints `seconds
/// cpu_seconds faces links light_links error`, the error (decimated only, else NaN) per face
/// against every link in full at accuracy 2e-5.
fn light_links(arg: &str) {
    let (mode, source) = arg.split_once(':').unwrap();
    let scene = if source == "decimated" {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/real/monastery_scene.json");
        let mut scene = read_scene(std::path::Path::new(path)).unwrap();
        scene.settings.basis_order = 1;
        scene.settings.corner_gather = false;
        scene
    } else {
        obj_under_a_light(source)
    };
    let hs = HierarchySettings { light_links: mode == "light", ..HierarchySettings::of(&scene.settings) };
    let (t, cpu) = (Instant::now(), cpu_seconds());
    let h = solve_frame(&scene, 0.0, &hs, &no_progress).unwrap();
    let (seconds, cpu) = (t.elapsed().as_secs_f64(), cpu_seconds() - cpu);
    eprintln!("peak {}", peak_rss_mib());
    let error = if source == "decimated" {
        let fine = HierarchySettings { accuracy: 2e-5, light_links: false, ..hs };
        let reference = solve_frame(&scene, 0.0, &fine, &no_progress).unwrap();
        let mut want = face_means(&reference);
        for (w, e) in want.iter_mut().zip(&h.hierarchy.tree.faces) {
            if scene.materials[e.material as usize].emission.iter().any(|&x| x > 0.0) {
                *w = f64::NAN;
            }
        }
        relative_rms(&face_means(&h), &want)
    } else {
        f64::NAN
    };
    let st = &h.stats;
    println!("{seconds} {cpu} {} {} {} {error}", st.faces, st.links, st.constant_links);
}

/// User and system CPU seconds of this process so far (`/proc/self/stat`, at 100 ticks a
/// second); NaN where `/proc` cannot tell. Beside the wall time: the machine is shared.
fn cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            // Fields after the command's closing parenthesis: utime and stime are the 12th and 13th.
            let rest = &s[s.rfind(')')? + 2..];
            let f: Vec<&str> = rest.split_whitespace().collect();
            Some((f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / 100.0)
        })
        .unwrap_or(f64::NAN)
}

/// An OBJ (`v` and `f` lines) on a ground, lit by an emissive square above it: order 1.
/// `PATH@F` keeps the faces whose centroid lies in the box of `F` times the model's half
/// extents around its centre, in both horizontal axes (a crop: `@0.22` keeps 9,950 of the full
/// monastery's triangles, `@0.3` 20,597, `@0.45` 43,085).
fn obj_under_a_light(arg: &str) -> Scene {
    use glam::DVec3;
    let (path, crop) = match arg.rsplit_once('@') {
        Some((p, f)) => (p, f.parse::<f64>().ok()),
        None => (arg, None),
    };
    let text = std::fs::read_to_string(path).unwrap();
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
    if let Some(f) = crop {
        let b = galerkin_radiosity::geometry::Aabb::from_points(&vertices);
        let (c, h) = (b.centre(), b.diagonal() * 0.5);
        faces.retain(|face: &Vec<u32>| {
            let m = face.iter().map(|&i| vertices[i as usize]).sum::<DVec3>() / face.len() as f64;
            (m.x - c.x).abs() <= f * h.x && (m.y - c.y).abs() <= f * h.y
        });
        let mut used = vec![u32::MAX; vertices.len()];
        let mut kept = Vec::new();
        for face in &mut faces {
            for i in face.iter_mut() {
                if used[*i as usize] == u32::MAX {
                    used[*i as usize] = kept.len() as u32;
                    kept.push(vertices[*i as usize]);
                }
                *i = used[*i as usize];
            }
        }
        vertices = kept;
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
        // The corner gather off, as the recorded full-monastery runs (docs/benchmarks.md) have it:
        // on, the gather alone ran for more than 28 minutes on 2 cores before it was stopped.
        Settings { basis_order: 1, corner_gather: false, ..Default::default() },
        (0, 0),
        materials,
        vec![Vec::new(); 2],
        objects,
    )
    .unwrap()
}

fn child(case: &str, arg: &str) -> Option<(Vec<f64>, f64)> {
    common_child::child(&["--case", case, arg])
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--case") {
        run_case(&args[i + 1], &args[i + 2]);
        return;
    }
    let quick = args.iter().any(|a| a == "--quick");
    // Each table after its caption: docs/benchmarks.md's "hierarchy-cornell",
    // "hierarchy-presubdivided" and "hierarchy-real" blocks (scripts/regenerate_docs.py).
    println!(
        "The Cornell box as modelled (16 faces), order 1, one thread; per-face error: relative RMS of \
         the per-face mean over lit faces against the flat solve of every face subdivided 8 x 8 at \
         order 2 with 4 x 4 visibility cells; peak RSS of the case's own process:\n"
    );
    println!("| accuracy | s | leaves | links | per-face error | peak RSS MiB |");
    println!("|---|---|---|---|---|---|");
    let accuracies: &[&str] =
        if quick { &["3e-3", "1e-3"] } else { &["1e-2", "3e-3", "1e-3", "3e-4", "1e-4"] };
    for a in accuracies {
        if let Some((v, peak)) = child("cornell", a) {
            println!("| {a} | {:.3} | {} | {} | {:.2}% | {peak:.0} |", v[0], v[2], v[3], 100.0 * v[4]);
        }
    }
    println!(
        "\nThe Cornell box pre-subdivided n x n per face, order 1, accuracy {:e} (the default), {} threads:\n",
        Settings::default().accuracy,
        rayon::current_num_threads()
    );
    println!("| n | faces | s | leaves | links | links per face | peak RSS MiB |");
    println!("|---|---|---|---|---|---|---|");
    let sizes: &[&str] = if quick { &["1", "4"] } else { &["1", "2", "4", "8"] };
    for n in sizes {
        if let Some((v, peak)) = child("presubdivided", n) {
            println!(
                "| {n} | {} | {:.3} | {} | {} | {:.1} | {peak:.0} |",
                v[1],
                v[0],
                v[2],
                v[3],
                v[3] / v[1]
            );
        }
    }
    println!(
        "\nReal meshes (tests/data/real), order 1, accuracy {:e} (the default), {} threads:\n",
        Settings::default().accuracy,
        rayon::current_num_threads()
    );
    println!("| scene | faces | s | leaves | links | peak RSS MiB |");
    println!("|---|---|---|---|---|---|");
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/real");
    // The reduced case keeps the bunny only: the monastery's corner gather takes about a minute,
    // most of the test suite's check that these rows are the document's.
    let real: &[(&str, &str)] = if quick {
        &[("bunny scene", "bunny_scene.json")]
    } else {
        &[
            ("monastery decimated (tests/data/real)", "monastery_scene.json"),
            ("bunny scene", "bunny_scene.json"),
        ]
    };
    for &(name, file) in real {
        if let Some((v, peak)) = child("scene", &format!("{dir}/{file}")) {
            println!("| {name} | {} | {:.2} | {} | {} | {peak:.0} |", v[1], v[0], v[2], v[3]);
        }
    }
    if let Ok(path) = std::env::var("GALERKIN_MONASTERY")
        && let Some((v, peak)) = child("obj", &path)
    {
        println!(
            "| monastery, full ({path}) + ground + light | {} | {:.2} | {} | {} | {peak:.0} |",
            v[1], v[0], v[2], v[3]
        );
    }
    println!(
        "\nHow near a cluster may link (`HierarchySettings::cluster_separation`, radii-sums): the \
         decimated monastery (tests/data/real, corner gather off), order 1, accuracy {:e}, {} \
         threads, per-face error against separation 3 at accuracy 2e-5; and a closed box (rho \
         0.5, E 1, B = 2 everywhere): its mean and worst face's departure from 2:\n",
        Settings::default().accuracy,
        rayon::current_num_threads()
    );
    println!("| separation | s | links | per-face error | box mean | box worst face | peak RSS MiB |");
    println!("|---|---|---|---|---|---|---|");
    let separations: &[&str] = if quick { &["3"] } else { &["3", "2.5", "2", "1.5"] };
    for sep in separations {
        if let Some((v, peak)) = child("separation", sep) {
            println!(
                "| {sep} | {:.2} | {} | {:.2}% | {:+.2}% | {:.2}% | {peak:.0} |",
                v[0],
                v[1],
                100.0 * v[2],
                100.0 * v[3],
                100.0 * v[4]
            );
        }
    }
    println!(
        "\nLight links (`HierarchySettings::light_links`: surface links that may carry at most \
         1/16 of the bar keep `G^00` alone, from 2 x 2 points and four segments), order 1, \
         accuracy {:e}, {} threads, corner gather off; per-face error against every link in full \
         at accuracy 2e-5 (the decimated monastery only); CPU seconds beside the wall time:\n",
        Settings::default().accuracy,
        rayon::current_num_threads()
    );
    println!("| scene, surface links | faces | s | CPU s | links | light | per-face error | peak RSS MiB |");
    println!("|---|---|---|---|---|---|---|---|");
    let mut sources = vec![("monastery decimated (tests/data/real)".to_string(), "decimated".to_string())];
    if let Ok(path) = std::env::var("GALERKIN_MONASTERY")
        && !quick
    {
        sources.push(("the monastery's centre, 0.22 of its half extents".into(), format!("{path}@0.22")));
        sources.push(("the monastery's centre, 0.3 of its half extents".into(), format!("{path}@0.3")));
    }
    for (name, source) in &sources {
        for mode in ["full", "light"] {
            if let Some((v, peak)) = child("light", &format!("{mode}:{source}")) {
                let error = if v[5].is_nan() { "-".to_string() } else { format!("{:.2}%", 100.0 * v[5]) };
                println!(
                    "| {name}, {mode} | {} | {:.2} | {:.2} | {} | {} | {error} | {peak:.0} |",
                    v[2], v[0], v[1], v[3], v[4]
                );
            }
        }
    }
}
