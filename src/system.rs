//! One frame's Galerkin system: elements, links, emission and radiosity coefficients, and the
//! evaluation of the solution on faces.

use std::time::Instant;

use glam::DVec3;

use crate::basis::Basis;
use crate::error::Result;
use crate::gather::{CornerGather, GatherStats};
use crate::geometry::{Patch, Rect};
use crate::kernel::PairContext;
use crate::kernel::assemble::{ElementGeometry, assemble};
use crate::lights::direct::DirectLight;
use crate::links::LinkStore;
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::scene::json::{ObjectResult, irradiance_from_radiosity};
use crate::scene::placement::{self, front_order};
use crate::solver::{self, Coefficients, ShootStats};
use crate::visibility::Occluders;

/// Progress callback: fraction done in `[0,1]` and a short stage name; returns false to cancel.
pub type Progress<'a> = &'a (dyn Fn(f64, &str) -> bool + Sync);

/// A progress callback that never cancels.
pub fn no_progress(_: f64, _: &str) -> bool {
    true
}

/// A region of a face that carries its own radiosity polynomial.
#[derive(Clone, Debug)]
pub struct Element {
    pub object: u32,
    pub face: u32,
    /// The element's part of the face's parameter domain (the whole face today).
    pub domain: Rect,
    /// World-space geometry of the element (a bilinear patch over `domain`).
    pub patch: Patch,
    pub material: u32,
    pub area: f64,
    /// `integral Gamma_k A ds dt` over the element: the mean radiosity is `sum_k b^k m_k / area`.
    pub moments: Vec<f64>,
    /// Placed with reversed winding (a mirroring matrix, [`crate::scene::placement::front_order`]):
    /// the face's `(s,t)` is the patch's `(1 - s, t)`.
    pub mirrored: bool,
    /// The back of an open surface's face ([`crate::backs`]): reflects, emits nothing, is read
    /// back nowhere.
    pub back: bool,
}

impl Element {
    /// The surface's reflectance over the element: its face's ([`Scene::reflectance_of`]).
    pub fn reflectance(&self, scene: &Scene) -> [f64; 3] {
        scene.reflectance_of(self.object as usize, self.face as usize, self.material)
    }

    /// The surface's exitance over the element at `frame`: its face's ([`Scene::emission_of`]);
    /// none for a back.
    pub fn emission(&self, scene: &Scene, frame: f64) -> [f64; 3] {
        if self.back {
            return [0.0; 3];
        }
        scene.emission_of(self.object as usize, self.face as usize, self.material, frame)
    }
}

/// World-space elements of a scene at a frame: one per non-degenerate face.
pub fn build_elements(scene: &Scene, frame: f64, basis: Basis) -> Vec<Element> {
    build_elements_reusing(scene, frame, basis, &[])
}

/// [`build_elements`], taking from `previous` (the elements of another frame, in their order)
/// every element whose face sits where it sat there: only moved faces pay for their area and
/// moments (placing the 1,079 faces of the moving-light box, of which 9 move: 0.8 -> 0.33 ms).
pub fn build_elements_reusing(scene: &Scene, frame: f64, basis: Basis, previous: &[Element]) -> Vec<Element> {
    let rule = GaussLegendre::new(4);
    let mut elements = Vec::with_capacity(scene.face_count());
    let mut degenerate = scene.degenerate_faces.iter().peekable();
    let mut previous = previous.iter().peekable();
    for (o, obj) in scene.objects.iter().enumerate() {
        let m = obj.world_from_object(frame);
        let mirrored = placement::mirrors(&m);
        let world: Vec<DVec3> = obj.vertices.iter().map(|v| m.transform_point3(*v)).collect();
        for (f, face) in obj.faces.iter().enumerate() {
            if degenerate.peek() == Some(&&(o, f)) {
                degenerate.next();
                continue;
            }
            let corners: Vec<DVec3> =
                front_order(face, mirrored).iter().map(|&v| world[v as usize]).collect();
            let patch = Patch::from_corners(&corners);
            // Previous elements of faces before this one (degenerate there, not here) are passed.
            while previous.next_if(|e| (e.object, e.face) < (o as u32, f as u32)).is_some() {}
            if let Some(e) = previous.next_if(|e| (e.object, e.face) == (o as u32, f as u32))
                && e.patch == patch
                && e.material == obj.face_materials[f]
                && e.moments.len() == basis.len()
            {
                elements.push(e.clone());
                continue;
            }
            let mut e = element(o as u32, f as u32, Rect::UNIT, patch, obj.face_materials[f], basis, &rule);
            e.mirrored = mirrored;
            elements.push(e);
        }
    }
    elements
}

