//! Galerkin radiosity (Zatz 1993) with the incremental animation update of Arques, Biri and
//! Michelin (2001). See README.md for the method and ARCHITECTURE.md for the layout.
//!
//! Conventions: right-handed world space, units as given (the solver is scale-free); radiosity
//! and exitance in W/m^2 per RGB channel; faces are one-sided, front counter-clockwise (open
//! surfaces may get a back, [`backs`]).

// Numeric kernels index several arrays with one loop variable, as the equations do.
#![allow(clippy::needless_range_loop)]

pub mod animation;
pub mod backs;
pub mod basis;
pub mod budget;
pub mod contact_split;
pub mod diagnose;
pub mod error;
pub mod ffi;
pub mod finite;
pub mod gather;
pub mod geometry;
pub mod hemisphere;
pub mod hierarchy;
pub mod kernel;
pub mod lights;
pub mod links;
pub mod overlap;
pub mod progress;
pub mod quadrature;
pub mod replay;
pub mod scene;
pub mod scenes;
pub mod session;
mod simd;
pub mod solids;
pub mod solver;
pub mod system;
pub mod visibility;

pub use error::{Error, Result};
