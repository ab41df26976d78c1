//! Point queries of the direct irradiance ([`DirectLight::irradiance`]): each light's, the
//! World's and the emitters' backs' share at a point, with their shadow rays ([`Shadows`]).

use std::f64::consts::PI;

use glam::DVec3;

use super::DirectLight;
use super::placed::{Placed, ROUND_SIDES, soft_disk};
use crate::geometry::{Aabb, Patch};
use crate::kernel::point::point_to_polygon;
use crate::lights::LightKind;
use crate::lights::backs::Back;
use crate::lights::kept::{KeptRays, Outcomes, Probe};
use crate::visibility::bvh::{Bvh, Triangle};

/// Cycles' `smoothstepf`: 0 below 0, 1 above 1, `(3 - 2f) f^2` between.
fn smoothstep(f: f64) -> f64 {
    if f <= 0.0 {
        0.0
    } else if f >= 1.0 {
        1.0
    } else {
        (3.0 - 2.0 * f) * f * f
    }
}

/// A spot's cone and blend along the unit direction `to_light` from the receiver to a point of
/// the light (Cycles' `spot_attenuation`, per sampled point of a disk or sphere); 1 for a Point
/// light.
fn spot_attenuation(l: &Placed, to_light: DVec3) -> f64 {
    if l.kind != LightKind::Spot {
        return 1.0;
    }
    let off = (-to_light).dot(l.axis);
    if off <= l.cos_half {
        return 0.0;
    }
    if l.smooth > 0.0 { smoothstep((off - l.cos_half) / l.smooth) } else { 1.0 }
}

/// Every element as shadow casters (the scene's hull too: a sun shines in from outside).
pub(super) struct Shadows {
    bvh: Bvh,
}

impl Shadows {
    pub(super) fn new(patches: &[Patch]) -> Self {
        let tris = patches
            .iter()
            .enumerate()
            .flat_map(|(e, p)| p.triangles().into_iter().map(move |v| Triangle { v, element: e as u32 }))
            .collect();
        Shadows { bvh: Bvh::build(tris) }
    }

    /// Whether the segment from `x` (on element `e`) to `y` is unobstructed, as `probe` answers.
    fn visible(&self, probe: &mut Probe, x: DVec3, y: DVec3, e: u32) -> bool {
        self.visible_between(probe, x, y, e, e)
    }

    /// Whether the segment from `x` (on element `e`) to `y` (on element `f`) is unobstructed, as
    /// `probe` answers (traced, or kept from the last frame: [`crate::lights::kept`]).
    fn visible_between(&self, probe: &mut Probe, x: DVec3, y: DVec3, e: u32, f: u32) -> bool {
        probe.passes(x, y, || !self.bvh.occluded(x, y - x, 1e-9, 1.0 - 1e-9, e, f))
    }
}

impl DirectLight {
    /// Direct irradiance (W/m^2, RGB) at `x` on element `e`, front normal `n` (unit): a point
    /// whose value is shown (a corner, a foot), with the World's finer rule.
    pub fn irradiance(&self, x: DVec3, n: DVec3, e: u32) -> [f64; 3] {
        self.irradiance_with(&mut Probe::tracing(), x, n, e, self.world_axis.0, self.soft_corner)
    }

    /// [`DirectLight::irradiance`] with `m x m` World directions and [`soft_disk`]`(soft)`'s rays
    /// to soft lights.
    pub(super) fn irradiance_with(
        &self,
        probe: &mut Probe,
        x: DVec3,
        n: DVec3,
        e: u32,
        m: usize,
        soft: usize,
    ) -> [f64; 3] {
        let mut out = [0.0; 3];
        // Each source's rays are a section of the probe's: their sequence depends on their own
        // outcomes alone (crate::lights::kept).
        for l in &self.lights {
            probe.section();
            let k = self.factor(probe, l, x, n, e, soft);
            for c in 0..3 {
                out[c] += k * l.scale[c];
            }
        }
        if let Some(world) = &self.world {
            probe.section();
            let sky = world.irradiance(n, m, |w| self.shadows.visible(probe, x, x + w * self.far, e));
            for c in 0..3 {
                out[c] += sky[c];
            }
        }
        for b in &self.backs {
            probe.section();
            let k = self.back_factor(probe, b, x, n, e);
            for c in 0..3 {
                out[c] += k * b.exitance[c];
            }
        }
        out
    }

    /// A face's back's form factor from `x`, times the share of its sample points seen (the
    /// Area light's rule, [`DirectLight::factor`]).
    fn back_factor(&self, probe: &mut Probe, b: &Back, x: DVec3, n: DVec3, e: u32) -> f64 {
        if b.element == e {
            return 0.0;
        }
        polygon_factor((x, n), (&b.polygon, b.normal, &b.samples), |y| {
            self.shadows.visible_between(probe, x, y, e, b.element)
        })
    }

