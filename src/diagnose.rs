//! The hemisphere bound as a measurement: how much of each receiver's hemisphere the kernel
//! thinks it sees.
//!
//! The form factors from a point `x` to everything it sees sum to at most 1 (eq. 2 integrated over
//! the hemisphere), and to exactly 1 inside a closed scene. For the Galerkin kernel (eq. 6) with
//! the orthonormal basis (`Gamma_0 = 1`), the row sum `sum_j G_ij^00` is the parameter-space mean of
//! that point sum over element `i`; at a corner the gather's `sum_j m_j^0` (plus its feet) is the
//! point sum itself. Values above 1 create energy (a closed box then returns more than
//! `1 / (1 - rho)` of its emission), values below 1 in a closed scene lose it. Brute force needs no
//! integration here: the answer is known, which makes these sums the sharpest test of the kernel,
//! the visibility and the gather on real meshes.

use crate::error::Result;
use crate::scene::Scene;
use crate::system::{System, no_progress};

/// Per element `i`, `sum_j G_ij^00`: the mean form-factor sum over the element.
pub fn element_sums(sys: &System) -> Vec<f64> {
    (0..sys.elements.len() as u32).map(|i| crate::hemisphere::row_sum(&sys.links, i)).collect()
}

/// Per object, per face corner (in face order, as results report them): the form-factor sum the
/// corner gather sees at the corner. Builds the scene at `frame` and gathers a unit solution
/// (every element's `B = 1`, reflectance 1, no bound), then takes the emission back off.
pub fn corner_sums(scene: &Scene, frame: f64) -> Result<Vec<Vec<f64>>> {
    let mut sys = System::build(scene, frame, &no_progress)?;
    let nb = sys.basis.len();
    for (k, b) in sys.solution.b.iter_mut().enumerate() {
        *b = if k % nb == 0 { [1.0; 3] } else { [0.0; 3] };
    }
    sys.surface_reflectance.iter_mut().for_each(|r| *r = [1.0; 3]);
    sys.corner_bound = false;
    sys.gather_corners(scene, frame, &no_progress)?;
    let corners = sys.corners.take().expect("gathered");
    let mut out = Vec::with_capacity(corners.len());
    for (o, (obj, values)) in scene.objects.iter().zip(corners).enumerate() {
        let mut sums = Vec::with_capacity(values.len());
        let mut corner = 0;
        for (f, face) in obj.faces.iter().enumerate() {
            let e = scene.emission_of(o, f, obj.face_materials[f], frame);
            for _ in face {
                sums.push(values[corner][0] - e[0]);
                corner += 1;
            }
        }
        out.push(sums);
    }
    Ok(out)
}
