//! Frame-to-frame update of a solved system (seed, sections 3.1, 3.3 and 3.4).
//!
//! Each new frame: place the elements, find the links whose kernel changed, recompute them,
//! and turn the change into initial unshot energy, eq. (9):
//! `Delta b_i = Delta e_i + sum_j Delta K_ij b_j + sum_j (K_ij + Delta K_ij) Delta b_j`,
//! so `unshot = Delta e + Delta K b` (with the previous frame's `b`) and progressive shooting with
//! the new kernel propagates the rest, starting from the previous solution.
//!
//! Links that change: every pair with a moved element, and every pair of static elements whose
//! shaft the moving elements' swept bounds (old and new positions) may enter or leave: the
//! visibility changes the seed left to a separate shadow algorithm (issue 3, item 4).

use rayon::prelude::*;

use crate::basis::Basis;
use crate::error::{Error, Result};
use crate::geometry::{Aabb, Patch};
use crate::kernel::PairContext;
use crate::kernel::assemble::{ElementGeometry, compute_pair};
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::solver;
use crate::system::{Progress, System, build_elements};
use crate::visibility::shaft::Shaft;
use crate::visibility::{Occluders, Visibility};

/// What one update did.
#[derive(Clone, Debug, Default)]
pub struct UpdateStats {
    pub moved_elements: usize,
    pub links_recomputed: usize,
    /// Static pairs re-examined because a moving element's swept bounds cross their shaft.
    pub recomputed_visibility: usize,
    /// Pairs with a moved element, by how it moved.
    pub recomputed_translation: usize,
    pub recomputed_non_translation: usize,
    pub kernel_seconds: f64,
    pub solve_seconds: f64,
    pub shots: usize,
}

/// Why an update cannot proceed and the frame must be rebuilt from scratch.
pub enum Outcome {
    Updated(UpdateStats),
    /// Topology changed (faces appeared, vanished or became degenerate).
    NeedsRebuild,
}

