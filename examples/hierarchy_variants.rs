//! One frame through the hierarchy with its settings overridden, for measuring what a setting
//! does to accuracy and cost: `cargo run --release --example hierarchy_variants SCENE.json|MODEL.obj
//! [accuracy=A] [clusters=0|1] [light=0|1] [sep=S] [depth=D] [rounds=R] [gather=1] [flat=1]`.
//!
//! An OBJ is placed on a ground under a light as the benches place it (order 1). Prints the time,
//! the links and the peak RSS on stderr, and on stdout either the faces' mean radiosity per
//! object (`[[name, [B per face]], ...]`, the three channels' mean) or, with `gather=1`, the
//! corners in the CLI's output format (`{"frames": [{"objects": [{"name", "corner_radiosity"}]}]}`,
//! which `tools.compare_ref` reads against a Cycles reference). With `flat=1` it also solves the
//! flat system of the same scene and prints each object's mean face radiosity over the flat
//! solve's, with the smallest and largest face's ratio, on stderr. docs/benchmarks.md, "The
//! hierarchy's rooms: where the rest of the error is", was measured with it.

use galerkin_radiosity::hierarchy::{HierarchySettings, solve_frame};
use galerkin_radiosity::scene::json::read_scene;
use galerkin_radiosity::system::{System, no_progress};

#[path = "../benches/common/obj.rs"]
mod obj;
#[path = "../benches/common/rss.rs"]
mod rss;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: hierarchy_variants SCENE.json|MODEL.obj [key=value ...]");
        std::process::exit(2);
    };
    let mut scene = if path.ends_with(".obj") {
        obj::obj_under_a_light(path, false)
    } else {
        read_scene(std::path::Path::new(path)).unwrap_or_else(|e| panic!("{path}: {e}"))
    };
    let gather = args.iter().any(|a| a == "gather=1");
    scene.settings.corner_gather = gather;
    let mut hs = HierarchySettings::of(&scene.settings);
    for a in &args[2..] {
        let (key, value) = a.split_once('=').unwrap_or_else(|| panic!("{a}: want key=value"));
        let number = || value.parse::<f64>().unwrap_or_else(|_| panic!("{a}: not a number"));
        match key {
            "accuracy" => hs.accuracy = number(),
            "clusters" => hs.clusters = value == "1",
            "light" => hs.light_links = value == "1",
            "sep" => hs.cluster_separation = number(),
            "depth" => hs.max_depth = number() as u32,
            "rounds" => hs.rounds = number() as usize,
            "gather" | "flat" => {}
            _ => panic!("{key}: unknown setting"),
        }
    }
    hs.corner_gather = gather;
    let t = std::time::Instant::now();
    let h = solve_frame(&scene, 0.0, &hs, &no_progress).unwrap();
    eprintln!(
        "{:.2} s (links {:.2} s, gather {:.2} s); {} links, {} of them cluster links; peak {:.0} MiB",
        t.elapsed().as_secs_f64(),
        h.stats.link_seconds,
        h.stats.gather_seconds,
        h.stats.links,
        h.stats.cluster_links,
        rss::peak_rss_mib()
    );
    let results = h.face_results(&scene, 0.0);
    if args.iter().any(|a| a == "flat=1") {
        let mut flat = System::build(&scene, 0.0, &no_progress).unwrap();
        flat.solve(scene.settings.tolerance, &|| false).unwrap();
        let lum = |v: &[f32; 3]| (v[0] + v[1] + v[2]) as f64 / 3.0;
        for (got, want) in results.iter().zip(flat.face_results(&scene, 0.0).iter()) {
            let ratios: Vec<f64> =
                got.face_radiosity.iter().zip(&want.face_radiosity).map(|(a, b)| lum(a) / lum(b)).collect();
            let mean = |o: &galerkin_radiosity::scene::json::ObjectResult| {
                o.face_radiosity.iter().map(lum).sum::<f64>() / o.face_radiosity.len().max(1) as f64
            };
            let (lo, hi) = ratios.iter().fold((f64::INFINITY, 0.0f64), |(l, h), &r| (l.min(r), h.max(r)));
            eprintln!(
                "{}: mean {:.4} of the flat solve's, faces {lo:.3} to {hi:.3}",
                got.name,
                mean(got) / mean(want)
            );
        }
    }
    let out = if gather {
        let objects: Vec<serde_json::Value> = results
            .iter()
            .map(|o| serde_json::json!({"name": o.name, "corner_radiosity": o.corner_radiosity}))
            .collect();
        serde_json::json!({"frames": [{"objects": objects}]})
    } else {
        let mean = |v: &[f32; 3]| (v[0] + v[1] + v[2]) as f64 / 3.0;
        serde_json::json!(
            results
                .iter()
                .map(|o| (o.name.clone(), o.face_radiosity.iter().map(mean).collect::<Vec<f64>>()))
                .collect::<Vec<_>>()
        )
    };
    println!("{out}");
}
