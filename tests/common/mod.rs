//! Helpers shared by the animation tests: comparing link stores pair by pair.

use std::collections::HashMap;

use galerkin_radiosity::links::LinkStore;

/// Both blocks of every pair with a non-zero kernel, by (min, max) element.
pub fn blocks(links: &LinkStore) -> HashMap<(u32, u32), Vec<f32>> {
    let mut out = HashMap::new();
    for p in 0..links.len() as u32 {
        let pair = links.pair(p);
        let (a, b) = (pair.a.min(pair.b), pair.a.max(pair.b));
        let v: Vec<f32> = links.block(p, a).into_iter().chain(links.block(p, b)).collect();
        if v.iter().any(|&x| x != 0.0) {
            out.insert((a, b), v);
        }
    }
    out
}

/// The largest of `a` and `b`, a NaN counting as larger than anything (a NaN must fail a bound).
pub fn worse(a: f32, b: f32) -> f32 {
    if b > a || b.is_nan() { b } else { a }
}

/// The worst block entry of `got` off `want` (pairs missing from one side count as zero),
/// relative to `want`'s peak block entry, and the pair where it is.
pub fn link_difference(got: &LinkStore, want: &LinkStore) -> (f32, (u32, u32)) {
    let (got, want) = (blocks(got), blocks(want));
    let peak = want.values().flatten().fold(0.0f32, |m, x| m.max(x.abs()));
    let Some(len) = want.values().chain(got.values()).next().map(Vec::len) else {
        return (0.0, (0, 0));
    };
    let zeros = vec![0.0f32; len];
    let mut worst = (0.0f32, (0, 0));
    for key in got.keys().chain(want.keys()) {
        let (g, w) = (got.get(key).unwrap_or(&zeros), want.get(key).unwrap_or(&zeros));
        let d = g.iter().zip(w).map(|(x, y)| (x - y).abs()).fold(0.0f32, worse);
        if worse(worst.0, d) != worst.0 {
            worst = (d, *key);
        }
    }
    (worst.0 / peak.max(f32::MIN_POSITIVE), worst.1)
}
