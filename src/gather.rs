//! Final gather at face corners: radiosity evaluated at a point from the Galerkin solution,
//!
//! `B(x) = E(x) + rho(x) sum_j integral_j g(x,y) V(x,y) B_j(y) dA_y`   (eq. 1 at one point),
//!
//! with `B_j(y) = sum_l b_j^l Gamma_l(y)` the solved polynomials (eq. 3) and the visibility `V`
//! cast from `x` itself. A face's own polynomial cannot follow what changes inside the face: a
//! corner hidden under a block standing on the floor, or behind a light hung just below the
//! ceiling, and the contact shadow next to it. The gather sees those at the corner, as a path
//! tracer's vertex bake does; where the polynomial is good, both agree to quadrature error. This
//! is the classic "final gather" / local pass of radiosity systems (e.g. Lischinski et al. 1993).
//!
//! Sources are the emitters, always with shadow rays from the corner (direct light casts the
//! sharpest shadows, and a corner on its element's edge can sit in a penumbra none of the
//! element's visibility samples is in), and the elements linked with the corner's element. For
//! those, which rays are cast depends on the link's visibility and on what lies next to the
//! corner: a corner on an element edge can be hidden while every visibility sample of its element
//! sees (a light hung just below the ceiling over a corner), or see while none does, and a pair
//! blocked everywhere has no link at all. So when some occluder comes within the element's radius
//! of the corner, every element in front is a source and every ray is cast; elsewhere only
//! partial links cast rays, a fully visible link stays visible and a blocked one blocked.
//! Measured on the Cornell box (819 faces, Cycles 1,024 spp): per-corner relative RMSE 16.8% with
//! the polynomials' corners, 6.0% gathered with element visibility only, 5.x% with this rule.

use glam::DVec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geometry::{Aabb, Patch, Rect};
use crate::kernel::point::{point_kernel, point_to_polygon};
use crate::kernel::samples::Samples;
use crate::links::ElementId;
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::system::{Progress, System, corner_params};
use crate::visibility::{Occluders, Visibility};

/// Corners are gathered this far inside their face (in its parameter domain): exactly on an edge,
/// a perpendicular neighbour is seen edge-on and drops out, while a vertex bake and the eye see
/// the limit from inside.
pub const INSET: f64 = 1e-3;

/// A source (sub-)rectangle is integrated by the Gauss rule once the distance from the corner to
/// its centre is this many times its bounding radius; closer, it is split in four.
const GAUSS_RATIO: f64 = 3.0;

/// Gauss points per axis on a separated source rectangle.
const GAUSS_POINTS: usize = 3;

/// Splits before a source rectangle is taken as a polygon of constant radiosity (its exact
/// point-to-polygon form factor times `B` at its centre).
const MAX_DEPTH: u32 = 12;

/// Radiosity at every face corner, per object in face order (the order of
/// [`crate::scene::json::ObjectResult::corner_radiosity`]); skipped zero-area faces report their
/// exitance. Runs on the current rayon pool; `progress` may cancel.
pub fn corner_radiosity(
    sys: &System,
    scene: &Scene,
    frame: f64,
    occluders: Option<&Occluders>,
    progress: Progress,
) -> Result<Vec<Vec<[f64; 3]>>> {
    let rule = GaussLegendre::new(GAUSS_POINTS);
    let patches: Vec<Patch> = sys.elements.iter().map(|e| e.patch).collect();
    // Each source's Gauss nodes over its whole domain, with B there: the common far case.
    let cells_per_axis = scene.settings.visibility_samples;
    let nodes: Vec<Nodes> = patches
        .par_iter()
        .enumerate()
        .map(|(j, p)| Nodes::new(sys, j, p, &Rect::UNIT, &rule, cells_per_axis))
        .collect();
    let nb = sys.basis.len();
    let is_emitter: Vec<bool> =
        (0..patches.len()).map(|e| sys.emission[e * nb].iter().any(|&x| x > 0.0)).collect();
    let emitters: Vec<usize> = (0..patches.len()).filter(|&e| is_emitter[e]).collect();
    // One task per distinct corner point: faces of one object meeting at a vertex with the same
    // normal and material see the same light there (4 faces per vertex of a grid), gathered once.
    let mut tasks = Vec::new();
    let mut task_of_corner = Vec::new();
    let mut shared = std::collections::HashMap::new();
    for (o, obj) in scene.objects.iter().enumerate() {
        for (f, face) in obj.faces.iter().enumerate() {
            for (&v, (s, t)) in face.iter().zip(corner_params(face.len())) {
                let (si, ti) = (s.clamp(INSET, 1.0 - INSET), t.clamp(INSET, 1.0 - INSET));
                let at = sys.element_of_face(o, f, si, ti);
                let material = obj.face_materials[f];
                let key = at.map(|(e, s, t)| {
                    let n = sys.elements[e].patch.area_vector(s, t).normalize_or_zero();
                    (o, v, material, (n * 1e6).round().as_i64vec3().to_array())
                });
                let task = match key.and_then(|k| shared.get(&k)) {
                    Some(&task) => task,
                    None => {
                        tasks.push((at, material));
                        if let Some(k) = key {
                            shared.insert(k, tasks.len() - 1);
                        }
                        tasks.len() - 1
                    }
                };
                task_of_corner.push(task);
            }
        }
    }
    let total = tasks.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let values: Vec<[f64; 3]> = tasks
        .par_iter()
        .map(|&(at, material)| {
            let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if d.is_multiple_of(256) && !progress(d as f64 / total.max(1) as f64, "corner gather") {
                return Err(Error::Cancelled);
            }
            Ok(match at {
                Some((e, s, t)) => {
                    let gather = Gather {
                        sys,
                        emitters: &emitters,
                        is_emitter: &is_emitter,
                        patches: &patches,
                        nodes: &nodes,
                        rule: &rule,
                        occluders,
                        cells_per_axis,
                    };
                    gather.at(e, s, t)
                }
                None => scene.emission_at(material as usize, frame),
            })
        })
        .collect::<Result<_>>()?;
    let mut out: Vec<Vec<[f64; 3]>> = Vec::with_capacity(scene.objects.len());
    let mut it = task_of_corner.into_iter().map(|task| values[task]);
    for obj in &scene.objects {
        let n: usize = obj.faces.iter().map(|f| corner_params(f.len()).len()).sum();
        out.push(it.by_ref().take(n).collect());
    }
    Ok(out)
}

