//! Hierarchical Galerkin radiosity with clustering (issue 20): elements below faces where the
//! transfer needs them, clusters above faces where it does not, links between any two nodes.
//!
//! `tree.rs` holds the nodes (clusters over faces, quadtrees of `Rect`s below them),
//! `two_scale.rs` the push and pull between a surface and its quadrants, `lobes.rs` how clusters
//! shoot and receive, `coupling.rs` what a link holds and how it is computed, `refine/` the
//! oracle and the link hierarchy, `solve/` the Jacobi sweeps with push-pull. [`solve_frame`]
//! runs it on one frame of a scene from scratch: link from the sources' brightness, solve,
//! link again where the solution's brightness asks for it, solve again.

pub mod anderson;
pub mod coupling;
pub mod gather;
pub mod lobes;
pub mod packed;
pub mod pair_tree;
mod push_pull;
pub mod refine;
pub mod solve;
pub mod touch;
pub mod tree;
pub mod two_scale;
pub mod update;

use rayon::prelude::*;
use std::time::Instant;

use crate::basis::Basis;
use crate::error::{Error, Result};
use crate::geometry::Patch;
use crate::kernel::PairContext;
use crate::lights::direct::DirectLight;
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::scene::json::{ObjectResult, irradiance_from_radiosity};
use crate::system::{Progress, build_elements, corner_params};
use crate::visibility::Occluders;

use coupling::LinkContext;
use refine::{Hierarchy, Oracle};
use solve::State;
use tree::Tree;

/// [`HierarchySettings::accuracy`] unless a scene says otherwise.
pub const DEFAULT_ACCURACY: f64 = 1e-3;

/// The hierarchy's knobs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HierarchySettings {
    /// The largest power an unrefined link may carry, as a share of the emitted power: the one
    /// accuracy knob (smaller is finer).
    pub accuracy: f64,
    /// Deepest quadtree level below a face.
    pub max_depth: u32,
    /// Smallest element, as a share of the scene's surface area.
    pub min_area: f64,
    /// Link-and-solve rounds (the first links from the sources' brightness alone).
    pub rounds: usize,
    /// Jacobi sweeps per round at most.
    pub max_sweeps: usize,
    /// Steps the sweeps' Anderson mixer keeps ([`anderson`]; 0: plain Jacobi sweeps).
    pub anderson_depth: usize,
    /// Links may end at clusters (off only to test the surface hierarchy alone).
    pub clusters: bool,
    /// How far apart, in sums of bounding-sphere radii, two nodes must be for a link between
    /// them to end at a cluster (nearer pairs open the cluster): 3 keeps a closed box's faces
    /// within 0.5% of their balance; 1.5 links a 20k-triangle model 2.2x faster but puts a face
    /// of that box 5.8% off (docs/method.md, "How near a cluster may link").
    pub cluster_separation: f64,
    /// How links between near surfaces are integrated.
    pub near: coupling::NearRule,
    /// Surface links that can carry only a small share of the accuracy's power keep their
    /// constant coefficients only, from a cheaper rule and a few visibility segments
    /// ([`coupling::Coupling::Constants`]); off: every surface link in full.
    pub light_links: bool,
    /// Corners gathered through the links ([`gather`]); else read from the leaf polynomials.
    pub corner_gather: bool,
    /// Keep the refinement's pair tree ([`pair_tree`], about 14 bytes per stored pair) so that the
    /// next frame's update can coarsen where a move no longer needs fine links; off, updates
    /// only refine. [`crate::session::Session`] keeps it for scenes of more than one frame.
    pub keep_pair_tree: bool,
    /// Keep the corner gather's values of each point's sources, so that the next frame's gather
    /// takes those its changes cannot have altered ([`gather::KeptGather`]; at most an eighth of
    /// the memory budget, and 512 MB). [`crate::session::Session`] keeps them for animations.
    pub keep_gather: bool,
    /// Something may move in a later frame, which an update must then relink: off for a scene of
    /// one frame promised still ([`crate::session::Session::set_still`], as the CLI bakes one
    /// frame), whose hierarchy then does not store its idle pairs ([`refine::Hierarchy::idle`];
    /// 53M, 0.4 GB, on the full monastery), and an update that finds something moved after all
    /// solves afresh.
    pub moves: bool,
    /// Check every hemisphere bound whose furnace gathered only the changed receivers against
    /// one that gathers them all: an internal error where they differ. For tests.
    #[doc(hidden)]
    pub check_furnace: bool,
    /// An updated frame takes the last frame's casts of the cluster links a move cannot have
    /// changed ([`coupling::Reuse`]; on by default, the same links either way). Off, for the
    /// benches' side-by-side measure of what it saves.
    #[doc(hidden)]
    pub reuse_casts: bool,
}

