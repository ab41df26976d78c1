//! The backs of open surfaces (issue 19): a sheet reflects from both sides.
//!
//! A face is one-sided in the Galerkin system: it receives and sends light in front of its plane.
//! Cycles' Diffuse BSDF is two-sided: the underside of a roof modelled as one sheet is lit by the
//! ground and lights it in turn, and a ground plane lit from below reflects downwards. For a closed
//! surface the difference is nothing (its inside sees only itself, and no light gets in), so only
//! faces of *open* surfaces get a back: a face whose connected piece of mesh has a boundary edge,
//! an edge used by more than two faces, or two faces that disagree on its orientation.
//!
//! A back is an element of its own (its own radiosity polynomial, linked as any other) placed on
//! the face with the winding reversed. It is not an occluder of its own: the face's triangles
//! already are, and rays leaving the back skip them as they skip the front's
//! ([`crate::visibility::Occluders::with_aliases`]). It emits nothing (a two-sided emitter's back
//! is [`crate::lights`]' job), it is split as a face ([`crate::contact_split`]), and it is read
//! back nowhere: a corner attribute holds one value per corner, the front's, as Cycles bakes the
//! front. Only planar faces get one (within `1e-9`, [`Patch::front_plane`]). On with
//! `settings.reflecting_backs`, off by default: docs/validation-real.md, "Backs".
//!
//! Which faces are open is worked out again at every frame placed (a hash of the edges, linear
//! in the faces): cheap next to a frame's links, not kept.

use std::collections::HashMap;

use glam::DVec3;

use crate::basis::Basis;
use crate::geometry::{Aabb, Patch, Rect};
use crate::quadrature::GaussLegendre;
use crate::scene::placement::front_order;
use crate::scene::{Object, Scene};
use crate::solids::{find, union};
use crate::system::{Element, element};

/// Per object, per face: whether the face gets a back. Empty when the scene's settings turn
/// backs off. Decided in object space, so the same in every frame.
pub fn faces_with_backs(scene: &Scene) -> Vec<Vec<bool>> {
    if !scene.settings.reflecting_backs {
        return Vec::new();
    }
    scene
        .objects
        .iter()
        .enumerate()
        .map(|(o, obj)| {
            let open = open_faces(obj);
            obj.faces
                .iter()
                .enumerate()
                .map(|(f, _)| open[f] && !scene.may_emit(o, f, obj.face_materials[f]))
                .collect()
        })
        .collect()
}

/// Per face of `obj`: whether its connected piece (faces joined by shared edges, vertices welded
/// by position) is open: some edge of the piece is used once, more than twice, or twice in the
/// same direction (its two faces disagree on which side is the front).
pub fn open_faces(obj: &Object) -> Vec<bool> {
    let id = welded(&obj.vertices);
    // Per undirected edge: its uses as (count, forward minus backward, first face).
    let mut edges: HashMap<(u32, u32), (u32, i32, u32)> = HashMap::with_capacity(obj.faces.len() * 3);
    let mut parent: Vec<u32> = (0..obj.faces.len() as u32).collect();
    for (f, face) in obj.faces.iter().enumerate() {
        for k in 0..face.len() {
            let (a, b) = (id[face[k] as usize], id[face[(k + 1) % face.len()] as usize]);
            if a == b {
                continue;
            }
            let key = (a.min(b), a.max(b));
            let e = edges.entry(key).or_insert((0, 0, f as u32));
            e.0 += 1;
            e.1 += if a < b { 1 } else { -1 };
            union(&mut parent, e.2, f as u32);
        }
    }
    let mut open_piece = vec![false; obj.faces.len()];
    for &(count, balance, f) in edges.values() {
        if count != 2 || balance != 0 {
            open_piece[find(&mut parent, f) as usize] = true;
        }
    }
    (0..obj.faces.len() as u32).map(|f| open_piece[find(&mut parent, f) as usize]).collect()
}

/// Per vertex, an id shared by the vertices within `1e-9` of the mesh's size of it: meshes split
/// at UV seams repeat vertices, and a mesh assembled from parts repeats them with rounding.
fn welded(vertices: &[DVec3]) -> Vec<u32> {
    let bounds = vertices.iter().fold(Aabb::EMPTY, |b, &v| b.grow(v));
    let eps = 1e-9 * bounds.diagonal().length().max(f64::MIN_POSITIVE);
    let cell = |v: DVec3| (v / eps).floor().as_i64vec3().to_array();
    let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::with_capacity(vertices.len());
    let mut id = Vec::with_capacity(vertices.len());
    for (k, &v) in vertices.iter().enumerate() {
        let c = cell(v);
        // A vertex within eps lies in this cell or a neighbour.
        let mut found = None;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    for &other in cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]).into_iter().flatten() {
                        if vertices[other as usize].distance(v) <= eps {
                            found = Some(id[other as usize]);
                            break 'search;
                        }
                    }
                }
            }
        }
        id.push(found.unwrap_or(k as u32));
        cells.entry(c).or_default().push(k as u32);
    }
    id
}

