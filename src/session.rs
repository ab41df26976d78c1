//! A baking session: a scene, its thread pool, and the solution of the last completed frame.
//! The CLI, the C ABI and the Blender add-on all drive this type.
//!
//! Frames are solved by one of three [`Method`]s. A host may override an object's placement or a
//! material's emission for the coming frames (the add-on samples Blender's depsgraph); otherwise
//! the scene's keys apply. A cancelled frame leaves the last completed frame readable.

use std::time::Instant;

use glam::DMat4;

use crate::animation::{self, AnimationState, Outcome};
use crate::error::{Error, Result};
use crate::finite::{check_results, clamp_rounding};
use crate::gather::GatherStats;
use crate::lights::direct::DirectLight;
use crate::scene::json::ObjectResult;
use crate::scene::{MAX_EMISSION, Scene, check_placed};
use crate::solver;
use crate::system::{Progress, System};

/// How each frame after the first is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The seed's update: series for translated links, exact recompute at discontinuities,
    /// progressive shooting of the differences.
    Incremental,
    /// Incremental, but every changed link recomputed by quadrature (no series).
    Exact,
    /// Every frame from scratch: all links recomputed, fresh solve.
    Full,
    /// On the hierarchy of clusters and elements below faces ([`crate::hierarchy`]): what
    /// scenes of 10^4 faces and more need. The first frame is solved from scratch, each later
    /// one from the frame before ([`crate::hierarchy::update`]: only the pairs a move touched
    /// are linked again, the solve starts from the last solution). Corners are gathered
    /// through the links ([`crate::hierarchy::gather`]) with `corner_gather` on, else read from
    /// the leaves' polynomials (as in a preview).
    Hierarchical,
}

/// What one frame cost and did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct FrameStats {
    pub frame: f64,
    pub seconds: f64,
    pub kernel_seconds: f64,
    /// Of `kernel_seconds` on an updated frame, the kernel update's phases
    /// ([`crate::animation::UpdateStats`]): finding the candidate pairs (with the frame's
    /// occluders), computing them, and writing them into the store with their `Delta K` products.
    pub kernel_scan_seconds: f64,
    pub kernel_pairs_seconds: f64,
    pub kernel_apply_seconds: f64,
    pub solve_seconds: f64,
    pub elements: usize,
    pub pairs: usize,
    pub links_series: usize,
    pub links_recomputed: usize,
    pub recomputed_bound: usize,
    /// Series abandoned because the motion left the expansion direction (a curved path).
    pub recomputed_direction: usize,
    /// Pairs (re-)expanded into a series this frame.
    pub series_expanded: usize,
    /// Pairs holding a series after this frame, and the bytes of their terms.
    pub series_pairs: usize,
    pub series_bytes: usize,
    pub recomputed_half_space: usize,
    pub recomputed_visibility: usize,
    pub recomputed_non_translation: usize,
    /// Pairs with a moved element whose motion is a pure translation.
    pub recomputed_translation: usize,
    /// Shots of the progressive solve; on the hierarchy, its Jacobi sweeps.
    pub shots: usize,
    /// How much of the last frame's shots the solve replayed first ([`crate::replay`]): near 1
    /// under steady motion, 0 without a replay.
    pub replay_scale: f64,
    /// Time of the corner gather ([`crate::gather`]), included in `seconds`.
    pub gather_seconds: f64,
    /// (Corner, source) moments of the gather, and how many were computed this frame (the rest
    /// were kept from the last frame).
    pub gather_moments: usize,
    pub gather_recomputed: usize,
    /// The lights' shadow rays for the frame's direct light: traced, and taken from the last
    /// frame's where no move could have changed them (updated frames of the flat path;
    /// [`crate::lights::direct::DirectLight::project_keeping`]).
    pub direct_rays_traced: u64,
    pub direct_rays_taken: u64,
    /// The frame was built from scratch (first frame, `--full`, or after a topology change).
    pub full_rebuild: bool,
    /// The frame is a preview ([`Session::set_preview`]): solved to [`preview_tolerance`],
    /// corners from the face polynomials, until [`Session::refine`].
    pub preview: bool,
    /// One line each, for the host to show (emitters that light nothing, on rebuilt frames).
    pub warnings: Vec<String>,
}

