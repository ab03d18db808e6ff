//! Checkpoints: save + load + continue is bit-identical to an uninterrupted run; bad files give
//! typed errors naming the file, never a panic; saving leaves no temporary file behind. Also the
//! typed errors of `Trainer::step`.

use bbsplat::demo::{DemoConfig, generate};
use bbsplat::model::RawBillboards;
use bbsplat::scene::split::camera_extent;
use bbsplat::train::checkpoint::{MAGIC, OLDEST_VERSION, VERSION};
use bbsplat::train::{
    AdamMode, CheckpointError, ClampGradient, LearningRateScales, TextureMode, TrainConfig, TrainError, TrainView,
    Trainer,
};
use glam::Vec3;
use std::path::PathBuf;

fn setup(adam: AdamMode, texture_mode: TextureMode) -> (Trainer, Vec<TrainView>) {
    let scene = generate(&DemoConfig {
        resolution: 24,
        train_views: 5,
        test_views: 1,
        points: 150,
        seed: 8,
    });
    let views: Vec<TrainView> = scene
        .train
        .iter()
        .map(|v| TrainView {
            camera: v.camera,
            rgb: v.rgb.clone().into(),
            loss_mask: None,
        })
        .collect();
    let mut model = RawBillboards::from_points(&scene.points, &scene.colours, 4, 8);
    // A few dead billboards so that relocation (and its RNG draws) happens inside the run.
    for d in [3, 40, 77] {
        for k in 0..16 {
            model.alpha_logits[d * 16 + k] = -12.0;
        }
    }
    let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        // Short schedule: textures on from step 1, relocation window (0.06, 3.1) × 100 steps.
        iterations: 128,
        seed: 8,
        background: Vec3::from_array(scene.background),
        extent: camera_extent(&cams),
        relocate_every: 3,
        adam,
        texture_mode,
        // Not the defaults: a resumed run that lost them would drift from the straight one.
        lr_scales: LearningRateScales {
            position: 1.5,
            sh: 0.75,
            shape: 1.25,
            texture: 2.0,
        },
        clamp_gradient: ClampGradient::PassThrough,
        ..TrainConfig::default()
    };
    (Trainer::new(model, config), views)
}

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bbsplat-ckpt-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn resume_equals_uninterrupted(adam: AdamMode, mode: TextureMode, tag: &str) {
    const N: usize = 7;
    let (mut straight, views) = setup(adam, mode);
    let mut relocated = 0;
    for _ in 0..2 * N {
        relocated += straight.step(&views).unwrap().relocated;
    }
    assert!(relocated > 0, "the run must exercise relocation");

    let (mut first, _) = setup(adam, mode);
    for _ in 0..N {
        first.step(&views).unwrap();
    }
    let dir = temp_dir(tag);
    let path = dir.join("run.ckpt");
    first.save_checkpoint(&path).unwrap();
    drop(first);
    let mut resumed = Trainer::load_checkpoint(&path).unwrap();
    assert_eq!(resumed.step_index(), N);
    for _ in 0..N {
        resumed.step(&views).unwrap();
    }
    // Model parameters, Adam moments and counters, RNG and view order: the whole serialised state.
    assert_eq!(resumed.model(), straight.model(), "{tag}: model parameters differ");
    assert_eq!(resumed.adam(), straight.adam(), "{tag}: Adam state differs");
    assert_eq!(resumed.opacity_logits(), straight.opacity_logits());
    assert_eq!(resumed.activated().textures, straight.activated().textures);
    assert!(
        resumed.checkpoint_bytes() == straight.checkpoint_bytes(),
        "{tag}: state differs"
    );
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["run.ckpt".to_string()], "no temporary file is left behind");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn resume_is_bit_identical_dense_full() {
    resume_equals_uninterrupted(AdamMode::Dense, TextureMode::Full, "dense-full");
}

#[test]
fn resume_is_bit_identical_lazy_full() {
    resume_equals_uninterrupted(AdamMode::Lazy, TextureMode::Full, "lazy-full");
}

#[test]
fn resume_is_bit_identical_sparse_gaussian() {
    resume_equals_uninterrupted(AdamMode::Sparse, TextureMode::Gaussian, "sparse-gaussian");
}

fn small_checkpoint() -> Vec<u8> {
    let (mut tr, views) = setup(AdamMode::Dense, TextureMode::Full);
    tr.step(&views).unwrap();
    tr.checkpoint_bytes()
}

