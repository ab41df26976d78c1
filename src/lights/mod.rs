//! Blender Light objects as sources (issue 22, item 1): Point, Spot, Sun and Area lights in
//! Blender's units, keyed over frames like objects.
//!
//! A light has no area in the system: its *direct* irradiance `E_d(x)` on each receiver is
//! computed with shadow rays ([`direct`]) and `rho E_d` projected onto the receiver's Legendre
//! basis enters the solve as emission of the receiver (eq. 5 with `E` replaced by `rho E_d`),
//! so the shooting starts from the lit surfaces and every later bounce is the solver's. A change
//! of a light from frame to frame is a change of that emission, which the incremental update
//! takes as `Delta e` (eq. 9) like a keyed material emission.
//!
//! Conventions (Blender 4.x/5.x, Cycles; checked against Cycles bakes in
//! `tools/validate_lights.py`): a light looks down its local -Z axis; colour multiplies power.
//! - Point, power `P` W, radius 0: radiant intensity `P / (4 pi)` W/sr, so
//!   `E = P cos / (4 pi d^2)`. Of radius `r > 0`, radiance `P / (4 pi^2 r^2)` (Cycles'
//!   `PointLight`: `eval_fac = 1 / (pi 4 pi r^2)`) over one of two shapes, by Blender's Soft
//!   Falloff (`use_soft_falloff`, on by default; Cycles' `is_sphere` is its negation):
//!   - Soft Falloff on: a disk of radius `r` about the centre facing the receiver, so
//!     `E = P cos / (4 pi (d^2 + r^2))` seen whole above the horizon;
//!   - Soft Falloff off: a sphere of radius `r`, `E = P cos / (4 pi d^2)` seen whole (its
//!     irradiance is that of its tangent circle, a disk of radius `r sqrt(d^2 - r^2) / d`
//!     about `c + (x - c) r^2 / d^2`); a receiver inside it gets `P / (4 pi r^2)`.
//!
//!   Shadows and the horizon are [`direct`]'s: the disk's exact form factor times the share
//!   of fixed shadow rays to it that arrive (64 at a corner at Medium quality, 16 at each
//!   projection point).
//! - Spot: the point's (or disk's, sphere's) radiance inside the cone of full angle
//!   `spot_size`, faded by `smoothstep((cos a - cos(size/2)) / ((1 - cos(size/2)) blend))` with
//!   `a` the angle off the axis of the direction from the light's point to the receiver
//!   (Cycles' `spot_attenuation`, per shadow ray for a radius).
//! - Sun, strength `S` W/m^2: irradiance `S cos` on a surface, the direction the -Z axis. Of
//!   angular diameter `angle > 0`, radiance `S / (pi sin^2(angle / 2))` over the cone
//!   (Cycles' `SunLight`), which leaves `E = S cos` while the cone is above the horizon; its
//!   visibility is the share of fixed rays over the cone that escape (as many as a round
//!   light's).
//! - Area, power `P` W over area `A` (one-sided, emitting to -Z): exitance `P / A`, so
//!   `E = (P / A) F(x -> light)` with the exact unoccluded point-to-polygon form factor
//!   ([`crate::kernel::point::point_to_polygon`]; a disk or an ellipse as a 32-gon) times the
//!   fraction of shadow rays to the light's sample points that arrive.
//!
//! Beside the Light objects, the same direct path carries the World ([`world`]: a background
//! colour or equirectangular image from infinitely far, with the sky's visibility) and the
//! backs of two-sided emitters ([`backs`]).

mod backs;
pub mod direct;
pub(crate) mod kept;
pub mod world;

pub use world::{Environment, World, WorldKey};

use glam::{DMat4, DVec3};

use crate::error::{Result, invalid_scene};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightKind {
    Point,
    Spot,
    Sun,
    Area,
}

