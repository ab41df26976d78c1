//! The lights as placed at a frame ([`Placed`], made by [`super::DirectLight::new`]), the
//! fixed points of the unit disk the soft lights' shadow rays go through ([`soft_disk`]) and the
//! World's strata per point.

use std::f64::consts::PI;

use glam::DVec3;

use crate::lights::{AreaShape, Light, LightKind, LightState, direction};

/// Shadow-ray sample points per axis of an area light.
const AREA_SAMPLES: usize = 4;

/// Sides of the polygon standing for a disk or ellipse (of the same area).
pub(super) const ROUND_SIDES: usize = 32;

/// Shadow rays per axis of a round light (Point or Spot of radius > 0) or the cone of a sun of
/// angle > 0, per visibility sample per axis of the quality setting at a gathered corner or
/// foot (Medium: 8 x 8 = 64 rays), and at each of an element's 6 x 6 projection points (4 x 4 =
/// 16, whatever the quality: their mean over the element feeds the later bounces). Fixed rays
/// per point, so a bake is reproducible and an incremental frame equals its full solve. With 16
/// at the corners, the validation room's block top under the penumbra of a wall's edge (a
/// 10-degree sun, `tools/validate_lights.py`) came out 6% over Cycles, one ray of 16, the whole
/// row of corners alike (the edge parallel to it); 64 took the block's mean ratio to Cycles from
/// 1.022 to 0.997 (the floor's 0.993 to 1.002).
const SOFT_AXIS: usize = 4;

/// The turn (radians) of [`soft_disk`]'s points about the disk's centre, for 1 to 4 visibility
/// samples per axis (4 x 4 to 16 x 16 points): the turn in steps of 0.001 rad whose points'
/// shadows along the disk's axes and diagonals lie farthest apart.
const SOFT_TURNS: [f64; 4] = [0.1, 0.282, 0.3, 0.334];

/// World strata per axis, per visibility sample per axis of the quality setting
/// (`Settings::visibility_samples`: 1 Draft .. 4 Ultra): at a gathered corner or foot, whose
/// value is what the host shows (Medium: 16 x 16 strata, 289 rays and 16 more per stratum on
/// an edge of the sky), and at each of an element's 6 x 6 projection points, whose mean over the
/// element feeds the later bounces (Medium: 8 x 8, 81 rays and the edges'). Coarser projections
/// cost less and took the indirectly lit wall of `tools/validate_lights.py`'s sky from a mean
/// ratio to Cycles of 0.999 (8 x 8) to 0.992 (6 x 6) and 0.991 (4 x 4); 8 x 8 cost about 1 s a
/// frame over 2.1 s on the 364-face Cornell box with a World (CLI `--full`, a loaded machine).
pub(super) const WORLD_CORNER_AXIS: usize = 8;
pub(super) const WORLD_PROJECTION_AXIS: usize = 4;

/// One light as placed at a frame, ready for point queries.
#[derive(Clone, Debug)]
pub(super) struct Placed {
    pub(super) kind: LightKind,
    pub(super) position: DVec3,
    /// Unit direction the light faces (local -Z).
    pub(super) axis: DVec3,
    /// Point and Spot: intensity W/sr; Sun: irradiance normal to the rays; Area: exitance.
    pub(super) scale: [f64; 3],
    pub(super) cos_half: f64,
    pub(super) smooth: f64,
    /// Point and Spot: the radius (0: a point); Sun: half its angular diameter (0: parallel
    /// rays).
    pub(super) extent: f64,
    /// Point and Spot of radius > 0: a sphere (Soft Falloff off) rather than a disk facing the
    /// receiver.
    pub(super) sphere: bool,
    /// Area: the outline (front = `axis`) and shadow sample points with their areas.
    pub(super) polygon: Vec<DVec3>,
    pub(super) samples: Vec<DVec3>,
}

impl Placed {
    /// Whether `other` casts the same shadow rays from any point as this light: the same but for
    /// its colour and power (`scale`), which weigh what the rays find and choose none of them (a
    /// light fading in or flickering casts the rays of the frame before).
    pub(super) fn casts_alike(&self, other: &Placed) -> bool {
        let Placed { kind, position, axis, scale: _, cos_half, smooth, extent, sphere, polygon, samples } =
            self;
        (*kind, *position, *axis, *cos_half, *smooth, *extent, *sphere)
            == (
                other.kind,
                other.position,
                other.axis,
                other.cos_half,
                other.smooth,
                other.extent,
                other.sphere,
            )
            && *polygon == other.polygon
            && *samples == other.samples
    }

