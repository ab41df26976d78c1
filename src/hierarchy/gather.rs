//! Final gather at face corners through the hierarchy: `B` at a corner point from the links that
//! light it, cast from the point itself (the flat system's [`crate::gather`], eq. 1 at a point).
//!
//! A leaf's light arrives through its own links and through those of every ancestor: the push
//! hands what a node gathered down to all its descendants ([`super::solve`]). So the links of
//! the corner's leaf, of the surfaces above it up to its face, and of the clusters above the face
//! up to the root partition what the corner sees, each source once. The gather takes each of
//! them from the corner instead of from the receiving node:
//!
//! - a surface source `S` (a face or part of one, polynomial `b_S`) by its point moments
//!   `m^l = integral_S g(x,y) V(x,y) Gamma_l(y) dA_y`, integrated adaptively with shadow rays
//!   from the corner, so that the contact shadows and the penumbrae inside a large receiving
//!   element show at its corners; `H += sum_l m^l b_S^l`;
//! - a cluster source (or any source linked with a cluster) by its intensity towards the corner,
//!   `I_S(w) T / d^2 max(0, n.(-w))`, the link's transmittance `T` and the exact cosine at the
//!   corner (the solve's receiving lobes truncate it).
//!
//! Then `B = E + rho (bound(F) H + E_d)`, with `F` the corner's form factors summed (the
//! hemisphere bound, [`crate::hemisphere`]) and `E_d` the lights' direct irradiance at the point.
//! A corner inside another closed surface receives nothing ([`crate::solids`]).
//!
//! Three things the first version lacked, measured on the 300-triangle bunny against Cycles per
//! corner (tests/hierarchy.rs; Bunny / Ground relative RMSE at accuracy 1e-4):
//! - a source linked through a cluster link but itself a surface (a light linked with a model's
//!   cluster) is integrated from the point like any surface, with rays: the model's shadows on
//!   itself show (cluster intensity at the point: 34.7% / 4.7%);
//! - a point that touches a source (a model's corner on the floor) takes the part of the source
//!   next to it from `B` gathered at the foot ([`Gather::touch`], the flat gather's feet);
//! - pairs the refinement found blocked ([`super::refine::Hierarchy::blocked`]) are sources too:
//!   a corner on the edge of a shadow sees past what every sample of its leaf saw blocked
//!   (without them 7.8% / 4.9%, with them 5.7% / 0.7%; the flat gather 5.2% / 1.4%).
//!
//! Nothing is kept from frame to frame yet: the hierarchy solves every frame from scratch.

use glam::DVec3;
use rayon::prelude::*;

use super::coupling::{SplitMix, sample_point, weighted_rays};
use super::solve::{Incoming, State};
use super::tree::{Kind, NodeId, Surface, Tree};
use crate::basis::MAX_LEN as MAX_NB;
use crate::error::Result;
use crate::gather::{
    BALL_EDGE, CornerValues, FACING, FOOT_BALL, NEAR_FACING, Stop, behind_plane, corner_points, shading_point,
};
use crate::geometry::{Patch, Rect};
use crate::kernel::point::{point_kernel, point_to_polygon};
use crate::lights::direct::DirectLight;
use crate::quadrature::GaussLegendre;
use crate::scene::Scene;
use crate::solids::Solids;
use crate::system::Progress;
use crate::visibility::Occluders;

use super::coupling::Link;

/// A source (sub-)rectangle is integrated by the Gauss rule once the distance from the corner to
/// its centre is this many times its bounding radius; closer, it is split in four (as
/// [`crate::gather`] does).
const GAUSS_RATIO: f64 = 3.0;

/// Gauss points per axis of a source rectangle.
const GAUSS_POINTS: usize = 3;

/// Past this many bounding radii a source rectangle takes [`FAR_POINTS`] per axis: 4 rays
/// instead of 9. Measured on the bunny against Cycles (accuracy 1e-4, tests/hierarchy.rs):
/// 5.66% / 0.66% per corner with 3 x 3 everywhere, 5.71% / 0.69% with this, 4 radii 5.72% /
/// 0.92%; the decimated monastery's gather 83 -> 63 s, the bunny's 4.5 -> 3.4 s (one run).
const FAR_RATIO: f64 = 6.0;
const FAR_POINTS: usize = 2;

