//! The projections of `rho E_d` onto the elements' bases ([`DirectLight::project`] and the
//! Gauss rules they take), and the shadow rays' outcomes kept from one frame's projection to the
//! next ([`DirectLight::project_keeping`], [`LastFrame`]).

use rayon::prelude::*;

use super::DirectLight;
use crate::basis::Basis;
use crate::geometry::{Aabb, Patch};
use crate::lights::kept::{KeptRays, Outcomes, Probe};
use crate::quadrature::GaussLegendre;

/// Gauss points per axis of an element for the projection of `rho E_d`: the irradiance of a
/// light is smooth where nothing casts a shadow, so a rule beyond the basis' degree is exact to
/// a fraction of a percent there; a shadow edge inside the element is averaged by it.
pub(super) const PROJECTION_POINTS: usize = 6;

/// [`PROJECTION_POINTS`] of a live preview's frame (`Settings::preview_lights`): a quarter of the
/// shadow rays, the element's direct light averaged more coarsely until the refinement projects
/// it again with the full rule. On the add-on's 1,015-face box with a Point light moving, the
/// projection was most of a preview frame change (8.5-10.7 of 14.6-21 ms, 36 rays an element).
pub(super) const PREVIEW_PROJECTION_POINTS: usize = 3;

/// The last frame's projection, as [`DirectLight::project_keeping`] takes it.
#[derive(Clone, Copy)]
pub struct LastFrame<'a> {
    /// The last frame's lights, after its [`DirectLight::project_keeping`].
    pub lights: &'a DirectLight,
    /// Per element, whether its patch changed since.
    pub moved: &'a [bool],
    /// Boxes holding every moved element's old and new place.
    pub swept: &'a [Aabb],
}

impl DirectLight {
    /// `rho E_d` projected on each element's basis (eq. 4's parameter-space inner product), `nb`
    /// coefficients per element: the lights' share of the emission.
    pub fn project(&self, patches: &[Patch], reflectance: &[[f64; 3]], basis: Basis) -> Vec<[f64; 3]> {
        let nb = basis.len();
        let rule = self.rule();
        let mut out = vec![[0.0; 3]; patches.len() * nb];
        out.par_chunks_mut(nb).enumerate().for_each(|(e, coeffs)| {
            self.project_onto(&patches[e], e as u32, reflectance[e], basis, &rule, coeffs);
        });
        out
    }

    /// [`DirectLight::project`], keeping each element's shadow-ray outcomes for the next frame and
    /// taking those of `last` where they still hold ([`crate::lights::kept`]): the same
    /// coefficients as [`DirectLight::project`], bit for bit. `last` serves only when it casts
    /// its sources' rays alike over as many elements ([`DirectLight::changed_sources`]), and then
    /// for the sources it placed as this frame does.
    pub fn project_keeping(
        &mut self,
        patches: &[Patch],
        reflectance: &[[f64; 3]],
        basis: Basis,
        last: Option<LastFrame>,
    ) -> (Vec<[f64; 3]>, KeptRays) {
        let nb = basis.len();
        let rule = self.rule();
        // The sources `last` placed otherwise: their sections are cast again, the others' rays
        // taken where they hold (a light moving under a still World casts its own rays alone).
        let changed = last
            .filter(|l| l.lights.outcomes.len() == patches.len())
            .and_then(|l| self.changed_sources(l.lights));
        let last = last.filter(|_| changed.is_some());
        let changed = changed.unwrap_or_default();
        let swept = last.map_or_else(Vec::new, |l| self.swept_for_rays(l.swept));
        let this = &*self;
        // Per element: its coefficients, its rays' outcomes, and how many were traced and taken.
        type Projected = (Vec<[f64; 3]>, (Outcomes, KeptRays));
        let projected: Vec<Projected> = (0..patches.len())
            .into_par_iter()
            .map(|e| {
                let kept = last.filter(|l| !l.moved[e]).map(|l| &l.lights.outcomes[e]);
                let mut coeffs = vec![[0.0; 3]; nb];
                let (p, rho) = (&patches[e], reflectance[e]);
                let kept = this.project_onto_keeping(
                    p,
                    e as u32,
                    rho,
                    basis,
                    &rule,
                    &mut coeffs,
                    (kept, &swept, &changed),
                );
                (coeffs, kept)
            })
            .collect();
        let mut out = Vec::with_capacity(patches.len() * nb);
        let mut rays = KeptRays::default();
        self.outcomes = projected
            .into_iter()
            .map(|(coeffs, (outcomes, counts))| {
                out.extend(coeffs);
                rays.add(counts);
                outcomes
            })
            .collect();
        rays.bytes = self.outcomes.iter().map(Outcomes::bytes).sum();
        self.rays = rays;
        (out, rays)
    }

    /// What [`DirectLight::project_keeping`] did with its shadow rays.
    pub fn kept_rays(&self) -> KeptRays {
        self.rays
    }

