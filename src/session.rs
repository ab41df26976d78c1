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
use crate::gather::GatherStats;
use crate::scene::Scene;
use crate::scene::json::ObjectResult;
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
}

/// What one frame cost and did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct FrameStats {
    pub frame: f64,
    pub seconds: f64,
    pub kernel_seconds: f64,
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
    /// The frame was built from scratch (first frame, `--full`, or after a topology change).
    pub full_rebuild: bool,
}

pub struct Session {
    scene: Scene,
    method: Method,
    pool: rayon::ThreadPool,
    /// Host overrides of world-from-object, per object.
    placement: Vec<Option<DMat4>>,
    /// Host overrides of emission, per material.
    emission: Vec<Option<[f64; 3]>>,
    system: Option<System>,
    /// What the incremental update keeps between frames (series, shape epochs).
    animation: Option<AnimationState>,
    /// The links belong to a cancelled update: the next frame rebuilds from scratch.
    stale: bool,
    frame: Option<f64>,
    /// Frames are solved without their corner gather until [`Session::gather_corners`].
    defer_gather: bool,
}

impl Session {
    pub fn new(scene: Scene, method: Method) -> Result<Self> {
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
            system: None,
            animation: None,
            stale: false,
            frame: None,
            defer_gather: false,
        })
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
        if emission.iter().any(|e| !e.is_finite() || *e < 0.0) {
            return Err(Error::InvalidArgument(format!(
                "material {m}: emission {emission:?} must be finite and >= 0"
            )));
        }
        self.emission[m] = Some(emission);
        Ok(())
    }

    /// While `defer` holds, [`Session::solve_frame`] leaves the corner gather out: the frame's
    /// corners are the face polynomials' until [`Session::gather_corners`] gathers them. For a
    /// host that previews while the timeline is scrubbed: the gather is a third of such a frame,
    /// and only the frame the user stops on needs it. (No effect with `corner_gather` off.)
    pub fn set_defer_gather(&mut self, defer: bool) {
        self.defer_gather = defer;
    }

    /// Whether the readable frame's corners still wait for their gather (it was deferred).
    pub fn gather_pending(&self) -> bool {
        self.scene.settings.corner_gather && self.system.as_ref().is_some_and(|s| s.corners.is_none())
    }

    /// Gathers the corners of the readable frame if its solve deferred them, updating the last
    /// gather made (whatever frame that was: what moved since is recomputed, as between two
    /// consecutive frames). Returns its time and counts, or `None` when there was nothing to
    /// gather. On error (including cancel) the frame stays readable with the polynomials'
    /// corners, and the next gather starts afresh.
    pub fn gather_corners(&mut self, progress: Progress) -> Result<Option<(f64, GatherStats)>> {
        if !self.gather_pending() {
            return Ok(None);
        }
        let frame = self.frame.expect("a system is only kept with its frame");
        let placed = self.scene_at(frame);
        let sys = self.system.as_mut().expect("pending implies a system");
        let start = Instant::now();
        let g = self.pool.install(|| sys.gather_corners(&placed, frame, progress))?;
        Ok(Some((start.elapsed().as_secs_f64(), g)))
    }

    /// The scene as placed at `frame`: keys, then host overrides.
    fn scene_at(&self, frame: f64) -> Scene {
        let mut scene = self.scene.clone();
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
        let placed = self.scene_at(frame);
        let gather = placed.settings.corner_gather && !self.defer_gather;
        let incremental = self.method != Method::Full && !self.stale;
        if let (true, Some(sys), Some(state)) = (incremental, self.system.as_mut(), self.animation.as_mut()) {
            // Keep what reads need, so a cancelled update leaves the last frame readable.
            let saved = (
                sys.solution.clone(),
                sys.elements.clone(),
                sys.emission.clone(),
                sys.reflectance.clone(),
                sys.corners.take(),
            );
            let outcome = self.pool.install(|| {
                let outcome = animation::advance(sys, state, &placed, frame, progress)?;
                if let (Outcome::Updated(_), true) = (&outcome, gather) {
                    let start = Instant::now();
                    let g = sys.gather_corners(&placed, frame, progress)?;
                    return Ok((outcome, (start.elapsed().as_secs_f64(), g)));
                }
                Ok((outcome, (0.0, GatherStats::default())))
            });
            match outcome {
                Ok((Outcome::Updated(u), (gather_seconds, g))) => {
                    let stats = FrameStats {
                        frame,
                        seconds: start.elapsed().as_secs_f64(),
                        kernel_seconds: u.kernel_seconds,
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
                        ..Default::default()
                    };
                    self.frame = Some(frame);
                    return Ok(stats);
                }
                Ok((Outcome::NeedsRebuild, _)) => {}
                Err(e) => {
                    (sys.solution, sys.elements, sys.emission, sys.reflectance, sys.corners) = saved;
                    self.stale = true;
                    return Err(e);
                }
            }
        }
        let cancel = || !progress(1.0, "solve");
        let (system, gather_seconds, g) = self.pool.install(|| -> Result<(System, f64, GatherStats)> {
            let mut sys = System::build(&placed, frame, progress)?;
            sys.solve(placed.settings.tolerance, &cancel)?;
            if !gather {
                return Ok((sys, 0.0, GatherStats::default()));
            }
            let start = Instant::now();
            let g = sys.gather_corners(&placed, frame, progress)?;
            Ok((sys, start.elapsed().as_secs_f64(), g))
        })?;
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
            ..Default::default()
        };
        self.animation = Some(AnimationState::new(system.elements.len(), self.method == Method::Incremental));
        self.system = Some(system);
        self.stale = false;
        self.frame = Some(frame);
        Ok(stats)
    }

    fn solved(&self) -> Result<&System> {
        self.system.as_ref().ok_or_else(|| Error::InvalidArgument("no frame has been solved yet".into()))
    }

    /// Per object: mean radiosity per face and radiosity per face corner.
    ///
    /// Point values of the polynomial are clamped at 0: a low-order polynomial across a shadow
    /// edge or a contact (a block standing on a floor patch) undershoots, and negative light is
    /// never what a host should display. Face means are exact integrals and are not clamped.
    pub fn face_results(&self) -> Result<Vec<ObjectResult>> {
        let frame = self.frame.unwrap_or(0.0);
        let mut results = self.solved()?.face_results(&self.scene_at(frame), frame);
        for r in &mut results {
            for c in &mut r.corner_radiosity {
                *c = c.map(|x| x.max(0.0));
            }
        }
        Ok(results)
    }

    /// `B` at `(s,t)` of face `f` of object `o`, clamped at 0 like the corners; a skipped
    /// zero-area face reports its exitance.
    pub fn eval(&self, o: usize, f: usize, s: f64, t: f64) -> Result<[f64; 3]> {
        let sys = self.solved()?;
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
        match sys.element_of_face(o, f, s, t) {
            Some((e, ls, lt)) => Ok(sys.eval(e, ls, lt).map(|x| x.max(0.0))),
            None => Ok(self.scene.emission_at(obj.face_materials[f] as usize, self.frame.unwrap_or(0.0))),
        }
    }
}