impl LightKind {
    pub fn parse(name: &str) -> Option<Self> {
        match name.to_ascii_lowercase().as_str() {
            "point" => Some(Self::Point),
            "spot" => Some(Self::Spot),
            "sun" => Some(Self::Sun),
            "area" => Some(Self::Area),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Point => "point",
            Self::Spot => "spot",
            Self::Sun => "sun",
            Self::Area => "area",
        }
    }
}

/// An area light's outline in its local XY plane, centred on its origin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AreaShape {
    /// `size[0]` x `size[0]`.
    Square,
    /// `size[0]` x `size[1]`.
    Rectangle,
    /// Diameter `size[0]`.
    Disk,
    /// Diameters `size[0]` x `size[1]`.
    Ellipse,
}

impl AreaShape {
    pub fn parse(name: &str) -> Option<Self> {
        match name.to_ascii_lowercase().as_str() {
            "square" => Some(Self::Square),
            "rectangle" => Some(Self::Rectangle),
            "disk" => Some(Self::Disk),
            "ellipse" => Some(Self::Ellipse),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Square => "square",
            Self::Rectangle => "rectangle",
            Self::Disk => "disk",
            Self::Ellipse => "ellipse",
        }
    }
}

/// What a light is at one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct LightState {
    /// World-from-light: the origin is the position, local -Z the direction.
    pub matrix: DMat4,
    /// RGB multiplier of `power`.
    pub color: [f64; 3],
    /// Watts (Point, Spot, Area) or W/m^2 (Sun strength).
    pub power: f64,
    /// Full cone angle of a spot, radians.
    pub spot_size: f64,
    /// Spot blend in `[0,1]`.
    pub spot_blend: f64,
    /// Point and Spot radius, metres (0: a point).
    pub radius: f64,
    /// Point and Spot of radius > 0: Blender's Soft Falloff (`use_soft_falloff`, default on), a
    /// disk facing the receiver; off, a sphere (module docs).
    pub soft_falloff: bool,
    /// Sun angular diameter, radians (0: parallel rays).
    pub angle: f64,
    /// Area size along local X and Y, metres (`size[1]` used by Rectangle and Ellipse).
    pub size: [f64; 2],
}

/// Keyed values of a light at `frame`: fields left `None` keep the light's own. Numbers are
/// linear between keys; `soft_falloff`, a switch, holds the earlier key's value up to the next
/// key, as Blender's constant interpolation of a boolean does.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LightKey {
    pub frame: f64,
    pub matrix: Option<DMat4>,
    pub color: Option<[f64; 3]>,
    pub power: Option<f64>,
    pub spot_size: Option<f64>,
    pub spot_blend: Option<f64>,
    pub radius: Option<f64>,
    pub soft_falloff: Option<bool>,
    pub angle: Option<f64>,
    pub size: Option<[f64; 2]>,
}

/// A Blender Light object.
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    pub name: String,
    pub kind: LightKind,
    /// The state at frames without keys (and the values keys leave out).
    pub base: LightState,
    pub shape: AreaShape,
    /// Keys sorted by frame: linear between keys, held outside them.
    pub animation: Vec<LightKey>,
}

impl Light {
    /// A light of `kind` at `matrix` with Blender's defaults for the rest.
    pub fn new(name: &str, kind: LightKind, matrix: DMat4, power: f64) -> Self {
        Light {
            name: name.to_string(),
            kind,
            base: LightState {
                matrix,
                color: [1.0; 3],
                power,
                spot_size: 45f64.to_radians(),
                spot_blend: 0.15,
                radius: 0.0,
                soft_falloff: true,
                angle: 0.0,
                size: [1.0, 1.0],
            },
            shape: AreaShape::Square,
            animation: Vec::new(),
        }
    }