pub(crate) fn element(
    object: u32,
    face: u32,
    domain: Rect,
    patch: Patch,
    material: u32,
    basis: Basis,
    rule: &GaussLegendre,
) -> Element {
    let nb = basis.len();
    let mut moments = vec![0.0; nb];
    let mut area = 0.0;
    let mut g = vec![0.0; nb];
    for (s, ws) in rule.iter() {
        for (t, wt) in rule.iter() {
            let a = patch.area_vector(s, t).length() * ws * wt;
            area += a;
            basis.eval_into(s, t, &mut g);
            for k in 0..nb {
                moments[k] += a * g[k];
            }
        }
    }
    Element { object, face, domain, patch, material, area, moments, mirrored: false, back: false }
}

/// The occluders of `elements` (their patches `patches`) with `m x m` visibility samples: a back
/// ([`crate::backs`]) and its parts share the triangles of its face's last front part, which
/// comes before them.
pub fn occluders_of(elements: &[Element], patches: &[Patch], m: usize) -> Occluders {
    let mut front = 0;
    let alias = elements
        .iter()
        .enumerate()
        .map(|(e, el)| {
            if !el.back {
                front = e;
            }
            debug_assert!(!el.back || (elements[front].object, elements[front].face) == (el.object, el.face));
            front as u32
        })
        .collect();
    Occluders::with_aliases(patches, m, alias)
}

/// [`crate::hemisphere::bounded_reflectance`] of every element.
pub fn bounded_reflectances(links: &LinkStore, surface: &[[f64; 3]]) -> Vec<[f64; 3]> {
    use rayon::prelude::*;
    surface
        .par_iter()
        .enumerate()
        .map(|(i, &rho)| crate::hemisphere::bounded_reflectance(links, i as u32, rho))
        .collect()
}

/// Timings and counts of one build and solve.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SystemStats {
    pub elements: usize,
    pub pairs: usize,
    pub link_bytes: usize,
    pub pairs_with_partial_visibility: usize,
    /// Triangles in the occluder BVH (hull elements such as room walls are left out).
    pub occluder_triangles: usize,
    pub kernel_seconds: f64,
    pub solve_seconds: f64,
    pub shots: usize,
    /// One line per emitting object that lights nothing ([`System::dark_emitters`]).
    pub warnings: Vec<String>,
}

/// The Galerkin system of one frame.
pub struct System {
    pub basis: Basis,
    pub elements: Vec<Element>,
    pub links: LinkStore,
    /// The reflectance the solver's kernel `K = rho G` uses per element: the surface's, bounded
    /// so that the element takes in at most its hemisphere ([`crate::hemisphere`]).
    pub reflectance: Vec<[f64; 3]>,
    /// The surfaces' own reflectance per element (the corner gather applies its own bound).
    pub surface_reflectance: Vec<[f64; 3]>,
    /// Each element's weight as a source, below 1 where coplanar faces cover it
    /// ([`crate::overlap`]); the link store's blocks carry it, the corner gather applies it.
    pub source_weights: Vec<f64>,
    /// Whether corners are bounded by their hemisphere (off only to measure the raw sums,
    /// [`crate::diagnose::corner_sums`]).
    pub corner_bound: bool,
    /// Emission coefficients `e_i^k` (eq. 5): constant exitance projects onto `k = 0` only.
    pub emission: Vec<[f64; 3]>,
    /// The lights' share of the sources, `rho E_d` projected (all `k`; empty without lights):
    /// the solve starts from `emission + direct` ([`System::sources`]).
    pub direct: Vec<[f64; 3]>,
    /// The lights as placed for `direct`, for point queries (the corner gather).
    pub lights: Option<std::sync::Arc<DirectLight>>,
    pub solution: Coefficients,
    /// `B` gathered at every face corner for the current solution ([`crate::gather`]), per object
    /// in face order; `None` when corners come from the face polynomials.
    pub corners: Option<Vec<Vec<[f64; 3]>>>,
    /// The irradiance `H` at the same corners (`B = E + rho H`), present with `corners`.
    pub corner_irradiance: Option<Vec<Vec<[f64; 3]>>>,
    /// The last corner gather, which the next one updates.
    gather: Option<CornerGather>,
    /// The occluders of the elements as placed now (visibility on): kept by the build and each
    /// animation update for the corner gather and the next update.
    pub occluders: Option<Occluders>,
    pub stats: SystemStats,
}