/// The tolerance a preview frame is solved to: ten times the scene's, but no looser than 1e-3
/// (where the scene's is finer than 1e-3), never finer than the scene's. At the default 1e-4
/// that is 1e-3: worst corner 1% of the mean radiosity off a converged solve, for 40% of the
/// solve's time (README, the tolerance sweep).
pub fn preview_tolerance(tolerance: f64) -> f64 {
    tolerance.max((10.0 * tolerance).min(1e-3))
}

/// What [`Session::refine`] did to a preview frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Refinement {
    /// The rest of the solve: its time and the coefficient columns shot.
    pub solve_seconds: f64,
    pub shots: usize,
    /// The frame was built and solved afresh instead (its links were those of a cancelled
    /// update): the kernels' time, and the solve's above.
    pub rebuilt: Option<f64>,
    /// The corner gather's time and counts (`None` with `corner_gather` off).
    pub gather: Option<(f64, GatherStats)>,
}

impl FrameStats {
    /// The frame's statistics once `r` refined it: its solve's and gather's parts those of the
    /// whole frame, no longer a preview.
    pub fn refined(mut self, r: &Refinement) -> FrameStats {
        let kernel_seconds = r.rebuilt.unwrap_or(0.0);
        self.seconds += kernel_seconds + r.solve_seconds + r.gather.map_or(0.0, |g| g.0);
        self.kernel_seconds += kernel_seconds;
        self.solve_seconds += r.solve_seconds;
        self.shots += r.shots;
        if let Some((seconds, g)) = r.gather {
            (self.gather_seconds, self.gather_moments, self.gather_recomputed) =
                (seconds, g.moments, g.recomputed);
        }
        self.preview = false;
        self.full_rebuild |= r.rebuilt.is_some();
        self
    }
}

/// The corner gather of `sys` placed as `placed` is at `frame`, and its time in seconds.
fn timed_gather(
    sys: &mut System,
    placed: &Scene,
    frame: f64,
    progress: Progress,
) -> Result<(f64, GatherStats)> {
    let start = Instant::now();
    let g = sys.gather_corners(placed, frame, progress)?;
    Ok((start.elapsed().as_secs_f64(), g))
}

pub struct Session {
    scene: Scene,
    method: Method,
    pool: rayon::ThreadPool,
    /// Host overrides of world-from-object, per object.
    placement: Vec<Option<DMat4>>,
    /// Host overrides of emission, per material.
    emission: Vec<Option<[f64; 3]>>,
    /// Host override of the lights ([`Session::set_lights`]).
    lights: Option<Vec<crate::lights::Light>>,
    /// Host override of the World ([`Session::set_world`]): `Some(None)` is no World.
    world: Option<Option<crate::lights::World>>,
    /// Host override of the two-sided objects ([`Session::set_two_sided`]).
    two_sided: Option<Vec<bool>>,
    system: Option<System>,
    /// What the incremental update keeps between frames (series, shape epochs).
    animation: Option<AnimationState>,
    /// The readable frame when the method is [`Method::Hierarchical`].
    hierarchical: Option<crate::hierarchy::HierarchicalFrame>,
    /// The links belong to a cancelled update: the next frame rebuilds from scratch.
    stale: bool,
    frame: Option<f64>,
    /// Frames are solved as previews ([`Session::set_preview`]).
    preview: bool,
    /// The readable frame is a preview that [`Session::refine`] has not refined.
    unrefined: bool,
    /// No object will be moved by [`Session::set_object_matrix`] ([`Session::set_still`]).
    still: bool,
    /// Frames will follow, whatever the scene's own frames ([`Session::set_animated`]).
    animated: bool,
}

