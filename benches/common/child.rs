//! Shared by the benches: a case run in a child process of the bench's own binary, so that its
//! peak RSS is its own.

use std::process::Command;

/// Runs this binary with `args`; returns the numbers of its stdout's line and the `peak N` its
/// stderr reports (NaN if none), or `None` (with the child's stderr printed) when it failed.
pub fn child(args: &[&str]) -> Option<(Vec<f64>, f64)> {
    let out = Command::new(std::env::current_exe().unwrap()).args(args).output().ok()?;
    if !out.status.success() {
        eprintln!("{}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr));
        return None;
    }
    let line = String::from_utf8_lossy(&out.stdout);
    let v: Vec<f64> = line.split_whitespace().map(|x| x.parse().unwrap_or(f64::NAN)).collect();
    let err = String::from_utf8_lossy(&out.stderr);
    let peak =
        err.lines().find_map(|l| l.strip_prefix("peak ")).and_then(|x| x.parse().ok()).unwrap_or(f64::NAN);
    Some((v, peak))
}