/// Deepest split of a source rectangle; there its form factor is taken analytically.
const MAX_DEPTH: u32 = 12;

/// What the gather of one hierarchical frame reads.
pub struct Inputs<'a> {
    pub tree: &'a Tree,
    pub links: &'a [Link],
    /// Pairs whose sampled rays were all blocked ([`super::refine::Hierarchy::blocked`]).
    pub blocked: &'a [(NodeId, NodeId)],
    pub state: &'a State,
    /// Per face, its exitance.
    pub emission: &'a [[f64; 3]],
    pub occluders: Option<&'a Occluders>,
    pub lights: Option<&'a DirectLight>,
}

/// `B` and the light received `H` (`B = E + rho H`) at every face corner of `scene` (placed at
/// `frame`), per object in face order (the order of
/// [`crate::scene::json::ObjectResult::corner_radiosity`]), and the number of distinct points.
pub fn corners(
    inputs: &Inputs,
    scene: &Scene,
    frame: f64,
    progress: Progress,
) -> Result<(CornerValues, CornerValues, usize)> {
    let tree = inputs.tree;
    let (points, point_of_corner, corners_per_object) = corner_points(
        scene,
        frame,
        |o, f, s, t| {
            let key = (o as u32, f as u32);
            let face = tree.faces.binary_search_by(|e| (e.object, e.face).cmp(&key)).ok()?;
            // The face's own parameters (a mirrored face runs its `s` backwards, as
            // `HierarchicalFrame::eval_face` reads it).
            let s = if tree.faces[face].mirrored { 1.0 - s } else { s };
            Some((face, s, t))
        },
        |face| tree.faces[face].patch,
    );
    let stop = Stop::new(progress, points.len());
    if !progress(0.0, "corner gather") {
        return Err(crate::error::Error::Cancelled);
    }
    let gather = Gather::new(inputs, &stop)?;
    let solids = inputs
        .occluders
        .is_some()
        .then(|| Solids::new(&tree.faces, scene.objects.len()))
        .filter(|s| !s.is_empty());
    let values: Vec<[[f64; 3]; 2]> = points
        .par_iter()
        .map(|p| {
            stop.done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if stop.stopped() {
                return [[0.0; 3]; 2];
            }
            match p.at {
                Some(at) => gather.point(at, p.normal, solids.as_ref(), true),
                None => [p.exitance(scene, frame), [0.0; 3]],
            }
        })
        .collect();
    stop.outcome()?;
    let per_object = |which: usize| {
        let mut out = Vec::with_capacity(corners_per_object.len());
        let mut it = point_of_corner.iter().map(|&k| values[k][which]);
        for &n in &corners_per_object {
            out.push(it.by_ref().take(n).collect());
        }
        out
    };
    Ok((per_object(0), per_object(1), points.len()))
}

/// The point being gathered: where it is and which face it is on (its rays skip that face).
struct Receiver {
    x: DVec3,
    n: DVec3,
    face: u32,
    /// Its face's bounding radius.
    radius: f64,
}

/// A surface source being integrated from a point: its face, its patch, and the occluder
/// triangles that may block the point's rays to it ([`Occluders::point_candidates`]).
struct Source<'a> {
    face: u32,
    patch: &'a Patch,
    candidates: &'a [usize],
}

/// Where a point touches a source (a model's corner on the floor it stands on): the foot
/// point's parameters on the source node and the radius around the point that counts with
/// `B` gathered at the foot.
#[derive(Clone, Copy, Debug)]
struct Touch {
    s: f64,
    t: f64,
    radius: f64,
}

struct Gather<'a> {
    inputs: &'a Inputs<'a>,
    stop: &'a Stop<'a>,
    incoming: Incoming,
    blocked: Incoming,
    /// Per node, its parent (the root's is itself).
    parent: Vec<NodeId>,
    rule: GaussLegendre,
    /// The rule past [`FAR_RATIO`].
    far_rule: GaussLegendre,
}