impl HierarchySettings {
    /// The defaults with the scene's accuracy.
    pub fn of(settings: &crate::scene::Settings) -> Self {
        Self { accuracy: settings.accuracy, corner_gather: settings.corner_gather, ..Default::default() }
    }
}

impl Default for HierarchySettings {
    fn default() -> Self {
        Self {
            accuracy: DEFAULT_ACCURACY,
            max_depth: 6,
            min_area: 1e-6,
            rounds: 3,
            max_sweeps: 500,
            anderson_depth: solve::ANDERSON_DEPTH,
            clusters: true,
            cluster_separation: 3.0,
            near: coupling::NearRule::Coarse,
            light_links: true,
            corner_gather: false,
            keep_pair_tree: false,
            keep_gather: false,
            moves: true,
            check_furnace: false,
            reuse_casts: true,
        }
    }
}

/// A record of the pair tree's splits if `hs` keeps one.
fn splits_for(hs: &HierarchySettings) -> pair_tree::Splits {
    if hs.keep_pair_tree { pair_tree::Splits::kept() } else { pair_tree::Splits::off() }
}

/// Counts and timings of one hierarchical frame.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct HierarchyStats {
    pub faces: usize,
    /// The lights' shadow rays of the leaves' projections: traced, and taken from the frame
    /// before where no move changed them ([`solve::LeafRays`]).
    pub direct_rays_traced: u64,
    pub direct_rays_taken: u64,
    pub nodes: usize,
    pub leaves: usize,
    pub links: usize,
    /// Links between surfaces with all their coefficients, and those that carry so little that
    /// they keep only the constant ones ([`coupling::Coupling::Constants`]).
    pub surface_links: usize,
    pub constant_links: usize,
    pub cluster_links: usize,
    pub link_bytes: usize,
    pub sweeps: usize,
    /// The hemisphere bound's furnaces (one per solve) and the rows they gathered, of `nodes`
    /// each at most ([`solve::State::bound_leaves`]).
    pub furnaces: usize,
    pub furnace_rows: usize,
    pub link_seconds: f64,
    /// Of `link_seconds`, computing the couplings of accepted pairs
    /// ([`refine::RefineStats::compute_seconds`]).
    pub compute_seconds: f64,
    /// Of the cluster links computed, those whose cast was the last frame's
    /// ([`coupling::Reuse`]).
    pub reused_casts: usize,
    pub solve_seconds: f64,
    /// Where an updated frame's time goes, in wall seconds, its phases in turn: the set-up
    /// (faces placed, the frame's lights and occluders, the last frame's tree and solution
    /// copied), finding and taking out the touched pairs, the first round's linking and the
    /// later rounds' (the relinks), packing the links for the solve, the hemisphere bound's
    /// furnaces and the sweeps. The first three are of `link_seconds` (the set-up from the
    /// lights on), the last three of `solve_seconds`. A frame from scratch has only the
    /// linking, packing, furnaces and sweeps.
    pub setup_seconds: f64,
    pub touch_seconds: f64,
    pub first_link_seconds: f64,
    pub relink_seconds: f64,
    pub pack_seconds: f64,
    pub furnace_seconds: f64,
    pub sweep_seconds: f64,
    /// Distinct corner points gathered, and the gather's time (0 without it).
    pub gather_points: usize,
    /// The gather's sources (feet's included) whose values were the last frame's
    /// ([`gather::KeptGather`]), and those computed.
    pub gather_kept: u64,
    pub gather_computed: u64,
    /// Bytes the gather keeps for the next frame.
    pub kept_gather_bytes: usize,
    pub gather_seconds: f64,
    /// The frame was updated from the frame before ([`update`]), not solved from scratch: its
    /// faces that moved, the pairs it linked again, and the links it kept as they were.
    pub updated: bool,
    pub moved_faces: usize,
    pub touched_pairs: usize,
    /// Links and blocked pairs the relink rounds tested again with the solution's brightness
    /// ([`refine::RefineStats::tested`]).
    pub retested: usize,
    /// Relink rounds after which no node had grown much, which read only the pairs' loads
    /// ([`refine::RefineStats::quick`]).
    pub quick_relinks: usize,
    pub kept_links: usize,
    /// Of an update with the pair tree kept: the pairs its touched ones were refined again from
    /// (fewer than `touched_pairs` where whole subtrees were touched and could coarsen).
    pub refined_from: usize,
    /// Inner pairs of the pair tree kept, and their bytes.
    pub pair_tree: usize,
    pub pair_tree_bytes: usize,
}

