//! The element tree: clusters over faces, faces split into quadtrees of `Rect`s.
//!
//! Faces (the input geometry: patches, occluder ids, read-back) are the scene's non-degenerate
//! faces in [`crate::system::build_elements`] order; a face is a surface node of depth 0. Above
//! them a binary volume hierarchy of clusters (median splits of the face centroids along the
//! longest axis); below them each face's parameter domain is split into quadrants on demand, and
//! a sub-rectangle of a bilinear patch is again a bilinear patch
//! ([`crate::geometry::Patch::sub_patch`]), so every kernel sees only patches. Node ids are
//! indices that are only appended while a tree lives. A later frame of an animation keeps the
//! tree and re-places the faces that moved ([`Tree::place_faces`]): the clusters keep their
//! members and refit their bounds, the quadtrees keep their splits.

use glam::DVec3;

use crate::basis::Basis;
use crate::geometry::{Aabb, FrontPlane, Patch, Rect};
use crate::quadrature::GaussLegendre;
use crate::system::Element;

pub type NodeId = u32;

/// `|sum A_f n_f| / sum A_f` above which a cluster counts as planar.
pub const PLANAR: f64 = 0.999;

/// A face or a sub-rectangle of one.
#[derive(Clone, Debug)]
pub struct Surface {
    /// The face (index into [`Tree::faces`]).
    pub face: u32,
    /// The node's part of the face's parameter domain.
    pub domain: Rect,
    /// World-space geometry over `domain`.
    pub patch: Patch,
    /// Unit front normal at the centre.
    pub normal: DVec3,
    /// `patch.front_plane()`, asked of both ends of every link computed (kept: the plane test
    /// is several square roots).
    pub front: Option<FrontPlane>,
    /// `integral Gamma_k A ds dt` over the node's own `(s,t)`: mean `B = sum_k b^k m_k / area`.
    pub moments: Vec<f64>,
    /// Quadtree depth below the face.
    pub depth: u32,
    /// The four quadrants, once split, in [`Rect::quadrants`] order.
    pub children: Option<[NodeId; 4]>,
}

/// A node of the tree.
// Clusters are at most half the nodes (one fewer than the faces), and a boxed surface would
// cost every link computed a pointer chase: the clusters' unused bytes are cheaper.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Kind {
    Cluster { children: [NodeId; 2] },
    Surface(Surface),
}

#[derive(Clone, Debug)]
pub struct Node {
    /// Bounding sphere.
    pub centre: DVec3,
    pub radius: f64,
    /// Surface area below the node.
    pub area: f64,
    /// Largest reflectance channel of any face below (the oracle's `rho`).
    pub rho_max: f64,
    /// The common unit normal when every face below is coplanar-facing (area-weighted normals
    /// summing to at least [`PLANAR`] of the area): such a node shoots and receives with the
    /// exact cosine, not the lobes' truncation.
    pub plane_normal: Option<DVec3>,
    /// `sum A_f n_f` over the faces below.
    pub normal_sum: DVec3,
    pub kind: Kind,
}

impl Node {
    pub fn surface(&self) -> Option<&Surface> {
        match &self.kind {
            Kind::Surface(s) => Some(s),
            Kind::Cluster { .. } => None,
        }
    }

    pub fn is_cluster(&self) -> bool {
        matches!(self.kind, Kind::Cluster { .. })
    }
}

/// Clusters, faces and their sub-elements.
#[derive(Clone)]
pub struct Tree {
    pub basis: Basis,
    pub nodes: Vec<Node>,
    pub root: NodeId,
    /// The input faces, one element each (whole domain).
    pub faces: Vec<Element>,
    /// Each face's reflectance.
    pub reflectance: Vec<[f64; 3]>,
    rule: GaussLegendre,
    /// Where a point below a cluster is drawn from ([`Tree::draw_face`]).
    draws: FaceDraws,
    /// Per node: split ahead of linking where another object comes close
    /// ([`Tree::split_for_contacts`]), so that no link may end at it (its children, not its
    /// polynomial, carry the contact's light). Nodes added later are not.
    opened: Vec<bool>,
}