impl<'a> Gather<'a> {
    fn new(inputs: &'a Inputs<'a>, stop: &'a Stop<'a>) -> Result<Self> {
        let tree = inputs.tree;
        let mut parent: Vec<NodeId> = (0..tree.nodes.len() as NodeId).collect();
        for (id, node) in tree.nodes.iter().enumerate() {
            let children: &[NodeId] = match &node.kind {
                Kind::Cluster { children } => children,
                Kind::Surface(s) => s.children.as_ref().map_or(&[], |c| c),
            };
            for &c in children {
                parent[c as usize] = id as NodeId;
            }
        }
        Ok(Self {
            inputs,
            stop,
            incoming: Incoming::new(tree.nodes.len(), inputs.links)?,
            blocked: Incoming::of_pairs(tree.nodes.len(), inputs.blocked)?,
            parent,
            rule: GaussLegendre::new(GAUSS_POINTS),
            far_rule: GaussLegendre::new(FAR_POINTS),
        })
    }

    /// `B` and `H` at `(s,t)` of face `f` (its patch's parameters), gathered with the shading normal
    /// `normal` where it is not the face's own; with `feet`, the part of a touched source next
    /// to the point counts with `B` gathered at the foot point (itself without feet).
    fn point(
        &self,
        (f, s, t): (usize, f64, f64),
        normal: Option<DVec3>,
        solids: Option<&Solids>,
        feet: bool,
    ) -> [[f64; 3]; 2] {
        let tree = self.inputs.tree;
        let face = &tree.faces[f];
        let (x, n) = shading_point(&face.patch, s, t, normal);
        let emission = self.inputs.emission[f];
        if let Some(solids) = solids {
            let (centre, radius) = face.patch.bounding_sphere();
            let nf = face.patch.area_vector(s, t).normalize_or_zero();
            if solids.buries(crate::solids::test_point(face.patch.point(s, t), nf, centre, radius)) {
                return [emission, [0.0; 3]];
            }
        }
        let rx = Receiver { x, n, face: f as u32, radius: face.patch.bounding_sphere().1 };
        let feet = feet.then_some(solids);
        let (leaf, _, _) = tree.leaf_at(f, s, t);
        let mut h = [0.0; 3];
        let mut form_factors = 0.0;
        let mut node = leaf;
        loop {
            let linked = self.incoming.of(node as usize).iter().map(|&(l, side)| {
                let link = &self.inputs.links[l as usize];
                if side == 0 { link.b } else { link.a }
            });
            let blocked = self.blocked.of(node as usize).iter().map(|&(k, side)| {
                let (a, b) = self.inputs.blocked[k as usize];
                if side == 0 { b } else { a }
            });
            for source in linked.chain(blocked) {
                // A surface source is integrated from the point whatever the link (a light linked
                // with the cluster of a model's faces casts the model's own shadows on them).
                if tree.node(source).is_cluster() {
                    self.cluster_source(&rx, source, &mut h);
                } else {
                    self.surface_source(&rx, source, feet, &mut h, &mut form_factors);
                }
                if self.stop.stopped() {
                    return [[0.0; 3]; 2];
                }
            }
            let up = self.parent[node as usize];
            if up == node {
                break;
            }
            node = up;
        }
        let bound = crate::hemisphere::bound(form_factors);
        let direct = self.inputs.lights.map_or([0.0; 3], |l| l.irradiance(x, n, f as u32));
        let rho = tree.reflectance[f];
        let received: [f64; 3] = std::array::from_fn(|c| bound * h[c] + direct[c]);
        [std::array::from_fn(|c| emission[c] + rho[c] * received[c]), received]
    }

    /// Adds the surface node `source`'s light at the point to `h` and its form factor to `ff`.
    /// With `feet = Some(solids)`, a source the point touches ([`Gather::touch`]) takes its part
    /// next to the point from `B` at the foot: nearly all of its form factor comes from there,
    /// in a contact shadow far finer than the source's polynomial ([`crate::gather`]'s feet).
    fn surface_source(
        &self,
        rx: &Receiver,
        source: NodeId,
        feet: Option<Option<&Solids>>,
        h: &mut [f64; 3],
        ff: &mut f64,
    ) {
        let tree = self.inputs.tree;
        let node = tree.node(source);
        let s = node.surface().expect("a surface link's ends are surfaces");
        let nb = tree.basis.len();
        let mut m = [0.0; MAX_NB];
        let touch = feet.and_then(|_| self.touch(rx, node.radius, s));
        let mut weight = 0.0;
        let ball = touch.map(|t| (t.radius, &mut weight));
        // The triangles that may block the point's rays to any part of the source, found once.
        let mut candidates = Vec::new();
        if let Some(o) = self.inputs.occluders {
            o.point_candidates(rx.x, rx.n, (rx.face, s.face), &s.patch.bounds(), &mut candidates);
        }
        let src = Source { face: s.face, patch: &s.patch, candidates: &candidates };
        self.moments(rx, &src, &Rect::UNIT, 0, &mut m[..nb], ball);
        let b = self.inputs.state.coefficients(source);
        for l in 0..nb {
            for c in 0..3 {
                h[c] += m[l] * b[l][c];
            }
        }
        // Gamma_0 = 1: the l = 0 moment is the form factor.
        *ff += m[0] + weight;
        if let (Some(t), Some(solids), true) = (touch, feet, weight > 0.0) {
            let (fs, ft) = s.domain.map(t.s, t.t);
            let [foot, _] = self.point((s.face as usize, fs, ft), None, solids, false);
            for c in 0..3 {
                h[c] += weight * foot[c];
            }
        }
    }

