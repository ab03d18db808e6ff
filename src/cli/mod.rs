//! Subcommands of the `bbsplat` binary (the library does the work; these parse flags, print and
//! write files).

pub mod benchmark;
pub mod blocks;
pub mod blocks_chain;
pub mod blocks_files;
pub mod blocks_report;
pub mod blocks_seams;
pub mod common;
pub mod demo;
pub mod export;
pub mod flag_parsers;
pub mod http;
pub mod live;
pub mod mesh;
pub mod preflight;
pub mod render;
pub mod resume;
pub mod signals;
pub mod train;
pub mod train_args;
pub mod validate;
pub mod view;