/// The faces in the order of the cluster tree's leaves, each cluster's faces a run of it, and
/// the running sum of their areas: a face below a cluster drawn by area is a binary search in
/// that cluster's run, instead of a walk down the tree with a random number per level (the
/// cluster links' and the gather's sampled segments spent a tenth of the link phase walking).
#[derive(Clone, Default)]
struct FaceDraws {
    order: Vec<NodeId>,
    /// Per cluster node id (the build's nodes): its faces' run in `order`.
    run: Vec<(u32, u32)>,
    /// `area_before[k]`: the area of `order[..k]`.
    area_before: Vec<f64>,
    /// Per node of the build ([`Tree::built`]), its area centroid ([`Tree::centroid`]): a face's
    /// by [`face_centroid`], a cluster's its run's `sum A_f c_f` over its area, so that it is its
    /// children's area-weighted (read by every sweep's push).
    centroids: Vec<DVec3>,
    /// `(face, patch)` of `order[k]`: a drawn point reads its face from here, a cluster's faces
    /// side by side, not from the face's node (a cache miss per point, an eighth of the time of
    /// drawing one).
    patches: Vec<(u32, Patch)>,
}

impl Tree {
    /// Clusters over `faces` (non-empty), each face a surface node.
    pub fn new(faces: Vec<Element>, reflectance: Vec<[f64; 3]>, basis: Basis) -> Self {
        assert!(!faces.is_empty(), "a tree needs a face");
        let mut tree = Tree {
            basis,
            nodes: Vec::new(),
            root: 0,
            faces,
            reflectance,
            rule: GaussLegendre::new(4),
            draws: FaceDraws::default(),
            opened: Vec::new(),
        };
        for f in 0..tree.faces.len() {
            let e = &tree.faces[f];
            let (centre, radius) = e.patch.bounding_sphere();
            let node = Node {
                centre,
                radius,
                area: e.area,
                rho_max: tree.reflectance[f].iter().copied().fold(0.0, f64::max),
                plane_normal: Some(e.patch.centre_normal()),
                normal_sum: e.patch.centre_normal() * e.area,
                kind: Kind::Surface(Surface {
                    face: f as u32,
                    domain: Rect::UNIT,
                    patch: e.patch,
                    normal: e.patch.centre_normal(),
                    front: e.patch.front_plane(),
                    moments: e.moments.clone(),
                    depth: 0,
                    children: None,
                }),
            };
            tree.nodes.push(node);
        }
        let mut ids: Vec<NodeId> = (0..tree.faces.len() as NodeId).collect();
        let bounds: Vec<Aabb> = tree.faces.iter().map(|e| e.patch.bounds()).collect();
        let mut runs = vec![(0, 0); tree.faces.len()];
        tree.root = tree.cluster(&mut ids, 0, &bounds, &mut runs);
        tree.draws = FaceDraws { order: ids, run: runs, ..Default::default() };
        tree.refresh_draws();
        tree
    }

    /// Splits each face's quadtree down to its `parts` (per face, the quadtree rectangles of
    /// [`crate::contact_split::plan`]; `[Rect::UNIT]` where nothing comes close), and marks every
    /// node split on the way as opened: the refinement links below it only (a face half under
    /// another object is one polynomial too bright beside the contact and negative under it;
    /// docs/validation-real.md, "The contact split").
    pub fn split_for_contacts(&mut self, parts: &[Vec<Rect>]) {
        for (f, parts) in parts.iter().enumerate() {
            for part in parts.iter().filter(|r| **r != Rect::UNIT) {
                let mut id = f as NodeId;
                while let Kind::Surface(s) = &self.nodes[id as usize].kind {
                    if s.domain == *part || s.domain.s1 - s.domain.s0 <= part.s1 - part.s0 {
                        break;
                    }
                    let children = self.split(id);
                    self.opened.resize(self.nodes.len(), false);
                    self.opened[id as usize] = true;
                    let (cs, ct) = ((part.s0 + part.s1) * 0.5, (part.t0 + part.t1) * 0.5);
                    id = *children
                        .iter()
                        .find(|&&c| {
                            let d = &self.nodes[c as usize].surface().expect("a quadrant").domain;
                            (d.s0..=d.s1).contains(&cs) && (d.t0..=d.t1).contains(&ct)
                        })
                        .expect("a quadrant holds the part's centre");
                }
            }
        }
    }

