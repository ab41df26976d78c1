//! `galerkin-radiosity`: bake a scene file, or write the demo scene.
//!
//! ```text
//! galerkin-radiosity bake SCENE.json -o OUT.json [--frames A:B] [--full | --exact | --hierarchy] [--accuracy A] [--threads N] [--memory-budget MB] [--no-corner-gather] [--reflecting-backs] [--quiet]
//! galerkin-radiosity demo-scene -o SCENE.json [--frames N] [--subdiv N] [--order N]
//! ```
//! Exits 0 on success, 1 on any error with a one-line message on stderr, 2 on a usage error.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use galerkin_radiosity::progress::Lines;
use galerkin_radiosity::scene::json::{FrameResult, ResultFile, read_scene, scene_to_json};
use galerkin_radiosity::scene::{MAX_THREADS, Settings, check_animation, check_frames};
use galerkin_radiosity::scenes;
use galerkin_radiosity::session::{Method, Session};

const USAGE: &str = "usage:
  galerkin-radiosity bake SCENE.json -o OUT.json [--frames A:B] [--full | --exact | --hierarchy] [--accuracy A] [--threads N] [--memory-budget MB] [--no-corner-gather] [--reflecting-backs] [--quiet]
  galerkin-radiosity demo-scene -o SCENE.json [--kind cornell|cornell-light|room|billiard] [--frames N] [--subdiv N] [--order N]";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("bake") => bake(&args[1..]),
        Some("demo-scene") => demo_scene(&args[1..]),
        Some("-h" | "--help") => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        _ => Err(CliError::Usage("expected a command".into())),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(CliError::Usage(m)) => {
            eprintln!("galerkin-radiosity: {m}\n{USAGE}");
            ExitCode::from(2)
        }
        Err(CliError::Failed(m)) => {
            eprintln!("galerkin-radiosity: error: {m}");
            ExitCode::from(1)
        }
    }
}

enum CliError {
    Usage(String),
    Failed(String),
}

impl From<galerkin_radiosity::Error> for CliError {
    fn from(e: galerkin_radiosity::Error) -> Self {
        CliError::Failed(e.to_string())
    }
}

/// Pulls `--name VALUE` out of `args`.
fn take_value(args: &mut Vec<String>, names: &[&str]) -> Result<Option<String>, CliError> {
    match args.iter().position(|a| names.contains(&a.as_str())) {
        None => Ok(None),
        Some(i) if i + 1 < args.len() => {
            let v = args.remove(i + 1);
            args.remove(i);
            Ok(Some(v))
        }
        Some(i) => Err(CliError::Usage(format!("{} needs a value", args[i]))),
    }
}

fn take_flag(args: &mut Vec<String>, name: &str) -> bool {
    match args.iter().position(|a| a == name) {
        Some(i) => {
            args.remove(i);
            true
        }
        None => false,
    }
}

fn parse<T: std::str::FromStr>(v: &str, what: &str) -> Result<T, CliError> {
    v.parse().map_err(|_| CliError::Usage(format!("{what}: cannot parse {v:?}")))
}

fn bake(args: &[String]) -> Result<(), CliError> {
    let mut args = args.to_vec();
    let out = take_value(&mut args, &["-o", "--output"])?
        .ok_or_else(|| CliError::Usage("bake needs -o OUT.json".into()))?;
    let frames = take_value(&mut args, &["--frames"])?;
    let threads = take_value(&mut args, &["--threads"])?;
    let budget: Option<u64> =
        take_value(&mut args, &["--memory-budget"])?.map(|v| parse(&v, "--memory-budget")).transpose()?;
    let accuracy: Option<f64> =
        take_value(&mut args, &["--accuracy"])?.map(|v| parse(&v, "--accuracy")).transpose()?;
    let hierarchy = take_flag(&mut args, "--hierarchy");
    let full = take_flag(&mut args, "--full");
    let exact = take_flag(&mut args, "--exact");
    let quiet = take_flag(&mut args, "--quiet");
    let no_gather = take_flag(&mut args, "--no-corner-gather");
    let backs = take_flag(&mut args, "--reflecting-backs");
    if [full, exact, hierarchy].iter().filter(|&&x| x).count() > 1 {
        return Err(CliError::Usage("--full, --exact and --hierarchy exclude each other".into()));
    }
    let [input] = args.as_slice() else {
        return Err(CliError::Usage(format!("bake takes one scene file, got {args:?}")));
    };
    let partial = writable_output(&out)?;
    let method = if hierarchy {
        Method::Hierarchical
    } else if full {
        Method::Full
    } else if exact {
        Method::Exact
    } else {
        Method::Incremental
    };
    let result = bake_into(
        input,
        &out,
        partial.as_deref(),
        (frames, threads, budget, accuracy),
        (method, quiet, no_gather, backs),
    );
    if let Some(partial) = &partial {
        let _ = std::fs::remove_file(partial);
    }
    result
}