impl System {
    /// Places the scene at `frame`, builds elements and every link. Runs on the current rayon pool.
    pub fn build(scene: &Scene, frame: f64, progress: Progress) -> Result<System> {
        let s = &scene.settings;
        let basis = Basis::new(s.basis_order);
        let rule = GaussLegendre::new(s.quadrature_order);
        let ctx = PairContext {
            basis,
            rule: &rule,
            vis_axis: s.visibility_samples,
            adaptive: s.adaptive_quadrature,
        };
        let start = Instant::now();
        // Open surfaces' faces reflect from both sides (crate::backs): a back is split as a face.
        let faces = crate::backs::with_backs(scene, frame, build_elements(scene, frame, basis), basis, &[]);
        // Faces split where another object comes close or faces of one object meet at a crease
        // (crate::contact_split): only shadows need it, and there are none without visibility.
        let elements = if s.visibility {
            let parts = crate::contact_split::plan_with_creases(scene, &faces);
            crate::contact_split::split_faces(faces, &parts, basis, &[])
        } else {
            faces
        };
        let patches: Vec<Patch> = elements.iter().map(|e| e.patch).collect();
        let occluders = s.visibility.then(|| occluders_of(&elements, &patches, s.visibility_samples));
        let geom = ElementGeometry::new(&patches, &ctx);
        let mut links = assemble(&ctx, &geom, occluders.as_ref(), &|done, total| {
            progress(if total > 0 { done as f64 / total as f64 } else { 1.0 }, "kernel")
        })?;
        let source_weights = geom.source_weights().to_vec();
        links.set_receiver_areas(&elements.iter().map(|e| e.area).collect::<Vec<_>>());
        let kernel_seconds = start.elapsed().as_secs_f64();
        let nb = basis.len();
        let surface_reflectance: Vec<[f64; 3]> = elements.iter().map(|e| e.reflectance(scene)).collect();
        let reflectance = bounded_reflectances(&links, &surface_reflectance);
        let (emission, direct, lights) = frame_sources(scene, frame, &elements, basis, None);
        let stats = SystemStats {
            elements: elements.len(),
            pairs: links.len(),
            link_bytes: links.memory_bytes(),
            pairs_with_partial_visibility: links
                .pairs()
                .iter()
                .filter(|p| matches!(p.visibility, crate::visibility::Visibility::Partial(_)))
                .count(),
            kernel_seconds,
            occluder_triangles: occluders.as_ref().map_or(0, |o| o.occluder_triangles()),
            ..Default::default()
        };
        let solution = Coefficients::zeros(elements.len(), nb);
        let mut sys = System {
            basis,
            elements,
            links,
            reflectance,
            surface_reflectance,
            source_weights,
            corner_bound: true,
            emission,
            direct,
            lights,
            solution,
            corners: None,
            corner_irradiance: None,
            gather: None,
            occluders,
            stats,
        };
        sys.stats.warnings = sys.dark_emitters(scene);
        Ok(sys)
    }

    /// The solve's sources: emission plus the lights' `rho E_d`.
    pub fn sources(&self) -> Vec<[f64; 3]> {
        let mut out = self.emission.clone();
        for (o, d) in out.iter_mut().zip(&self.direct) {
            for c in 0..3 {
                o[c] += d[c];
            }
        }
        out
    }

    /// Takes a frame's sources ([`frame_sources`]: emission, the lights' `rho E_d`, the lights)
    /// in place of the current ones, adding their change to `delta` (Delta e of eq. 9, one entry
    /// per coefficient), which the caller adds to the solution and its unshot part.
    pub fn take_sources(&mut self, (emission, direct, lights): FrameSources, delta: &mut [[f64; 3]]) {
        let old = self.sources();
        for (k, d) in delta.iter_mut().enumerate() {
            let new =
                std::array::from_fn::<f64, 3, _>(|c| emission[k][c] + direct.get(k).map_or(0.0, |x| x[c]));
            for c in 0..3 {
                d[c] += new[c] - old[k][c];
            }
        }
        (self.emission, self.direct, self.lights) = (emission, direct, lights);
    }

