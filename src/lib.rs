//! # bbsplat
//!
//! Billboard splatting (BBSplat) on the CPU: planar primitives carrying a small learned RGB
//! texture, an alpha texture and spherical-harmonics colour, rendered by ray-plane intersection
//! and front-to-back alpha compositing, and trained by gradient descent.
//!
//! The crate is built from small pure stages, each with a forward pass and an analytic backward
//! pass (a vector-Jacobian product) that is checked against central finite differences by the
//! public `gradcheck` module (feature `testing`). Conventions (frames, units, ranges, thresholds) are collected in
//! `docs/numerics.md`; every module states the ones it relies on.

#![warn(missing_docs)]
// Numeric kernels index several parallel arrays with one loop counter; iterator chains would hide
// the index arithmetic the docs describe.
#![allow(clippy::needless_range_loop)]

pub mod billboards;
pub mod camera;
#[cfg(feature = "tools")]
pub mod demo;
pub mod eval;
#[cfg(feature = "testing")]
pub mod gradcheck;
pub mod init;
pub mod loss;
pub mod memory;
pub mod model;
pub mod model_file;
pub mod raster;
pub mod report;
pub mod rng;
pub mod scene;
pub mod stages;
#[cfg(feature = "testing")]
pub mod strategies;
#[cfg(feature = "tools")]
pub mod sweep;
pub mod train;