/// The file a bake writes before renaming it to `out` (so a failed bake leaves `out` as it was),
/// created now: a missing folder or one that cannot be written to is an error before any work.
/// `None` when `out` exists and is not a regular file (`/dev/null`, a pipe): it is written to
/// directly, since a rename would replace the device or pipe with a file.
fn writable_output(out: &str) -> Result<Option<PathBuf>, CliError> {
    let path = Path::new(out);
    if std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
        return Ok(None);
    }
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !folder.is_dir() {
        return Err(CliError::Failed(format!("{out}: the folder {} does not exist", folder.display())));
    }
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    let partial = folder.join(name);
    std::fs::File::create(&partial)
        .map_err(|e| CliError::Failed(format!("{out}: cannot write there: {e}")))?;
    Ok(Some(partial))
}

/// A flat bake of this many faces or more is told of `--hierarchy` (the add-on's
/// `LARGE_FLAT_FACES`: on a 2,407-face room the flat Update took 26 s and 3.1 GB, the hierarchy
/// 6.6 s and 50 MB).
const LARGE_FLAT_FACES: usize = 2000;

/// A flat bake refused for its memory: the same line, and `--hierarchy` named when its own
/// estimate is within the budget (the flat links grow with the square of the faces, the
/// hierarchy's about linearly, so a scene too large for one often fits the other).
fn suggest_hierarchy(
    e: galerkin_radiosity::Error,
    scene: &galerkin_radiosity::scene::Scene,
    kept: u64,
) -> CliError {
    use galerkin_radiosity::{Error, budget};
    match e {
        Error::OverBudget(m) if budget::check_hierarchical(scene, kept).is_ok() => {
            let mb = budget::hierarchical_estimate(scene, kept).total().div_ceil(1 << 20);
            CliError::Failed(
                Error::OverBudget(format!("{m}; or bake with --hierarchy, which plans for {mb} MB here"))
                    .to_string(),
            )
        }
        e => e.into(),
    }
}