    pub(super) fn new(light: &Light, s: &LightState) -> Self {
        let position = s.matrix.w_axis.truncate();
        let axis = direction(&s.matrix);
        let colour = |k: f64| std::array::from_fn(|c| s.color[c] * s.power * k);
        let cos_half = (0.5 * s.spot_size).cos();
        let (mut polygon, mut samples) = (Vec::new(), Vec::new());
        let scale = match light.kind {
            LightKind::Point | LightKind::Spot => colour(1.0 / (4.0 * PI)),
            LightKind::Sun => colour(1.0),
            LightKind::Area => {
                let (a, b) = match light.shape {
                    AreaShape::Square | AreaShape::Disk => (s.size[0], s.size[0]),
                    AreaShape::Rectangle | AreaShape::Ellipse => (s.size[0], s.size[1]),
                };
                let round = matches!(light.shape, AreaShape::Disk | AreaShape::Ellipse);
                // Local outline wound clockwise about +Z, so that its front is -Z.
                let local: Vec<(f64, f64)> = if round {
                    let n = ROUND_SIDES as f64;
                    let r = (2.0 * PI / (n * (2.0 * PI / n).sin())).sqrt(); // same area as the ellipse
                    (0..ROUND_SIDES)
                        .map(|k| {
                            let th = -2.0 * PI * k as f64 / n;
                            (0.5 * a * r * th.cos(), 0.5 * b * r * th.sin())
                        })
                        .collect()
                } else {
                    vec![(-0.5 * a, -0.5 * b), (-0.5 * a, 0.5 * b), (0.5 * a, 0.5 * b), (0.5 * a, -0.5 * b)]
                };
                let world = |x: f64, y: f64| s.matrix.transform_point3(DVec3::new(x, y, 0.0));
                polygon = local.iter().map(|&(x, y)| world(x, y)).collect();
                let m = AREA_SAMPLES as f64;
                for i in 0..AREA_SAMPLES {
                    for j in 0..AREA_SAMPLES {
                        let (u, v) = ((i as f64 + 0.5) / m - 0.5, (j as f64 + 0.5) / m - 0.5);
                        if !round || u * u + v * v <= 0.25 {
                            samples.push(world(u * a, v * b));
                        }
                    }
                }
                colour(1.0 / light.area(s))
            }
        };
        let smooth = (1.0 - cos_half) * s.spot_blend;
        let extent = match light.kind {
            LightKind::Point | LightKind::Spot => s.radius,
            LightKind::Sun => 0.5 * s.angle,
            LightKind::Area => 0.0,
        };
        let sphere = !s.soft_falloff;
        Placed { kind: light.kind, position, axis, scale, cos_half, smooth, extent, sphere, polygon, samples }
    }
}

/// The fixed points of the unit disk the soft lights' shadow rays go through, `v` (1..=4,
/// clamped) visibility samples per axis: the midpoints of `m x m` strata (`m = SOFT_AXIS v`) of
/// the square carried onto the disk by Shirley and Chiu's concentric map ("A low distortion map
/// between disk and square", 1997). The map keeps areas, so the strata stay equal in area, and
/// it is odd (`-p` maps to minus the image of `p`), so the points' mean is the disk's centre:
/// [`DirectLight::cone_factor`] relies on that, and [`DirectLight::round_factor`] takes them as
/// equal-area points of its disk. The points are turned by [`SOFT_TURNS`] about the centre:
/// unturned they line up along the disk's axes, which a light straight above an axis-aligned
/// edge shares, and its penumbra went in 6 steps of up to a quarter of the light (4 x 4);
/// turned, their 16 shadows along either axis (or a diagonal) are distinct, steps of sixteenths.
///
/// [`DirectLight::cone_factor`]: super::DirectLight::cone_factor
/// [`DirectLight::round_factor`]: super::DirectLight::round_factor
pub(super) fn soft_disk(v: usize) -> &'static [(f64, f64)] {
    static DISKS: std::sync::LazyLock<Vec<Vec<(f64, f64)>>> = std::sync::LazyLock::new(|| {
        (1..=SOFT_TURNS.len())
            .map(|v| {
                let n = SOFT_AXIS * v;
                let m = n as f64;
                let mid = |i: usize| 2.0 * (i as f64 + 0.5) / m - 1.0;
                let (c, s) = (SOFT_TURNS[v - 1].cos(), SOFT_TURNS[v - 1].sin());
                let mut points = Vec::with_capacity(n * n);
                for i in 0..n {
                    for j in 0..n {
                        let (a, b) = (mid(i), mid(j));
                        let (r, phi) = if a.abs() > b.abs() {
                            (a, 0.25 * PI * b / a)
                        } else {
                            (b, 0.5 * PI - 0.25 * PI * a / b)
                        };
                        let (x, y) = (r * phi.cos(), r * phi.sin());
                        points.push((c * x - s * y, s * x + c * y));
                    }
                }
                points
            })
            .collect()
    });
    &DISKS[v.clamp(1, SOFT_TURNS.len()) - 1]
}