impl Session {
    /// Refused at once when the scene's estimated memory is over its budget
    /// ([`crate::budget::check`], one frame's results kept).
    pub fn new(scene: Scene, method: Method) -> Result<Self> {
        if method == Method::Hierarchical {
            crate::budget::check_hierarchical(&scene, 1)?;
        } else {
            crate::budget::check(&scene, 1)?;
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(scene.settings.threads)
            .build()
            .map_err(|e| Error::Internal(format!("thread pool: {e}")))?;
        let placement = vec![None; scene.objects.len()];
        let emission = vec![None; scene.materials.len()];
        Ok(Self {
            scene,
            method,
            pool,
            placement,
            emission,
            lights: None,
            world: None,
            two_sided: None,
            system: None,
            animation: None,
            hierarchical: None,
            stale: false,
            frame: None,
            preview: false,
            unrefined: false,
            still: false,
            animated: false,
        })
    }

    /// Says that frames will follow the next one, moved by the scene's keys or by
    /// [`Session::set_object_matrix`] (a host that bakes an animation, or previews while the
    /// timeline is scrubbed, from a scene of one frame): the hierarchy then keeps its pair tree,
    /// so that its updates link coarser again where a move has passed
    /// ([`crate::hierarchy::pair_tree`]), as it does for a scene whose own frames span more
    /// than one. Set before the first frame: a change after it solves the next frame afresh.
    pub fn set_animated(&mut self, on: bool) {
        self.animated = on;
    }

    /// Promises that no object will be moved by [`Session::set_object_matrix`] (a bake of a scene
    /// file): the hierarchy of a scene whose own frames do not move it then keeps less
    /// ([`crate::hierarchy::HierarchySettings::moves`]: 0.34 GB of the full monastery's 2.4).
    /// Moving an object after all is still right: the frame after it is solved afresh.
    pub fn set_still(&mut self) {
        self.still = true;
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn method(&self) -> Method {
        self.method
    }

    /// The frame whose solution is readable, if any.
    pub fn frame(&self) -> Option<f64> {
        self.frame
    }

    /// Overrides object `o`'s world-from-object matrix from the next solved frame on.
    pub fn set_object_matrix(&mut self, o: usize, world_from_object: DMat4) -> Result<()> {
        if o >= self.scene.objects.len() {
            return Err(Error::InvalidArgument(format!(
                "object {o} out of range (0..{})",
                self.scene.objects.len()
            )));
        }
        if !world_from_object.is_finite() {
            return Err(Error::InvalidArgument(format!("object {o}: matrix is not finite")));
        }
        self.placement[o] = Some(world_from_object);
        self.still = false;
        Ok(())
    }

    /// Overrides material `m`'s emission from the next solved frame on.
    pub fn set_material_emission(&mut self, m: usize, emission: [f64; 3]) -> Result<()> {
        if m >= self.scene.materials.len() {
            return Err(Error::InvalidArgument(format!(
                "material {m} out of range (0..{})",
                self.scene.materials.len()
            )));
        }
        if emission.iter().any(|e| !e.is_finite() || *e < 0.0 || *e > MAX_EMISSION) {
            return Err(Error::InvalidArgument(format!(
                "material {m}: emission {emission:?} must be finite, >= 0 and at most {MAX_EMISSION:e}"
            )));
        }
        self.emission[m] = Some(emission);
        Ok(())
    }

    /// While `on`, [`Session::solve_frame`] solves previews: to [`preview_tolerance`] instead of
    /// the scene's tolerance, and without the corner gather (the corners are the face
    /// polynomials'), until [`Session::refine`] finishes the frame. For a host that previews
    /// while the timeline is scrubbed: such a frame costs its kernel update and a shorter solve,
    /// and only the frame the user stops on is refined. Progressive refinement keeps
    /// `b = e + K (b - u)` at every shot, so refining continues the preview's shooting where it
    /// stopped, and the next frame's update starts from whichever state is readable.
    pub fn set_preview(&mut self, on: bool) {
        self.preview = on;
    }

    /// Whether the readable frame is a preview not yet refined.
    pub fn unrefined(&self) -> bool {
        self.unrefined && (self.system.is_some() || self.hierarchical.is_some())
    }

    /// Brings the readable frame from a preview to what [`Session::solve_frame`] gives without
    /// previews: shoots the rest of its solve down to the scene's tolerance, then gathers its
    /// corners (with `corner_gather` on), updating the last gather made whatever frame that was
    /// (what moved since is recomputed, as between two consecutive frames). Returns what it
    /// did, or `None` when the frame was no preview. On error (including cancel) the frame
    /// stays readable and still a preview: its solution as far as the shooting came (a
    /// consistent state, closer to converged), its corners the polynomials' (after a cancel
    /// inside the gather, the next gather starts afresh). After a cancelled
    /// [`Session::solve_frame`] the readable frame's solution is back but its links are the
    /// cancelled frame's, so the frame is then built and solved afresh
    /// ([`Refinement::rebuilt`]). On [`Method::Hierarchical`] the preview is updated with
    /// nothing moved (its links kept, the solve warm-started to the tolerance, relinked where
    /// the brighter solution asks for it) and its corners gathered.
    pub fn refine(&mut self, progress: Progress) -> Result<Option<Refinement>> {
        if !self.unrefined() {
            return Ok(None);
        }
        let frame = self.frame.expect("a system is only kept with its frame");
        let placed = self.scene_at(frame);
        if self.method == Method::Hierarchical && self.hierarchical.is_some() {
            // The frame updated from its preview with nothing moved: its links kept, the solve
            // warm-started to the scene's tolerance, then its corners gathered.
            let start = Instant::now();
            let s = self.solve_hierarchical(&placed, frame, start, false, progress)?;
            return Ok(Some(Refinement {
                solve_seconds: s.solve_seconds,
                shots: s.shots,
                rebuilt: s.full_rebuild.then_some(s.kernel_seconds),
                gather: placed.settings.corner_gather.then_some((s.gather_seconds, GatherStats::default())),
            }));
        }
        if self.stale {
            // The next frame's update was cancelled: its solution was put back, its links were
            // not, and shooting through them would mix the two frames. Solved afresh.
            let (system, seconds, g) =
                self.rebuild(&placed, frame, placed.settings.corner_gather, progress)?;
            check_results(&system.face_results(&placed, frame), &placed, frame)?;
            let r = Refinement {
                rebuilt: Some(system.stats.kernel_seconds),
                solve_seconds: system.stats.solve_seconds,
                shots: system.stats.shots,
                gather: placed.settings.corner_gather.then_some((seconds, g)),
            };
            self.keep_rebuilt(system, frame);
            self.unrefined = false;
            return Ok(Some(r));
        }
        let sys = self.system.as_mut().expect("checked by unrefined");
        let cancel = || !progress(1.0, "solve");
        let refinement = self.pool.install(|| -> Result<Refinement> {
            let start = Instant::now();
            // A preview's lights were projected coarsely: projected again in full, the change
            // entering as Delta e (eq. 9) before the shooting goes on.
            if sys.lights.as_deref().is_some_and(DirectLight::is_preview) {
                sys.replace_sources(crate::system::frame_sources(
                    &placed,
                    frame,
                    &sys.elements,
                    sys.basis,
                    None,
                ));
            }
            let stop = placed.settings.tolerance * sys.emitted_power();
            let shot = solver::shoot(&sys.links, &sys.reflectance, &mut sys.solution, stop, &cancel)?;
            let solve_seconds = start.elapsed().as_secs_f64();
            let mut gather = None;
            if placed.settings.corner_gather {
                gather = Some(timed_gather(sys, &placed, frame, progress)?);
            }
            Ok(Refinement { solve_seconds, shots: shot.shots, rebuilt: None, gather })
        })?;
        if let Err(e) = check_results(&sys.face_results(&placed, frame), &placed, frame) {
            // The frame's own solution went bad: nothing readable is left to keep.
            (self.system, self.animation, self.frame) = (None, None, None);
            return Err(e);
        }
        self.unrefined = false;
        Ok(Some(refinement))
    }

    /// Replaces object `o`'s surface data ([`crate::scene::Surface`]: shading normals, per-face
    /// reflectance and emission scale); the next solved frame is built afresh with them. On
    /// error nothing changes.
    pub fn set_surface(&mut self, o: usize, surface: crate::scene::Surface) -> Result<()> {
        self.scene.set_surface(o, surface)?;
        self.stale = true;
        Ok(())
    }

    /// Object `o`'s surface data (the default, empty one where it has none).
    pub fn surface(&self, o: usize) -> crate::scene::Surface {
        self.scene.surfaces.get(o).cloned().unwrap_or_default()
    }

    /// Replaces only object `o`'s emission scale per face ([`crate::scene::Surface::face_emission`],
    /// empty: 1), keeping its other surface data; validated, and on error nothing changes.
    pub fn set_face_emission(&mut self, o: usize, face_emission: Vec<[f64; 3]>) -> Result<()> {
        let surface = crate::scene::Surface { face_emission, ..self.surface(o) };
        self.set_surface(o, surface)
    }

    /// Replaces the scene's lights from the next solved frame on (a host sampling its own
    /// animation sets them each frame); validated as a scene's are.
    pub fn set_lights(&mut self, lights: Vec<crate::lights::Light>) -> Result<()> {
        crate::lights::validate(&lights)?;
        self.lights = Some(lights);
        Ok(())
    }

    /// Replaces the scene's World from the next solved frame on (`None`: black); validated as a
    /// scene's is.
    pub fn set_world(&mut self, world: Option<crate::lights::World>) -> Result<()> {
        if let Some(w) = &world {
            w.validate()?;
        }
        self.world = Some(world);
        Ok(())
    }

    /// Makes object `o`'s emitting faces emit from both sides (or only their front) from the
    /// next solved frame on.
    pub fn set_two_sided(&mut self, o: usize, on: bool) -> Result<()> {
        let n = self.scene.objects.len();
        if o >= n {
            return Err(Error::InvalidArgument(format!("object {o} out of range (0..{n})")));
        }
        let flags = self.two_sided.get_or_insert_with(|| {
            (0..n).map(|i| self.scene.two_sided.get(i).copied().unwrap_or(false)).collect()
        });
        flags[o] = on;
        Ok(())
    }

    /// Face `f` of object `o`'s exitance at `frame` as the solved frames see it: the host's
    /// override of its material's emission where set (else the keyed one), times the face's
    /// emission scale ([`Scene::emission_scale`]), which an override does not replace.
    fn face_exitance(&self, o: usize, f: usize, frame: f64) -> [f64; 3] {
        let m = self.scene.objects[o].face_materials[f] as usize;
        let e = self.emission[m].unwrap_or_else(|| self.scene.emission_at(m, frame));
        crate::scene::scaled(e, self.scene.emission_scale(o, f))
    }

    /// The scene as placed at `frame`: keys, then host overrides.
    fn scene_at(&self, frame: f64) -> Scene {
        let mut scene = self.scene.clone();
        if let Some(lights) = &self.lights {
            scene.lights = lights.clone();
        }
        if let Some(world) = &self.world {
            scene.world = world.clone();
        }
        if let Some(two_sided) = &self.two_sided {
            scene.two_sided = two_sided.clone();
        }
        for (o, obj) in scene.objects.iter_mut().enumerate() {
            obj.matrix = self.placement[o].unwrap_or_else(|| obj.world_from_object(frame));
            obj.animation.clear();
        }
        for (m, mat) in scene.materials.iter_mut().enumerate() {
            mat.emission = self.emission[m].unwrap_or_else(|| self.scene.emission_at(m, frame));
            scene.emission_keys[m].clear();
        }
        scene
    }

    /// Solves `frame`. On error (including cancel) the previous frame stays readable.
    pub fn solve_frame(&mut self, frame: f64, progress: Progress) -> Result<FrameStats> {
        if !frame.is_finite() {
            return Err(Error::InvalidArgument(format!("frame {frame} is not finite")));
        }
        let start = Instant::now();
        let mut placed = self.scene_at(frame);
        check_placed(&placed, frame)?;
        if self.preview {
            placed.settings.tolerance = preview_tolerance(placed.settings.tolerance);
            // (The hierarchy's refinement projects every leaf's light again whatever moved: its
            // previews keep the full rule, and their kept rays.)
            placed.settings.preview_lights = self.method != Method::Hierarchical;
        }
        if self.method == Method::Hierarchical {
            return self.solve_hierarchical(&placed, frame, start, self.preview, progress);
        }
        let gather = placed.settings.corner_gather && !self.preview;
        let incremental = self.method != Method::Full && !self.stale;
        if let (true, Some(sys), Some(state)) = (incremental, self.system.as_mut(), self.animation.as_mut()) {
            // Keep what reads need, so a cancelled update leaves the last frame readable.
            let saved = (
                sys.solution.clone(),
                sys.elements.clone(),
                sys.emission.clone(),
                sys.reflectance.clone(),
                sys.corners.take(),
                sys.corner_irradiance.take(),
            );
            let outcome = self.pool.install(|| {
                let outcome = animation::advance(sys, state, &placed, frame, progress)?;
                if let (Outcome::Updated(_), true) = (&outcome, gather) {
                    return Ok((outcome, timed_gather(sys, &placed, frame, progress)?));
                }
                Ok((outcome, (0.0, GatherStats::default())))
            });
            // A frame whose values are not all finite is not kept (`crate::finite`).
            let outcome = outcome.and_then(|(o, g)| {
                if let Outcome::Updated(_) = o {
                    check_results(&sys.face_results(&placed, frame), &placed, frame)?;
                }
                Ok((o, g))
            });
            match outcome {
                Ok((Outcome::Updated(u), (gather_seconds, g))) => {
                    let stats = FrameStats {
                        frame,
                        seconds: start.elapsed().as_secs_f64(),
                        kernel_seconds: u.kernel_seconds,
                        kernel_scan_seconds: u.scan_seconds,
                        kernel_pairs_seconds: u.pairs_seconds,
                        kernel_apply_seconds: u.apply_seconds,
                        solve_seconds: u.solve_seconds,
                        elements: sys.elements.len(),
                        pairs: sys.links.len(),
                        links_recomputed: u.links_recomputed,
                        recomputed_visibility: u.recomputed_visibility,
                        recomputed_bound: u.recomputed_bound,
                        recomputed_direction: u.recomputed_direction,
                        recomputed_half_space: u.recomputed_half_space,
                        links_series: u.links_series,
                        series_expanded: u.series_expanded,
                        series_pairs: state.series_memory().0,
                        series_bytes: state.series_memory().1,
                        recomputed_non_translation: u.recomputed_non_translation,
                        recomputed_translation: u.recomputed_translation,
                        shots: u.shots,
                        replay_scale: u.replay_scale,
                        gather_seconds,
                        gather_moments: g.moments,
                        gather_recomputed: g.recomputed,
                        direct_rays_traced: u.direct_rays_traced,
                        direct_rays_taken: u.direct_rays_taken,
                        preview: self.preview,
                        ..Default::default()
                    };
                    self.frame = Some(frame);
                    self.unrefined = self.preview;
                    return Ok(stats);
                }
                Ok((Outcome::NeedsRebuild, _)) => {}
                Err(e) => {
                    (
                        sys.solution,
                        sys.elements,
                        sys.emission,
                        sys.reflectance,
                        sys.corners,
                        sys.corner_irradiance,
                    ) = saved;
                    self.stale = true;
                    return Err(e);
                }
            }
        }
        let (system, gather_seconds, g) = self.rebuild(&placed, frame, gather, progress)?;
        check_results(&system.face_results(&placed, frame), &placed, frame)?;
        let stats = FrameStats {
            frame,
            seconds: start.elapsed().as_secs_f64(),
            kernel_seconds: system.stats.kernel_seconds,
            solve_seconds: system.stats.solve_seconds,
            elements: system.stats.elements,
            pairs: system.stats.pairs,
            links_recomputed: system.stats.pairs,
            shots: system.stats.shots,
            gather_seconds,
            gather_moments: g.moments,
            gather_recomputed: g.recomputed,
            full_rebuild: true,
            preview: self.preview,
            warnings: system.stats.warnings.clone(),
            ..Default::default()
        };
        self.keep_rebuilt(system, frame);
        self.unrefined = self.preview;
        Ok(stats)
    }

    /// [`Method::Hierarchical`]'s frame: solved from scratch on its own hierarchy, kept only when
    /// its results are finite (else the last frame stays readable).
    fn solve_hierarchical(
        &mut self,
        placed: &Scene,
        frame: f64,
        start: Instant,
        preview: bool,
        progress: Progress,
    ) -> Result<FrameStats> {
        // Nothing with area to link: the flat path's frame of exitances (as a flat session bakes
        // an empty scene), not an error.
        if crate::system::build_elements(placed, frame, crate::basis::Basis::new(0)).is_empty() {
            let (system, _, _) = self.rebuild(placed, frame, false, progress)?;
            self.hierarchical = None;
            self.keep_rebuilt(system, frame);
            return Ok(FrameStats {
                frame,
                seconds: start.elapsed().as_secs_f64(),
                full_rebuild: true,
                ..Default::default()
            });
        }
        let mut settings = crate::hierarchy::HierarchySettings::of(&placed.settings);
        // A preview reads the leaves, as the flat path's preview skips its gather.
        settings.corner_gather &= !preview;
        // An animation's updates coarsen where a move has passed (`hierarchy::pair_tree`); a still
        // scene's hierarchy need not keep what only a move could change.
        settings.keep_pair_tree = placed.is_animation() || self.animated;
        settings.keep_gather = settings.keep_pair_tree;
        settings.moves = placed.is_animation() || self.animated || !self.still;
        // A later frame starts from the last one's hierarchy and solution, unless an update
        // failed on its way (it took the links) or the surfaces were replaced since.
        let previous = self.hierarchical.as_mut().filter(|_| !self.stale);
        let solved = self.pool.install(|| match previous {
            Some(previous) => {
                crate::hierarchy::update::update_frame(previous, placed, frame, &settings, progress)
            }
            None => crate::hierarchy::solve_frame(placed, frame, &settings, progress),
        });
        let solved = solved.inspect_err(|_| self.stale = true)?;
        if let Err(e) = check_results(&solved.face_results(placed, frame), placed, frame) {
            self.stale = true;
            return Err(e);
        }
        self.stale = false;
        let h = &solved.stats;
        let stats = FrameStats {
            frame,
            seconds: start.elapsed().as_secs_f64(),
            kernel_seconds: h.link_seconds,
            solve_seconds: h.solve_seconds,
            shots: h.sweeps,
            elements: h.leaves,
            pairs: h.links,
            links_recomputed: h.links - h.kept_links,
            gather_seconds: h.gather_seconds,
            gather_moments: (h.gather_kept + h.gather_computed) as usize,
            gather_recomputed: h.gather_computed as usize,
            full_rebuild: !h.updated,
            preview,
            ..Default::default()
        };
        self.hierarchical = Some(solved);
        self.frame = Some(frame);
        self.unrefined = preview;
        Ok(stats)
    }

    /// `placed` at `frame` built and solved from scratch, and gathered when `gather`, with the
    /// gather's time.
    fn rebuild(
        &self,
        placed: &Scene,
        frame: f64,
        gather: bool,
        progress: Progress,
    ) -> Result<(System, f64, GatherStats)> {
        let cancel = || !progress(1.0, "solve");
        self.pool.install(|| {
            let mut sys = System::build(placed, frame, progress)?;
            sys.solve(placed.settings.tolerance, &cancel)?;
            if !gather {
                return Ok((sys, 0.0, GatherStats::default()));
            }
            let (seconds, g) = timed_gather(&mut sys, placed, frame, progress)?;
            Ok((sys, seconds, g))
        })
    }

    /// Makes a rebuilt `system` the readable frame, with a fresh animation state.
    fn keep_rebuilt(&mut self, system: System, frame: f64) {
        self.animation = Some(AnimationState::new(system.elements.len(), self.method == Method::Incremental));
        self.system = Some(system);
        self.stale = false;
        self.frame = Some(frame);
    }

    fn solved(&self) -> Result<&System> {
        self.system.as_ref().ok_or_else(|| Error::InvalidArgument("no frame has been solved yet".into()))
    }

    /// Per object: mean radiosity per face and radiosity per face corner.
    ///
    /// Point values of the polynomial are clamped at 0: a low-order polynomial across a shadow
    /// edge or a contact (a block standing on a floor patch) undershoots, and negative light is
    /// never what a host should display. Face means are exact integrals: a frame with one below
    /// rounding (`crate::finite::ROUNDING` of the peak) was refused when solved, and what is
    /// left of rounding is clamped at 0 here. Every value is finite (checked when solved).
    pub fn face_results(&self) -> Result<Vec<ObjectResult>> {
        let frame = self.frame.unwrap_or(0.0);
        let mut results = match &self.hierarchical {
            Some(h) => h.face_results(&self.scene_at(frame), frame),
            None => self.solved()?.face_results(&self.scene_at(frame), frame),
        };
        clamp_rounding(&mut results);
        Ok(results)
    }

    /// `B` at `(s,t)` of face `f` of object `o`, clamped at 0 like the corners; a skipped
    /// zero-area face reports its exitance.
    pub fn eval(&self, o: usize, f: usize, s: f64, t: f64) -> Result<[f64; 3]> {
        if self.hierarchical.is_none() {
            self.solved()?;
        }
        let obj = self
            .scene
            .objects
            .get(o)
            .ok_or_else(|| Error::InvalidArgument(format!("object {o} out of range")))?;
        if f >= obj.faces.len() {
            return Err(Error::InvalidArgument(format!(
                "object {o} face {f} out of range (0..{})",
                obj.faces.len()
            )));
        }
        if !((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t)) {
            return Err(Error::InvalidArgument(format!("(s, t) = ({s}, {t}) is outside [0,1]^2")));
        }
        let exitance = || self.face_exitance(o, f, self.frame.unwrap_or(0.0));
        if let Some(h) = &self.hierarchical {
            return Ok(h
                .face_index(o, f)
                .map_or_else(exitance, |i| h.eval_face(i, s, t).map(|x| x.max(0.0))));
        }
        let sys = self.solved()?;
        match sys.element_of_face(o, f, s, t) {
            Some((e, ls, lt)) => Ok(sys.eval(e, ls, lt).map(|x| x.max(0.0))),
            None => Ok(exitance()),
        }
    }

    /// The irradiance `H` at `(s,t)` of face `f` of object `o` from the face's polynomial, as
    /// [`Session::eval`] gives `B`: `(B - E) / rho` per channel
    /// ([`crate::scene::json::irradiance_from_radiosity`]: 0 where `rho` is below 1e-4),
    /// clamped at 0; a skipped zero-area face reports 0.
    pub fn eval_irradiance(&self, o: usize, f: usize, s: f64, t: f64) -> Result<[f64; 3]> {
        let b = self.eval(o, f, s, t)?;
        let from = crate::scene::json::irradiance_from_radiosity;
        if let Some(h) = &self.hierarchical {
            if h.face_index(o, f).is_none() {
                return Ok([0.0; 3]);
            }
            let e = self.face_exitance(o, f, self.frame.unwrap_or(0.0));
            let m = self.scene.objects[o].face_materials[f];
            return Ok(from(b, e, self.scene.reflectance_of(o, f, m)).map(|x| x.max(0.0)));
        }
        let sys = self.solved()?;
        Ok(match sys.element_of_face(o, f, s, t) {
            Some((e, ..)) => {
                let (rho, emission) = (sys.surface_reflectance[e], sys.emission[e * sys.basis.len()]);
                from(b, emission, rho).map(|x| x.max(0.0))
            }
            None => [0.0; 3],
        })
    }
}