/// `elements` (sorted by object and face, the fronts) with a back inserted after the last
/// element of each face [`faces_with_backs`] marks and that is planar, reusing from `previous`
/// (the elements of another frame) each whole back whose patch did not change. A face that is
/// not planar keeps no back: a twisted sheet's two sides would see each other through rays that
/// skip the face. The backs are whole: the contact and crease split splits them as faces
/// ([`crate::contact_split`]), the back of a floor slab standing 2 cm above the ground first.
pub fn with_backs(
    scene: &Scene,
    frame: f64,
    elements: Vec<Element>,
    basis: Basis,
    previous: &[Element],
) -> Vec<Element> {
    let backs = faces_with_backs(scene);
    if backs.iter().all(|b| b.iter().all(|&x| !x)) {
        return elements;
    }
    let rule = GaussLegendre::new(4);
    let placed: Vec<(glam::DMat4, bool)> = scene
        .objects
        .iter()
        .map(|o| {
            let m = o.world_from_object(frame);
            (m, crate::scene::placement::mirrors(&m))
        })
        .collect();
    let mut kept = previous.iter().filter(|e| e.back).peekable();
    let mut out = Vec::with_capacity(elements.len() + elements.len() / 2);
    let mut elements = elements.into_iter().peekable();
    while let Some(e) = elements.next() {
        let (o, f) = (e.object, e.face);
        out.push(e);
        if elements.peek().is_some_and(|n| (n.object, n.face) == (o, f)) {
            continue;
        }
        if !backs.get(o as usize).and_then(|b| b.get(f as usize)).copied().unwrap_or(false) {
            continue;
        }
        let obj = &scene.objects[o as usize];
        let (m, mirrored) = placed[o as usize];
        // The back's winding is the front's reversed: the face's (s, t) is its patch's (1 - s, t).
        let corners: Vec<_> = front_order(&obj.faces[f as usize], !mirrored)
            .iter()
            .map(|&v| m.transform_point3(obj.vertices[v as usize]))
            .collect();
        let patch = Patch::from_corners(&corners);
        if patch.front_plane().is_none() {
            continue;
        }
        while kept.next_if(|k| (k.object, k.face) < (o, f)).is_some() {}
        let material = obj.face_materials[f as usize];
        let back = match kept.next_if(|k| (k.object, k.face) == (o, f)) {
            Some(k)
                if k.domain == Rect::UNIT
                    && k.patch == patch
                    && k.material == material
                    && k.moments.len() == basis.len() =>
            {
                k.clone()
            }
            _ => {
                let mut b = element(o, f, Rect::UNIT, patch, material, basis, &rule);
                b.mirrored = !mirrored;
                b.back = true;
                b
            }
        };
        out.push(back);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn object(vertices: Vec<DVec3>, faces: Vec<Vec<u32>>) -> Object {
        let n = faces.len();
        Object {
            name: "o".into(),
            vertices,
            faces,
            face_materials: vec![0; n],
            matrix: glam::DMat4::IDENTITY,
            animation: Vec::new(),
        }
    }

    /// A unit cube as six quads, outward: closed; without its top, open; with one face
    /// reversed, open (the reversed face's edges are used twice in one direction).
    #[test]
    fn a_cube_is_closed_until_opened_or_flipped() {
        let v: Vec<DVec3> =
            (0..8).map(|k| DVec3::new((k & 1) as f64, ((k >> 1) & 1) as f64, (k >> 2) as f64)).collect();
        let faces: Vec<Vec<u32>> = vec![
            vec![0, 2, 3, 1],
            vec![4, 5, 7, 6],
            vec![0, 1, 5, 4],
            vec![2, 6, 7, 3],
            vec![0, 4, 6, 2],
            vec![1, 3, 7, 5],
        ];
        assert_eq!(open_faces(&object(v.clone(), faces.clone())), vec![false; 6]);
        assert_eq!(open_faces(&object(v.clone(), faces[..5].to_vec())), vec![true; 5]);
        let mut flipped = faces.clone();
        flipped[1].reverse();
        assert_eq!(open_faces(&object(v.clone(), flipped)), vec![true; 6]);
        // Two pieces: the closed cube and a separate open quad beside it.
        let mut v2 = v.clone();
        v2.extend([
            DVec3::new(3.0, 0.0, 0.0),
            DVec3::new(4.0, 0.0, 0.0),
            DVec3::new(4.0, 1.0, 0.0),
            DVec3::new(3.0, 1.0, 0.0),
        ]);
        let mut f2 = faces.clone();
        f2.push(vec![8, 9, 10, 11]);
        assert_eq!(open_faces(&object(v2, f2)), [vec![false; 6], vec![true]].concat());
    }

    /// A cube whose faces have their own vertices (split at every edge, as an exporter with
    /// per-face UVs writes it) is welded by position and stays closed.
    #[test]
    fn seams_are_welded() {
        let corner = |k: u32| DVec3::new((k & 1) as f64, ((k >> 1) & 1) as f64, (k >> 2) as f64);
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let mut v = Vec::new();
        let mut faces = Vec::new();
        for q in quads {
            let base = v.len() as u32;
            v.extend(q.iter().map(|&k| corner(k)));
            faces.push((0..4).map(|k| base + k).collect());
        }
        assert_eq!(open_faces(&object(v, faces)), vec![false; 6]);
    }
}