    /// [`System::take_sources`] with the change added to the solution at once
    /// ([`System::add_unshot`]).
    pub fn replace_sources(&mut self, sources: FrameSources) {
        let mut delta = vec![[0.0; 3]; self.solution.b.len()];
        self.take_sources(sources, &mut delta);
        self.add_unshot(&delta);
    }

    /// Adds `delta` (one entry per coefficient) to `b` and to its unshot part alike: a change of
    /// the sources (or of `K (b - u)`) not yet shot, which keeps the shooting invariant
    /// `b = e + K (b - u)`.
    pub fn add_unshot(&mut self, delta: &[[f64; 3]]) {
        for (k, d) in delta.iter().enumerate() {
            for c in 0..3 {
                self.solution.b[k][c] += d[c];
                self.solution.unshot[k][c] += d[c];
            }
        }
    }

    /// One line per object whose emitting faces deliver nothing to any other face (an emissive
    /// plane left facing the sky): no link leaves any of them.
    pub fn dark_emitters(&self, scene: &Scene) -> Vec<String> {
        let nb = self.basis.len();
        let transfers = self.links.transfers();
        let mut emits = vec![false; scene.objects.len()];
        let mut lights = vec![false; scene.objects.len()];
        for (i, e) in self.elements.iter().enumerate() {
            if self.emission[i * nb].iter().any(|&x| x > 0.0) {
                emits[e.object as usize] = true;
                lights[e.object as usize] |= transfers.get(i * nb).is_some_and(|&t| t > 0.0);
            }
        }
        scene
            .objects
            .iter()
            .enumerate()
            // A two-sided emitter's backs light by the direct path, not by links.
            .filter(|&(o, _)| emits[o] && !lights[o] && !scene.two_sided.get(o).copied().unwrap_or(false))
            .map(|(_, obj)| {
                format!(
                    "emitter \"{}\" lights nothing: its emitting faces face away from all geometry \
                     (flip its normals, or turn on Two-Sided in its Radiosity object panel)",
                    obj.name
                )
            })
            .collect()
    }

    /// Adds `rho E_d(x)` of the lights to `values` at face points `at` (element, local `s`, `t`;
    /// and a shading normal where it is not the element's own), each with its own shadow rays:
    /// the corner gather's direct light.
    pub fn add_direct_light(
        &self,
        at: impl Iterator<Item = Option<((usize, f64, f64), Option<DVec3>)>>,
        values: &mut [[f64; 3]],
    ) {
        if self.lights.is_none() {
            return;
        }
        for (v, at) in values.iter_mut().zip(at) {
            if let Some((at, normal)) = at
                && let Some(irr) = self.direct_irradiance(at, normal)
            {
                for c in 0..3 {
                    v[c] += self.surface_reflectance[at.0][c] * irr[c];
                }
            }
        }
    }

    /// The lights' direct irradiance `E_d` at the face point `(e, s, t)` (gathered with the
    /// shading normal `normal` where it is not the element's own), with its own shadow rays;
    /// `None` without lights.
    pub fn direct_irradiance(&self, (e, s, t): (usize, f64, f64), normal: Option<DVec3>) -> Option<[f64; 3]> {
        let lights = self.lights.as_ref()?;
        let (x, n) = crate::gather::shading_point(&self.elements[e].patch, s, t, normal);
        Some(lights.irradiance(x, n, e as u32))
    }

    /// Element areas, in element order.
    pub fn areas(&self) -> Vec<f64> {
        self.elements.iter().map(|e| e.area).collect()
    }

    /// Total emitted power-norm, the reference for the tolerance.
    pub fn emitted_power(&self) -> f64 {
        let nb = self.basis.len();
        let sources = self.sources();
        self.elements
            .iter()
            .enumerate()
            .map(|(i, e)| solver::power(&sources[i * nb..(i + 1) * nb], e.area))
            .sum()
    }