    /// Whether node `id` was split ahead of linking ([`Tree::split_for_contacts`]).
    pub fn opened(&self, id: NodeId) -> bool {
        self.opened.get(id as usize).copied().unwrap_or(false)
    }

    /// The running area sums and the patches of [`FaceDraws`], from the faces' current nodes.
    fn refresh_draws(&mut self) {
        let (mut sum, mut moment) = (0.0, DVec3::ZERO);
        let mut before = Vec::with_capacity(self.draws.order.len() + 1);
        let mut moment_before = Vec::with_capacity(self.draws.order.len() + 1);
        before.push(0.0);
        moment_before.push(DVec3::ZERO);
        let mut centroids = vec![DVec3::ZERO; self.draws.run.len()];
        for &f in &self.draws.order {
            let node = &self.nodes[f as usize];
            let c = face_centroid(&node.surface().expect("faces are surfaces").patch);
            centroids[f as usize] = c;
            sum += node.area;
            moment += node.area * c;
            before.push(sum);
            moment_before.push(moment);
        }
        for id in self.faces.len()..self.draws.run.len() {
            let (lo, hi) = self.draws.run[id];
            let area = before[hi as usize] - before[lo as usize];
            centroids[id] = if area > 0.0 {
                (moment_before[hi as usize] - moment_before[lo as usize]) / area
            } else {
                self.nodes[id].centre
            };
        }
        self.draws.area_before = before;
        self.draws.centroids = centroids;
        self.draws.patches = (self.draws.order.iter())
            .map(|&f| {
                let s = self.nodes[f as usize].surface().expect("faces are surfaces");
                (s.face, s.patch)
            })
            .collect();
    }

    /// The area centroid of the faces below node `id`, a cluster or a face (its bounding
    /// sphere's centre for a node below a face). A cluster's is its children's, area-weighted,
    /// so that a slope pushed from it to them moves no light ([`crate::hierarchy::push_pull`]).
    pub fn centroid(&self, id: NodeId) -> DVec3 {
        self.draws.centroids.get(id as usize).copied().unwrap_or(self.nodes[id as usize].centre)
    }

    /// The nodes of the cluster build, the faces then the clusters (`0..built`); the nodes
    /// below faces come after.
    pub fn built(&self) -> usize {
        self.draws.run.len()
    }

    /// A face below cluster `id` drawn with probability proportional to its area, from `u` in
    /// [0, 1).
    pub fn draw_face(&self, id: NodeId, u: f64) -> NodeId {
        self.draws.order[self.draw(id, u)]
    }

    /// [`Tree::draw_face`]'s face and its patch.
    pub fn draw_face_patch(&self, id: NodeId, u: f64) -> (u32, &Patch) {
        let (face, patch) = &self.draws.patches[self.draw(id, u)];
        (*face, patch)
    }

    /// The index in the draw order of the face [`Tree::draw_face`] draws.
    fn draw(&self, id: NodeId, u: f64) -> usize {
        let (lo, hi) = self.draws.run[id as usize];
        let before = &self.draws.area_before;
        let (start, end) = (before[lo as usize], before[hi as usize]);
        let target = start + u * (end - start);
        // The last face whose run starts at or below the target: `before[lo + k] <= target`.
        lo as usize + before[lo as usize + 1..hi as usize].partition_point(|&x| x <= target)
    }