/// Gauss nodes of a source rectangle: position, unit normal, area weight and `B` there.
struct Nodes {
    position: Vec<DVec3>,
    /// Visibility cell of each node in its element.
    cell: Vec<usize>,
    normal: Vec<DVec3>,
    area_weight: Vec<f64>,
    radiosity: Vec<[f64; 3]>,
}

impl Nodes {
    fn new(sys: &System, j: usize, patch: &Patch, rect: &Rect, rule: &GaussLegendre, m: usize) -> Self {
        let nb = sys.basis.len();
        let s = Samples::new(patch, rect, rule, sys.basis, m);
        let b = &sys.solution.b[j * nb..(j + 1) * nb];
        let radiosity = (0..s.len())
            .map(|k| {
                let g = &s.basis[k * nb..(k + 1) * nb];
                std::array::from_fn(|c| (0..nb).map(|l| g[l] * b[l][c]).sum())
            })
            .collect();
        Nodes { position: s.position, cell: s.cell, normal: s.normal, area_weight: s.area_weight, radiosity }
    }
}

/// What one corner needs: the solved system, its elements' geometry and the occluders.
struct Gather<'a> {
    sys: &'a System,
    /// Elements with emission, and the flag per element.
    emitters: &'a [usize],
    is_emitter: &'a [bool],
    patches: &'a [Patch],
    nodes: &'a [Nodes],
    rule: &'a GaussLegendre,
    occluders: Option<&'a Occluders>,
    /// Visibility samples per axis of the link masks.
    cells_per_axis: usize,
}

/// The receiving point and what its rays skip.
struct Receiver {
    x: DVec3,
    n: DVec3,
    element: u32,
    /// Some occluder lies next to `x` ([`Occluders::any_near`]).
    near: bool,
    /// Visibility cell of `x` in its element.
    cell: usize,
}

/// Shadow rays of one link from the corner.
#[derive(Clone, Copy)]
enum Rays<'v> {
    None,
    All,
    /// No rays: the link's mask, from the corner's visibility cell (`cell`) to each node's.
    Mask {
        vis: &'v Visibility,
        cell: usize,
        corner_is_a: bool,
    },
}

