//! Blender Light objects through the C ABI ([`crate::lights`]): a host sets the lights as they
//! are at the coming frame, as it sets object matrices, so its own animation system (keys,
//! drivers, constraints) decides them and the incremental update takes their change as an
//! emission change.

use glam::DMat4;

use super::error::{Failure, GrStatus};
use super::panic::boundary;
use super::session::{GrSession, array, session};
use crate::lights::{AreaShape, Light, LightKind};

/// The type of a light (Blender's `Light.type`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GrLightKind {
    GrLightPoint = 0,
    GrLightSpot = 1,
    GrLightSun = 2,
    GrLightArea = 3,
}

/// The outline of an area light (Blender's `AreaLight.shape`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GrLightShape {
    GrLightSquare = 0,
    GrLightRectangle = 1,
    GrLightDisk = 2,
    GrLightEllipse = 3,
}

/// One light as it is at the coming frame. Fill with `gr_light_default` first: `struct_size`
/// carries the size of the struct the caller was compiled with, so fields appended later keep
/// their defaults for older callers.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct GrLight {
    /// `sizeof(GrLight)` as the caller knows it.
    pub struct_size: u32,
    /// A `GrLightKind` value.
    pub kind: u32,
    /// A `GrLightShape` value (area lights).
    pub shape: u32,
    /// World-from-light, row-major (as Blender's `matrix_world`); the light looks down local -Z.
    pub matrix: [f64; 16],
    /// RGB multiplier of `power`.
    pub color: [f64; 3],
    /// Watts (point, spot, area) or W/m^2 (sun strength).
    pub power: f64,
    /// Point and spot radius (m).
    pub radius: f64,
    /// Full cone angle of a spot (radians) and its blend in [0,1].
    pub spot_size: f64,
    pub spot_blend: f64,
    /// Sun angular diameter (radians).
    pub angle: f64,
    /// Area light size along local X and Y (m).
    pub area_size: [f64; 2],
}

/// Writes Blender's defaults for a point light of 1000 W at the origin to `out`.
///
/// # Safety
/// `out` is NULL or points to a writable `GrLight`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_light_default(out: *mut GrLight) -> GrStatus {
    boundary("gr_light_default", || {
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        let d = Light::new("", LightKind::Point, DMat4::IDENTITY, 1000.0);
        let light = GrLight {
            struct_size: size_of::<GrLight>() as u32,
            kind: GrLightKind::GrLightPoint as u32,
            shape: GrLightShape::GrLightSquare as u32,
            matrix: DMat4::IDENTITY.to_cols_array(),
            color: d.base.color,
            power: d.base.power,
            radius: d.radius,
            spot_size: d.base.spot_size,
            spot_blend: d.base.spot_blend,
            angle: d.angle,
            area_size: d.size,
        };
        // SAFETY: non-null per the check, writable per the contract.
        unsafe { out.write_unaligned(light) };
        Ok(())
    })
}

pub(super) fn light_of(i: usize, g: &GrLight) -> Result<Light, Failure> {
    if g.struct_size as usize != size_of::<GrLight>() {
        return Err(Failure::invalid(format!(
            "lights[{i}].struct_size is {}, this library's GrLight has {} bytes (fill it with gr_light_default)",
            g.struct_size,
            size_of::<GrLight>()
        )));
    }
    let kind = match g.kind {
        0 => LightKind::Point,
        1 => LightKind::Spot,
        2 => LightKind::Sun,
        3 => LightKind::Area,
        k => return Err(Failure::invalid(format!("lights[{i}].kind {k} is not a GrLightKind (0..=3)"))),
    };
    let shape = match g.shape {
        0 => AreaShape::Square,
        1 => AreaShape::Rectangle,
        2 => AreaShape::Disk,
        3 => AreaShape::Ellipse,
        k => return Err(Failure::invalid(format!("lights[{i}].shape {k} is not a GrLightShape (0..=3)"))),
    };
    let matrix = DMat4::from_cols_array(&g.matrix).transpose();
    let mut light = Light::new(&format!("lights[{i}]"), kind, matrix, g.power);
    light.base.color = g.color;
    light.base.spot_size = g.spot_size;
    light.base.spot_blend = g.spot_blend;
    light.radius = g.radius;
    light.angle = g.angle;
    light.shape = shape;
    light.size = g.area_size;
    Ok(light)
}

/// Replaces the session's lights with `count` lights from the next solved frame on (`count` 0
/// removes them). Each is checked (`struct_size`, kind, shape, finite non-negative power and
/// colour, spot size in (0, pi], blend in [0,1], area size > 0); on error nothing changes.
///
/// # Safety
/// `s` is NULL or a live session; `lights` is NULL (with `count` 0) or points to `count`
/// readable `GrLight`s.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_lights(
    s: *mut GrSession,
    lights: *const GrLight,
    count: usize,
) -> GrStatus {
    boundary("gr_session_set_lights", || {
        let s = unsafe { session(s) }?;
        let given = unsafe { array(lights, count, "lights") }?;
        let lights = given.iter().enumerate().map(|(i, g)| light_of(i, g)).collect::<Result<Vec<_>, _>>()?;
        s.write()?.session.set_lights(lights)?;
        Ok(())
    })
}

/// Replaces the session's World from the next solved frame on: radiance `strength x color`
/// from every direction, times the equirectangular image's texel where `pixels` is given
/// (`width x height` RGB triples, linear, bottom row first as Blender stores images; Blender's
/// equirectangular mapping, README of the add-on, "The World"). `strength` 0 removes the
/// World. Checked (finite, non-negative, `pixels` NULL with `width = height = 0` or both > 0);
/// on error nothing changes.
///
/// # Safety
/// `s` is NULL or a live session; `color` is NULL or points to 3 readable doubles; `pixels` is
/// NULL or points to `3 * width * height` readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_world(
    s: *mut GrSession,
    color: *const f64,
    strength: f64,
    pixels: *const f32,
    width: u32,
    height: u32,
) -> GrStatus {
    boundary("gr_session_set_world", || {
        let s = unsafe { session(s) }?;
        let color = unsafe { array(color, 3, "color") }?;
        let (w, h) = (width as usize, height as usize);
        let texels = if pixels.is_null() && w == 0 && h == 0 {
            None
        } else {
            if w == 0 || h == 0 {
                return Err(Failure::invalid(format!("world image is {w} x {h}: both must be > 0")));
            }
            let n = w
                .checked_mul(h)
                .and_then(|n| n.checked_mul(3))
                .ok_or_else(|| Failure::invalid(format!("world image {w} x {h} is too large")))?;
            let p = unsafe { array(pixels, n, "pixels") }?;
            Some(p.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
        };
        let world = (strength != 0.0).then(|| {
            let mut world = crate::lights::World::uniform([color[0], color[1], color[2]], strength);
            world.image = texels.map(|pixels| {
                std::sync::Arc::new(crate::lights::Environment { width: w, height: h, pixels })
            });
            world
        });
        s.write()?.session.set_world(world)?;
        Ok(())
    })
}

/// Makes object `object`'s emitting faces emit from both sides (`on` non-zero) or only from
/// their front (0, the default) from the next solved frame on.
///
/// # Safety
/// `s` is NULL or a live session.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_two_sided(s: *mut GrSession, object: u32, on: u32) -> GrStatus {
    boundary("gr_session_set_two_sided", || {
        let s = unsafe { session(s) }?;
        s.write()?.session.set_two_sided(object as usize, on != 0)?;
        Ok(())
    })
}
