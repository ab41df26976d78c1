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
    /// Full cone angle of a spot (radians) and its blend in `[0,1]`.
    pub spot_size: f64,
    pub spot_blend: f64,
    /// Sun angular diameter (radians).
    pub angle: f64,
    /// Area light size along local X and Y (m).
    pub area_size: [f64; 2],
    /// Point and spot of radius > 0: 1 (the default, Blender's Soft Falloff) a disk facing the
    /// receiver, 0 a sphere. Appended: a caller whose `struct_size` ends before it gets 1.
    pub soft_falloff: u32,
}

/// The size of `GrLight` before `soft_falloff` was appended: the smallest `struct_size` taken.
const GR_LIGHT_V1_SIZE: usize = std::mem::offset_of!(GrLight, soft_falloff);

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
            radius: d.base.radius,
            spot_size: d.base.spot_size,
            spot_blend: d.base.spot_blend,
            angle: d.base.angle,
            area_size: d.base.size,
            soft_falloff: d.base.soft_falloff as u32,
        };
        // SAFETY: non-null per the check, writable per the contract.
        unsafe { out.write_unaligned(light) };
        Ok(())
    })
}

/// The caller's light `i` at `given`, read as far as its `struct_size` says (from
/// [`GR_LIGHT_V1_SIZE`], the layout before `soft_falloff`, to `sizeof(GrLight)`), the fields
/// beyond it at their defaults; checked as [`light_of`] does.
///
/// # Safety
/// `given` is non-NULL and points to a readable `u32` `struct_size` followed by the rest of
/// that many readable bytes.
pub(super) unsafe fn read_light(i: usize, given: *const GrLight) -> Result<Light, Failure> {
    // SAFETY: the first field is there in every version, readable per the contract.
    let size = unsafe { given.cast::<u32>().read_unaligned() };
    super::sized::check(
        &format!("lights[{i}]"),
        size,
        GR_LIGHT_V1_SIZE,
        size_of::<GrLight>(),
        "gr_light_default",
    )?;
    let mut light = std::mem::MaybeUninit::<GrLight>::uninit();
    // SAFETY: `gr_light_default` initialises every field of the (non-null, writable) struct;
    // then the caller's `size` bytes, readable per the contract and at most the struct's,
    // overwrite the leading fields whole, the layouts agreeing on those (fields are only
    // appended, and `size` ends at a field's end or at the struct's).
    let g = unsafe {
        gr_light_default(light.as_mut_ptr());
        std::ptr::copy_nonoverlapping(given.cast::<u8>(), light.as_mut_ptr().cast::<u8>(), size as usize);
        light.assume_init()
    };
    light_of(i, &g)
}

/// A whole `GrLight` as a light (its `struct_size` already taken by [`read_light`]).
fn light_of(i: usize, g: &GrLight) -> Result<Light, Failure> {
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
    light.base.radius = g.radius;
    light.base.soft_falloff = match g.soft_falloff {
        0 => false,
        1 => true,
        k => return Err(Failure::invalid(format!("lights[{i}].soft_falloff {k} is not 0 or 1"))),
    };
    light.base.angle = g.angle;
    light.shape = shape;
    light.base.size = g.area_size;
    Ok(light)
}

/// Replaces the session's lights with `count` lights from the next solved frame on (`count` 0
/// removes them). The array's stride is the first light's `struct_size` (a host built against
/// an older header passes an array of its smaller structs), which every light must carry. Each
/// is checked (`struct_size`, kind, shape, `soft_falloff` 0 or 1, finite non-negative power
/// and colour, spot size in (0, pi], blend in `[0,1]`, area size > 0); on error nothing changes.
///
/// # Safety
/// `s` is NULL or a live session; `lights` is NULL (with `count` 0) or points to `count`
/// readable `GrLight`s of the caller's layout (`struct_size` bytes each).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_session_set_lights(
    s: *mut GrSession,
    lights: *const GrLight,
    count: usize,
) -> GrStatus {
    boundary("gr_session_set_lights", || {
        let s = unsafe { session(s) }?;
        let lights = unsafe { read_lights(lights, count) }?;
        s.write()?.session.set_lights(lights)?;
        Ok(())
    })
}

/// `count` lights at `p`, each `struct_size` (the first's) bytes long.
///
/// # Safety
/// As `gr_session_set_lights`'s `lights`.
unsafe fn read_lights(p: *const GrLight, count: usize) -> Result<Vec<Light>, Failure> {
    if count == 0 {
        return Ok(Vec::new());
    }
    if p.is_null() {
        return Err(Failure::null("lights"));
    }
    // SAFETY: non-null, and the first light's first field is readable per the contract.
    let stride = unsafe { p.cast::<u32>().read_unaligned() } as usize;
    super::sized::check(
        "lights[0]",
        stride as u32,
        GR_LIGHT_V1_SIZE,
        size_of::<GrLight>(),
        "gr_light_default",
    )?;
    if count.checked_mul(stride).is_none_or(|bytes| bytes > isize::MAX as usize) {
        return Err(Failure::invalid(format!("lights: {count} elements is more than any buffer can hold")));
    }
    (0..count)
        .map(|i| {
            // SAFETY: light `i` starts `i * stride` bytes in, inside the caller's array.
            let at = unsafe { p.cast::<u8>().add(i * stride) }.cast::<GrLight>();
            // SAFETY: as above; its first field is readable.
            let size = unsafe { at.cast::<u32>().read_unaligned() } as usize;
            if size != stride {
                return Err(Failure::invalid(format!(
                    "lights[{i}].struct_size is {size} but lights[0]'s is {stride}: an array's lights share one layout"
                )));
            }
            // SAFETY: `stride` readable bytes at `at`.
            unsafe { read_light(i, at) }
        })
        .collect()
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
