//! The hemisphere bound: a receiver cannot take in more than its hemisphere.
//!
//! The form factors from a point to everything it sees sum to at most 1 (eq. 2 integrated over
//! the hemisphere). The kernel can exceed that where the scene is not what the integral assumes:
//! coplanar duplicate faces (each is seen in full, so the wall counts twice), objects crossing
//! each other with visibility off or coarse, quadrature next to a contact. Above 1 the kernel
//! creates light: a closed box returns more than `1 / (1 - rho)` of its emission, and a material
//! near white makes the solve diverge (issue 19: duplicates raised a closed box's ratio from 3.33
//! to 5.40; RenderPark's office diverged).
//!
//! So each receiver's row of `K = rho G` is scaled by `min(1, 1 / S_i)` with
//! `S_i = sum_j G_ij^00` the element's mean form-factor sum ([`row_sum`]; `Gamma_0 = 1`): the
//! solver shoots with `rho_i min(1, 1 / S_i)` in place of `rho_i`, so `rho S <= rho < 1` and every
//! solve converges. The link store keeps the raw, reciprocal `G`; only the reflectance the solver
//! uses carries the bound. Inside a closed scene `S_i` is 1 up to quadrature error, so the bound
//! also removes the error's upward half. The corner gather bounds each corner by its own point
//! sum the same way ([`crate::gather`]).

use crate::links::{ElementId, LinkStore};

/// `S_i = sum_j G_ij^00`: the mean over element `i` (in its parameter domain) of the form factors
/// from its points to everything it is linked with. Kept by the store through every write
/// ([`LinkStore::row_sum`], exact and order-free), so O(1): an animation frame re-bounds each
/// receiver whose links changed at the cost of its changed pairs, not of its row.
pub fn row_sum(links: &LinkStore, i: ElementId) -> f64 {
    links.row_sum(i)
}

/// [`row_sum`] summed over the row in adjacency order (f64, sequential): what the store keeps,
/// up to the f64 rounding of a sequential sum; for tests.
pub fn row_sum_from_scratch(links: &LinkStore, i: ElementId) -> f64 {
    links.pairs_of(i).iter().map(|&p| links.column(p, i, 0)[0] as f64).sum()
}

/// The factor a receiver whose form factors sum to `sum` takes its reflectance with.
#[inline]
pub fn bound(sum: f64) -> f64 {
    if sum > 1.0 { 1.0 / sum } else { 1.0 }
}

/// The reflectance the solver uses for element `i`: its surface's, bounded by [`row_sum`].
pub fn bounded_reflectance(links: &LinkStore, i: ElementId, surface: [f64; 3]) -> [f64; 3] {
    let f = bound(row_sum(links, i));
    surface.map(|r| r * f)
}
