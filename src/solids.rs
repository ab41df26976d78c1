//! Closed surfaces and the points they bury.
//!
//! Artists push objects into each other instead of modelling them to touch: a bunny sunk a
//! little into a table, a teddy made of convex hulls that pass through each other, a block's
//! bottom face lying on the floor. A point of one surface inside another closed surface receives
//! no light (a path tracer's vertex bake is black there), but the kernel and the corner gather
//! do not know it: a source's polynomial is not zero under the contact, and a ray from inside to
//! a face coplanar with the contact (the floor under a block's bottom) passes between the two.
//! Measured on two boxes pushed into each other (tests/hemisphere.rs): buried corners saw
//! 1-16% of their hemisphere and got 0.4-1.2% of the peak.
//!
//! So the rule is geometric, decided per point: a point buried in a closed, outward-facing
//! component of the scene (its generalized winding number, the triangles' signed solid angles
//! over `4 pi`, is at least 1/2) receives nothing. A *component* is a set of faces of one object
//! connected through shared corner points; it is *closed* when every edge is used once in each
//! direction, and *outward* when its signed volume is positive (an inward room is not solid: its
//! inside is where the light is). The point is taken a hair in front of its own face
//! ([`test_point`]), so its own component does not count it as inside.

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::Aabb;
use crate::system::Element;

/// Corner points closer than this fraction of the scene's size are one vertex.
const WELD: f64 = 1e-6;

/// The closed, outward components of the scene as placed at one frame.
pub struct Solids {
    components: Vec<Component>,
}

struct Component {
    bounds: Aabb,
    triangles: Vec<[DVec3; 3]>,
}

impl Solids {
    /// The solids among `elements` (one per face, world space, as placed now). Faces join a
    /// component where they share a corner point (welded within a millionth of the scene's
    /// size, so that meshes whose vertices are split along seams still close).
    pub fn new(elements: &[Element], objects: usize) -> Self {
        let mut by_object: Vec<Vec<usize>> = vec![Vec::new(); objects];
        // (Backs, crate::backs, lie on their fronts: not part of a solid.)
        for (e, el) in elements.iter().enumerate().filter(|(_, el)| !el.back) {
            by_object[el.object as usize].push(e);
        }
        let scale = elements.iter().fold(Aabb::EMPTY, |b, e| b.union(e.patch.bounds())).diagonal().length();
        let scale = scale.max(f64::MIN_POSITIVE);
        let components = by_object
            .par_iter()
            .flat_map_iter(|members| closed_components(elements, members, WELD * scale))
            .collect();
        Self { components }
    }

    /// Whether there are any solids at all.
    pub fn is_empty(&self) -> bool {
        self.components.is_empty()
    }

    /// Whether the surface point `x` (front normal `n`) of a face of centre `centre` and bounding
    /// radius `radius` is buried: both [`test_point`] and the point itself, lifted alike, lie
    /// inside a solid. The step towards the centre keeps a point lifted off a concave edge out of
    /// its own solid; alone, it buried points of faces that cross into another solid within that
    /// thousandth of the point (hulls of one model meeting at nearly coplanar faces: the teddy's
    /// cut planes, docs/validation-real.md), whose own point is outside and which Cycles bakes lit.
    pub fn buries_surface_point(&self, x: DVec3, n: DVec3, centre: DVec3, radius: f64) -> bool {
        self.buries(test_point(x, n, centre, radius)) && self.buries(test_point(x, n, x, radius))
    }

    /// Whether `p` lies inside some solid. For a point of a surface, see
    /// [`Solids::buries_surface_point`].
    pub fn buries(&self, p: DVec3) -> bool {
        self.components.iter().any(|c| {
            c.bounds.min.cmple(p).all()
                && p.cmple(c.bounds.max).all()
                && winding_number(&c.triangles, p) >= 0.5
        })
    }
}

/// The point to test for the surface point `x` (front normal `n`) of a face of centre `centre`
/// and bounding radius `radius`: a thousandth of the way to the centre, then a hundred-thousandth
/// of the radius in front. A corner sits on its face's edges (a triangle's apex on two of them),
/// where a point lifted straight off the face can pass behind the neighbour across a concave
/// edge, inside its own solid; moved in first, the lift stays far below its distance to them.
pub fn test_point(x: DVec3, n: DVec3, centre: DVec3, radius: f64) -> DVec3 {
    x + (centre - x) * 1e-3 + n * (1e-5 * radius)
}

/// The polygon of a face element: its patch's corners without the collapsed one of a triangle.
fn polygon(el: &Element) -> Vec<DVec3> {
    let c = el.patch.corners;
    if c[3] == c[2] { c[..3].to_vec() } else { c.to_vec() }
}

