//! Kernel coefficients `K_ij^kl` (eq. 6) by quadrature.
//!
//! [`point`]: the point kernels; [`samples`]: quadrature samples of an element; [`pair`]: one pair
//! of elements, adaptive near the singularity; [`assemble`]: every pair of a scene, in parallel.

pub mod assemble;
pub mod pair;
pub mod point;
pub mod samples;
pub mod series;

pub use pair::{PairCoefficients, PairContext, integrate_pair};
