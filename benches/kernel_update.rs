//! The kernel update of the animation (everything in `animation::advance` before the solve) on
//! the moving-light Cornell box of issue 3: `cargo bench --bench kernel_update [-- OPTIONS]`.
//!
//! Options: `--frames N` (default 16), `--subdiv N` (default 14: 1,079 patches), `--demo` (the
//! demo animation instead: light and short block moving), `--room` / `--billiard` (the seed's
//! Fig. 5a and 5b scenes as `cargo bench --bench animation` builds them), `--exact`
//! (no series), `--reasons` (per frame, why pairs were recomputed), `--threads N` (default: one
//! per core), `--gather` (also the corner gather after each frame, as a session with
//! `corner_gather` on runs it: its time, moments held and moments recomputed), `--save PATH` /
//! `--check PATH` (write, or compare against, every frame's link store and solution, and with
//! `--gather` its corners: the link store must match bit for bit, the solution and the corners
//! within 1e-6 of peak), `--tolerance T` (the solve's, default 1e-4; a host's preview frame is
//! solved to 1e-3, `session::preview_tolerance`), `--order N` (the basis order, default 2),
//! `--fixed-rule` (adaptive quadrature off: every pair on the full rule, where the series pays).
//!
//! Prints per frame `kernel_seconds` and the counts that do not depend on timing noise (pairs
//! whose shafts were tested against the swept box, link visibility checks, segments tested).

use std::collections::BTreeMap;
use std::io::Write;

use galerkin_radiosity::animation::{self, AnimationState, Outcome};
use galerkin_radiosity::gather::GatherStats;
use galerkin_radiosity::scene::Settings;
use galerkin_radiosity::scenes;
use galerkin_radiosity::system::{System, no_progress};

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter().position(|a| a == name).and_then(|k| args.get(k + 1).cloned())
}

/// Every stored pair by `(min, max)` element: visibility and both blocks' f32 bits (oriented
/// from the smaller element), so stores built in different pair orders compare equal.
fn link_snapshot(sys: &System) -> BTreeMap<(u32, u32), Vec<u32>> {
    let links = &sys.links;
    let mut out = BTreeMap::new();
    for p in 0..links.len() as u32 {
        let pair = links.pair(p);
        let (a, b) = (pair.a.min(pair.b), pair.a.max(pair.b));
        let mut v: Vec<u32> =
            links.block(p, a).iter().chain(links.block(p, b).iter()).map(|x| x.to_bits()).collect();
        v.push(match &pair.visibility {
            galerkin_radiosity::visibility::Visibility::Full => 1,
            galerkin_radiosity::visibility::Visibility::Blocked => 0,
            galerkin_radiosity::visibility::Visibility::Partial(bits) => {
                bits.iter().fold(2u32, |h, w| h.wrapping_mul(31).wrapping_add((w ^ (w >> 32)) as u32))
            }
        });
        // A pair emptied to zero is the same as no pair.
        if v[..v.len() - 1].iter().any(|&x| f32::from_bits(x) != 0.0) {
            out.insert((a, b), v);
        }
    }
    out
}