    /// A cluster over the face nodes `ids` (their node id is their face index), by median split
    /// of the centroids along the longest axis of their spread; `ids` starts at `start` in the
    /// whole order, and `runs` gets each new cluster's run in it (indexed by node id less the
    /// faces).
    fn cluster(
        &mut self,
        ids: &mut [NodeId],
        start: u32,
        bounds: &[Aabb],
        runs: &mut Vec<(u32, u32)>,
    ) -> NodeId {
        if ids.len() == 1 {
            runs[ids[0] as usize] = (start, start + 1);
            return ids[0];
        }
        let spread = ids.iter().fold(Aabb::EMPTY, |b, &i| b.grow(bounds[i as usize].centre()));
        let d = spread.diagonal();
        let axis = if d.x >= d.y && d.x >= d.z {
            0
        } else if d.y >= d.z {
            1
        } else {
            2
        };
        let mid = ids.len() / 2;
        ids.select_nth_unstable_by(mid, |&a, &b| {
            bounds[a as usize].centre()[axis].total_cmp(&bounds[b as usize].centre()[axis])
        });
        let (lo, hi) = ids.split_at_mut(mid);
        let a = self.cluster(lo, start, bounds, runs);
        let b = self.cluster(hi, start + mid as u32, bounds, runs);
        let box_of = |ids: &[NodeId]| ids.iter().fold(Aabb::EMPTY, |u, &i| u.union(bounds[i as usize]));
        let all = box_of(lo).union(box_of(hi));
        let (na, nb) = (&self.nodes[a as usize], &self.nodes[b as usize]);
        let area = na.area + nb.area;
        let normal_sum = na.normal_sum + nb.normal_sum;
        let node = Node {
            centre: all.centre(),
            radius: 0.5 * all.diagonal().length(),
            area,
            rho_max: na.rho_max.max(nb.rho_max),
            plane_normal: (normal_sum.length() >= PLANAR * area && area > 0.0)
                .then(|| normal_sum.normalize()),
            normal_sum,
            kind: Kind::Cluster { children: [a, b] },
        };
        self.nodes.push(node);
        runs.push((start, start + (lo.len() + hi.len()) as u32));
        (self.nodes.len() - 1) as NodeId
    }

    /// Takes this frame's `faces` (the same faces in the same order, some moved) and
    /// `reflectance`: every node of a face whose patch changed is placed again from the face's
    /// new patch (its quadtree's splits kept), and the clusters refit their bounds, areas and
    /// normals to their members' new places, as [`Tree::new`] would compute them for the same
    /// membership. Returns which faces moved.
    pub fn place_faces(&mut self, faces: Vec<Element>, reflectance: Vec<[f64; 3]>) -> Vec<bool> {
        assert_eq!(faces.len(), self.faces.len(), "the same faces, placed again");
        let moved: Vec<bool> =
            faces.iter().zip(&self.faces).map(|(new, old)| new.patch != old.patch).collect();
        self.faces = faces;
        self.reflectance = reflectance;
        let rho_max: Vec<f64> =
            self.reflectance.iter().map(|r| r.iter().copied().fold(0.0, f64::max)).collect();
        // Face and sub-face nodes first (any order: each depends on its face only), then the
        // clusters in id order, which puts every cluster after its children ([`Tree::cluster`]).
        let mut boxes = vec![Aabb::EMPTY; self.nodes.len()];
        for id in 0..self.nodes.len() {
            let Kind::Surface(s) = &self.nodes[id].kind else { continue };
            let (face, depth, domain) = (s.face, s.depth, s.domain);
            let f = face as usize;
            self.nodes[id].rho_max = rho_max[f];
            if moved[f] {
                let face_patch = self.faces[f].patch;
                let (patch, moments, area) = if depth == 0 {
                    (face_patch, self.faces[f].moments.clone(), self.faces[f].area)
                } else {
                    let patch = face_patch.sub_patch(&domain);
                    let e = crate::system::element(0, face, domain, patch, 0, self.basis, &self.rule);
                    (patch, e.moments, e.area)
                };
                let (centre, radius) = patch.bounding_sphere();
                let normal = patch.centre_normal();
                let node = &mut self.nodes[id];
                (node.centre, node.radius, node.area) = (centre, radius, area);
                node.plane_normal = Some(normal);
                node.normal_sum = normal * area;
                if let Kind::Surface(s) = &mut node.kind {
                    (s.patch, s.normal, s.front, s.moments) = (patch, normal, patch.front_plane(), moments);
                }
            }
            if depth == 0 {
                boxes[id] = self.faces[f].patch.bounds();
            }
        }
        for id in 0..self.nodes.len() {
            let Kind::Cluster { children: [a, b] } = self.nodes[id].kind else { continue };
            let all = boxes[a as usize].union(boxes[b as usize]);
            boxes[id] = all;
            let (na, nb) = (&self.nodes[a as usize], &self.nodes[b as usize]);
            let area = na.area + nb.area;
            let normal_sum = na.normal_sum + nb.normal_sum;
            let rho = na.rho_max.max(nb.rho_max);
            let node = &mut self.nodes[id];
            node.centre = all.centre();
            node.radius = 0.5 * all.diagonal().length();
            node.area = area;
            node.rho_max = rho;
            node.normal_sum = normal_sum;
            node.plane_normal =
                (normal_sum.length() >= PLANAR * area && area > 0.0).then(|| normal_sum.normalize());
        }
        self.refresh_draws();
        moved
    }

