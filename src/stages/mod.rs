//! The differentiable stages of the renderer, one file per operation.
//!
//! Each stage has a plain scalar forward function and a `*_vjp` backward function that takes the
//! upstream gradient of a scalar loss with respect to the stage's outputs and returns the
//! gradients with respect to its inputs.

pub mod bilinear;
pub mod composite;
pub mod depth_distortion;
pub mod ray_plane;
pub mod rotation;
pub mod sh;
#[cfg(target_arch = "x86_64")]
mod sh_sse;
pub mod splat_transform;
