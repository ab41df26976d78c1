//! Every pair of a scene's elements, in parallel: cull pairs that cannot exchange light, find
//! visibility, integrate the kernel, and fill the link store.

use rayon::prelude::*;

use glam::DVec3;

use super::pair::{FAR, MID, PairCoefficients, PairContext, integrate_pair_into};
use super::samples::Samples;
use crate::budget;
use crate::error::{Error, Result};
use crate::geometry::{FrontPlane, Patch, Rect};
use crate::links::{LinkRow, LinkStore};
use crate::quadrature::GaussLegendre;
use crate::visibility::{Occluders, Visibility};

/// Element geometry and the whole-domain samples the kernel reuses for every pair, for each of
/// the rules [`PairContext::points_for`] can choose.
pub struct ElementGeometry<'a> {
    pub patches: &'a [Patch],
    /// `samples[r][e]`: element `e` with `rules[r]` points per axis.
    samples: Vec<Vec<Samples>>,
    rules: Vec<usize>,
    /// Per element, what [`may_face`] and the pair integrator ask of it, computed once.
    info: Vec<ElementInfo>,
    /// Per element, its weight as a source ([`crate::overlap`]).
    weights: Vec<f64>,
}

/// An [`ElementGeometry`] without its patches, kept between animation frames.
pub struct KeptGeometry {
    key: GeometryKey,
    samples: Vec<Vec<Samples>>,
    rules: Vec<usize>,
    info: Vec<ElementInfo>,
    weights: Vec<f64>,
}

/// What the samples depend on besides the patches.
#[derive(Clone, Copy, PartialEq)]
struct GeometryKey {
    order: usize,
    rule: usize,
    vis_axis: usize,
    adaptive: bool,
}

impl GeometryKey {
    fn of(ctx: &PairContext) -> Self {
        Self {
            order: ctx.basis.order(),
            rule: ctx.rule.len(),
            vis_axis: ctx.vis_axis,
            adaptive: ctx.adaptive,
        }
    }
}

/// Per-element geometry that every pair of the element needs.
struct ElementInfo {
    /// Bounding sphere (centre, radius).
    sphere: (DVec3, f64),
    /// `None` when the element is not planar (then it may face anything).
    plane: Option<FrontPlane>,
}

impl ElementInfo {
    fn new(p: &Patch) -> Self {
        Self { sphere: p.bounding_sphere(), plane: p.front_plane() }
    }

