//! Every pair of a scene's elements, in parallel: cull pairs that cannot exchange light, find
//! visibility, integrate the kernel, and fill the link store.

use rayon::prelude::*;

use super::pair::{FAR, MID, PairCoefficients, PairContext, integrate_pair};
use super::samples::Samples;
use crate::geometry::{Patch, Rect};
use crate::links::LinkStore;
use crate::quadrature::GaussLegendre;
use crate::visibility::{Occluders, Visibility};

/// Element geometry and the whole-domain samples the kernel reuses for every pair, for each of
/// the rules [`PairContext::points_for`] can choose.
pub struct ElementGeometry<'a> {
    pub patches: &'a [Patch],
    /// `samples[r][e]`: element `e` with `rules[r]` points per axis.
    samples: Vec<Vec<Samples>>,
    rules: Vec<usize>,
}

impl<'a> ElementGeometry<'a> {
    pub fn new(patches: &'a [Patch], ctx: &PairContext) -> Self {
        let mut rules =
            vec![ctx.points_for(f64::INFINITY), ctx.points_for(0.5 * (MID + FAR)), ctx.rule.len()];
        rules.dedup();
        let samples = rules
            .iter()
            .map(|&n| {
                let rule = GaussLegendre::new(n);
                patches
                    .par_iter()
                    .map(|p| Samples::new(p, &Rect::UNIT, &rule, ctx.basis, ctx.vis_axis))
                    .collect()
            })
            .collect();
        Self { patches, samples, rules }
    }

    /// Element `e`'s whole-domain samples with `n` points per axis.
    pub fn samples(&self, e: usize, n: usize) -> &Samples {
        let r = self.rules.iter().position(|&m| m == n).expect("rule prepared");
        &self.samples[r][e]
    }
}

/// True when some point of `b` may lie in front of `a` (conservative for non-planar patches).
pub fn may_face(a: &Patch, b: &Patch) -> bool {
    if a.non_planarity() > 1e-9 {
        return true;
    }
    let n = a.centre_normal();
    let c = a.point(0.5, 0.5);
    let (_, r) = a.bounding_sphere();
    b.corners.iter().any(|p| n.dot(*p - c) > 1e-9 * r)
}

/// The coefficients and visibility of one pair, or `None` when it exchanges nothing.
pub fn compute_pair(
    ctx: &PairContext,
    geom: &ElementGeometry,
    occluders: Option<&Occluders>,
    i: usize,
    j: usize,
) -> Option<(PairCoefficients, Visibility)> {
    let (pi, pj) = (&geom.patches[i], &geom.patches[j]);
    if !may_face(pi, pj) || !may_face(pj, pi) {
        return None;
    }
    let vis = match occluders {
        Some(o) => o.link_visibility(i, pi, j, pj),
        None => Visibility::Full,
    };
    integrate_visible(ctx, geom, i, j, &vis).map(|c| (c, vis))
}

/// The coefficients of a pair whose visibility is known, or `None` when it exchanges nothing.
pub fn integrate_visible(
    ctx: &PairContext,
    geom: &ElementGeometry,
    i: usize,
    j: usize,
    vis: &Visibility,
) -> Option<PairCoefficients> {
    let (pi, pj) = (&geom.patches[i], &geom.patches[j]);
    if *vis == Visibility::Blocked || !may_face(pi, pj) || !may_face(pj, pi) {
        return None;
    }
    let c = integrate_pair(ctx, pi, pj, |second, n| geom.samples(if second { j } else { i }, n), vis);
    (!c.is_zero()).then_some(c)
}

/// Builds the link store of all interacting pairs. `progress(done, total)` is called from worker
/// threads now and then and returns false to cancel (then `None` is returned).
pub fn assemble(
    ctx: &PairContext,
    geom: &ElementGeometry,
    occluders: Option<&Occluders>,
    progress: &(dyn Fn(usize, usize) -> bool + Sync),
) -> Option<LinkStore> {
    let n = geom.patches.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let cancelled = std::sync::atomic::AtomicBool::new(false);
    // One task per receiver row i, pairs (i, j > i); rows are uneven, rayon balances them.
    let rows: Vec<Vec<(u32, PairCoefficients, Visibility)>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if cancelled.load(std::sync::atomic::Ordering::Relaxed) {
                return Vec::new();
            }
            let row: Vec<_> = ((i + 1)..n)
                .filter_map(|j| compute_pair(ctx, geom, occluders, i, j).map(|(c, v)| (j as u32, c, v)))
                .collect();
            let d = done.fetch_add(n - 1 - i, std::sync::atomic::Ordering::Relaxed) + n - 1 - i;
            if !progress(d, n * (n - 1) / 2) {
                cancelled.store(true, std::sync::atomic::Ordering::Relaxed);
            }
            row
        })
        .collect();
    if cancelled.load(std::sync::atomic::Ordering::Relaxed) {
        return None;
    }
    let mut store = LinkStore::new(n, ctx.basis.len());
    for (i, row) in rows.into_iter().enumerate() {
        for (j, c, v) in row {
            store.push(i as u32, j, &c.ij, &c.ji, v);
        }
    }
    Some(store)
}
