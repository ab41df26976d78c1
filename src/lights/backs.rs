//! Two-sided emitters (issue 22, item 6): the back of each emitting face of an object marked
//! two-sided ([`crate::scene::Scene::two_sided`]) emits the face's exitance too, as Cycles' mesh
//! lights do. Faces are one-sided in the system (their kernel rows and columns see only their
//! front), so the back is a source without an element, like an Area light: a planar polygon,
//! the face's corners, facing the other way, whose direct light on every receiver is the exact
//! unoccluded point-to-polygon form factor times the share of shadow rays to its sample points
//! that arrive ([`super::direct`]). The back reflects nothing (a face's back is black
//! everywhere in this solver); its light's later bounces are the solver's.

use glam::DVec3;

use crate::scene::Scene;
use crate::system::Element;

/// Shadow-ray sample points per axis of a face's back.
const BACK_SAMPLES: usize = 2;

/// The back of one emitting face.
#[derive(Clone, Debug)]
pub(super) struct Back {
    /// The face's element: shadow rays ending on it skip it.
    pub element: u32,
    /// Exitance of the back (the face's own), W/m^2.
    pub exitance: [f64; 3],
    pub polygon: Vec<DVec3>,
    /// Unit normal of the back (minus the face's front normal).
    pub normal: DVec3,
    pub samples: Vec<DVec3>,
}

impl Back {
    /// Whether `other` casts the same shadow rays as this back: the same but for its exitance,
    /// which weighs what the rays find.
    pub(super) fn casts_alike(&self, other: &Back) -> bool {
        let Back { element, exitance: _, polygon, normal, samples } = self;
        *element == other.element
            && *polygon == other.polygon
            && *normal == other.normal
            && *samples == other.samples
    }
}

/// The backs of the emitting faces of `scene`'s two-sided objects at `frame`.
pub(super) fn emitter_backs(scene: &Scene, frame: f64, elements: &[Element]) -> Vec<Back> {
    if !scene.two_sided.iter().any(|&t| t) {
        return Vec::new();
    }
    elements
        .iter()
        .enumerate()
        .filter(|(_, e)| !e.back && scene.two_sided.get(e.object as usize).copied().unwrap_or(false))
        .filter_map(|(i, e)| {
            let exitance = e.emission(scene, frame);
            if exitance.iter().all(|&c| c <= 0.0) {
                return None;
            }
            let p = &e.patch;
            let mut polygon = p.corners.to_vec();
            polygon.dedup();
            let m = BACK_SAMPLES as f64;
            let samples = (0..BACK_SAMPLES * BACK_SAMPLES)
                .map(|k| {
                    p.point(((k % BACK_SAMPLES) as f64 + 0.5) / m, ((k / BACK_SAMPLES) as f64 + 0.5) / m)
                })
                .collect();
            Some(Back { element: i as u32, exitance, polygon, normal: -p.centre_normal(), samples })
        })
        .collect()
}