    /// [`may_face`] with `a` = this element.
    fn may_face(&self, b: &Patch) -> bool {
        self.plane.is_none_or(|pl| pl.any_in_front(b))
    }
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
        let info = patches.par_iter().map(ElementInfo::new).collect();
        let weights = crate::overlap::source_weights(patches);
        Self { patches, samples, rules, info, weights }
    }

    /// [`ElementGeometry::new`] for `patches`, taking from `kept` (the geometry of the previous
    /// frame, [`ElementGeometry::into_kept`]) every element not in `moved`: an element's samples
    /// depend on its patch alone. Without `kept`, or when it was made for another context, all
    /// elements are computed. The source weights are the kept ones: the caller rebuilds when a
    /// move changes them.
    pub fn reusing(
        kept: Option<KeptGeometry>,
        patches: &'a [Patch],
        moved: &[bool],
        ctx: &PairContext,
    ) -> Self {
        let Some(mut kept) = kept.filter(|k| {
            k.key == GeometryKey::of(ctx) && k.info.len() == patches.len() && moved.len() == patches.len()
        }) else {
            return Self::new(patches, ctx);
        };
        let redo: Vec<usize> = (0..patches.len()).filter(|&e| moved[e]).collect();
        for (r, &n) in kept.rules.iter().enumerate() {
            let rule = GaussLegendre::new(n);
            let fresh: Vec<Samples> = redo
                .par_iter()
                .map(|&e| Samples::new(&patches[e], &Rect::UNIT, &rule, ctx.basis, ctx.vis_axis))
                .collect();
            for (&e, s) in redo.iter().zip(fresh) {
                kept.samples[r][e] = s;
            }
        }
        for &e in &redo {
            kept.info[e] = ElementInfo::new(&patches[e]);
        }
        Self { patches, samples: kept.samples, rules: kept.rules, info: kept.info, weights: kept.weights }
    }

    /// What [`ElementGeometry::reusing`] takes to the next frame (no borrow of the patches).
    pub fn into_kept(self, ctx: &PairContext) -> KeptGeometry {
        KeptGeometry {
            key: GeometryKey::of(ctx),
            samples: self.samples,
            rules: self.rules,
            info: self.info,
            weights: self.weights,
        }
    }

    /// Element `e`'s whole-domain samples with `n` points per axis.
    pub fn samples(&self, e: usize, n: usize) -> &Samples {
        let r = self.rules.iter().position(|&m| m == n).expect("rule prepared");
        &self.samples[r][e]
    }

    /// `may_face(i, j) && may_face(j, i)` for elements `i` and `j`.
    pub fn face_each_other(&self, i: usize, j: usize) -> bool {
        self.info[i].may_face(&self.patches[j]) && self.info[j].may_face(&self.patches[i])
    }

    /// Each element's weight as a source ([`crate::overlap`]).
    pub fn source_weights(&self) -> &[f64] {
        &self.weights
    }

    /// Weighs a pair's blocks by their sources ([`crate::overlap`]): `G_ij` by `w_j`, `G_ji` by
    /// `w_i`. Every block the store takes passes here, whatever computed it.
    pub fn weigh(&self, i: usize, j: usize, ij: &mut [f64], ji: &mut [f64]) {
        let (wi, wj) = (self.weights[i], self.weights[j]);
        if wj != 1.0 {
            ij.iter_mut().for_each(|x| *x *= wj);
        }
        if wi != 1.0 {
            ji.iter_mut().for_each(|x| *x *= wi);
        }
    }

    /// Element `e`'s bounding sphere (centre, radius).
    pub fn sphere(&self, e: usize) -> (DVec3, f64) {
        self.info[e].sphere
    }

    /// Element `e`'s plane ([`Patch::front_plane`]): `None` when it is not planar.
    pub fn plane(&self, e: usize) -> Option<FrontPlane> {
        self.info[e].plane
    }
}

/// True when some point of `b` may lie in front of `a` (conservative for non-planar patches).
pub fn may_face(a: &Patch, b: &Patch) -> bool {
    a.front_plane().is_none_or(|pl| pl.any_in_front(b))
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
    let mut c = PairCoefficients::zeros(ctx.basis.len());
    integrate_visible_into(ctx, geom, i, j, vis, &mut c.ij, &mut c.ji).then_some(c)
}

/// [`integrate_visible`] into the caller's blocks (`nb x nb` each, overwritten): false when the
/// pair exchanges nothing.
pub fn integrate_visible_into(
    ctx: &PairContext,
    geom: &ElementGeometry,
    i: usize,
    j: usize,
    vis: &Visibility,
    ij: &mut [f64],
    ji: &mut [f64],
) -> bool {
    if *vis == Visibility::Blocked || !geom.face_each_other(i, j) {
        return false;
    }
    ij.fill(0.0);
    ji.fill(0.0);
    let (pi, pj) = (&geom.patches[i], &geom.patches[j]);
    let spheres = (geom.info[i].sphere, geom.info[j].sphere);
    let whole = |second: bool, n| geom.samples(if second { j } else { i }, n);
    integrate_pair_into(ctx, pi, pj, spheres, whole, vis, ij, ji);
    ij.iter().chain(ji.iter()).any(|&x| x != 0.0)
}

/// Sources per shared visibility traversal ([`Occluders::group_visibility`]): consecutive
/// elements, most often a strip of one face's grid.
const VISIBILITY_GROUP: usize = 8;

/// What the link rows are called in an out-of-memory message.
const ROWS: &str = "the links (kernel rows)";