/// Updates `sys` (solved for `prev`) to `next` at `frame`.
pub fn advance(
    sys: &mut System,
    prev: &Scene,
    next: &Scene,
    frame: f64,
    progress: Progress,
) -> Result<Outcome> {
    let start = std::time::Instant::now();
    let s = &next.settings;
    let basis: Basis = sys.basis;
    let new_elements = build_elements(next, frame, basis);
    if new_elements.len() != sys.elements.len()
        || new_elements.iter().zip(&sys.elements).any(|(a, b)| (a.object, a.face) != (b.object, b.face))
    {
        return Ok(Outcome::NeedsRebuild);
    }
    let n = new_elements.len();
    let moved: Vec<bool> = new_elements.iter().zip(&sys.elements).map(|(a, b)| a.patch != b.patch).collect();
    // Objects whose placement changed by a pure translation (the seed's case) or otherwise.
    let translated: Vec<bool> = prev
        .objects
        .iter()
        .zip(&next.objects)
        .map(|(a, b)| {
            let (ma, mb) = (a.world_from_object(frame), b.world_from_object(frame));
            ma.x_axis == mb.x_axis && ma.y_axis == mb.y_axis && ma.z_axis == mb.z_axis
        })
        .collect();
    let swept = moved.iter().enumerate().filter(|(_, m)| **m).fold(Aabb::EMPTY, |b, (e, _)| {
        b.union(sys.elements[e].patch.bounds()).union(new_elements[e].patch.bounds())
    });
    let any_moved = moved.iter().any(|&m| m);
    let mut stats =
        UpdateStats { moved_elements: moved.iter().filter(|&&m| m).count(), ..Default::default() };

    let patches: Vec<Patch> = new_elements.iter().map(|e| e.patch).collect();
    let mut delta_b = vec![[0.0f64; 3]; n * basis.len()];
    if any_moved {
        let rule = GaussLegendre::new(s.quadrature_order);
        let ctx = PairContext {
            basis,
            rule: &rule,
            vis_axis: s.visibility_samples,
            adaptive: s.adaptive_quadrature,
        };
        let occluders = s.visibility.then(|| Occluders::new(&patches, s.visibility_samples));
        let geom = ElementGeometry::new(&patches, &ctx);
        let scale = swept.diagonal().length().max(1e-300) * 1e-9;
        // Candidate pairs, with the reason they are recomputed.
        let candidates: Vec<(u32, u32, bool)> = (0..n)
            .into_par_iter()
            .flat_map_iter(|i| {
                let (moved, patches, swept) = (&moved, &patches, &swept);
                ((i + 1)..n).filter_map(move |j| {
                    if moved[i] || moved[j] {
                        return Some((i as u32, j as u32, false));
                    }
                    if !s.visibility {
                        return None;
                    }
                    let (bi, bj) = (patches[i].bounds(), patches[j].bounds());
                    if !bi.union(bj).overlaps(swept) {
                        return None;
                    }
                    Shaft::new(&bi, &bj).may_contain_box(swept, scale).then_some((i as u32, j as u32, true))
                })
            })
            .collect();
        let total = candidates.len();
        let done = std::sync::atomic::AtomicUsize::new(0);
        let computed: Vec<Option<(crate::kernel::PairCoefficients, Visibility)>> = candidates
            .par_iter()
            .map(|&(i, j, _)| {
                let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if d.is_multiple_of(4096) && !progress(d as f64 / total.max(1) as f64, "kernel update") {
                    return Err(Error::Cancelled);
                }
                Ok(compute_pair(&ctx, &geom, occluders.as_ref(), i as usize, j as usize))
            })
            .collect::<Result<_>>()?;
        let nb = basis.len();
        let zeros = vec![0.0; nb * nb];
        for (&(i, j, vis_only), new) in candidates.iter().zip(computed) {
            let existing = sys.links.find(i, j);
            let (old_ij, old_ji) = match existing {
                Some(p) => sys.links.blocks_f64(p, i),
                None => (zeros.clone(), zeros.clone()),
            };
            if existing.is_none() && new.is_none() {
                continue;
            }
            let (new_ij, new_ji, vis) = match &new {
                Some((c, v)) => (c.ij.clone(), c.ji.clone(), v.clone()),
                None => (zeros.clone(), zeros.clone(), Visibility::Blocked),
            };
            if vis_only {
                let old_vis =
                    existing.map(|p| sys.links.pair(p).visibility.clone()).unwrap_or(Visibility::Blocked);
                if old_vis == vis {
                    continue;
                }
                stats.recomputed_visibility += 1;
            } else {
                let obj = |e: u32| sys.elements[e as usize].object as usize;
                let pure =
                    (!moved[i as usize] || translated[obj(i)]) && (!moved[j as usize] || translated[obj(j)]);
                if pure {
                    stats.recomputed_translation += 1;
                } else {
                    stats.recomputed_non_translation += 1;
                }
            }
            stats.links_recomputed += 1;
            // Delta K b with the previous frame's b, both directions (eq. 9).
            add_delta(&mut delta_b, sys, i as usize, j as usize, &new_ij, &old_ij);
            add_delta(&mut delta_b, sys, j as usize, i as usize, &new_ji, &old_ji);
            match existing {
                Some(p) => {
                    let (ab, ba) =
                        if sys.links.pair(p).a == i { (&new_ij, &new_ji) } else { (&new_ji, &new_ij) };
                    sys.links.set(p, ab, ba, vis);
                }
                None => {
                    sys.links.push(i, j, &new_ij, &new_ji, vis);
                }
            }
        }
    }
    stats.kernel_seconds = start.elapsed().as_secs_f64();

    // Emission changes enter as Delta e (eq. 9).
    let nb = basis.len();
    let mut emission = vec![[0.0; 3]; n * nb];
    for (i, e) in new_elements.iter().enumerate() {
        emission[i * nb] = next.emission_at(e.material as usize, frame);
        for c in 0..3 {
            delta_b[i * nb][c] += emission[i * nb][c] - sys.emission[i * nb][c];
        }
    }
    for (k, d) in delta_b.iter().enumerate() {
        for c in 0..3 {
            sys.solution.b[k][c] += d[c];
            sys.solution.unshot[k][c] += d[c];
        }
    }
    sys.elements = new_elements;
    sys.emission = emission;
    sys.reflectance = sys.elements.iter().map(|e| next.materials[e.material as usize].reflectance).collect();

    let solve_start = std::time::Instant::now();
    let stop = s.tolerance * sys.emitted_power();
    let cancel = || !progress(1.0, "solve");
    let shot = solver::shoot(&sys.links, &sys.reflectance, &sys.areas(), &mut sys.solution, stop, &cancel)?;
    stats.solve_seconds = solve_start.elapsed().as_secs_f64();
    stats.shots = shot.shots;
    Ok(Outcome::Updated(stats))
}

/// `delta_b_r += rho_r (G_new - G_old) b_s` for receiver `r`, source `s`.
fn add_delta(delta_b: &mut [[f64; 3]], sys: &System, r: usize, s: usize, new: &[f64], old: &[f64]) {
    let nb = sys.basis.len();
    let rho = sys.reflectance[r];
    for k in 0..nb {
        for l in 0..nb {
            let d = new[k * nb + l] - old[k * nb + l];
            if d == 0.0 {
                continue;
            }
            for c in 0..3 {
                delta_b[r * nb + k][c] += rho[c] * d * sys.solution.b[s * nb + l][c];
            }
        }
    }
}