    /// Whether the point touches the surface node `s` (bounding radius `radius`): it lies just
    /// in front of `s`'s plane and its foot falls on `s` (as [`crate::gather`] decides it for an
    /// element). Facing `s` from closer than [`NEAR_FACING`] of its radius, the foot is the
    /// point's projection and the ball [`FOOT_BALL`] times the distance; at an angle, the foot is
    /// as far along the point's normal as the point is above `s` (at least a hundredth of its
    /// face's radius), projected, and the ball three times that.
    fn touch(&self, rx: &Receiver, radius: f64, s: &Surface) -> Option<Touch> {
        let (normal, centre) = (s.normal, s.patch.point(0.5, 0.5));
        let d = normal.dot(rx.x - centre);
        let on = |foot: DVec3, radius: f64| {
            let (u, v) = s.patch.locate(foot);
            ((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v)).then_some(Touch { s: u, t: v, radius })
        };
        if rx.n.dot(normal) < -FACING {
            return (d > 0.0 && d < NEAR_FACING * radius).then(|| on(rx.x - d * normal, FOOT_BALL * d))?;
        }
        let touching = d > 0.0 && d < 1e-2 * rx.radius;
        let near = d > 0.0 && d < NEAR_FACING * radius;
        if !(touching || near) || rx.n.dot(normal).abs() > 0.9 {
            return None;
        }
        let offset = if touching { 1e-2 * rx.radius } else { d };
        let foot = rx.x + offset * rx.n;
        on(foot - normal.dot(foot - centre) * normal, 3.0 * offset)
    }

    /// Adds the light of the cluster `source` at the corner: its intensity towards the corner
    /// over the squared distance, times the cosine there and the share of rays from the corner
    /// to points of the cluster facing it that arrive (the link's own transmittance is between
    /// the two nodes, blind to the shadows inside the receiving node).
    fn cluster_source(&self, rx: &Receiver, source: NodeId, h: &mut [f64; 3]) {
        let tree = self.inputs.tree;
        let ns = tree.node(source);
        let v = rx.x - ns.centre;
        let d2 = v.length_squared();
        if d2 <= 0.0 {
            return;
        }
        let w = v / d2.sqrt();
        let cos = (-rx.n.dot(w)).max(0.0);
        if cos == 0.0 {
            return;
        }
        // The intensity first: a dark cluster costs no rays.
        let intensity = super::lobes::eval(self.inputs.state.lobes(source), w);
        if intensity == [0.0; 3] {
            return;
        }
        let t = self.point_transmittance(rx, source);
        for c in 0..3 {
            h[c] += intensity[c] * t * cos / d2;
        }
    }

    /// The transmittance from the corner to the cluster `source`: [`weighted_rays`] to points
    /// below it (area-weighted), with `d` to its centre, as the links' own.
    fn point_transmittance(&self, rx: &Receiver, source: NodeId) -> f64 {
        let d2 = rx.x.distance_squared(self.inputs.tree.node(source).centre);
        let seed = rx.x.to_array().iter().fold(source as u64, |h, c| h.rotate_left(21) ^ c.to_bits());
        let mut rng = SplitMix(seed ^ 0x2545_F491_4F6C_DD1D);
        let corner = (rx.face, rx.x, rx.n);
        weighted_rays(self.inputs.occluders, d2, || {
            (corner, sample_point(self.inputs.tree, source, &mut rng))
        })
        .weighted
    }