impl Gather<'_> {
    /// `B` at local `(s,t)` of element `i`.
    fn at(&self, i: usize, s: f64, t: f64) -> [f64; 3] {
        let sys = self.sys;
        let nb = sys.basis.len();
        let patch = &self.patches[i];
        let n = patch.area_vector(s, t).normalize_or_zero();
        let x = patch.point(s, t);
        let near = self.occluders.is_some_and(|o| o.any_near(x, n, patch.bounding_sphere().1, i as u32));
        let cell = crate::visibility::cell_of(s, t, self.cells_per_axis);
        let rx = Receiver { x, n, element: i as u32, near, cell };
        let mut irradiance = [0.0; 3];
        let mut add = |e: [f64; 3]| (0..3).for_each(|c| irradiance[c] += e[c]);
        let mut linked = Vec::new();
        for &p in sys.links.pairs_of(i as ElementId) {
            let pair = sys.links.pair(p);
            let j = sys.links.other(p, i as ElementId) as usize;
            linked.push(j);
            if self.is_emitter[j] {
                continue;
            }
            let cast = match (&pair.visibility, rx.near) {
                _ if self.occluders.is_none() => Rays::None,
                (_, true) => Rays::All,
                (Visibility::Full, false) => Rays::None,
                (Visibility::Blocked, false) => continue,
                (vis @ Visibility::Partial(_), false) => {
                    Rays::Mask { vis, cell: rx.cell, corner_is_a: pair.a == i as ElementId }
                }
            };
            add(self.irradiance_from(&rx, j, &Rect::UNIT, cast, 0));
        }
        // Direct light makes the sharpest shadows, and a corner can sit in a penumbra that none
        // of its element's visibility samples is in: emitters are always sources, with rays.
        let faces_corner = |j: usize| {
            j != i && self.patches[j].front_plane().is_none_or(|f| f.any_in_front(&self.patches[i]))
        };
        for &j in self.emitters.iter().filter(|&&j| faces_corner(j)) {
            let rays = if self.occluders.is_some() { Rays::All } else { Rays::None };
            add(self.irradiance_from(&rx, j, &Rect::UNIT, rays, 0));
        }
        // Next to an occluder the corner may see what no sample of its element sees, and the
        // store holds no link for a pair blocked everywhere: every other element is a source.
        if rx.near {
            linked.sort_unstable();
            let unlinked = |j: &usize| linked.binary_search(j).is_err() && !self.is_emitter[*j];
            for j in (0..self.patches.len()).filter(unlinked).filter(|&j| faces_corner(j)) {
                add(self.irradiance_from(&rx, j, &Rect::UNIT, Rays::All, 0));
            }
        }
        let rho = sys.reflectance[i];
        let emission = sys.emission[i * nb];
        std::array::from_fn(|c| emission[c] + rho[c] * irradiance[c])
    }

    /// `integral g(x,y) V(x,y) B_j(y) dA_y` over `rect` of source `j`.
    fn irradiance_from(&self, rx: &Receiver, j: usize, rect: &Rect, cast: Rays<'_>, depth: u32) -> [f64; 3] {
        let patch = &self.patches[j];
        let sub = patch.sub_patch(rect);
        let (centre, radius) = sub.bounding_sphere();
        let distance = rx.x.distance(centre);
        if distance >= GAUSS_RATIO * radius {
            let local;
            let nodes = if depth == 0 {
                &self.nodes[j]
            } else {
                local = Nodes::new(self.sys, j, patch, rect, self.rule, self.cells_per_axis);
                &local
            };
            return self.gauss(rx, j, nodes, &sub.bounds(), cast);
        }
        if depth >= MAX_DEPTH {
            let (s, t) = rect.map(0.5, 0.5);
            let y = patch.point(s, t);
            if !self.visible(rx, j, y, crate::visibility::cell_of(s, t, self.cells_per_axis), cast) {
                return [0.0; 3];
            }
            let polygon = sub.corners;
            let f = point_to_polygon(rx.x, rx.n, &polygon, sub.centre_normal());
            let b = self.sys.eval(j, s, t);
            return b.map(|b| f * b);
        }
        let mut sum = [0.0; 3];
        for q in rect.quadrants() {
            let e = self.irradiance_from(rx, j, &q, cast, depth + 1);
            for c in 0..3 {
                sum[c] += e[c];
            }
        }
        sum
    }

    /// The Gauss sum over `nodes` of source `j` (inside `bounds`), shadow rays as `cast` says.
    fn gauss(&self, rx: &Receiver, j: usize, nodes: &Nodes, bounds: &Aabb, cast: Rays<'_>) -> [f64; 3] {
        let mut lit: Vec<(usize, f64)> = (0..nodes.position.len())
            .map(|k| (k, point_kernel(rx.x, rx.n, nodes.position[k], nodes.normal[k])))
            .filter(|&(_, g)| g != 0.0)
            .collect();
        if let (Rays::All, Some(o), false) = (cast, self.occluders, lit.is_empty()) {
            let targets: Vec<DVec3> = lit.iter().map(|&(k, _)| nodes.position[k]).collect();
            let mut visible = Vec::with_capacity(targets.len());
            o.point_visibility(rx.x, rx.n, (rx.element, j as u32), bounds, &targets, &mut visible);
            let mut v = visible.into_iter();
            lit.retain(|_| v.next() == Some(true));
        } else if let Rays::Mask { .. } = cast {
            lit.retain(|&(k, _)| self.visible(rx, j, nodes.position[k], nodes.cell[k], cast));
        }
        let mut sum = [0.0; 3];
        for (k, g) in lit {
            let w = g * nodes.area_weight[k];
            for c in 0..3 {
                sum[c] += w * nodes.radiosity[k][c];
            }
        }
        sum
    }

    /// Whether `y` (in visibility cell `cell` of source `j`) is seen from the corner.
    fn visible(&self, rx: &Receiver, j: usize, y: DVec3, cell: usize, rays: Rays<'_>) -> bool {
        let cells = self.cells_per_axis * self.cells_per_axis;
        match (rays, self.occluders) {
            (Rays::None, _) | (_, None) => true,
            (Rays::All, Some(o)) => o.segment_visible(rx.x, y, rx.element, j as u32),
            (Rays::Mask { vis, cell: corner, corner_is_a }, _) => {
                if corner_is_a {
                    vis.at(corner, cell, cells) > 0.0
                } else {
                    vis.at(cell, corner, cells) > 0.0
                }
            }
        }
    }
}
