//! A corner point's value from its row once the solution is known: the dot products of its
//! moments with the sources' coefficients, the feet's light, the hemisphere bound, and
//! `B = E + rho H`.

use super::Row;
use crate::system::System;

/// `B = E_i + rho_i sum_j sum_l m_j^l b_j^l` at a point of element `i`.
fn radiosity(sys: &System, i: usize, row: &Row) -> [f64; 3] {
    let [irradiance] = source_irradiance(sys, [row]);
    finish(sys, i, row, irradiance)
}

/// `sum_j sum_l m_j^l b_j^l` of each of `K` rows, each summed in its own order (sources, then
/// basis functions), the rows interleaved so that their chains of additions overlap.
pub(super) fn source_irradiance<const K: usize>(sys: &System, rows: [&Row; K]) -> [[f64; 3]; K] {
    let nb = sys.basis.len();
    let b = &sys.solution.b;
    let mut irradiance = [[0.0; 3]; K];
    let add = |irradiance: &mut [f64; 3], row: &Row, k: usize| {
        let m = &row.moments[k * nb..(k + 1) * nb];
        let j = row.sources[k] as usize;
        let (b, w) = (&b[j * nb..(j + 1) * nb], sys.source_weights[j]);
        for l in 0..nb {
            for c in 0..3 {
                irradiance[c] += w * m[l] as f64 * b[l][c];
            }
        }
    };
    let common = rows.iter().map(|r| r.sources.len()).min().unwrap_or(0);
    for k in 0..common {
        for (irradiance, row) in irradiance.iter_mut().zip(rows) {
            add(irradiance, row, k);
        }
    }
    for (irradiance, row) in irradiance.iter_mut().zip(rows) {
        for k in common..row.sources.len() {
            add(irradiance, row, k);
        }
    }
    irradiance
}

/// [`radiosity`] from the sources' part of the irradiance: the feet's added, bounded by the
/// point's hemisphere, then `E + rho` times it.
fn finish(sys: &System, i: usize, row: &Row, irradiance: [f64; 3]) -> [f64; 3] {
    let nb = sys.basis.len();
    let irradiance = received(sys, row, irradiance);
    let (rho, e) = (sys.surface_reflectance[i], sys.emission[i * nb]);
    std::array::from_fn(|c| e[c] + rho[c] * irradiance[c])
}

/// The irradiance `H` a point receives from the surfaces (the lights' direct light is added
/// apart), from the sources' part: the feet's added, bounded by the point's hemisphere.
/// [`finish`] makes `B = E + rho H` of it.
pub(super) fn received(sys: &System, row: &Row, mut irradiance: [f64; 3]) -> [f64; 3] {
    for foot in &row.feet {
        let mut b = [radiosity(sys, foot.element as usize, &foot.row)];
        sys.add_direct_light(
            std::iter::once(Some(((foot.element as usize, foot.at.0, foot.at.1), None))),
            &mut b,
        );
        let [b] = b;
        let w = foot.weight as f64 * sys.source_weights[foot.element as usize];
        for c in 0..3 {
            irradiance[c] += w * b[c];
        }
    }
    let bound = if sys.corner_bound { crate::hemisphere::bound(form_factor_sum(sys, row)) } else { 1.0 };
    irradiance.map(|x| bound * x)
}

/// The point's form factors summed over its sources (`m_j^0`, `Gamma_0 = 1`) and feet, each
/// with its source weight: at most 1 for a point that sees its hemisphere ([`crate::hemisphere`]).
fn form_factor_sum(sys: &System, row: &Row) -> f64 {
    let nb = sys.basis.len();
    let w = &sys.source_weights;
    let sources: f64 =
        row.moments.iter().step_by(nb).zip(&row.sources).map(|(&m, &j)| m as f64 * w[j as usize]).sum();
    sources + row.feet.iter().map(|f| f.weight as f64 * w[f.element as usize]).sum::<f64>()
}
