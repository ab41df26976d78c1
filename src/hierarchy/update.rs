//! A frame after the first on the hierarchy of the frame before (issue 21; Drettakis and Sillion
//! 1997 in spirit): the faces that moved are placed again in the same tree, only the pairs a
//! change may have altered are linked again, and the solve starts from the last frame's solution.
//!
//! A pair of nodes (a link, a blocked pair or an idle one: together they partition every pair of
//! leaves, [`super::refine::Hierarchy::idle`]) can change this frame only if
//! - one of its nodes holds a face that moved (the pair's geometry changed), or
//! - a moved face's swept box, the bounds of its old and its new place, meets the shaft between
//!   the two nodes' boxes (what blocks the pair may have changed).
//!
//! Every other pair is computed from the very same patches and occluders in the shaft as the
//! frame before, so its link is what a fresh computation would give, bit for bit (the tests check
//! every link of an updated frame against [`coupling::compute`] on the new geometry). The touched
//! pairs are found by a walk down the pair tree when it is kept, else by a scan of every stored
//! pair ([`super::touch`]), and refined again with this frame's brightness: from where they
//! stood, or, with the pair tree kept, from the top of each largest subtree of pairs all touched
//! ([`super::pair_tree`]), so that a region a moving object has left can link coarser again.
//! The quadtrees keep their nodes.
//!
//! Emission, reflectance and lights may change every frame: the sources are computed again for
//! every leaf, the oracle's threshold follows the new source power, and the link-and-solve rounds
//! run as in [`super::solve_frame`], the first round on the touched pairs only.
//!
//! What this does not do yet (issue 21): take the touched pairs out of the stores without a pass
//! over them (the walk finds them, a hash lookup per stored pair removes them), coarsen a
//! subtree only partly touched (its untouched links are kept as they are, so a shadow's fine
//! links outside the swept shafts stay), expand moving links in the seed's series, remove the
//! quadtree nodes no link uses. The corner gather takes the last frame's values of each point's
//! sources where the move spares them ([`super::gather::KeptGather`]).

use crate::basis::Basis;
use crate::error::{Error, Result};
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::system::{Progress, build_elements_reusing};

use super::refine::{Hierarchy, Oracle};
use super::touch::{Moves, Touch, neutral};
use super::{HierarchicalFrame, HierarchySettings, HierarchyStats, Lighting, Start};
use super::{coupling, gather};

/// Solves `scene` at `frame` from `previous`, the solution of another frame of the same scene
/// (the same objects and faces): what a frame of an animation costs on the hierarchy.
///
/// `previous` stays readable whatever happens (its tree and solution are not changed), but its
/// links are taken: after an error it cannot be updated again, and the next frame must be
/// solved from scratch. A scene whose faces differ from `previous`' (a face with no area in one
/// frame and some in the other) is solved from scratch.
pub fn update_frame(
    previous: &mut HierarchicalFrame,
    scene: &Scene,
    frame: f64,
    hs: &HierarchySettings,
    progress: Progress,
) -> Result<HierarchicalFrame> {
    let start = std::time::Instant::now();
    let basis = Basis::new(scene.settings.basis_order);
    let old = &previous.hierarchy.tree;
    let faces = build_elements_reusing(scene, frame, basis, &old.faces);
    let faces = crate::backs::with_backs(scene, frame, faces, basis, &old.faces);
    let same_faces = faces.len() == old.faces.len()
        && faces
            .iter()
            .zip(&old.faces)
            .all(|(a, b)| (a.object, a.face, a.back) == (b.object, b.face, b.back));
    if !same_faces || basis != old.basis {
        return super::solve_frame(scene, frame, hs, progress);
    }
    if !progress(0.0, "links") {
        return Err(Error::Cancelled);
    }
    let t = std::time::Instant::now();
    let swept = Moves::swept_bounds(&old.faces, &faces);
    // The pairs a move touched are found in the pair tree or among the stored idle pairs; a
    // hierarchy that keeps neither (a still scene's), or whose pair tree the settings now add or
    // drop, is solved afresh.
    let h = &previous.hierarchy;
    let finds_touched = h.splits.is_kept() || h.stores_idle || swept.is_empty();
    if !finds_touched || hs.keep_pair_tree != h.splits.is_kept() {
        return super::solve_frame(scene, frame, hs, progress);
    }
    let reflectance = super::face_reflectance(scene, &faces);
    let lit = Lighting::new(scene, frame, &faces);
    let total_area: f64 = faces.iter().map(|e| e.area).sum();
    let mut tree = old.clone();
    let moved_faces = tree.place_faces(faces, reflectance);
    let moves = Moves { faces: moved_faces, swept };

    let mut state = previous.state.clone();
    state.clear_sources();
    // The leaves' shadow rays toward the lights: the last frame's taken where no move changed them.
    let last_rays = std::mem::take(&mut previous.leaf_rays);
    let lights = (lit.lights.as_ref(), previous.direct.as_deref());
    let mut rays = super::solve::LeafRays::after(last_rays, lights, &moves.faces, &moves.swept);
    state.add_sources_keeping(&tree, &lit.emission, lit.lights.as_ref(), &mut rays);
    state.refresh(&tree);
    let oracle = Oracle::of(hs, state.source_power(&tree), total_area);
    // What the last frame's verdicts were decided at holds for this oracle only if it decides
    // by the same rules.
    let mut decided_at = std::mem::take(&mut previous.hierarchy.decided_at);
    if !oracle.same_rules(&previous.hierarchy.oracle) {
        decided_at.clear();
    }
    let mut hierarchy = Hierarchy {
        tree,
        links: std::mem::take(&mut previous.hierarchy.links),
        link_load: std::mem::take(&mut previous.hierarchy.link_load),
        blocked: std::mem::take(&mut previous.hierarchy.blocked),
        blocked_load: std::mem::take(&mut previous.hierarchy.blocked_load),
        idle: std::mem::take(&mut previous.hierarchy.idle),
        oracle,
        stores_idle: previous.hierarchy.stores_idle,
        splits: std::mem::take(&mut previous.hierarchy.splits),
        decided_at,
        changes: std::mem::take(&mut previous.hierarchy.changes),
        packed: previous.hierarchy.packed.take(),
        casts: Default::default(),
    };
    let last_casts = std::mem::take(&mut previous.hierarchy.casts);
    // About as many as the last frame's.
    hierarchy.casts.try_reserve(last_casts.len())?;
    let setup_seconds = start.elapsed().as_secs_f64();
    // Nothing moved (an emission change alone): no pair is touched.
    let touch = (!moves.swept.is_empty()).then(|| Touch::new(&hierarchy.tree, &moves));
    let (touched, work) = match &touch {
        None => (0, Vec::new()),
        Some(touch) => take_changed(&mut hierarchy, touch, &state.radiosity_estimate()),
    };
    let mut stats = HierarchyStats {
        faces: hierarchy.tree.faces.len(),
        moved_faces: moves.faces.iter().filter(|&&m| m).count(),
        touched_pairs: touched,
        refined_from: work.len(),
        kept_links: hierarchy.links.len(),
        updated: true,
        setup_seconds,
        touch_seconds: start.elapsed().as_secs_f64() - setup_seconds,
        ..Default::default()
    };
    stats.link_seconds += t.elapsed().as_secs_f64();
    let rule = GaussLegendre::new(scene.settings.quadrature_order);
    let mut ctx = super::link_context(scene, hs, &rule, lit.occluders.as_ref());
    // The next frame takes the casts this one makes; this one those of the frame before, where
    // the move cannot have changed them.
    let no_move = [];
    let holds = touch.as_ref().map_or(&no_move[..], |t| t.holds());
    ctx.reuse =
        hs.reuse_casts.then(|| coupling::Reuse::new(&last_casts, holds, &moves.swept, &hierarchy.tree));
    super::link_and_solve(
        &mut hierarchy,
        &mut state,
        &ctx,
        (&lit, &mut rays),
        hs,
        Start::Pairs(work),
        &mut stats,
        progress,
    )?;
    // The last gathered frame's values, where what moved since spares them: this frame's moves,
    // and those of the frames between that passed them on without gathering (previews).
    let last_gather = previous.kept_gather.take();
    let since = previous.moved_since_gather.take().map(|mut m| {
        m.add(&moves);
        m
    });
    let since_touch = since.as_ref().filter(|m| !m.swept.is_empty()).map(|m| Touch::new(&hierarchy.tree, m));
    let changes = gather::Changes::of(if since.is_some() { since_touch.as_ref() } else { touch.as_ref() });
    let kept = last_gather.as_ref().map(|k| (k, changes));
    // (A kept gather passed on below keeps its own frame's lights.)
    let mut next = super::finish(hierarchy, state, stats, (lit, rays), scene, frame, hs, kept, progress)?;
    if !hs.corner_gather && last_gather.is_some() {
        next.kept_gather = last_gather;
        next.moved_since_gather = Some(since.unwrap_or(moves));
    }
    Ok(next)
}

