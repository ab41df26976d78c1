//! Direct irradiance from lights on the receivers, with shadow rays, and its projection onto the
//! receivers' Legendre bases (module docs of [`crate::lights`] give the conventions).
//!
//! [`DirectLight`] is split by phase, an `impl DirectLight` block per file: this file holds the
//! struct, the placing of a frame's sources ([`DirectLight::new`]) and the comparison of two
//! frames' (`changed_sources`); `placed.rs` the lights as placed at a frame, the
//! fixed points of the soft lights' shadow rays and the World's strata per point;
//! `irradiance.rs` the point queries ([`DirectLight::irradiance`]) with their shadow rays;
//! `project.rs` the projections of `rho E_d` onto the bases ([`DirectLight::project`], the Gauss
//! rules, a preview's `settle_rule`) and the shadow rays' outcomes kept from one frame's
//! projection to the next ([`DirectLight::project_keeping`], [`LastFrame`]).

mod irradiance;
mod placed;
mod project;

use irradiance::Shadows;
use placed::{Placed, WORLD_CORNER_AXIS, WORLD_PROJECTION_AXIS};
pub use project::LastFrame;
use project::{PREVIEW_PROJECTION_POINTS, PROJECTION_POINTS};

use super::backs::{Back, emitter_backs};
pub use super::kept::KeptRays;
use super::kept::Outcomes;
use super::world::PlacedWorld;
use crate::geometry::{Aabb, Patch};
use crate::scene::Scene;
use crate::system::Element;

/// The scene's lights, World and two-sided emitters' backs placed at one frame with the
/// elements as shadow casters.
pub struct DirectLight {
    lights: Vec<Placed>,
    world: Option<PlacedWorld>,
    backs: Vec<Back>,
    /// World directions per axis at corners and at projection points.
    world_axis: (usize, usize),
    /// Visibility samples per axis of the soft lights' rays at corners ([`soft_disk`]).
    ///
    /// [`soft_disk`]: placed::soft_disk
    soft_corner: usize,
    /// Gauss points per axis of an element's projection ([`PROJECTION_POINTS`], or
    /// [`PREVIEW_PROJECTION_POINTS`] for a preview).
    projection_points: usize,
    shadows: Shadows,
    /// Beyond the scene: how far a ray towards the sun or the sky is followed.
    far: f64,
    /// Per element, the outcomes of its projection's shadow rays, for the next frame's
    /// ([`DirectLight::project_keeping`]; empty until then), and what that projection did.
    outcomes: Vec<Outcomes>,
    rays: KeptRays,
}

impl DirectLight {
    /// The direct sources of `scene` at `frame` over `elements`; `None` without lights, World
    /// or two-sided emitters.
    pub fn new(scene: &Scene, frame: f64, elements: &[Element]) -> Option<Self> {
        let world = scene.world.as_ref().and_then(|w| PlacedWorld::new(w, frame));
        let backs = emitter_backs(scene, frame, elements);
        if scene.lights.is_empty() && world.is_none() && backs.is_empty() {
            return None;
        }
        let patches: Vec<Patch> = elements.iter().map(|e| e.patch).collect();
        let bounds = patches.iter().fold(Aabb::EMPTY, |b, p| b.union(p.bounds()));
        let far = 4.0 * bounds.diagonal().length().max(1e-300);
        let lights = scene.lights.iter().map(|l| Placed::new(l, &l.state_at(frame))).collect();
        let v = scene.settings.visibility_samples.max(1);
        Some(DirectLight {
            lights,
            world,
            backs,
            world_axis: (WORLD_CORNER_AXIS * v, WORLD_PROJECTION_AXIS * v),
            soft_corner: v,
            projection_points: if scene.settings.preview_lights {
                PREVIEW_PROJECTION_POINTS
            } else {
                PROJECTION_POINTS
            },
            shadows: Shadows::new(&patches),
            far,
            outcomes: Vec::new(),
            rays: KeptRays::default(),
        })
    }

    /// Per source, in the order a point casts their sections (the lights, the World, the
    /// emitters' backs: [`DirectLight::irradiance_with`]), whether `other` cast its rays otherwise
    /// than `self` (a light that moved or changed shape: its rays from an unmoved element are then
    /// cast again, the others' taken where no move changed them); `None` when none of `other`'s
    /// record serves: the two do not cast their sections alike (other sources, another rule, rays
    /// of another reach), or every source changed.
    pub(crate) fn changed_sources(&self, other: &DirectLight) -> Option<Vec<bool>> {
        (self.projection_points == other.projection_points).then(|| self.changed_placements(other))?
    }

    /// [`DirectLight::changed_sources`] whatever the projections' rules.
    fn changed_placements(&self, other: &DirectLight) -> Option<Vec<bool>> {
        let alike = self.lights.len() == other.lights.len()
            && self.world.is_some() == other.world.is_some()
            && self.backs.len() == other.backs.len()
            && self.world_axis == other.world_axis
            && self.soft_corner == other.soft_corner
            && self.far == other.far;
        if !alike {
            return None;
        }
        // What a source casts depends on where it is and its shape, not on its colour or power
        // (which weigh what the rays find): a light fading or a sky dimming keeps its rays. The
        // World's rays are its strata's, set by the receiver's normal and the quality alone.
        let mut changed: Vec<bool> =
            self.lights.iter().zip(&other.lights).map(|(a, b)| !a.casts_alike(b)).collect();
        if self.world.is_some() {
            changed.push(false);
        }
        changed.extend(self.backs.iter().zip(&other.backs).map(|(a, b)| !a.casts_alike(b)));
        changed.iter().any(|&c| !c).then_some(changed)
    }
}
