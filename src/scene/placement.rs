//! Keyed placement and emission: linear interpolation between keys, held outside them.

use glam::{DMat4, DVec3};

use super::EmissionKey;

#[derive(Clone, Debug, PartialEq)]
pub enum KeyTransform {
    /// World translation of the object's origin; the rest of the base matrix is kept.
    Translation(DVec3),
    /// The whole world-from-object matrix.
    Matrix(DMat4),
}

#[derive(Clone, Debug, PartialEq)]
pub struct Key {
    pub frame: f64,
    pub transform: KeyTransform,
}

impl Key {
    fn matrix(&self, base: DMat4) -> DMat4 {
        match &self.transform {
            KeyTransform::Translation(t) => {
                let mut m = base;
                m.w_axis = t.extend(1.0);
                m
            }
            KeyTransform::Matrix(m) => *m,
        }
    }
}

/// Finds the keys around `frame` and the blend weight of the second.
pub(crate) fn bracket<T>(
    keys: &[T],
    frame: f64,
    key_frame: impl Fn(&T) -> f64,
) -> Option<(usize, usize, f64)> {
    let first = keys.first()?;
    let last = keys.last()?;
    if frame <= key_frame(first) {
        return Some((0, 0, 0.0));
    }
    if frame >= key_frame(last) {
        let n = keys.len() - 1;
        return Some((n, n, 0.0));
    }
    let hi = keys.partition_point(|k| key_frame(k) <= frame);
    let lo = hi - 1;
    let (f0, f1) = (key_frame(&keys[lo]), key_frame(&keys[hi]));
    Some((lo, hi, (frame - f0) / (f1 - f0)))
}

pub(super) fn world_from_object(base: DMat4, keys: &[Key], frame: f64) -> DMat4 {
    match bracket(keys, frame, |k| k.frame) {
        None => base,
        Some((lo, hi, w)) => {
            let a = keys[lo].matrix(base);
            if w == 0.0 {
                return a;
            }
            let b = keys[hi].matrix(base);
            a * (1.0 - w) + b * w
        }
    }
}

/// True when `m` mirrors space (negative determinant): a face wound counter-clockwise about its
/// front normal in object space is wound clockwise in the world, so its front would turn inward.
/// Blender keeps the front side under a mirror (its normals are transformed by the inverse
/// transpose, which flips them back); so does the placement, through [`front_order`].
pub fn mirrors(m: &DMat4) -> bool {
    m.determinant() < 0.0
}

/// A face's corners in the order that keeps its object-space front under a mirroring placement:
/// corners 0 and 1 (and 2 and 3 of a quad) swapped. For a bilinear patch this is the
/// reparametrisation `s -> 1 - s` (the triangle's collapsed edge `t = 1` stays where it is), so
/// a face corner at `(s,t)` sits at `(1 - s, t)` of the placed patch.
pub fn front_order<T: Copy>(corners: &[T], mirrored: bool) -> Vec<T> {
    let mut out = corners.to_vec();
    if mirrored && out.len() >= 3 {
        out.swap(0, 1);
        if out.len() == 4 {
            out.swap(2, 3);
        }
    }
    out
}

pub(super) fn emission_at(base: [f64; 3], keys: &[EmissionKey], frame: f64) -> [f64; 3] {
    match bracket(keys, frame, |k| k.frame) {
        None => base,
        Some((lo, hi, w)) => {
            let (a, b) = (keys[lo].emission, keys[hi].emission);
            std::array::from_fn(|c| a[c] * (1.0 - w) + b[c] * w)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn translation_keys_interpolate_and_hold() {
        let keys = vec![
            Key { frame: 1.0, transform: KeyTransform::Translation(DVec3::ZERO) },
            Key { frame: 11.0, transform: KeyTransform::Translation(DVec3::new(10.0, 0.0, 0.0)) },
        ];
        let base = DMat4::from_scale(DVec3::splat(2.0));
        let at = |f| world_from_object(base, &keys, f).w_axis.truncate();
        assert_eq!(at(-5.0), DVec3::ZERO);
        assert!((at(6.0) - DVec3::new(5.0, 0.0, 0.0)).length() < 1e-12);
        assert_eq!(at(50.0), DVec3::new(10.0, 0.0, 0.0));
        // The base scale is kept under translation keys.
        assert_eq!(world_from_object(base, &keys, 6.0).x_axis.x, 2.0);
    }

    #[test]
    fn a_mirrored_placement_keeps_the_object_space_front() {
        use crate::geometry::Patch;
        let quad = [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y];
        let tri = [DVec3::ZERO, DVec3::X, DVec3::Y];
        for m in
            [DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0)), DMat4::from_scale(DVec3::new(2.0, -3.0, 0.5))]
        {
            assert!(mirrors(&m));
            for face in [&quad[..], &tri[..]] {
                let world: Vec<DVec3> = face.iter().map(|v| m.transform_point3(*v)).collect();
                let placed = Patch::from_corners(&front_order(&world, true));
                // The front is the object-space +z taken through the inverse transpose.
                let front = m.inverse().transpose().transform_vector3(DVec3::Z);
                assert!(placed.area_vector(0.3, 0.4).dot(front) > 0.0);
                // A face corner at (s,t) is the placed patch's (1 - s, t).
                assert!((placed.point(1.0, 0.0) - world[0]).length() < 1e-12);
                assert!((placed.point(0.0, 0.0) - world[1]).length() < 1e-12);
            }
        }
        assert!(!mirrors(&DMat4::from_scale(DVec3::new(-1.0, -1.0, 1.0))));
        assert_eq!(front_order(&[0, 1, 2, 3], false), vec![0, 1, 2, 3]);
    }
}