    /// The light at `frame`.
    pub fn state_at(&self, frame: f64) -> LightState {
        let Some((lo, hi, w)) = crate::scene::placement::bracket(&self.animation, frame, |k| k.frame) else {
            return self.base.clone();
        };
        let at = |k: &LightKey| LightState {
            matrix: k.matrix.unwrap_or(self.base.matrix),
            color: k.color.unwrap_or(self.base.color),
            power: k.power.unwrap_or(self.base.power),
            spot_size: k.spot_size.unwrap_or(self.base.spot_size),
            spot_blend: k.spot_blend.unwrap_or(self.base.spot_blend),
            radius: k.radius.unwrap_or(self.base.radius),
            soft_falloff: k.soft_falloff.unwrap_or(self.base.soft_falloff),
            angle: k.angle.unwrap_or(self.base.angle),
            size: k.size.unwrap_or(self.base.size),
        };
        let (a, b) = (at(&self.animation[lo]), at(&self.animation[hi]));
        if w == 0.0 {
            return a;
        }
        let mix = |x: f64, y: f64| x * (1.0 - w) + y * w;
        LightState {
            matrix: a.matrix * (1.0 - w) + b.matrix * w,
            color: std::array::from_fn(|c| mix(a.color[c], b.color[c])),
            power: mix(a.power, b.power),
            spot_size: mix(a.spot_size, b.spot_size),
            spot_blend: mix(a.spot_blend, b.spot_blend),
            radius: mix(a.radius, b.radius),
            soft_falloff: a.soft_falloff,
            angle: mix(a.angle, b.angle),
            size: std::array::from_fn(|c| mix(a.size[c], b.size[c])),
        }
    }

    /// The light's area (Area lights) in state `s`, m^2.
    pub fn area(&self, s: &LightState) -> f64 {
        let [a, b] = s.size;
        match self.shape {
            AreaShape::Square => a * a,
            AreaShape::Rectangle => a * b,
            AreaShape::Disk => std::f64::consts::PI * a * a / 4.0,
            AreaShape::Ellipse => std::f64::consts::PI * a * b / 4.0,
        }
    }
}

fn check_state(place: &str, kind: LightKind, s: &LightState) -> Result<()> {
    if !s.matrix.is_finite() {
        return Err(invalid_scene!("{place}: matrix is not finite"));
    }
    if !(s.power.is_finite() && s.power >= 0.0) {
        return Err(invalid_scene!("{place}: power {} must be finite and >= 0", s.power));
    }
    if s.color.iter().any(|c| !(c.is_finite() && *c >= 0.0)) {
        return Err(invalid_scene!("{place}: color {:?} must be finite and >= 0", s.color));
    }
    if !(s.spot_size > 0.0 && s.spot_size <= std::f64::consts::PI) {
        return Err(invalid_scene!("{place}: spot_size {} is outside (0, pi]", s.spot_size));
    }
    if !(0.0..=1.0).contains(&s.spot_blend) {
        return Err(invalid_scene!("{place}: spot_blend {} is outside [0,1]", s.spot_blend));
    }
    if !(s.radius.is_finite() && s.radius >= 0.0) {
        return Err(invalid_scene!("{place}: radius {} must be finite and >= 0", s.radius));
    }
    if !(s.angle.is_finite() && s.angle >= 0.0) {
        return Err(invalid_scene!("{place}: angle {} must be finite and >= 0", s.angle));
    }
    if kind == LightKind::Area && s.size.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
        return Err(invalid_scene!("{place}: size {:?} must be finite and > 0", s.size));
    }
    Ok(())
}

/// Checks a scene's lights, with messages that name the light and the field.
pub fn validate(lights: &[Light]) -> Result<()> {
    for (l, light) in lights.iter().enumerate() {
        let place = format!("light {l} \"{}\"", light.name);
        check_state(&place, light.kind, &light.base)?;
        for k in &light.animation {
            if !k.frame.is_finite() {
                return Err(invalid_scene!("{place}: animation key frame {} is not finite", k.frame));
            }
            check_state(&format!("{place} key at frame {}", k.frame), light.kind, &light.state_at(k.frame))?;
        }
    }
    Ok(())
}

/// Blender's light direction: local -Z in the world, unit length.
pub fn direction(m: &DMat4) -> DVec3 {
    (-m.z_axis.truncate()).normalize_or_zero()
}