fn fnv1a(data: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &b in data {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Byte offset of the learning-rate multipliers in a checkpoint of version ≥ 2 (after magic,
/// version, length, iterations, SH degree, background, seed, extent, three regulariser settings,
/// three mode bytes and `relocate_every`).
const LR_SCALES_AT: usize = 8 + 4 + 8 + 8 + 4 + 12 + 8 + 4 + 12 + 3 + 8;

/// Byte offset of the clamp-gradient byte (version ≥ 3), right after the multipliers.
const CLAMP_AT: usize = LR_SCALES_AT + 16;

/// Byte offset of the geometry regularisers (version ≥ 5: four f32), right after the clamp byte.
const GEOMETRY_AT: usize = CLAMP_AT + 1;

/// Byte offset of the error-growth share (version ≥ 6: one f32), right after the geometry
/// regularisers.
const ERROR_GROWTH_AT: usize = GEOMETRY_AT + 16;

/// A current checkpoint as format version 5 wrote it (without the error-growth share; version
/// not changed, not resealed).
fn as_version_5(mut bytes: Vec<u8>) -> Vec<u8> {
    bytes.drain(ERROR_GROWTH_AT..ERROR_GROWTH_AT + 4);
    bytes
}

/// A current checkpoint as format version 4 wrote it (without the error-growth share and the
/// geometry regularisers; version not changed, not resealed).
fn as_version_4(bytes: Vec<u8>) -> Vec<u8> {
    let mut bytes = as_version_5(bytes);
    bytes.drain(GEOMETRY_AT..GEOMETRY_AT + 16);
    bytes
}

/// A checkpoint without its run-record section (the trailing length and JSON before the
/// checksum); not resealed.
fn strip_record(mut bytes: Vec<u8>) -> Vec<u8> {
    let len = bytes.len();
    let body_end = len - 8;
    // The record is the JSON object that ends just before the checksum; its length precedes it.
    let record_start = (0..body_end - 8)
        .rev()
        .find(|&at| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize == body_end - at - 8)
        .expect("a run record section");
    bytes.drain(record_start..body_end);
    bytes
}

/// Bytes of the version-4 growth and time-budget section of a checkpoint without a time plan
/// (growth cap u64, learning rate by run length u8, plan flag u8), just before the run record.
const GROWTH_SECTION: usize = 10;

/// `bytes`, already without its run record ([`strip_record`]), without the growth section (not
/// resealed).
fn without_growth_section(mut bytes: Vec<u8>) -> Vec<u8> {
    let len = bytes.len();
    assert_eq!(
        bytes[len - 8 - 1],
        0,
        "no time plan: the section is {GROWTH_SECTION} bytes"
    );
    bytes.drain(len - 8 - GROWTH_SECTION..len - 8);
    bytes
}

/// A current checkpoint as format version 3 ended (without the run record and the growth and
/// time-budget section; version not changed, not resealed).
fn as_version_3(bytes: Vec<u8>) -> Vec<u8> {
    without_growth_section(strip_record(as_version_4(bytes)))
}

/// `bytes` with the header's length and the checksum recomputed.
fn resealed(mut bytes: Vec<u8>) -> Vec<u8> {
    let len = bytes.len();
    bytes[12..20].copy_from_slice(&(len as u64).to_le_bytes());
    let sum = fnv1a(&bytes[..len - 8]);
    bytes[len - 8..].copy_from_slice(&sum.to_le_bytes());
    bytes
}

#[test]
fn version_1_checkpoints_load_with_the_reference_learning_rates() {
    let (mut tr, views) = setup(AdamMode::Dense, TextureMode::Full);
    tr.step(&views).unwrap();
    let v3 = tr.checkpoint_bytes();
    let stored: Vec<f32> = v3[LR_SCALES_AT..LR_SCALES_AT + 16]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(
        stored,
        [1.5, 0.75, 1.25, 2.0],
        "the multipliers sit where this test expects"
    );
    assert_eq!(
        v3[CLAMP_AT], 1,
        "the clamp gradient (pass-through) sits where this test expects"
    );
    // The same state as version 1 wrote it: no multipliers, no clamp gradient.
    let mut v1 = as_version_3(v3.clone());
    v1.drain(LR_SCALES_AT..CLAMP_AT + 1);
    v1[8..12].copy_from_slice(&OLDEST_VERSION.to_le_bytes());
    let v1 = resealed(v1);
    let path = PathBuf::from("old.ckpt");
    let old = Trainer::from_checkpoint_bytes(&v1, &path).unwrap();
    assert_eq!(old.config().lr_scales, LearningRateScales::REFERENCE);
    assert_eq!(
        *old.config(),
        TrainConfig {
            lr_scales: LearningRateScales::REFERENCE,
            clamp_gradient: ClampGradient::Exact,
            ..*tr.config()
        }
    );
    assert_eq!(old.step_index(), tr.step_index());
    // Everything else is the same state: written again with the original multipliers and clamp
    // gradient, it is the version-3 file byte for byte.
    let mut again = old.checkpoint_bytes();
    for (k, x) in [1.5f32, 0.75, 1.25, 2.0].iter().enumerate() {
        again[LR_SCALES_AT + 4 * k..LR_SCALES_AT + 4 * k + 4].copy_from_slice(&x.to_le_bytes());
    }
    assert_eq!(again[CLAMP_AT], 0, "read as exact");
    again[CLAMP_AT] = 1;
    assert_eq!(resealed(again), v3);
    // A negative or NaN multiplier is refused.
    for bad_value in [-1.0f32, f32::NAN] {
        let mut bad = v3.clone();
        bad[LR_SCALES_AT + 4..LR_SCALES_AT + 8].copy_from_slice(&bad_value.to_le_bytes());
        let err = Trainer::from_checkpoint_bytes(&resealed(bad), &path)
            .err()
            .expect("must fail");
        assert!(
            matches!(&err, CheckpointError::Inconsistent { what, .. } if what.contains("learning-rate")),
            "{err}"
        );
    }
}

/// Version 2 (multipliers, no clamp gradient) loads with the exact clamp gradient; version 3
/// keeps either setting; an unknown clamp-gradient byte is refused by name.
#[test]
fn the_clamp_gradient_is_checkpointed_and_version_2_reads_as_exact() {
    let (mut tr, views) = setup(AdamMode::Dense, TextureMode::Full);
    tr.step(&views).unwrap();
    let v3 = tr.checkpoint_bytes();
    let path = PathBuf::from("c.ckpt");
    let back = Trainer::from_checkpoint_bytes(&v3, &path).unwrap();
    assert_eq!(back.config().clamp_gradient, ClampGradient::PassThrough);
    assert_eq!(*back.config(), *tr.config());

    let mut v2 = as_version_3(v3.clone());
    v2.remove(CLAMP_AT);
    v2[8..12].copy_from_slice(&2u32.to_le_bytes());
    let old = Trainer::from_checkpoint_bytes(&resealed(v2), &path).unwrap();
    assert_eq!(
        *old.config(),
        TrainConfig {
            clamp_gradient: ClampGradient::Exact,
            ..*tr.config()
        }
    );
    let mut again = old.checkpoint_bytes();
    again[CLAMP_AT] = 1;
    assert_eq!(resealed(again), v3, "nothing else changed");

    let mut bad = v3.clone();
    bad[CLAMP_AT] = 7;
    let err = Trainer::from_checkpoint_bytes(&resealed(bad), &path)
        .err()
        .expect("must fail");
    assert!(
        matches!(&err, CheckpointError::Inconsistent { what, .. } if what.contains("clamp gradient")),
        "{err}"
    );
}

#[test]
fn truncated_files_are_reported_as_truncated() {
    let bytes = small_checkpoint();
    let path = PathBuf::from("some/dir/run.ckpt");
    let mut cut = 0;
    while cut < bytes.len() {
        let err = Trainer::from_checkpoint_bytes(&bytes[..cut], &path)
            .err()
            .expect("must fail");
        match &err {
            CheckpointError::BadMagic { .. } => assert!(cut < 8, "cut {cut}: {err}"),
            CheckpointError::Truncated { found, .. } => assert_eq!(*found, cut as u64),
            other => panic!("cut at {cut}: unexpected {other}"),
        }
        assert!(err.to_string().contains("some/dir/run.ckpt"), "{err}");
        cut = if cut < 64 { cut + 1 } else { cut * 5 / 4 };
    }
    let err = Trainer::from_checkpoint_bytes(&bytes[..bytes.len() - 1], &path)
        .err()
        .unwrap();
    assert!(matches!(err, CheckpointError::Truncated { .. }), "{err}");
}

#[test]
fn corrupted_files_give_typed_errors() {
    let bytes = small_checkpoint();
    let path = PathBuf::from("run.ckpt");
    let load = |b: &[u8]| Trainer::from_checkpoint_bytes(b, &path).err().expect("must fail");

    let mut bad = bytes.clone();
    bad[0] = b'X';
    assert!(matches!(load(&bad), CheckpointError::BadMagic { .. }));

    let mut bad = bytes.clone();
    bad[8..12].copy_from_slice(&(VERSION + 1).to_le_bytes());
    let err = load(&bad);
    assert!(
        matches!(err, CheckpointError::UnsupportedVersion { found, .. } if found == VERSION + 1),
        "{err}"
    );

    // A flipped bit anywhere in the body is caught by the checksum.
    for at in [25, bytes.len() / 3, bytes.len() / 2, bytes.len() - 9] {
        let mut bad = bytes.clone();
        bad[at] ^= 0x10;
        let err = load(&bad);
        assert!(matches!(err, CheckpointError::Checksum { .. }), "byte {at}: {err}");
    }

    // Extra bytes after the stated length.
    let mut bad = bytes.clone();
    bad.push(0);
    assert!(matches!(load(&bad), CheckpointError::Inconsistent { .. }));

    // Consistent checksum but inconsistent content: texture mode Gaussian without opacity
    // logits. The texture-mode byte sits after magic, version, length and 56 bytes of config.
    let mut bad = bytes.clone();
    let at = 8 + 4 + 8 + 8 + 4 + 12 + 8 + 4 + 12 + 1;
    assert_eq!(bad[at], 0, "texture-mode byte");
    bad[at] = 1;
    let n = bad.len();
    let sum = fnv1a(&bad[..n - 8]);
    bad[n - 8..].copy_from_slice(&sum.to_le_bytes());
    let err = load(&bad);
    assert!(matches!(err, CheckpointError::Inconsistent { .. }), "{err}");
    assert!(err.to_string().contains("opacity"), "{err}");

    // A huge billboard count with a valid checksum does not allocate or panic.
    let mut bad = bytes.clone();
    let order_len_at = ERROR_GROWTH_AT + 4 + 8 + 32;
    let k = u64::from_le_bytes(bad[order_len_at..order_len_at + 8].try_into().unwrap()) as usize;
    let n_at = order_len_at + 8 + 8 * k;
    bad[n_at..n_at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    let sum = fnv1a(&bad[..n - 8]);
    bad[n - 8..].copy_from_slice(&sum.to_le_bytes());
    assert!(matches!(load(&bad), CheckpointError::Inconsistent { .. }));

    assert_eq!(&bytes[..8], &MAGIC);
}

#[test]
fn missing_file_and_unwritable_folder_are_io_errors() {
    let dir = temp_dir("io");
    let missing = dir.join("nope.ckpt");
    let err = Trainer::load_checkpoint(&missing).err().unwrap();
    assert!(matches!(err, CheckpointError::Io { .. }));
    assert!(err.to_string().contains("nope.ckpt"), "{err}");
    let (tr, _) = setup(AdamMode::Sparse, TextureMode::Full);
    let err = tr
        .save_checkpoint(dir.join("no-such-folder").join("x.ckpt"))
        .unwrap_err();
    assert!(matches!(err, CheckpointError::Io { .. }), "{err}");
    // Saving over an existing checkpoint replaces it and leaves only it.
    tr.save_checkpoint(dir.join("a.ckpt")).unwrap();
    tr.save_checkpoint(dir.join("a.ckpt")).unwrap();
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn streamed_file_equals_the_in_memory_checkpoint() {
    let dir = temp_dir("stream");
    for (adam, mode) in [
        (AdamMode::Sparse, TextureMode::Full),
        (AdamMode::Dense, TextureMode::Gaussian),
    ] {
        let (mut tr, views) = setup(adam, mode);
        for _ in 0..3 {
            tr.step(&views).unwrap();
        }
        let path = dir.join("s.ckpt");
        tr.save_checkpoint(&path).unwrap();
        let on_disk = std::fs::read(&path).unwrap();
        assert!(
            on_disk == tr.checkpoint_bytes(),
            "{adam:?} {mode:?}: streamed bytes differ"
        );
        let back = Trainer::load_checkpoint(&path).unwrap();
        assert!(back.checkpoint_bytes() == on_disk, "{adam:?} {mode:?}: round trip");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_views_are_typed_errors_and_leave_the_trainer_unchanged() {
    let (mut tr, mut views) = setup(AdamMode::Dense, TextureMode::Full);
    let before = tr.checkpoint_bytes();
    assert_eq!(tr.step(&[]).unwrap_err(), TrainError::NoViews);
    let whole = views[2].rgb.clone();
    let mut short = whole.to_f32().unwrap().into_owned();
    short.pop();
    views[2].rgb = short.into();
    let err = tr.step(&views).unwrap_err();
    assert!(matches!(err, TrainError::ImageSize { view: 2, .. }), "{err}");
    assert!(tr.checkpoint_bytes() == before, "a refused step changes nothing");
    views[2].rgb = whole;
    tr.step(&views).unwrap();
    // The stack now holds views 0..5 minus one; dropping views leaves stale indices.
    let err = tr.step(&views[..1]).unwrap_err();
    assert!(matches!(err, TrainError::ViewSetChanged { .. }), "{err}");
}

/// Version 4 stores the run record (arguments and dataset fingerprint) and reads it back; a
/// version-3 file (no record) reads with an empty one; a record that is not valid JSON is refused
/// by name.
#[test]
fn the_run_record_is_checkpointed_and_version_3_reads_as_empty() {
    use bbsplat::train::run_record::{DatasetFingerprint, RunRecord};
    let (mut tr, views) = setup(AdamMode::Dense, TextureMode::Full);
    tr.step(&views).unwrap();
    let record = RunRecord {
        arguments: [("--seed".to_string(), "8".to_string())].into(),
        dataset: Some(DatasetFingerprint::of_views(views.iter().map(|v| ("v", &v.camera)))),
    };
    tr.set_run_record(record.clone());
    let v4 = tr.checkpoint_bytes();
    assert_eq!(u32::from_le_bytes(v4[8..12].try_into().unwrap()), VERSION);
    let path = PathBuf::from("r.ckpt");
    let back = Trainer::from_checkpoint_bytes(&v4, &path).unwrap();
    assert_eq!(back.run_record(), &record);
    assert!(back.checkpoint_bytes() == v4);

    let mut v3 = as_version_3(v4.clone());
    v3[8..12].copy_from_slice(&3u32.to_le_bytes());
    let old = Trainer::from_checkpoint_bytes(&resealed(v3), &path).unwrap();
    assert!(old.run_record().is_empty());
    assert_eq!(old.step_index(), tr.step_index());

    let mut bad = v4.clone();
    let brace = bad.len() - 9; // the record's closing brace, just before the checksum
    assert_eq!(bad[brace], b'}');
    bad[brace] = b'!';
    let err = Trainer::from_checkpoint_bytes(&resealed(bad), &path)
        .err()
        .expect("must fail");
    assert!(
        matches!(&err, CheckpointError::Inconsistent { what, .. } if what.contains("run record")),
        "{err}"
    );
}

/// Version 3 (no growth and time-budget section) loads as no growth and no budget; version 4
/// keeps both, and a negative budget is refused by name.
#[test]
fn version_3_reads_as_no_growth_and_the_growth_section_round_trips() {
    let (mut tr, views) = setup(AdamMode::Dense, TextureMode::Full);
    tr.step(&views).unwrap();
    let current = tr.checkpoint_bytes();
    let mut v3 = as_version_3(current.clone());
    v3[8..12].copy_from_slice(&3u32.to_le_bytes());
    let path = PathBuf::from("v3.ckpt");
    let old = Trainer::from_checkpoint_bytes(&resealed(v3), &path).unwrap();
    assert_eq!(
        (old.config().growth_cap, old.config().lr_by_run_length, old.time_plan()),
        (0, false, None)
    );
    assert_eq!(
        resealed(old.checkpoint_bytes()),
        current,
        "the same state, written as version 4"
    );
    // A cap and a plan survive the round trip.
    let mut with = Trainer::from_checkpoint_bytes(&current, &path).unwrap();
    assert!(!with.config().lr_by_run_length);
    let mut plan = bbsplat::train::time_budget::TimePlan::new(2.5);
    plan.record(0, true, 0.25);
    plan.record(1, false, 0.5);
    with.set_time_plan(Some(plan));
    let bytes = with.checkpoint_bytes();
    let back = Trainer::from_checkpoint_bytes(&bytes, &path).unwrap();
    assert_eq!(back.time_plan(), Some(&plan));
    assert_eq!(back.checkpoint_bytes(), bytes);
    // The budget is the first of the plan's 9 fields of 8 bytes before the run record.
    let record_section = bytes.len() - strip_record(bytes.clone()).len();
    let at = bytes.len() - 8 - record_section - 8 * 9;
    let mut bad = bytes.clone();
    bad[at..at + 8].copy_from_slice(&(-1.0f64).to_le_bytes());
    let err = Trainer::from_checkpoint_bytes(&resealed(bad), &path)
        .err()
        .expect("must fail");
    assert!(
        matches!(&err, CheckpointError::Inconsistent { what, .. } if what.contains("time plan")),
        "{err}"
    );
}

/// Version 5 stores the geometry regularisers (weights and start fractions) and reads them
/// back; a version-4 file reads with them off; out-of-range values are refused by name.
#[test]
fn the_geometry_regularisers_are_checkpointed_and_version_4_reads_as_off() {
    use bbsplat::train::geometry::GeometryRegularisers;
    let (mut tr, views) = setup(AdamMode::Dense, TextureMode::Full);
    tr.step(&views).unwrap();
    let plain = tr.checkpoint_bytes();
    let geometry = GeometryRegularisers {
        lambda_normal: 0.05,
        lambda_distortion: 100.0,
        normal_from: 0.25,
        distortion_from: 0.125,
    };
    let mut bytes = plain.clone();
    for (k, v) in [0.05f32, 100.0, 0.25, 0.125].into_iter().enumerate() {
        bytes[GEOMETRY_AT + 4 * k..GEOMETRY_AT + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    let bytes = resealed(bytes);
    let path = PathBuf::from("g.ckpt");
    let back = Trainer::from_checkpoint_bytes(&bytes, &path).unwrap();
    assert_eq!(back.config().geometry, geometry);
    assert!(back.checkpoint_bytes() == bytes);
    // Version 4: no geometry section, read as off.
    let mut v4 = as_version_4(bytes.clone());
    v4[8..12].copy_from_slice(&4u32.to_le_bytes());
    let old = Trainer::from_checkpoint_bytes(&resealed(v4), &path).unwrap();
    assert_eq!(old.config().geometry, GeometryRegularisers::default());
    assert!(old.checkpoint_bytes() == plain);
    // A negative weight is refused by name.
    let mut bad = bytes.clone();
    bad[GEOMETRY_AT..GEOMETRY_AT + 4].copy_from_slice(&(-1.0f32).to_le_bytes());
    let err = Trainer::from_checkpoint_bytes(&resealed(bad), &path)
        .err()
        .expect("must fail");
    assert!(
        matches!(&err, CheckpointError::Inconsistent { what, .. } if what.contains("lambda_normal")),
        "{err}"
    );
}

/// The error-growth share is checkpointed; version 5 (without it) reads as 0 (growth by copies
/// alone); a share outside `[0, 1]` is refused by name.
#[test]
fn the_error_growth_share_is_checkpointed_and_version_5_reads_as_zero() {
    let (mut tr, views) = setup(AdamMode::Dense, TextureMode::Full);
    tr.step(&views).unwrap();
    let plain = tr.checkpoint_bytes();
    assert_eq!(tr.config().error_growth, 0.0);
    let mut bytes = plain.clone();
    bytes[ERROR_GROWTH_AT..ERROR_GROWTH_AT + 4].copy_from_slice(&0.25f32.to_le_bytes());
    let bytes = resealed(bytes);
    let path = PathBuf::from("e.ckpt");
    let back = Trainer::from_checkpoint_bytes(&bytes, &path).unwrap();
    assert_eq!(back.config().error_growth, 0.25);
    assert!(back.checkpoint_bytes() == bytes);
    let mut v5 = as_version_5(bytes.clone());
    v5[8..12].copy_from_slice(&5u32.to_le_bytes());
    let old = Trainer::from_checkpoint_bytes(&resealed(v5), &path).unwrap();
    assert_eq!(old.config().error_growth, 0.0);
    assert!(old.checkpoint_bytes() == plain);
    let mut bad = bytes.clone();
    bad[ERROR_GROWTH_AT..ERROR_GROWTH_AT + 4].copy_from_slice(&1.5f32.to_le_bytes());
    let err = Trainer::from_checkpoint_bytes(&resealed(bad), &path)
        .err()
        .expect("must fail");
    assert!(
        matches!(&err, CheckpointError::Inconsistent { what, .. } if what.contains("error growth")),
        "{err}"
    );
}