    /// Which nodes hold a face of `faces_moved` (a surface of such a face, or a cluster above
    /// one).
    pub fn nodes_holding(&self, faces_moved: &[bool]) -> Vec<bool> {
        let mut out = vec![false; self.nodes.len()];
        for id in 0..self.nodes.len() {
            out[id] = match &self.nodes[id].kind {
                Kind::Surface(s) => faces_moved[s.face as usize],
                Kind::Cluster { children: [a, b] } => out[*a as usize] || out[*b as usize],
            };
        }
        out
    }

    /// A box around everything below node `id`: a surface's patch bounds, a cluster's sphere.
    pub fn bounds(&self, id: NodeId) -> Aabb {
        let node = self.node(id);
        match &node.kind {
            Kind::Surface(s) => s.patch.bounds(),
            Kind::Cluster { .. } => {
                let r = DVec3::splat(node.radius);
                Aabb { min: node.centre - r, max: node.centre + r }
            }
        }
    }

    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id as usize]
    }

    /// The node's children: two for a cluster, four for a split surface, none for a leaf.
    pub fn children(&self, id: NodeId) -> &[NodeId] {
        match &self.nodes[id as usize].kind {
            Kind::Cluster { children } => children,
            Kind::Surface(s) => s.children.as_ref().map_or(&[], |c| &c[..]),
        }
    }

    /// Splits surface node `id` into its four quadrants (a no-op when split already).
    pub fn split(&mut self, id: NodeId) -> [NodeId; 4] {
        let Kind::Surface(s) = &self.nodes[id as usize].kind else { panic!("node {id} is a cluster") };
        if let Some(c) = s.children {
            return c;
        }
        let (face, domain, depth) = (s.face, s.domain, s.depth);
        let rho_max = self.nodes[id as usize].rho_max;
        let face_patch = self.faces[face as usize].patch;
        let first = self.nodes.len() as NodeId;
        for q in domain.quadrants() {
            // From the face's own patch, so that deep nodes do not accumulate rounding.
            let patch = face_patch.sub_patch(&q);
            let e = crate::system::element(0, face, q, patch, 0, self.basis, &self.rule);
            let (centre, radius) = patch.bounding_sphere();
            self.nodes.push(Node {
                centre,
                radius,
                area: e.area,
                rho_max,
                plane_normal: Some(patch.centre_normal()),
                normal_sum: patch.centre_normal() * e.area,
                kind: Kind::Surface(Surface {
                    face,
                    domain: q,
                    patch,
                    normal: patch.centre_normal(),
                    front: patch.front_plane(),
                    moments: e.moments,
                    depth: depth + 1,
                    children: None,
                }),
            });
        }
        let children = [first, first + 1, first + 2, first + 3];
        if let Kind::Surface(s) = &mut self.nodes[id as usize].kind {
            s.children = Some(children);
        }
        children
    }

    /// The leaf of face `f`'s quadtree holding the face parameter `(s,t)`, and `(s,t)` in it.
    pub fn leaf_at(&self, f: usize, s: f64, t: f64) -> (NodeId, f64, f64) {
        let mut id = f as NodeId;
        loop {
            let surface = self.nodes[id as usize].surface().expect("face nodes are surfaces");
            let Some(children) = surface.children else {
                let d = &surface.domain;
                return (id, (s - d.s0) / (d.s1 - d.s0), (t - d.t0) / (d.t1 - d.t0));
            };
            let d = &surface.domain;
            let (sm, tm) = (0.5 * (d.s0 + d.s1), 0.5 * (d.t0 + d.t1));
            id = match (s >= sm, t >= tm) {
                (false, false) => children[0],
                (true, false) => children[1],
                (true, true) => children[2],
                (false, true) => children[3],
            };
        }
    }

    /// The leaves below `id`, in depth-first order.
    pub fn leaves_below(&self, id: NodeId, out: &mut Vec<NodeId>) {
        let children = self.children(id);
        if children.is_empty() {
            out.push(id);
        } else {
            for &c in children {
                self.leaves_below(c, out);
            }
        }
    }
}

