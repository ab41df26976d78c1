//! Visibility from a point for the corner gather through the hierarchy
//! (`hierarchy::gather`): narrowing a candidate list to the shaft of a part of a source, and
//! rays straight through the BVH where no candidate list is worth gathering.

use glam::DVec3;

use super::Occluders;
use super::shaft::Shaft;
use crate::geometry::Aabb;

/// The shaft from a point to a box, to narrow a candidate list with
/// ([`Occluders::may_block`]).
pub struct PointShaft {
    shaft: Shaft,
    eps: f64,
}

impl Occluders {
    /// The shaft from `x` to `bounds`: a segment from `x` to a point inside `bounds` can be
    /// blocked only by a triangle it may hold.
    pub fn point_shaft(&self, x: DVec3, bounds: &Aabb) -> PointShaft {
        PointShaft { shaft: Shaft::new(&Aabb { min: x, max: x }, bounds), eps: 1e-9 * self.scale }
    }

    /// Whether occluder triangle `t` (an index of [`Occluders::point_candidates`]' lists) may
    /// lie in `shaft`: a candidate of a source stays one for a part of the source only if so.
    pub fn may_block(&self, shaft: &PointShaft, t: usize) -> bool {
        shaft.shaft.may_contain_triangle(&self.bvh.triangles()[t].v, shaft.eps)
    }

    /// Which segments from `x` (on element `i`) to `targets` (on element `j`) are unobstructed,
    /// into `out`: any-hit rays through the BVH, without gathering the shaft's triangles first
    /// (for a few rays to a far source the shaft query costs more than the rays).
    pub fn visible_from(&self, x: DVec3, (i, j): (u32, u32), targets: &[DVec3], out: &mut [bool]) {
        let (i, j) = self.ids((i, j));
        for (o, &y) in out.iter_mut().zip(targets) {
            *o = !self.bvh.occluded(x, y - x, 1e-9, 1.0 - 1e-9, i, j);
        }
    }
}
