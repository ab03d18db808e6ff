//! Initialisation of the primitive set (spec §8): farthest point sampling of the SfM cloud and
//! the Fibonacci sky sphere.
//!
//! - [`fps`]: deterministic farthest point sampling (start at index 0, Euclidean distance,
//!   ties to the lowest index), used when the SfM cloud has more points than the budget.
//! - [`hull`]: visual-hull initialisation from alpha masks (an option for RGBA scenes).
//! - [`fibonacci`]: points evenly spread on a sphere (the golden-angle spiral), the supplement's
//!   rule for how many sky points to add, and the sky-sphere radius (the reference rule and a
//!   rule robust to far outliers).
//!
//! Conventions and thresholds are collected in `docs/numerics-init-loss.md`.

pub mod budget;
pub mod fibonacci;
pub mod fps;
pub mod hull;
pub mod knn;
pub mod scene_init;