    /// The light's irradiance at `x` per unit of its `scale`.
    fn factor(&self, probe: &mut Probe, l: &Placed, x: DVec3, n: DVec3, e: u32, soft: usize) -> f64 {
        match l.kind {
            LightKind::Point | LightKind::Spot if l.extent > 0.0 => {
                self.round_factor(probe, l, x, n, e, soft)
            }
            LightKind::Point | LightKind::Spot => {
                let d = l.position - x;
                let d2 = d.length_squared();
                if d2 == 0.0 {
                    return 0.0;
                }
                let spot = spot_attenuation(l, d / d2.sqrt());
                if spot == 0.0 {
                    return 0.0;
                }
                let cos = n.dot(d) / d2.sqrt();
                if cos <= 0.0 || !self.shadows.visible(probe, x, l.position, e) {
                    return 0.0;
                }
                spot * cos / d2
            }
            LightKind::Sun if l.extent > 0.0 => self.sun_disk_factor(probe, -l.axis, l.extent, x, n, e, soft),
            LightKind::Sun => {
                let to_sun = -l.axis;
                let cos = n.dot(to_sun);
                if cos <= 0.0 || !self.shadows.visible(probe, x, x + to_sun * self.far, e) {
                    return 0.0;
                }
                cos
            }
            LightKind::Area => polygon_factor((x, n), (&l.polygon, l.axis, &l.samples), |y| {
                self.shadows.visible(probe, x, y, e)
            }),
        }
    }

    /// A Point or Spot light of radius `r > 0`: its irradiance at `x` per unit of its intensity
    /// `scale`, the light a Lambertian disk of radiance `scale / (pi r^2)` facing `x` (Cycles'
    /// `eval_fac = 1 / (4 pi r^2 pi)` of the power): of radius `r` about the centre `c` with
    /// Soft Falloff, or, for a sphere, its tangent circle from `x` (radius `r sqrt(d^2 - r^2) / d`
    /// about `c + (x - c) r^2 / d^2`, which subtends the sphere's cone). Unoccluded that is
    /// `pi F / (pi r^2)` with `F` the point-to-disk form factor: `cos r'^2 / (d'^2 + r'^2)` for a
    /// disk of radius `r'` at distance `d'` seen whole above the horizon (its vector irradiance
    /// lies along the axis), so `cos / (d^2 + r^2)` (disk) and `cos / d^2` (sphere); a disk
    /// across the horizon takes [`point_to_polygon`] of its same-area 32-gon. The shadows and
    /// the spot cone: `F` times the form-factor-weighted share of [`soft_disk`]'s points
    /// on the disk that are seen, each weighted by the spot's attenuation along its ray. A
    /// receiver inside a sphere sees its radiance over the hemisphere: `1 / r^2`.
    fn round_factor(&self, probe: &mut Probe, l: &Placed, x: DVec3, n: DVec3, e: u32, soft: usize) -> f64 {
        let r = l.extent;
        let from_centre = x - l.position;
        let d2 = from_centre.length_squared();
        if d2 == 0.0 || (l.sphere && d2 <= r * r) {
            return 1.0 / (r * r);
        }
        let (centre, rho) = if l.sphere {
            (l.position + from_centre * (r * r / d2), r * ((d2 - r * r) / d2).sqrt())
        } else {
            (l.position, r)
        };
        let to_disk = centre - x;
        let dist2 = to_disk.length_squared();
        let a = to_disk / dist2.sqrt();
        let cos = n.dot(a);
        let sin2 = rho * rho / (dist2 + rho * rho); // of the disk's half-angle from `x`
        let (b1, b2) = a.any_orthonormal_pair();
        let f = if cos * cos >= sin2 && cos > 0.0 {
            cos * sin2
        } else if cos <= 0.0 && cos * cos >= sin2 {
            return 0.0;
        } else {
            let k = ROUND_SIDES as f64;
            let grow = (2.0 * PI / (k * (2.0 * PI / k).sin())).sqrt(); // the 32-gon of the disk's area
            let polygon: Vec<DVec3> = (0..ROUND_SIDES)
                .map(|i| {
                    let th = 2.0 * PI * i as f64 / k;
                    centre + (b1 * th.cos() + b2 * th.sin()) * (rho * grow)
                })
                .collect();
            point_to_polygon(x, n, &polygon, -a)
        };
        if f <= 0.0 {
            return 0.0;
        }
        let (mut seen, mut all) = (0.0, 0.0);
        for &(u, v) in soft_disk(soft) {
            let y = centre + (b1 * u + b2 * v) * rho;
            let d = y - x;
            let t2 = d.length_squared();
            let w = (n.dot(d) * a.dot(d)).max(0.0) / (t2 * t2);
            if w > 0.0 {
                all += w;
                let spot = spot_attenuation(l, d / t2.sqrt());
                if spot > 0.0 && self.shadows.visible(probe, x, y, e) {
                    seen += w * spot;
                }
            }
        }
        let share = if all > 0.0 { seen / all } else { spot_attenuation(l, a) };
        f * share / (r * r)
    }