/// One frame solved on the hierarchy.
pub struct HierarchicalFrame {
    pub hierarchy: Hierarchy,
    pub state: State,
    pub stats: HierarchyStats,
    /// `B` and the light received `H` at every face corner per object, gathered ([`gather`]);
    /// `None`: from the leaves.
    pub corners: Option<(crate::gather::CornerValues, crate::gather::CornerValues)>,
    /// What the corner gather kept for the next frame's ([`gather::KeptGather`]; with
    /// [`HierarchySettings::keep_gather`]).
    pub kept_gather: Option<gather::KeptGather>,
    /// When this frame passed on an earlier frame's kept gather without gathering (a preview):
    /// what moved since that frame, which the next gather's kept values must have been spared.
    pub moved_since_gather: Option<touch::Moves>,
    /// The lights as placed for this frame, and its leaves' shadow rays toward them, for the next
    /// frame to take where no move changed them ([`solve::LeafRays`]).
    pub direct: Option<std::sync::Arc<DirectLight>>,
    pub leaf_rays: solve::LeafRays,
}

/// Solves `scene` at `frame` on the hierarchy, from scratch. Runs on the current rayon pool;
/// `progress` may cancel between phases and sweeps.
pub fn solve_frame(
    scene: &Scene,
    frame: f64,
    hs: &HierarchySettings,
    progress: Progress,
) -> Result<HierarchicalFrame> {
    // The preparation below is part of the links' stage: reported (and cancellable) from the
    // start, so that a large model's first line does not wait for it.
    let prepared = || if progress(0.0, "links") { Ok(()) } else { Err(Error::Cancelled) };
    prepared()?;
    let basis = Basis::new(scene.settings.basis_order);
    // Open surfaces' backs (crate::backs) are faces of the tree, after their fronts.
    let faces = crate::backs::with_backs(scene, frame, build_elements(scene, frame, basis), basis, &[]);
    if faces.is_empty() {
        return Err(Error::InvalidScene("the scene has no faces with area".into()));
    }
    let reflectance = face_reflectance(scene, &faces);
    let lit = Lighting::new(scene, frame, &faces);
    let total_area: f64 = faces.iter().map(|e| e.area).sum();
    // Faces split ahead where another object comes close, as the flat path splits them: only
    // shadows need it, and there are none without visibility.
    prepared()?;
    let contacts = scene.settings.visibility.then(|| crate::contact_split::plan(scene, &faces));
    prepared()?;
    let mut tree = Tree::new(faces, reflectance, basis);
    if let Some(parts) = contacts {
        tree.split_for_contacts(&parts);
    }
    let mut state = State::new(&tree);
    let mut rays = solve::LeafRays::default();
    state.add_sources_keeping(&tree, &lit.emission, lit.lights.as_ref(), &mut rays);
    state.start_from_sources(&tree);
    let oracle = Oracle::of(hs, state.source_power(&tree), total_area);
    let mut hierarchy = Hierarchy::new(tree, oracle, splits_for(hs), hs.moves);
    let mut stats = HierarchyStats { faces: hierarchy.tree.faces.len(), ..Default::default() };
    let rule = GaussLegendre::new(scene.settings.quadrature_order);
    let ctx = link_context(scene, hs, &rule, lit.occluders.as_ref());
    link_and_solve(
        &mut hierarchy,
        &mut state,
        &ctx,
        (&lit, &mut rays),
        hs,
        Start::Root,
        &mut stats,
        progress,
    )?;
    finish(hierarchy, state, stats, (lit, rays), scene, frame, hs, None, progress)
}

