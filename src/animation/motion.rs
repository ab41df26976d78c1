//! The update's first phase: the new frame's elements, checked against the system's (a change of
//! topology or of coplanar cover rebuilds), and how each element moved: its shift, whether that is
//! a pure translation, and the bounds each moving object sweeps.

use glam::DVec3;

use crate::geometry::{Aabb, Patch};
use crate::scene::Scene;
use crate::system::{Element, System, build_elements_reusing};

/// Moving objects up to which each gets its own swept box (each box costs a test per pair).
const MAX_SWEPT_BOXES: usize = 4;

/// The new frame's elements, in the system's order.
pub(super) struct NewFrame {
    pub(super) elements: Vec<Element>,
    /// Their patches.
    pub(super) patches: Vec<Patch>,
    /// Per element: whether its patch differs from the system's.
    pub(super) moved: Vec<bool>,
}

impl NewFrame {
    /// The elements of `next` at `frame`, or `None` when the system must be rebuilt.
    pub(super) fn place(sys: &System, next: &Scene, frame: f64) -> Option<Self> {
        let basis = sys.basis;
        // Split faces keep their parts (crate::contact_split), decided when the system was built.
        // (Open surfaces' backs are faces here: crate::backs.)
        let faces = build_elements_reusing(next, frame, basis, &sys.elements);
        let faces = crate::backs::with_backs(next, frame, faces, basis, &sys.elements);
        let parts = crate::contact_split::parts_of(&faces, &sys.elements);
        let new_elements = crate::contact_split::split_faces(faces, &parts, basis, &sys.elements);
        if new_elements.len() != sys.elements.len()
            || new_elements
                .iter()
                .zip(&sys.elements)
                .any(|(a, b)| (a.object, a.face, a.back) != (b.object, b.face, b.back))
        {
            return None;
        }
        let n = new_elements.len();
        let patches: Vec<Patch> = new_elements.iter().map(|e| e.patch).collect();
        let old: Vec<&Patch> = sys.elements.iter().map(|e| &e.patch).collect();
        let moved: Vec<bool> = (0..n).map(|e| patches[e] != *old[e]).collect();
        // A face that starts or stops covering a coplanar one changes that one's weight as a source,
        // so every pair of it (crate::overlap): rebuild, which is rare.
        if moved.iter().any(|&m| m) && crate::overlap::source_weights(&patches) != sys.source_weights {
            return None;
        }
        Some(Self { elements: new_elements, patches, moved })
    }

    /// How many elements moved.
    pub(super) fn moved_count(&self) -> usize {
        self.moved.iter().filter(|&&m| m).count()
    }
}

/// This frame's motion of each element.
pub(super) struct FrameMotion {
    /// The scene's bounding diagonal.
    pub(super) scene_scale: f64,
    /// Displacements up to this are no motion.
    pub(super) eps: f64,
    /// Per element: the displacement of its first corner.
    pub(super) shift: Vec<DVec3>,
    /// Per element: whether it moved by a pure translation (every corner by `shift`).
    pub(super) translated: Vec<bool>,
    /// The bounds the moving objects sweep, one box per object while they are few.
    pub(super) swept: Vec<Aabb>,
}

impl FrameMotion {
    /// From the system's elements, `previous`, to `new`.
    pub(super) fn of(new: &NewFrame, previous: &[Element]) -> Self {
        let (patches, moved) = (&new.patches, &new.moved);
        let n = patches.len();
        let old: Vec<&Patch> = previous.iter().map(|e| &e.patch).collect();
        let scene_scale = patches.iter().fold(Aabb::EMPTY, |b, p| b.union(p.bounds())).diagonal().length();
        let eps = 1e-12 * scene_scale.max(1e-300);
        // This frame's motion of each element, and whether it is a pure translation.
        let shift: Vec<DVec3> = (0..n).map(|e| patches[e].corners[0] - old[e].corners[0]).collect();
        let translated: Vec<bool> = (0..n)
            .map(|e| (0..4).all(|c| (patches[e].corners[c] - old[e].corners[c] - shift[e]).length() <= eps))
            .collect();
        // The bounds each moving object sweeps (old and new position), one box per object while
        // they are few: a light at the ceiling and a block on the floor together would span the
        // room.
        let mut swept_by_object = std::collections::BTreeMap::new();
        for e in (0..n).filter(|&e| moved[e]) {
            let b = swept_by_object.entry(previous[e].object).or_insert(Aabb::EMPTY);
            *b = b.union(old[e].bounds()).union(patches[e].bounds());
        }
        let mut swept: Vec<Aabb> = swept_by_object.into_values().collect();
        if swept.len() > MAX_SWEPT_BOXES {
            swept = vec![swept.iter().fold(Aabb::EMPTY, |a, b| a.union(*b))];
        }
        Self { scene_scale, eps, shift, translated, swept }
    }
}