/// Takes out of `hierarchy` every stored pair `touch` says the move may have changed and, with
/// the pair tree kept, the untouched stored pairs below the subtrees
/// [`super::pair_tree::Splits::coarsest_touched`] redoes (where the oracle may now link coarser),
/// all in one pass over the stores. Returns how many pairs the move touched and where to refine
/// again from: the tops of the redone subtrees, or without the pair tree the touched pairs
/// themselves (found by a scan of every stored pair).
fn take_changed(hierarchy: &mut Hierarchy, touch: &Touch, radiosity: &[f64]) -> (usize, Vec<(u32, u32)>) {
    use super::pair_tree::{PairSet, key};
    let (tree, oracle) = (&hierarchy.tree, &hierarchy.oracle);
    // One walk down the pair tree finds the touched pairs and the subtrees to redo.
    let redo = hierarchy.splits.coarsest_touched(
        tree,
        |a, b| touch.pair(a, b),
        |a, b| touch.may_below(a, b),
        |a, b| neutral(tree, a, b),
        |a, b| oracle.links_whole(tree, radiosity, a, b),
    );
    let Some(redo) = redo else {
        let touched = hierarchy.take_touched(|a, b| touch.pair(a, b));
        return (touched.len(), touched);
    };
    let taking = || redo.touched.iter().chain(&redo.untouched);
    if redo.touched.is_empty() && redo.untouched.is_empty() {
        return (0, redo.tops);
    }
    let set: PairSet = taking().map(|&(a, b)| key(a, b)).collect();
    // A pair can be taken only if each end has a pair to take with a partner of the other's
    // class (its id modulo 64): a look at two bits spares most stored pairs the hash lookup. (With
    // one flag per end, most pairs near the move still went to the hash: the verdicts were a
    // tenth of an updated frame of the full monastery.)
    let mut partners = vec![0u64; hierarchy.tree.nodes.len()];
    for &(a, b) in taking() {
        partners[a as usize] |= 1 << (b % 64);
        partners[b as usize] |= 1 << (a % 64);
    }
    let may_take = |a: u32, b: u32| {
        partners[a as usize] >> (b % 64) & 1 != 0 && partners[b as usize] >> (a % 64) & 1 != 0
    };
    let taken = hierarchy.take_touched(|a, b| may_take(a, b) && set.contains(&key(a, b)));
    // (Idle pairs are not stored with the pair tree kept.)
    debug_assert!(taken.len() <= set.len());
    (redo.touched.len(), redo.tops)
}