/// Each face's reflectance, in `faces`' order.
fn face_reflectance(scene: &Scene, faces: &[crate::system::Element]) -> Vec<[f64; 3]> {
    faces.iter().map(|e| scene.reflectance_of(e.object as usize, e.face as usize, e.material)).collect()
}

/// What lights one frame's faces and what stands between them.
pub struct Lighting {
    /// Each face's exitance.
    pub emission: Vec<[f64; 3]>,
    pub occluders: Option<Occluders>,
    pub lights: Option<DirectLight>,
    /// The source power's share a sweep may still change the leaves by when the solve stops.
    tolerance: f64,
}

impl Lighting {
    pub fn new(scene: &Scene, frame: f64, faces: &[crate::system::Element]) -> Self {
        let s = &scene.settings;
        let patches: Vec<Patch> = faces.iter().map(|e| e.patch).collect();
        Self {
            emission: faces.iter().map(|e| e.emission(scene, frame)).collect(),
            occluders: s
                .visibility
                .then(|| crate::system::occluders_of(faces, &patches, s.visibility_samples)),
            lights: DirectLight::new(scene, frame, faces),
            tolerance: s.tolerance,
        }
    }
}

impl Oracle {
    /// The settings' oracle for sources of `power` (W) in a scene of `total_area`.
    fn of(hs: &HierarchySettings, power: f64, total_area: f64) -> Self {
        Oracle {
            threshold: hs.accuracy * power,
            min_area: hs.min_area * total_area,
            max_depth: hs.max_depth,
            clusters: hs.clusters,
            cluster_separation: hs.cluster_separation,
            light_links: hs.light_links,
        }
    }
}

pub fn link_context<'a>(
    scene: &Scene,
    hs: &HierarchySettings,
    rule: &'a GaussLegendre,
    occluders: Option<&'a Occluders>,
) -> LinkContext<'a> {
    let s = &scene.settings;
    let mut ctx = LinkContext::new(
        PairContext {
            basis: Basis::new(s.basis_order),
            rule,
            vis_axis: s.visibility_samples,
            adaptive: s.adaptive_quadrature,
        },
        occluders,
    );
    ctx.near = hs.near;
    ctx
}

/// Where a frame's first round of links starts.
enum Start {
    /// The root's interaction with itself: every link made anew.
    Root,
    /// These pairs (a move touched them); the other links are kept.
    Pairs(Vec<(tree::NodeId, tree::NodeId)>),
}

/// The first link-and-solve round's share of the "links" stage's progress.
const FIRST_ROUND: f64 = 0.9;