    /// `boxes` as the keeping of shadow rays tests them: grown by a hair of the rays' reach (a
    /// ray grazing a moved triangle's old or new place is traced), empty ones left out (the slab
    /// test would say an empty box meets every segment).
    pub(crate) fn swept_for_rays(&self, boxes: &[Aabb]) -> Vec<Aabb> {
        boxes.iter().filter(|b| b.min.cmple(b.max).all()).map(|b| b.inflated(1e-9 * self.far)).collect()
    }

    /// A preview's lights (`Settings::preview_lights`) take the full rule after all where `last`,
    /// the frame before, placed some of its sources alike: their shadow rays are then taken where
    /// no move changed them ([`DirectLight::changed_sources`]), and a frame so projected needs no
    /// projecting again when it is refined (a World over a moving block, or under a moving light:
    /// 1.1 s to project the 1,015-face box again in full, against 0.15 s to refine without). The
    /// coarse rule is for frames whose every source changed, whose rays are all cast again
    /// whatever the rule.
    pub(crate) fn settle_rule(&mut self, last: Option<&DirectLight>) {
        let keeps_some = last.and_then(|l| self.changed_placements(l)).is_some();
        if self.is_preview() && keeps_some {
            self.projection_points = PROJECTION_POINTS;
        }
    }

    /// [`DirectLight::project`] of one patch lying on element `owner` (the whole element, or a
    /// part of it: the hierarchy's sub-elements), added to `coeffs` (`nb`); `rule` is
    /// [`DirectLight::projection_rule`].
    pub fn project_onto(
        &self,
        p: &Patch,
        owner: u32,
        rho: [f64; 3],
        basis: Basis,
        rule: &GaussLegendre,
        coeffs: &mut [[f64; 3]],
    ) {
        self.project_onto_with(&mut Probe::tracing(), p, owner, rho, basis, rule, coeffs);
    }

    /// [`DirectLight::project_onto`], recording its shadow rays' outcomes and taking those of
    /// `last` (the same patch's at the last frame, its lights cast alike:
    /// [`DirectLight::changed_sources`]) whose segments meet none of `swept` (made by
    /// [`DirectLight::swept_for_rays`]), but for the sources `changed` marks (empty: none): the
    /// same coefficients, bit for bit ([`crate::lights::kept`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn project_onto_keeping(
        &self,
        p: &Patch,
        owner: u32,
        rho: [f64; 3],
        basis: Basis,
        rule: &GaussLegendre,
        coeffs: &mut [[f64; 3]],
        (last, swept, changed): (Option<&Outcomes>, &[Aabb], &[bool]),
    ) -> (Outcomes, KeptRays) {
        let mut probe = Probe::new(last, swept, true).with_changed(changed);
        self.project_onto_with(&mut probe, p, owner, rho, basis, rule, coeffs);
        probe.finish()
    }

    /// [`DirectLight::project_onto`] with its shadow rays answered by `probe`.
    #[allow(clippy::too_many_arguments)]
    fn project_onto_with(
        &self,
        probe: &mut Probe,
        p: &Patch,
        owner: u32,
        rho: [f64; 3],
        basis: Basis,
        rule: &GaussLegendre,
        coeffs: &mut [[f64; 3]],
    ) {
        if rho.iter().all(|&r| r == 0.0) {
            return;
        }
        let nb = basis.len();
        let mut g = [0.0; 16];
        for (s, ws) in rule.iter() {
            for (t, wt) in rule.iter() {
                let n = p.area_vector(s, t).normalize_or_zero();
                let irr = self.irradiance_with(probe, p.point(s, t), n, owner, self.world_axis.1, 1);
                if irr.iter().all(|&v| v == 0.0) {
                    continue;
                }
                basis.eval_into(s, t, &mut g[..nb]);
                for k in 0..nb {
                    for c in 0..3 {
                        coeffs[k][c] += ws * wt * g[k] * rho[c] * irr[c];
                    }
                }
            }
        }
    }

    /// The Gauss rule [`DirectLight::project_onto`] takes in full (a bake's frames).
    pub fn projection_rule() -> GaussLegendre {
        GaussLegendre::new(PROJECTION_POINTS)
    }

    /// The Gauss rule these lights' projections take: [`DirectLight::projection_rule`], or a
    /// preview's coarser one (`Settings::preview_lights`).
    pub fn rule(&self) -> GaussLegendre {
        GaussLegendre::new(self.projection_points)
    }

    /// Whether these lights were projected at a preview's quality (`Settings::preview_lights`).
    pub fn is_preview(&self) -> bool {
        self.projection_points != PROJECTION_POINTS
    }
}

#[cfg(test)]
mod tests {
    use glam::{DMat4, DVec3};

    use super::*;
    use crate::lights::{Light, LightKey, LightKind, World, WorldKey};
    use crate::scene::{Material, Scene, Settings};
    use crate::scenes::{box_mesh, subdivided_quad, translation_keys};