/// Room in `row` for one more pair of `2 n2` coefficients, or the allocator's refusal.
fn reserve_pair(row: &mut LinkRow, n2: usize) -> Result<()> {
    budget::try_reserve(&mut row.coeffs, 2 * n2, ROWS)?;
    budget::try_reserve(&mut row.sources, 1, ROWS)?;
    budget::try_reserve(&mut row.visibility, 1, ROWS)
}

/// Builds the link store of all interacting pairs. `progress(done, total)` is called from worker
/// threads now and then and returns false to cancel (then [`Error::Cancelled`]). The rows and
/// the store are the bake's big allocations: when the allocator refuses one, the other rows stop
/// and [`Error::OutOfMemory`] is returned.
pub fn assemble(
    ctx: &PairContext,
    geom: &ElementGeometry,
    occluders: Option<&Occluders>,
    progress: &(dyn Fn(usize, usize) -> bool + Sync),
) -> Result<LinkStore> {
    let n = geom.patches.len();
    let nb = ctx.basis.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let cancelled = std::sync::atomic::AtomicBool::new(false);
    let failure: std::sync::Mutex<Option<Error>> = std::sync::Mutex::new(None);
    // One task per receiver row i, pairs (i, j > i); rows are uneven, rayon balances them.
    let mut rows: Vec<LinkRow> = budget::try_vec(n, ROWS)?;
    let rows_iter = (0..n).into_par_iter().map(|i| {
        let mut row = LinkRow { a: i as u32, ..Default::default() };
        if cancelled.load(std::sync::atomic::Ordering::Relaxed) {
            return row;
        }
        let (mut ij, mut ji) = ([0.0f64; 256], [0.0f64; 256]);
        let (ij, ji) = (&mut ij[..nb * nb], &mut ji[..nb * nb]);
        let pi = &geom.patches[i];
        let mut group: Vec<(usize, &Patch)> = Vec::with_capacity(VISIBILITY_GROUP);
        let mut vis: Vec<Visibility> = Vec::with_capacity(VISIBILITY_GROUP);
        for start in ((i + 1)..n).step_by(VISIBILITY_GROUP) {
            group.clear();
            vis.clear();
            let facing = (start..n.min(start + VISIBILITY_GROUP)).filter(|&j| geom.face_each_other(i, j));
            group.extend(facing.map(|j| (j, &geom.patches[j])));
            match occluders {
                Some(o) => o.group_visibility(i, pi, &group, &mut vis),
                None => vis.extend(group.iter().map(|_| Visibility::Full)),
            }
            for (&(j, _), v) in group.iter().zip(vis.drain(..)) {
                if integrate_visible_into(ctx, geom, i, j, &v, ij, ji) {
                    geom.weigh(i, j, ij, ji);
                    if let Err(e) = reserve_pair(&mut row, nb * nb) {
                        cancelled.store(true, std::sync::atomic::Ordering::Relaxed);
                        failure.lock().unwrap_or_else(|p| p.into_inner()).get_or_insert(e);
                        return LinkRow::default();
                    }
                    row.sources.push(j as u32);
                    row.coeffs.extend(ij.iter().chain(ji.iter()).map(|&x| x as f32));
                    row.visibility.push(v);
                }
            }
        }
        let d = done.fetch_add(n - 1 - i, std::sync::atomic::Ordering::Relaxed) + n - 1 - i;
        if !progress(d, n * (n - 1) / 2) {
            cancelled.store(true, std::sync::atomic::Ordering::Relaxed);
        }
        row
    });
    rows.par_extend(rows_iter);
    if let Some(e) = failure.into_inner().unwrap_or_else(|p| p.into_inner()) {
        return Err(e);
    }
    if cancelled.load(std::sync::atomic::Ordering::Relaxed) {
        return Err(Error::Cancelled);
    }
    let mut store = LinkStore::new(n, nb);
    store.extend_rows(rows)?;
    Ok(store)
}