/// The closed, outward components of one object's faces (`members`: its elements), corner
/// points welded on a grid of `weld`.
fn closed_components(elements: &[Element], members: &[usize], weld: f64) -> Vec<Component> {
    use std::collections::HashMap;
    let mut ids: HashMap<[i64; 3], u32> = HashMap::new();
    let faces: Vec<Vec<u32>> = members
        .iter()
        .map(|&e| {
            polygon(&elements[e])
                .iter()
                .map(|p| {
                    let key = (*p / weld).round().as_i64vec3().to_array();
                    let next = ids.len() as u32;
                    *ids.entry(key).or_insert(next)
                })
                .collect()
        })
        .collect();
    // Union-find over the welded points, joining each face's.
    let mut parent: Vec<u32> = (0..ids.len() as u32).collect();
    for face in &faces {
        for &v in &face[1..] {
            union(&mut parent, face[0], v);
        }
    }
    let mut groups: HashMap<u32, Vec<usize>> = HashMap::new();
    for (k, face) in faces.iter().enumerate() {
        groups.entry(find(&mut parent, face[0])).or_default().push(k);
    }
    let mut out = Vec::new();
    for group in groups.into_values() {
        // Closed: every edge used twice, once in each direction (a zero-area face skipped by
        // the scene leaves a hole, so its component is not a solid: conservative).
        let mut edges: HashMap<(u32, u32), (i32, u32)> = HashMap::new();
        for &k in &group {
            let face = &faces[k];
            for i in 0..face.len() {
                let (a, b) = (face[i], face[(i + 1) % face.len()]);
                let entry = edges.entry((a.min(b), a.max(b))).or_default();
                entry.0 += if a < b { 1 } else { -1 };
                entry.1 += 1;
            }
        }
        if edges.values().any(|&(direction, uses)| direction != 0 || uses != 2) {
            continue;
        }
        let triangles: Vec<[DVec3; 3]> = group
            .iter()
            .flat_map(|&k| {
                let p = polygon(&elements[members[k]]);
                (1..p.len() - 1).map(move |i| [p[0], p[i], p[i + 1]]).collect::<Vec<_>>()
            })
            .collect();
        let volume: f64 = triangles.iter().map(|t| t[0].dot(t[1].cross(t[2]))).sum::<f64>() / 6.0;
        if volume <= 0.0 {
            continue;
        }
        let bounds = triangles.iter().flatten().fold(Aabb::EMPTY, |b, &p| b.grow(p));
        out.push(Component { bounds, triangles });
    }
    out
}

/// The generalized winding number of a closed triangle set at `p`: the sum of the triangles'
/// signed solid angles (Van Oosterom and Strackee 1983) over `4 pi`; 1 inside, 0 outside.
fn winding_number(triangles: &[[DVec3; 3]], p: DVec3) -> f64 {
    let mut sum = 0.0;
    for t in triangles {
        let (a, b, c) = (t[0] - p, t[1] - p, t[2] - p);
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let det = a.dot(b.cross(c));
        let div = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
        sum += 2.0 * det.atan2(div);
    }
    sum / (4.0 * std::f64::consts::PI)
}

/// Union-find over ids `0..parent.len()` (each `parent[x] == x` to start): the root of `x`'s
/// set, halving the path on the way. Used for the solids' welded points and for the open pieces
/// of `crate::backs`.
pub(crate) fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        parent[x as usize] = parent[parent[x as usize] as usize];
        x = parent[x as usize];
    }
    x
}

/// Joins the sets of `a` and `b` (the smaller root becomes the root).
pub(crate) fn union(parent: &mut [u32], a: u32, b: u32) {
    let (a, b) = (find(parent, a), find(parent, b));
    if a != b {
        parent[a.max(b) as usize] = a.min(b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(min: DVec3, max: DVec3) -> Vec<[DVec3; 3]> {
        let o = crate::scenes::box_mesh("c", min, max, 1, false, 0);
        o.faces
            .iter()
            .flat_map(|f| {
                let v = |k: usize| o.vertices[f[k] as usize];
                [[v(0), v(1), v(2)], [v(0), v(2), v(3)]]
            })
            .collect()
    }

    #[test]
    fn winding_number_is_one_inside_and_zero_outside() {
        let t = cube(DVec3::ZERO, DVec3::ONE);
        assert!((winding_number(&t, DVec3::splat(0.5)) - 1.0).abs() < 1e-9);
        assert!((winding_number(&t, DVec3::new(0.99, 0.01, 0.5)) - 1.0).abs() < 1e-9);
        assert!(winding_number(&t, DVec3::new(1.5, 0.5, 0.5)).abs() < 1e-9);
        assert!(winding_number(&t, DVec3::new(1.0 + 1e-9, 0.5, 0.5)).abs() < 1e-6);
    }
}