    /// A block sliding over a floor beside a wall (frames 1-3, then still), lit by a World (dimming
    /// at frame 4), a soft Point light (moving from frame 4 to 6), a soft Sun (brighter at frame 4)
    /// and an Area light: each frame's projection that keeps the last frame's rays equals a fresh
    /// projection bit for bit; it takes the rays no move can have changed, every ray once nothing
    /// moved (whatever the colours), and all but the moving light's while it moves.
    #[test]
    fn kept_rays_project_as_fresh_ones() {
        let p = DVec3::new;
        let floor =
            subdivided_quad("Floor", [p(-2., -2., 0.), p(2., -2., 0.), p(2., 2., 0.), p(-2., 2., 0.)], 6, 0);
        let wall =
            subdivided_quad("Wall", [p(-2., 2., 0.), p(2., 2., 0.), p(2., 2., 2.), p(-2., 2., 2.)], 4, 0);
        let mut block = box_mesh("Block", p(-0.3, -0.3, 0.0), p(0.3, 0.3, 0.6), 2, false, 0);
        block.animation = translation_keys(&[(1.0, p(-1.0, 0.0, 0.0)), (3.0, p(1.0, 0.0, 0.0))]);
        let grey = Material { name: "grey".into(), reflectance: [0.6; 3], emission: [0.0; 3] };
        let mut point =
            Light::new("Point", LightKind::Point, DMat4::from_translation(p(0.5, -0.5, 1.5)), 80.0);
        point.base.radius = 0.1;
        // Still until frame 4, then moving: its rays are cast again, the other sources' taken.
        point.animation = vec![
            LightKey { frame: 4.0, ..LightKey::default() },
            LightKey {
                frame: 6.0,
                matrix: Some(DMat4::from_translation(p(0.9, -0.2, 1.3))),
                ..LightKey::default()
            },
        ];
        let mut sun = Light::new("Sun", LightKind::Sun, DMat4::from_rotation_x(0.4), 2.0);
        sun.base.angle = 0.1;
        // Brighter and redder at frame 4, the sky dimmer: colours and powers choose no ray, so
        // frame 4, where nothing moved, still takes every ray.
        sun.animation = vec![
            LightKey { frame: 3.0, ..LightKey::default() },
            LightKey { frame: 4.0, power: Some(3.0), color: Some([1.0, 0.7, 0.5]), ..LightKey::default() },
        ];
        let mut sky = World::uniform([0.3, 0.4, 0.5], 1.0);
        sky.animation = vec![
            WorldKey { frame: 3.0, color: None, strength: Some(1.0) },
            WorldKey { frame: 4.0, color: None, strength: Some(0.6) },
        ];
        let mut area = Light::new("Area", LightKind::Area, DMat4::from_translation(p(-0.5, 0.0, 1.8)), 60.0);
        area.base.size = [0.4, 0.4];
        let settings = Settings { basis_order: 1, ..Settings::default() };
        let scene = Scene::new(settings, (1, 6), vec![grey], vec![vec![]], vec![floor, wall, block])
            .unwrap()
            .with_lights(vec![point, sun, area])
            .unwrap()
            .with_world(Some(sky))
            .unwrap();
        let basis = Basis::new(1);
        let mut last: Option<(DirectLight, Vec<Patch>)> = None;
        for f in 1..=6 {
            let elements = crate::system::build_elements(&scene, f as f64, basis);
            let patches: Vec<Patch> = elements.iter().map(|e| e.patch).collect();
            let rho: Vec<[f64; 3]> = elements.iter().map(|e| e.reflectance(&scene)).collect();
            let fresh = DirectLight::new(&scene, f as f64, &elements).unwrap().project(&patches, &rho, basis);
            let (moved, swept): (Vec<bool>, Vec<Aabb>) = match &last {
                Some((_, old)) => {
                    let moved: Vec<bool> = patches.iter().zip(old).map(|(a, b)| a != b).collect();
                    let swept = (0..patches.len())
                        .filter(|&e| moved[e])
                        .fold(Aabb::EMPTY, |b, e| b.union(patches[e].bounds()).union(old[e].bounds()));
                    (moved, vec![swept])
                }
                None => (Vec::new(), Vec::new()),
            };
            let previous =
                last.as_ref().map(|(lights, _)| LastFrame { lights, moved: &moved, swept: &swept });
            let mut lights = DirectLight::new(&scene, f as f64, &elements).unwrap();
            let (kept, rays) = lights.project_keeping(&patches, &rho, basis, previous);
            let bits = |v: &[[f64; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert!(bits(&kept) == bits(&fresh), "frame {f}: the kept projection differs from a fresh one");
            match f {
                1 => assert_eq!(rays.taken, 0),
                2 | 3 => {
                    assert!(moved.iter().any(|&m| m), "frame {f}: the block did not move");
                    // Measured: 24-26% of the rays taken (the block is large against the floor).
                    assert!(4 * rays.taken > rays.traced, "frame {f}: {rays:?}");
                }
                4 => assert!(rays.traced == 0 && rays.taken > 0, "frame {f}, nothing moved: {rays:?}"),
                _ => {
                    // The Point light's rays (16 a point) cast again, the World's, the Sun's and
                    // the Area light's taken.
                    assert!(!moved.iter().any(|&m| m), "frame {f}");
                    assert!(
                        rays.traced > 0 && rays.taken > 2 * rays.traced,
                        "frame {f}, the light moved: {rays:?}"
                    );
                }
            }
            last = Some((lights, patches));
        }
    }
}