fn hash(words: impl Iterator<Item = u64>) -> u64 {
    words.fold(0xcbf29ce484222325u64, |h, w| (h ^ w).wrapping_mul(0x100000001b3))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let frames: i64 = arg(&args, "--frames").map_or(16, |v| v.parse().unwrap());
    let subdiv: usize = arg(&args, "--subdiv").map_or(14, |v| v.parse().unwrap());
    let exact = args.iter().any(|a| a == "--exact");
    let save = arg(&args, "--save");
    let check = arg(&args, "--check");
    let threads: usize = arg(&args, "--threads").map_or(0, |v| v.parse().unwrap());
    let tolerance: f64 =
        arg(&args, "--tolerance").map_or(Settings::default().tolerance, |v| v.parse().unwrap());
    let basis_order: usize = arg(&args, "--order").map_or(2, |v| v.parse().unwrap());
    let flag = |name: &str| args.iter().any(|a| a == name);
    let settings = Settings {
        basis_order,
        corner_gather: false,
        threads,
        tolerance,
        adaptive_quadrature: !flag("--fixed-rule"),
        ..Settings::default()
    };
    let scene = if flag("--demo") {
        scenes::cornell_box_animated(subdiv, 48, settings)
    } else if flag("--room") {
        scenes::seed_room(3.0, 48, settings)
    } else if flag("--billiard") {
        scenes::billiard(2.5, 48, settings)
    } else {
        scenes::cornell_box_moving_light(subdiv, 48, settings)
    };
    let reasons = flag("--reasons");
    let gather = flag("--gather");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(scene.settings.threads).build().unwrap();
    pool.install(|| {
        let mut sys = System::build(&scene, 1.0, &no_progress).unwrap();
        sys.solve(scene.settings.tolerance, &|| false).unwrap();
        if gather {
            sys.gather_corners(&scene, 1.0, &no_progress).unwrap();
        }
        let mut state = AnimationState::new(sys.elements.len(), !exact);
        // Per frame: link hash, then the solution's coefficients.
        let mut record: Vec<(u64, Vec<f64>)> = Vec::new();
        println!(
            "{} patches, method {}, {} threads",
            sys.elements.len(),
            if exact { "exact" } else { "series" },
            rayon::current_num_threads()
        );
        // Columns: the update's time and its parts, the solve, then counts that do not depend on
        // timing noise.
        let columns = |u: &animation::UpdateStats, g: &(f64, GatherStats)| -> [(&str, f64); 18] {
            [
                ("kernel s", u.kernel_seconds),
                ("scan s", u.scan_seconds),
                ("pairs s", u.pairs_seconds),
                ("apply s", u.apply_seconds),
                ("solve s", u.solve_seconds),
                ("shaft tests", u.shaft_tests as f64),
                ("candidates", u.candidates as f64),
                ("vis checks", u.visibility_checks as f64),
                ("relinked", u.visibility_relinked as f64),
                ("segments", u.segments_tested as f64),
                ("recomputed", u.links_recomputed as f64),
                ("series", u.links_series as f64),
                ("series terms", u.series_terms as f64),
                ("shots", u.shots as f64),
                ("replayed", u.replay_scale),
                ("gather s", g.0),
                ("moments", g.1.moments as f64),
                ("moments recomputed", g.1.recomputed as f64),
            ]
        };
        let row = |label: String, values: &[f64]| {
            let cells: Vec<String> = values
                .iter()
                .enumerate()
                .map(|(k, v)| if k < 5 || k == 14 || k == 15 { format!("{v:.4}") } else { format!("{v:.0}") })
                .collect();
            println!("| {label} | {} |", cells.join(" | "));
        };
        let names = columns(&Default::default(), &Default::default()).map(|(name, _)| name);
        println!("| frame | {} |", names.join(" | "));
        println!("|---{}|", "|---".repeat(names.len()));
        let mut sums = [0.0f64; 18];
        for f in 2..=frames {
            let Outcome::Updated(u) =
                animation::advance(&mut sys, &mut state, &scene, f as f64, &no_progress).unwrap()
            else {
                panic!("topology changed")
            };
            let g = if gather {
                let start = std::time::Instant::now();
                let g = sys.gather_corners(&scene, f as f64, &no_progress).unwrap();
                (start.elapsed().as_secs_f64(), g)
            } else {
                Default::default()
            };
            let values = columns(&u, &g).map(|(_, v)| v);
            if reasons {
                println!(
                    "frame {f} recomputed: bound {}, direction {}, half-space {}, visibility {}, \
                     non-translation {}, translation {}; expanded {}",
                    u.recomputed_bound,
                    u.recomputed_direction,
                    u.recomputed_half_space,
                    u.recomputed_visibility,
                    u.recomputed_non_translation,
                    u.recomputed_translation,
                    u.series_expanded
                );
            }
            row(f.to_string(), &values);
            for (s, x) in sums.iter_mut().zip(values) {
                *s += x;
            }
            if save.is_some() || check.is_some() {
                let snap = link_snapshot(&sys);
                let h = hash(snap.iter().flat_map(|(&(a, b), v)| {
                    std::iter::once(((a as u64) << 32) | b as u64).chain(v.iter().map(|&x| x as u64))
                }));
                let mut b: Vec<f64> = sys.solution.b.iter().flat_map(|c| c.iter().copied()).collect();
                // The corners follow the solution in the record, in their own peak.
                if let Some(corners) = &sys.corners {
                    b.push(f64::NAN);
                    b.extend(corners.iter().flatten().flatten());
                }
                record.push((h, b));
            }
        }
        let n = (frames - 1).max(1) as f64;
        row("mean".into(), &sums.map(|x| x / n));
        if let Some(path) = save {
            let mut f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
            for (h, b) in &record {
                writeln!(f, "{h} {}", b.iter().map(|x| format!("{:e}", x)).collect::<Vec<_>>().join(" "))
                    .unwrap();
            }
            println!("saved {path}");
        }
        if let Some(path) = check {
            let text = std::fs::read_to_string(&path).unwrap();
            for (k, (line, (h, b))) in text.lines().zip(&record).enumerate() {
                let mut words = line.split(' ');
                let want_h: u64 = words.next().unwrap().parse().unwrap();
                let want: Vec<f64> = words.map(|w| w.parse().unwrap()).collect();
                // Worst difference relative to the peak, per part (solution, then corners).
                let worst = |want: &[f64], got: &[f64]| {
                    let peak = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                    want.iter().zip(got).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max) / peak
                };
                let split = |v: &[f64]| {
                    let k = v.iter().position(|x| x.is_nan()).unwrap_or(v.len());
                    (v[..k].to_vec(), v.get(k + 1..).unwrap_or_default().to_vec())
                };
                let ((want_b, want_c), (got_b, got_c)) = (split(&want), split(b));
                let corners = if want_c.is_empty() && got_c.is_empty() {
                    String::new()
                } else if want_c.len() != got_c.len() {
                    ", corners DIFFER in number".into()
                } else {
                    format!(", corners worst {:.1e} of peak", worst(&want_c, &got_c))
                };
                println!(
                    "frame {}: links {}, solution worst {:.1e} of peak{corners}",
                    k + 2,
                    if want_h == *h { "identical" } else { "DIFFER" },
                    worst(&want_b, &got_b)
                );
            }
        }
    });
}
