//! Subcommands of the `bbsplat` binary (the library does the work; these parse flags, print and
//! write files).

pub mod common;
pub mod demo;
pub mod export;
pub mod render;
pub mod train;
pub mod view;