/// The link-and-solve rounds: link (from `start` in the first round, then where the solution's
/// brightness asks for it), solve, until no link changes or `hs.rounds` are done.
#[allow(clippy::too_many_arguments)]
fn link_and_solve(
    hierarchy: &mut Hierarchy,
    state: &mut State,
    ctx: &LinkContext,
    (lit, rays): (&Lighting, &mut solve::LeafRays),
    hs: &HierarchySettings,
    start: Start,
    stats: &mut HierarchyStats,
    progress: Progress,
) -> Result<()> {
    let cancel = || !progress(0.0, "hierarchy");
    let stop = lit.tolerance * state.source_power(&hierarchy.tree);
    let mut start = Some(start);
    // The first round makes the links (from the root or from a move's pairs), the others only
    // test them again and refine the few that fail: the first round is most of the "links"
    // stage's time (the 30k-triangle monastery's first frame: 17 s of 18), and was given a third
    // of it, so that the stage's own rate said 3x its time left until it ended.
    let rounds = hs.rounds.max(1);
    let span = |r: usize| match (rounds, r) {
        (1, _) => 1.0,
        (_, 0) => FIRST_ROUND,
        _ => (1.0 - FIRST_ROUND) / (rounds - 1) as f64,
    };
    let start_of = |r: usize| (0..r).map(span).sum::<f64>();
    for round in 0..rounds {
        if !progress(start_of(round), "links") {
            return Err(Error::Cancelled);
        }
        let t = Instant::now();
        let mut radiosity = state.radiosity_estimate();
        let (from, width) = (start_of(round), span(round));
        let linked = |f: f64| progress(from + width * f, "links");
        match start.take() {
            Some(Start::Root) => {
                let linked = hierarchy.link_all(ctx, &mut radiosity, &linked)?;
                stats.compute_seconds += linked.compute_seconds;
                stats.reused_casts += linked.reused_casts;
            }
            Some(Start::Pairs(work)) => {
                let linked = hierarchy.link_pairs(ctx, &mut radiosity, work, &linked)?;
                stats.compute_seconds += linked.compute_seconds;
                stats.reused_casts += linked.reused_casts;
            }
            None => {
                let relinked = hierarchy.relink(ctx, &mut radiosity, &linked)?;
                stats.compute_seconds += relinked.compute_seconds;
                stats.reused_casts += relinked.reused_casts;
                stats.retested += relinked.tested;
                stats.quick_relinks += usize::from(relinked.quick);
                if relinked.relinked == 0 {
                    break;
                }
            }
        }
        state.grow(&hierarchy.tree)?;
        state.add_sources_keeping(&hierarchy.tree, &lit.emission, lit.lights.as_ref(), rays);
        let linking = t.elapsed().as_secs_f64();
        stats.link_seconds += linking;
        *(if round == 0 { &mut stats.first_link_seconds } else { &mut stats.relink_seconds }) += linking;
        let t = Instant::now();
        let (nodes, nb) = (hierarchy.tree.nodes.len(), hierarchy.tree.basis.len());
        let (links, tree) = (&hierarchy.links, &hierarchy.tree);
        let geometry = |r, s, t| solve::cluster_entry(tree, r, s, t);
        packed::PackedLinks::update(
            &mut hierarchy.packed,
            nodes,
            links,
            nb,
            &mut hierarchy.changes,
            &geometry,
        )?;
        let packing = t.elapsed().as_secs_f64();
        let packed = hierarchy.packed.as_mut().expect("packed just now");
        let solved = state.solve_packed(&hierarchy.tree, packed, stop, hs, &cancel)?;
        stats.sweeps += solved.sweeps;
        stats.furnaces += 1;
        stats.furnace_rows += solved.furnace_rows;
        let solving = t.elapsed().as_secs_f64();
        stats.solve_seconds += solving;
        stats.pack_seconds += packing;
        stats.furnace_seconds += solved.furnace_seconds;
        stats.sweep_seconds += solving - packing - solved.furnace_seconds;
    }
    Ok(())
}