    /// Solves from scratch by progressive refinement down to `tolerance` x emitted power.
    pub fn solve(&mut self, tolerance: f64, cancel: &dyn Fn() -> bool) -> Result<ShootStats> {
        let start = Instant::now();
        self.solution = Coefficients::from_emission(&self.sources(), self.basis.len());
        let stop = tolerance * self.emitted_power();
        let stats = solver::shoot(&self.links, &self.reflectance, &mut self.solution, stop, cancel)?;
        self.stats.solve_seconds = start.elapsed().as_secs_f64();
        self.stats.shots = stats.shots;
        Ok(stats)
    }

    /// `B` of element `e` at its local `(s,t)`.
    pub fn eval(&self, e: usize, s: f64, t: f64) -> [f64; 3] {
        let g = self.basis.eval(s, t);
        let mut out = [0.0; 3];
        for (k, gk) in g.iter().enumerate() {
            for c in 0..3 {
                out[c] += gk * self.solution.b[e * g.len() + k][c];
            }
        }
        out
    }

    /// Area-mean `B` of element `e`.
    pub fn mean(&self, e: usize) -> [f64; 3] {
        let el = &self.elements[e];
        let nb = self.basis.len();
        let mut out = [0.0; 3];
        for k in 0..nb {
            for c in 0..3 {
                out[c] += el.moments[k] * self.solution.b[e * nb + k][c];
            }
        }
        out.map(|x| x / el.area)
    }

    /// Gathers `B` at every face corner ([`crate::gather`]) for the current solution, placed as
    /// `scene` is at `frame`, updating the last frame's gather; [`System::face_results`] then
    /// reports those corners.
    pub fn gather_corners(&mut self, scene: &Scene, frame: f64, progress: Progress) -> Result<GatherStats> {
        self.corners = None;
        self.corner_irradiance = None;
        let previous = self.gather.take();
        let changed = self.links.take_visibility_changes();
        let (corners, mut kept, stats) = CornerGather::run(
            self,
            scene,
            frame,
            self.occluders.as_ref(),
            previous,
            changed.as_deref(),
            progress,
        )?;
        self.corners = Some(corners);
        self.corner_irradiance = Some(kept.take_irradiance());
        self.gather = Some(kept);
        Ok(stats)
    }

    /// Per object, per face: the mean `B` and `B` at each corner (issue 2, items 6 and 8), the
    /// corners gathered when [`System::gather_corners`] ran for this solution.
    pub fn face_results(&self, scene: &Scene, frame: f64) -> Vec<ObjectResult> {
        let mut out: Vec<ObjectResult> = scene
            .objects
            .iter()
            .map(|o| ObjectResult {
                name: o.name.clone(),
                face_radiosity: Vec::with_capacity(o.faces.len()),
                corner_radiosity: Vec::new(),
                corner_irradiance: Vec::new(),
            })
            .collect();
        if let Some(corners) = &self.corners {
            for (res, c) in out.iter_mut().zip(corners) {
                res.corner_radiosity = c.iter().map(|v| to_f32(*v)).collect();
            }
            for (res, c) in out.iter_mut().zip(self.corner_irradiance.iter().flatten()) {
                res.corner_irradiance = c.iter().map(|v| to_f32(*v)).collect();
            }
        }
        let gathered = self.corners.is_some();
        for (o, obj) in scene.objects.iter().enumerate() {
            for (f, face) in obj.faces.iter().enumerate() {
                let res = &mut out[o];
                // The face's elements (several where it was split, crate::contact_split).
                let start = self.elements.partition_point(|e| (e.object as usize, e.face as usize) < (o, f));
                // (A back, after them, is read back nowhere: crate::backs.)
                let count = self.elements[start..]
                    .iter()
                    .take_while(|e| e.object as usize == o && e.face as usize == f && !e.back)
                    .count();
                if count == 0 {
                    // A skipped zero-area face shows its own exitance.
                    let e = to_f32(scene.emission_of(o, f, obj.face_materials[f], frame));
                    res.face_radiosity.push(e);
                    if !gathered {
                        res.corner_radiosity.extend(std::iter::repeat_n(e, face.len()));
                        res.corner_irradiance.extend(std::iter::repeat_n([0.0; 3], face.len()));
                    }
                    continue;
                }
                let (mut sum, mut area) = ([0.0; 3], 0.0);
                for e in start..start + count {
                    let (m, a) = (self.mean(e), self.elements[e].area);
                    (0..3).for_each(|c| sum[c] += m[c] * a);
                    area += a;
                }
                res.face_radiosity.push(to_f32(sum.map(|x| x / area.max(f64::MIN_POSITIVE))));
                if gathered {
                    continue;
                }
                for (s, t) in corner_params(face.len()) {
                    let (e, ls, lt) = self.element_of_face(o, f, s, t).expect("a corner lies on its face");
                    let v = if face.len() == 3 && t == 1.0 { self.apex(e) } else { self.eval(e, ls, lt) };
                    res.corner_radiosity.push(to_f32(v));
                    let (rho, emission) = (self.surface_reflectance[e], self.emission[e * self.basis.len()]);
                    res.corner_irradiance.push(to_f32(irradiance_from_radiosity(v, emission, rho)));
                }
            }
        }
        out
    }