fn bake_into(
    input: &str,
    out: &str,
    partial: Option<&Path>,
    (frames, threads, budget, accuracy): (Option<String>, Option<String>, Option<u64>, Option<f64>),
    (method, quiet, no_gather, backs): (Method, bool, bool, bool),
) -> Result<(), CliError> {
    let mut scene = read_scene(&PathBuf::from(input))?;
    if let Some(a) = accuracy {
        if !(a.is_finite() && a > 0.0 && a < 1.0) {
            return Err(CliError::Usage(format!("--accuracy {a} is outside (0,1)")));
        }
        scene.settings.accuracy = a;
    }
    if let Some(t) = threads {
        let n: usize = parse(&t, "--threads")?;
        if n > MAX_THREADS {
            return Err(CliError::Usage(format!("--threads {n} is above {MAX_THREADS}")));
        }
        scene.settings.threads = n;
    }
    if no_gather {
        scene.settings.corner_gather = false;
    }
    if backs {
        scene.settings.reflecting_backs = true;
    }
    if let Some(mb) = budget {
        scene.settings.memory_budget_mb = mb;
    }
    let (first, last) = match frames {
        None => scene.frames,
        Some(r) => {
            let (a, b) =
                r.split_once(':').ok_or_else(|| CliError::Usage(format!("--frames wants A:B, got {r:?}")))?;
            let (a, b): (i64, i64) = (parse(a, "--frames")?, parse(b, "--frames")?);
            check_frames((a, b)).map_err(|m| CliError::Usage(format!("--{m}")))?;
            (a, b)
        }
    };
    if !scene.degenerate_faces.is_empty() && !quiet {
        let (o, f) = scene.degenerate_faces[0];
        eprintln!(
            "warning: {} zero-area face(s) skipped (first: object \"{}\" face {f}); they report their own exitance",
            scene.degenerate_faces.len(),
            scene.objects[o].name
        );
    }
    // Every frame's placement, before the first is baked (the session checks each again).
    check_animation(&scene, (first, last))?;
    // Every frame's results are kept until the file is written.
    let kept = (last - first + 1) as u64;
    if method == Method::Hierarchical {
        galerkin_radiosity::budget::check_hierarchical(&scene, kept)?;
    } else {
        galerkin_radiosity::budget::check(&scene, kept).map_err(|e| suggest_hierarchy(e, &scene, kept))?;
        if scene.face_count() >= LARGE_FLAT_FACES && !quiet {
            eprintln!(
                "warning: {} faces: the flat methods link every pair of faces, so their memory and time grow \
                 with the square of the face count; --hierarchy grows about linearly",
                scene.face_count()
            );
        }
    }
    let gathers = scene.settings.corner_gather;
    let mut session = Session::new(scene, method)?;
    // One frame baked: nothing moves after it.
    if first == last {
        session.set_still();
    }
    let start = Instant::now();
    let mut frames_out = Vec::new();
    let total = (last - first + 1) as usize;
    // A line a second (galerkin_radiosity::progress: monotone, with the time spent and left):
    // from the session's callbacks, which come every few ms, and from a heartbeat thread that
    // repeats the line while they are silent (one slow link or corner of a 125k-face scene).
    let lines = Mutex::new(Lines::new(total, Duration::from_secs(1)).gathering(gathers));
    let done = AtomicBool::new(false);
    std::thread::scope(|scope| -> Result<(), CliError> {
        if !quiet {
            scope.spawn(|| {
                while !done.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(100));
                    if let Some(line) = lines.lock().unwrap().line(Instant::now(), None) {
                        eprintln!("{line}");
                    }
                }
            });
        }
        let solved = (|| {
            for (k, frame) in (first..=last).enumerate() {
                let progress = |fraction: f64, stage: &str| {
                    let mut lines = lines.lock().unwrap();
                    let now = Instant::now();
                    lines.meter.report(fraction, stage, now);
                    let running = format!("frame {frame} ({}/{total}): {stage}", k + 1);
                    if let Some(line) = lines.line(now, Some(running)).filter(|_| !quiet) {
                        eprintln!("{line}");
                    }
                    true
                };
                let stats = session.solve_frame(frame as f64, &progress)?;
                lines.lock().unwrap().frame_done(Instant::now());
                if !quiet {
                    eprintln!(
                        "frame {frame} ({}/{total}): {:.3} s, {} links ({} by series, {} recomputed), {} shots",
                        k + 1,
                        stats.seconds,
                        stats.pairs,
                        stats.links_series,
                        stats.links_recomputed,
                        stats.shots
                    );
                }
                frames_out.push(FrameResult {
                    frame,
                    objects: session.face_results()?,
                    stats: serde_json::to_value(&stats).expect("stats serialize"),
                });
            }
            Ok::<(), CliError>(())
        })();
        done.store(true, Ordering::Relaxed);
        solved
    })?;
    let result = ResultFile {
        frames: frames_out,
        stats: serde_json::json!({
            "seconds": start.elapsed().as_secs_f64(),
            "frames": total,
            "method": method,
        }),
    };
    let text =
        serde_json::to_string(&result).map_err(|e| CliError::Failed(format!("writing result: {e}")))?;
    let failed = |e: std::io::Error| CliError::Failed(format!("{out}: {e}"));
    match partial {
        Some(partial) => {
            std::fs::write(partial, text).map_err(failed)?;
            std::fs::rename(partial, out).map_err(failed)?;
        }
        None => std::fs::write(out, text).map_err(failed)?,
    }
    if !quiet {
        eprintln!("wrote {out}: {total} frame(s) in {:.2} s", start.elapsed().as_secs_f64());
    }
    Ok(())
}

fn demo_scene(args: &[String]) -> Result<(), CliError> {
    let mut args = args.to_vec();
    let out = take_value(&mut args, &["-o", "--output"])?
        .ok_or_else(|| CliError::Usage("demo-scene needs -o SCENE.json".into()))?;
    let frames: i64 =
        take_value(&mut args, &["--frames"])?.map(|v| parse(&v, "--frames")).transpose()?.unwrap_or(48);
    let subdiv: usize =
        take_value(&mut args, &["--subdiv"])?.map(|v| parse(&v, "--subdiv")).transpose()?.unwrap_or(8);
    let order: usize =
        take_value(&mut args, &["--order"])?.map(|v| parse(&v, "--order")).transpose()?.unwrap_or(2);
    let kind = take_value(&mut args, &["--kind"])?.unwrap_or_else(|| "cornell".into());
    if !args.is_empty() {
        return Err(CliError::Usage(format!("unexpected arguments {args:?}")));
    }
    if frames < 1 || !(1..=64).contains(&subdiv) || order > 3 {
        return Err(CliError::Usage("--frames >= 1, --subdiv in 1..=64, --order in 0..=3".into()));
    }
    let settings = Settings { basis_order: order, ..Settings::default() };
    // For room and billiard, --subdiv is patches per metre of wall.
    let scene = match kind.as_str() {
        "cornell" => scenes::cornell_box_animated(subdiv, frames, settings),
        "cornell-light" => scenes::cornell_box_moving_light(subdiv, frames, settings),
        "room" => scenes::seed_room(subdiv as f64, frames, settings),
        "billiard" => scenes::billiard(subdiv as f64, frames, settings),
        k => return Err(CliError::Usage(format!("--kind {k:?}: cornell, cornell-light, room or billiard"))),
    };
    std::fs::write(&out, scene_to_json(&scene)).map_err(|e| CliError::Failed(format!("{out}: {e}")))?;
    eprintln!("wrote {out}: {} faces, {frames} frames", scene.face_count());
    Ok(())
}