/// The frame's counts and, with `hs.corner_gather`, its gathered corners (taking what `kept`,
/// the last frame's gather, holds where the frame's changes spare it); the frame keeps its lights
/// and its leaves' shadow rays (`lit`, `rays`) for the next.
#[allow(clippy::too_many_arguments)]
fn finish(
    hierarchy: Hierarchy,
    state: State,
    mut stats: HierarchyStats,
    (lit, rays): (Lighting, solve::LeafRays),
    scene: &Scene,
    frame: f64,
    hs: &HierarchySettings,
    kept: Option<(&gather::KeptGather, gather::Changes)>,
    progress: Progress,
) -> Result<HierarchicalFrame> {
    stats.nodes = hierarchy.tree.nodes.len();
    let mut leaves = Vec::new();
    hierarchy.tree.leaves_below(hierarchy.tree.root, &mut leaves);
    stats.leaves = leaves.len();
    stats.links = hierarchy.links.len();
    // The counts in one pass over the links, the frame's largest store (15M on the full
    // monastery: 0.08 s of an updated frame in turn).
    let count = |[s, c, b]: [usize; 3], l: &coupling::Link| match &l.coupling {
        coupling::Coupling::Surfaces(x) => [s + 1, c, b + x.len()],
        coupling::Coupling::Constants { .. } => [s, c + 1, b],
        coupling::Coupling::Clusters { .. } => [s, c, b],
    };
    let [surfaces, constants, blocks] = hierarchy
        .links
        .par_iter()
        .fold(|| [0; 3], count)
        .reduce(|| [0; 3], |x, y| [x[0] + y[0], x[1] + y[1], x[2] + y[2]]);
    stats.surface_links = surfaces;
    stats.constant_links = constants;
    stats.cluster_links = stats.links - surfaces - constants;
    stats.link_bytes = (std::mem::size_of::<coupling::Link>() + 4) * stats.links + 4 * blocks;
    stats.pair_tree = hierarchy.splits.len();
    stats.pair_tree_bytes = hierarchy.splits.bytes();
    let (mut corners, mut kept_gather) = (None, None);
    if hs.corner_gather {
        let t = Instant::now();
        let inputs = gather::Inputs::new(&hierarchy, &state, &lit);
        let cap = if hs.keep_gather {
            gather::KeptGather::cap(crate::budget::budget_bytes(scene.settings.memory_budget_mb))
        } else {
            0
        };
        let keeping = gather::Keeping { from: kept, cap };
        let g = gather::corners_keeping(&inputs, scene, frame, progress, gather::Mode::Fast, keeping)?;
        stats.gather_points = g.counts.points;
        stats.gather_kept = g.reuse.kept;
        stats.gather_computed = g.reuse.computed;
        stats.gather_seconds = t.elapsed().as_secs_f64();
        corners = Some((g.radiosity, g.irradiance));
        stats.kept_gather_bytes = g.kept.as_ref().map_or(0, |k| k.bytes());
        kept_gather = g.kept;
    }
    (stats.direct_rays_traced, stats.direct_rays_taken) = (rays.counts.traced, rays.counts.taken);
    let direct = lit.lights.map(std::sync::Arc::new);
    if let Some(k) = &mut kept_gather {
        k.lights = direct.clone();
    }
    Ok(HierarchicalFrame {
        hierarchy,
        state,
        stats,
        corners,
        kept_gather,
        moved_since_gather: None,
        direct,
        leaf_rays: rays.into_kept(),
    })
}

impl HierarchicalFrame {
    /// The index among the tree's faces of face `f` of object `o` (its front); `None` for a
    /// face skipped for having no area.
    pub fn face_index(&self, o: usize, f: usize) -> Option<usize> {
        let faces = &self.hierarchy.tree.faces;
        let key = (o as u32, f as u32, false);
        faces.binary_search_by(|e| (e.object, e.face, e.back).cmp(&key)).ok()
    }