    /// Adds `integral g(x,y) V(x,y) Gamma_l(y) dA_y` over `rect` of `patch` (a node of face
    /// `face`, `Gamma_l` over the node's own parameters) to `out[l]`.
    /// With `ball = Some((r, weight))`, the part within `r` of the point adds its
    /// `integral g V dA` to `weight` instead.
    #[allow(clippy::too_many_arguments)]
    fn moments(
        &self,
        rx: &Receiver,
        src: &Source,
        rect: &Rect,
        depth: u32,
        out: &mut [f64],
        ball: Option<(f64, &mut f64)>,
    ) {
        if self.stop.stopped() {
            return;
        }
        let patch = src.patch;
        let sub = patch.sub_patch(rect);
        let (centre, radius) = sub.bounding_sphere();
        if behind_plane(rx.x, rx.n, &sub, radius) {
            return;
        }
        let distance = rx.x.distance(centre);
        if let Some((r, weight)) = ball {
            let edge = depth >= MAX_DEPTH || radius <= BALL_EDGE * r;
            if distance + radius <= r || (edge && distance <= r) {
                let mut m = [0.0; MAX_NB];
                self.moments(rx, src, rect, depth, &mut m[..out.len()], None);
                *weight += m[0];
                return;
            }
            if distance - radius < r && !edge {
                for q in rect.quadrants() {
                    self.moments(rx, src, &q, depth + 1, out, Some((r, &mut *weight)));
                }
                return;
            }
        }
        let basis = self.inputs.tree.basis;
        if distance >= GAUSS_RATIO * radius {
            let rule = if distance >= FAR_RATIO * radius { &self.far_rule } else { &self.rule };
            self.gauss(rx, src, rect, rule, out);
            return;
        }
        if depth >= MAX_DEPTH {
            let (s, t) = rect.map(0.5, 0.5);
            let y = patch.point(s, t);
            if let Some(o) = self.inputs.occluders {
                let mut seen = [true];
                o.visibility_among(src.candidates, rx.x, (rx.face, src.face), &[y], &mut seen);
                if !seen[0] {
                    return;
                }
            }
            let f = point_to_polygon(rx.x, rx.n, &sub.corners, sub.centre_normal());
            let mut g = [0.0; MAX_NB];
            basis.eval_into(s, t, &mut g[..out.len()]);
            for (o, g) in out.iter_mut().zip(g) {
                *o += f * g;
            }
            return;
        }
        for q in rect.quadrants() {
            self.moments(rx, src, &q, depth + 1, out, None);
        }
    }

    /// The Gauss sum over `rect` of the source into `out`, with one shadow ray per node that
    /// the point faces.
    fn gauss(&self, rx: &Receiver, src: &Source, rect: &Rect, rule: &GaussLegendre, out: &mut [f64]) {
        let patch = src.patch;
        const N: usize = GAUSS_POINTS * GAUSS_POINTS;
        let nb = out.len();
        let measure = rect.measure();
        let mut lit = [(DVec3::ZERO, 0.0f64, 0.0f64, 0.0f64); N];
        let mut count = 0;
        for (u, wu) in rule.iter() {
            for (v, wv) in rule.iter() {
                let (s, t) = rect.map(u, v);
                let av = patch.area_vector(s, t);
                let a = av.length();
                if a <= 0.0 {
                    continue;
                }
                let y = patch.point(s, t);
                let g = point_kernel(rx.x, rx.n, y, av / a);
                if g != 0.0 {
                    lit[count] = (y, g * wu * wv * measure * a, s, t);
                    count += 1;
                }
            }
        }
        if count == 0 {
            return;
        }
        let mut visible = [true; N];
        if let Some(o) = self.inputs.occluders {
            let targets: [DVec3; N] = std::array::from_fn(|k| lit[k.min(count - 1)].0);
            o.visibility_among(
                src.candidates,
                rx.x,
                (rx.face, src.face),
                &targets[..count],
                &mut visible[..count],
            );
        }
        let basis = self.inputs.tree.basis;
        let mut g = [0.0; MAX_NB];
        for (&(_, w, s, t), _) in lit[..count].iter().zip(&visible).filter(|(_, v)| **v) {
            basis.eval_into(s, t, &mut g[..nb]);
            for l in 0..nb {
                out[l] += w * g[l];
            }
        }
    }
}