/// The area centroid of a face's patch: `int x dA / int dA` by the 2 x 2 Gauss rule, exact for
/// a planar bilinear patch (its area element is linear in each parameter).
fn face_centroid(patch: &Patch) -> DVec3 {
    const G: [f64; 2] = [0.211_324_865_405_187_1, 0.788_675_134_594_812_9];
    let (mut moment, mut area) = (DVec3::ZERO, 0.0);
    for s in G {
        for t in G {
            let da = patch.area_vector(s, t).length();
            moment += da * patch.point(s, t);
            area += da;
        }
    }
    if area > 0.0 { moment / area } else { patch.point(0.5, 0.5) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Settings;

    /// A face drawn below a cluster comes up as often as its share of the cluster's area: with
    /// `u` on a grid of `n` points, each face's count is its share of `n` within one.
    #[test]
    fn faces_are_drawn_by_area() {
        let scene = crate::scenes::cornell_box(3, Settings { basis_order: 1, ..Default::default() });
        let faces = crate::system::build_elements(&scene, 0.0, Basis::new(1));
        let reflectance = vec![[0.5; 3]; faces.len()];
        let tree = Tree::new(faces, reflectance, Basis::new(1));
        let clusters: Vec<NodeId> =
            (0..tree.nodes.len() as NodeId).filter(|&id| tree.node(id).is_cluster()).collect();
        assert!(clusters.len() > 10);
        let n = 20_000;
        for &c in clusters.iter().step_by(7).chain([&tree.root]) {
            let mut below = Vec::new();
            tree.leaves_below(c, &mut below);
            let mut count = vec![0usize; tree.faces.len()];
            for k in 0..n {
                count[tree.draw_face(c, (k as f64 + 0.5) / n as f64) as usize] += 1;
            }
            let area = tree.node(c).area;
            for f in 0..tree.faces.len() {
                let want = if below.contains(&(f as NodeId)) {
                    n as f64 * tree.node(f as NodeId).area / area
                } else {
                    0.0
                };
                assert!(
                    (count[f] as f64 - want).abs() <= 1.0,
                    "cluster {c}, face {f}: {} draws, want {want}",
                    count[f]
                );
            }
        }
    }
}