    /// Area-mean `B` of face `f` (index into the tree's faces).
    pub fn face_mean(&self, f: usize) -> [f64; 3] {
        self.state.mean[f]
    }

    /// `B` at face parameter `(s,t)` of face `f` (face corner order), from the leaf there.
    pub fn eval_face(&self, f: usize, s: f64, t: f64) -> [f64; 3] {
        let tree = &self.hierarchy.tree;
        let s = if tree.faces[f].mirrored { 1.0 - s } else { s };
        let (leaf, ls, lt) = tree.leaf_at(f, s, t);
        let c = self.state.coefficients(leaf);
        let g = tree.basis.eval(ls, lt);
        let mut out = [0.0; 3];
        for (k, gk) in g.iter().enumerate() {
            for ch in 0..3 {
                out[ch] += gk * c[k][ch];
            }
        }
        out
    }

    /// `B` at a triangle's apex (its collapsed edge `t = 1`): the mean over that edge of the
    /// leaf at the middle of it, as [`crate::system::System`] takes it.
    fn apex(&self, f: usize) -> [f64; 3] {
        let tree = &self.hierarchy.tree;
        let (leaf, _, _) = tree.leaf_at(f, 0.5, 1.0);
        let n = tree.basis.order() + 1;
        let pt = crate::basis::legendre_1d(1.0);
        let c = self.state.coefficients(leaf);
        let mut out = [0.0; 3];
        for b in 0..n {
            for ch in 0..3 {
                out[ch] += pt[b] * c[b][ch];
            }
        }
        out
    }

    /// Per object, per face: the mean `B` and `B` at each corner (gathered, else from the leaf
    /// polynomials), as [`crate::system::System::face_results`] reports them.
    pub fn face_results(&self, scene: &Scene, frame: f64) -> Vec<ObjectResult> {
        let tree = &self.hierarchy.tree;
        let to_f32 = |v: [f64; 3]| v.map(|x| x as f32);
        let mut out = Vec::with_capacity(scene.objects.len());
        // (A back, crate::backs, is read back nowhere.)
        let mut faces = tree.faces.iter().enumerate().filter(|(_, e)| !e.back).peekable();
        for (o, obj) in scene.objects.iter().enumerate() {
            let mut res = ObjectResult {
                name: obj.name.clone(),
                face_radiosity: Vec::with_capacity(obj.faces.len()),
                corner_radiosity: Vec::new(),
                corner_irradiance: Vec::new(),
            };
            for (fi, face) in obj.faces.iter().enumerate() {
                match faces.peek() {
                    Some((f, e)) if e.object as usize == o && e.face as usize == fi => {
                        let f = *f;
                        faces.next();
                        res.face_radiosity.push(to_f32(self.face_mean(f)));
                        let material = obj.face_materials[fi];
                        let rho = scene.reflectance_of(o, fi, material);
                        let emission = scene.emission_of(o, fi, material, frame);
                        for (s, t) in corner_params(face.len()) {
                            let v = if face.len() == 3 && t == 1.0 {
                                self.apex(f)
                            } else {
                                self.eval_face(f, s, t)
                            };
                            res.corner_radiosity.push(to_f32(v));
                            res.corner_irradiance.push(to_f32(irradiance_from_radiosity(v, emission, rho)));
                        }
                    }
                    _ => {
                        let e = to_f32(scene.emission_of(o, fi, obj.face_materials[fi], frame));
                        res.face_radiosity.push(e);
                        res.corner_radiosity.extend(std::iter::repeat_n(e, face.len()));
                        res.corner_irradiance.extend(std::iter::repeat_n([0.0; 3], face.len()));
                    }
                }
            }
            if let Some((radiosity, irradiance)) = &self.corners {
                res.corner_radiosity = radiosity[o].iter().map(|&v| to_f32(v)).collect();
                res.corner_irradiance = irradiance[o].iter().map(|&v| to_f32(v)).collect();
            }
            out.push(res);
        }
        out
    }
}