    /// A sun of angular radius `half` (half its Angle) towards unit `to_sun`: irradiance `S cos`
    /// unoccluded (Cycles' distant light: radiance `S / (pi sin^2 half)` over the cone), the
    /// visibility averaged over the cone.
    #[allow(clippy::too_many_arguments)]
    fn sun_disk_factor(
        &self,
        probe: &mut Probe,
        to_sun: DVec3,
        half: f64,
        x: DVec3,
        n: DVec3,
        e: u32,
        soft: usize,
    ) -> f64 {
        let one_minus_cos = 2.0 * (0.5 * half).sin().powi(2);
        self.cone_factor(probe, to_sun, one_minus_cos, x, n, e, soft)
    }

    /// `integral_cone V(w) max(0, n.w) dw / integral_cone a.w dw` over the cone of unit axis `a`
    /// and `1 - cos(alpha) = one_minus_cos`, `V` the visibility from `x` (on element `e`) of the
    /// sun along `w`: an unoccluded cone above the horizon gives exactly `n.a`, a penumbra the
    /// cosine-weighted share of the cone that arrives.
    ///
    /// The directions are [`soft_disk`]'s points lifted onto the cone by the area-preserving map
    /// `cos(beta) = 1 - rho^2 (1 - cos alpha)` (uniform in solid angle; equal-area strata stay
    /// equal in solid angle), about a basis of `a` that depends on `a` alone (Duff et al. 2017),
    /// so the same point always gets the same rays. Both integrals take the same directions:
    /// the disk points' mean is the centre, so the cone's side components cancel and the ratio
    /// is `n.a` exactly, whatever the points' mean `cos(beta)`.
    #[allow(clippy::too_many_arguments)]
    fn cone_factor(
        &self,
        probe: &mut Probe,
        a: DVec3,
        one_minus_cos: f64,
        x: DVec3,
        n: DVec3,
        e: u32,
        soft: usize,
    ) -> f64 {
        let (b1, b2) = a.any_orthonormal_pair();
        let (mut seen, mut axial) = (0.0, 0.0);
        for &(u, v) in soft_disk(soft) {
            let h = (u * u + v * v) * one_minus_cos;
            let side = (one_minus_cos * (2.0 - h)).max(0.0).sqrt(); // sin(beta) / rho
            let w = a * (1.0 - h) + (b1 * u + b2 * v) * side;
            axial += 1.0 - h;
            let cos = n.dot(w);
            if cos > 0.0 && self.shadows.visible(probe, x, x + w * self.far, e) {
                seen += cos;
            }
        }
        seen / axial
    }

    /// [`DirectLight::irradiance`] at a gathered point, recording its shadow rays' outcomes and
    /// taking those of `last` (the same point's at the last gather, its lights cast alike:
    /// [`DirectLight::changed_sources`]) whose segments meet none of `swept`, but for the
    /// sources `changed` marks ([`crate::lights::kept`]; empty: none changed): the same
    /// irradiance as [`DirectLight::irradiance`], bit for bit.
    pub(crate) fn irradiance_keeping(
        &self,
        x: DVec3,
        n: DVec3,
        e: u32,
        (last, changed): (Option<&Outcomes>, &[bool]),
        swept: &[Aabb],
    ) -> ([f64; 3], Outcomes, KeptRays) {
        let mut probe = Probe::new(last, swept, true).with_changed(changed);
        let irradiance = self.irradiance_with(&mut probe, x, n, e, self.world_axis.0, self.soft_corner);
        let (outcomes, rays) = probe.finish();
        (irradiance, outcomes, rays)
    }
}

/// The form factor from the point `(x, n)` to a polygon facing `normal` (an Area light, an
/// emitter's back), times the arriving share of its sample points' form-factor weights: the
/// unoccluded form factor where no sample weighs (`visible(y)`: whether sample `y` is seen).
fn polygon_factor(
    (x, n): (DVec3, DVec3),
    (polygon, normal, samples): (&[DVec3], DVec3, &[DVec3]),
    mut visible: impl FnMut(DVec3) -> bool,
) -> f64 {
    let f = point_to_polygon(x, n, polygon, normal);
    if f <= 0.0 {
        return 0.0;
    }
    let (mut seen, mut all) = (0.0, 0.0);
    for &y in samples {
        let d = y - x;
        let d2 = d.length_squared();
        let w = (n.dot(d) * (-normal).dot(d)).max(0.0) / (d2 * d2);
        if w > 0.0 {
            all += w;
            if visible(y) {
                seen += w;
            }
        }
    }
    if all > 0.0 { f * seen / all } else { f }
}
