//! The integration tests, one crate: each module is one area (stages, raster, scene input,
//! initialisation, training, files, command line). One binary links once, instead of one per file.

#![allow(clippy::needless_range_loop)]

mod bench_scene;
mod camera;
#[cfg(feature = "cli")]
mod cli;
mod cli_benchmark;
mod cli_bounds;
#[cfg(feature = "cli")]
mod cli_export;
mod cli_full_disk;
mod cli_live;
mod cli_masks;
#[cfg(feature = "cli")]
mod cli_reliability;
mod cli_resume_time;
mod cli_scene_mark;
mod cli_serve;
mod cluster_slurm;
mod demo;
mod eval;
mod exp_f32;
mod export;
mod export_blender;
mod export_browser;
mod export_fixtures;
mod export_splat;
mod export_splat_browser;
mod external_tool;
mod f64_reference;
#[cfg(feature = "cli")]
mod file_kinds;
mod gradcheck;
mod init_fibonacci;
mod init_fps;
mod init_hull;
mod init_scene;
mod layering;
mod loss_normal_consistency;
mod loss_ssim;
mod lpips;
mod memory;
mod mesh;
mod model;
mod model_file;
mod model_file_npz;
mod model_file_ply;
mod model_knn;
mod plan;
mod progress;
mod raster;
mod raster_aux;
mod raster_backward;
mod raster_binning;
mod raster_camera;
mod raster_lanes;
mod raster_preprocess;
mod raster_schedule;
mod raster_spans;
mod raster_workload;
mod report;
mod rng;
mod scene_bad_input;
mod scene_colmap_roundtrip;
mod scene_distortion;
mod scene_duplicates;
mod scene_exif;
mod scene_fuzz;
mod scene_image_io;
mod scene_llff;
mod scene_load;
mod scene_neus;
mod scene_real_data;
mod scene_registration;
#[allow(dead_code)]
mod scene_support;
mod scene_unfold;
mod shared_data;
mod splat_reference;
mod stage_bilinear;
mod stage_composite;
mod stage_lanes;
mod stage_ray_plane;
mod stage_rotation;
mod stage_sh;
mod stage_splat_transform;
mod strategies;
mod sweep;
mod text_bom;
mod train_adam;
mod train_camera_fit;
mod train_checkpoint;
mod train_demo;
mod train_depth_sweep;
mod train_edit;
mod train_finite;
mod train_geometry;
mod train_grow;
mod train_place;
mod train_regularise;
mod train_relocate;
mod train_row_sums;
mod train_run;
mod train_texture_step;
mod train_time_budget;