    /// `B` at a triangle's apex, where the collapsed edge `t = 1` maps to one point: the mean
    /// over that edge (only the `a = 0` functions survive the integral over `s`).
    fn apex(&self, e: usize) -> [f64; 3] {
        let n = self.basis.order() + 1;
        let pt = crate::basis::legendre_1d(1.0);
        let mut out = [0.0; 3];
        for b in 0..n {
            for c in 0..3 {
                out[c] += pt[b] * self.solution.b[e * n * n + b][c];
            }
        }
        out
    }
}

/// Emission coefficients, the lights' `rho E_d` coefficients and the lights as placed.
pub type FrameSources = (Vec<[f64; 3]>, Vec<[f64; 3]>, Option<std::sync::Arc<DirectLight>>);

/// A frame's sources for `elements` of `scene` at `frame`: the materials' emission (`k = 0`),
/// the lights' `rho E_d` (every `k`; empty without lights) and the lights as placed, with their
/// shadow rays' outcomes kept for the next frame; `last`, the frame before and what moved since,
/// lends its outcomes where they hold.
pub fn frame_sources(
    scene: &Scene,
    frame: f64,
    elements: &[Element],
    basis: Basis,
    last: Option<crate::lights::direct::LastFrame>,
) -> FrameSources {
    let nb = basis.len();
    let mut emission = vec![[0.0; 3]; elements.len() * nb];
    for (i, e) in elements.iter().enumerate() {
        emission[i * nb] = e.emission(scene, frame);
    }
    let patches: Vec<Patch> = elements.iter().map(|e| e.patch).collect();
    let Some(mut lights) = DirectLight::new(scene, frame, elements) else {
        return (emission, Vec::new(), None);
    };
    lights.settle_rule(last.as_ref().map(|l| l.lights));
    let rho: Vec<[f64; 3]> = elements.iter().map(|e| e.reflectance(scene)).collect();
    // Each element's shadow rays are kept for the next frame, which takes those no move can
    // have changed (crate::lights::direct::DirectLight::project_keeping).
    let (direct, _) = lights.project_keeping(&patches, &rho, basis, last);
    (emission, direct, Some(std::sync::Arc::new(lights)))
}

/// Parameter coordinates of a face's corners, in face order.
pub fn corner_params(n: usize) -> Vec<(f64, f64)> {
    if n == 3 {
        vec![(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)]
    } else {
        vec![(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    }
}

fn to_f32(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}

impl System {
    /// The element covering `(s,t)` of face `f` of object `o` (`s,t` in face corner order, as
    /// [`corner_params`]), and the local coordinates in it.
    pub fn element_of_face(&self, o: usize, f: usize, s: f64, t: f64) -> Option<(usize, f64, f64)> {
        let start = self.elements.partition_point(|e| (e.object as usize, e.face as usize) < (o, f));
        self.elements[start..]
            .iter()
            .take_while(|e| e.object as usize == o && e.face as usize == f && !e.back)
            .position(|e| {
                let s = if e.mirrored { 1.0 - s } else { s };
                e.domain.s0 <= s && s <= e.domain.s1 && e.domain.t0 <= t && t <= e.domain.t1
            })
            .map(|k| {
                let el = &self.elements[start + k];
                let s = if el.mirrored { 1.0 - s } else { s };
                let d = &el.domain;
                (start + k, (s - d.s0) / (d.s1 - d.s0), (t - d.t0) / (d.t1 - d.t0))
            })
    }
}
