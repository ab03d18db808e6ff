//! Model folders: round trip, fixed point, corrupt files, atomic replacement, sizes.
//!
//! Run with `--nocapture` to see the bytes-per-billboard report.

use bbsplat::model::RawBillboards;
use bbsplat::model::{alpha_asset, sigmoid};
use bbsplat::model_file::{
    ALPHA_FILE, COLOUR_FILE, META_FILE, ModelFileError, ModelMeta, PLY_FILE, decode_alpha, decode_colour, encode_alpha,
    encode_colour, load_model, save_model,
};
use bbsplat::rng::Rng;
use bbsplat::testing_internals::model_file::stable_logit;
use glam::{Vec2, Vec3};
use std::fs;
use std::path::{Path, PathBuf};

const FILES: [&str; 4] = [PLY_FILE, COLOUR_FILE, ALPHA_FILE, META_FILE];

/// A fresh temporary folder for one test (removed by the test on success).
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bbsplat-model-file-{}-{name}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    fs::create_dir_all(&dir).unwrap();
    dir
}

fn fresh_model(n: usize, ts: usize, seed: u64) -> RawBillboards {
    let mut rng = Rng::new(seed);
    let pts: Vec<Vec3> = (0..n)
        .map(|_| Vec3::new(rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0)))
        .collect();
    let colours: Vec<[f32; 3]> = (0..n).map(|_| [rng.uniform(), rng.uniform(), rng.uniform()]).collect();
    RawBillboards::from_points(&pts, &colours, ts, seed)
}

/// A model with every parameter random ("trained-like": no structure for deflate to exploit
/// beyond the 8-bit quantisation), including saturated logits.
fn random_model(n: usize, ts: usize, seed: u64) -> RawBillboards {
    let mut m = fresh_model(n, ts, seed);
    let mut rng = Rng::new(seed ^ 0x5eed);
    for q in &mut m.quaternions {
        *q = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
    }
    for s in &mut m.log_scales {
        *s = Vec2::new(rng.range(-6.0, 0.0), rng.range(-6.0, 0.0));
    }
    for v in &mut m.sh {
        *v = rng.normal() * 0.5;
    }
    for l in m.alpha_logits.iter_mut().chain(m.colour_logits.iter_mut()) {
        *l = match rng.below(50) {
            0 => 30.0,
            1 => -30.0,
            _ => rng.normal() * 3.0,
        };
    }
    m
}

fn folder_bytes(dir: &Path) -> Vec<Vec<u8>> {
    FILES.iter().map(|f| fs::read(dir.join(f)).unwrap()).collect()
}

fn assert_only(dir: &Path, names: &[&str]) {
    let mut found: Vec<String> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    found.sort();
    let mut want: Vec<String> = names.iter().map(|s| s.to_string()).collect();
    want.sort();
    assert_eq!(found, want, "contents of {}", dir.display());
}

fn check_round_trip(m: &RawBillboards, what: &str, dir: &Path) {
    let meta = ModelMeta::for_model(m, 3, [0.25, 0.5, 1.0]);
    let path = dir.join("model");
    let bytes = save_model(&path, m, &meta).unwrap();
    let on_disk: u64 = FILES.iter().map(|f| fs::metadata(path.join(f)).unwrap().len()).sum();
    assert_eq!(bytes, on_disk, "{what}: returned size");
    let (l, meta2) = load_model(&path).unwrap();
    assert_eq!(meta2, meta, "{what}");
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(l.len(), m.len());
    for i in 0..m.len() {
        assert_eq!(
            bits(&l.positions[i].to_array()),
            bits(&m.positions[i].to_array()),
            "{what}: position {i}"
        );
        assert_eq!(
            bits(&l.quaternions[i]),
            bits(&m.quaternions[i]),
            "{what}: quaternion {i}"
        );
        assert_eq!(
            bits(&l.log_scales[i].to_array()),
            bits(&m.log_scales[i].to_array()),
            "{what}: scale {i}"
        );
    }
    assert_eq!(bits(&l.sh), bits(&m.sh), "{what}: SH");
    assert_eq!(l.alpha_mask, m.alpha_mask);
    assert_eq!(l.texture_size, m.texture_size);
    let (a, b) = (m.activate(), l.activate());
    let worst = |x: &[f32], y: &[f32]| x.iter().zip(y).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
    let channel = |x: &[[f32; 4]], c: std::ops::Range<usize>| -> Vec<f32> {
        x.iter().flat_map(|t| t[c.clone()].to_vec()).collect()
    };
    let (wa, wc) = (
        worst(&channel(&a.textures, 3..4), &channel(&b.textures, 3..4)),
        worst(&channel(&a.textures, 0..3), &channel(&b.textures, 0..3)),
    );
    // Half a quantisation step (2/255 alpha, 1/255 colour), plus f32 rounding.
    assert!(wa <= 1.0 / 255.0 + 1e-6, "{what}: alpha error {wa}");
    assert!(wc <= 0.5 / 255.0 + 1e-6, "{what}: colour error {wc}");
    let t = m.texture_size * m.texture_size;
    for (k, v) in b.textures.iter().map(|t| t[3]).enumerate() {
        if !m.alpha_mask[k % t] {
            assert_eq!(v, 0.0, "{what}: masked texel {k}");
        }
    }
    // Loaded logits are finite and moderate except at exact-tie saturation.
    assert!(
        l.alpha_logits
            .iter()
            .chain(&l.colour_logits)
            .all(|x| x.is_finite() && x.abs() <= 104.0)
    );
    // Fixed point: saving the loaded model reproduces every byte.
    let first = folder_bytes(&path);
    let path2 = dir.join("again");
    save_model(&path2, &l, &meta2).unwrap();
    assert!(
        folder_bytes(&path2) == first,
        "{what}: save(load(save(m))) differs from save(m)"
    );
    let (l2, _) = load_model(&path2).unwrap();
    assert_eq!(bits(&l2.alpha_logits), bits(&l.alpha_logits), "{what}: second load");
    assert_eq!(bits(&l2.colour_logits), bits(&l.colour_logits), "{what}: second load");
    fs::remove_dir_all(&path).unwrap();
    fs::remove_dir_all(&path2).unwrap();
}

#[test]
fn round_trip_is_exact_for_geometry_and_within_quantisation_for_textures() {
    let dir = scratch("round-trip");
    for seed in 0..3u64 {
        check_round_trip(&fresh_model(300, 16, seed), &format!("fresh, seed {seed}"), &dir);
        check_round_trip(&random_model(300, 16, seed), &format!("random, seed {seed}"), &dir);
    }
    for ts in [2usize, 5, 8, 24] {
        check_round_trip(&random_model(40, ts, 7), &format!("random, TS {ts}"), &dir);
    }
    check_round_trip(&fresh_model(0, 16, 0), "empty", &dir);
    check_round_trip(&fresh_model(1, 16, 0), "one billboard", &dir);
    assert_only(&dir, &[]);
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn replacing_is_atomic_and_leaves_no_temporary_folder() {
    let dir = scratch("replace");
    let path = dir.join("model");
    let (m1, m2) = (fresh_model(50, 16, 1), random_model(80, 16, 2));
    save_model(&path, &m1, &ModelMeta::for_model(&m1, 3, [0.0; 3])).unwrap();
    save_model(&path, &m2, &ModelMeta::for_model(&m2, 2, [1.0; 3])).unwrap();
    assert_only(&dir, &["model"]);
    assert_only(&path, &FILES);
    let (l, meta) = load_model(&path).unwrap();
    assert_eq!((l.len(), meta.sh_degree), (80, 2));

    // An invalid model writes nothing and keeps the old one.
    let mut broken = m1.clone();
    broken.sh.pop();
    let err = save_model(&path, &broken, &ModelMeta::for_model(&m1, 3, [0.0; 3])).unwrap_err();
    assert!(matches!(err, ModelFileError::InvalidModel { .. }), "{err}");
    assert!(err.to_string().contains("sh has"), "{err}");
    let mut bad_mask = m1.clone();
    bad_mask.alpha_mask[100] = false;
    let err = save_model(&path, &bad_mask, &ModelMeta::for_model(&m1, 3, [0.0; 3])).unwrap_err();
    assert!(matches!(err, ModelFileError::InvalidModel { .. }), "{err}");
    let err = save_model(&path, &m1, &ModelMeta::for_model(&m2, 3, [0.0; 3])).unwrap_err();
    assert!(matches!(err, ModelFileError::InvalidModel { .. }), "{err}");
    assert_eq!(load_model(&path).unwrap().0.len(), 80);
    assert_only(&dir, &["model"]);

    // A folder that is not a model is never replaced; an empty one is used.
    let other = dir.join("photos");
    fs::create_dir(&other).unwrap();
    fs::write(other.join("keep.txt"), b"precious").unwrap();
    let err = save_model(&other, &m1, &ModelMeta::for_model(&m1, 3, [0.0; 3])).unwrap_err();
    assert!(matches!(err, ModelFileError::NotAModelFolder { .. }), "{err}");
    assert_eq!(fs::read(other.join("keep.txt")).unwrap(), b"precious");
    let file = dir.join("a-file");
    fs::write(&file, b"x").unwrap();
    assert!(matches!(
        save_model(&file, &m1, &ModelMeta::for_model(&m1, 3, [0.0; 3])),
        Err(ModelFileError::NotAModelFolder { .. })
    ));
    let empty = dir.join("empty");
    fs::create_dir(&empty).unwrap();
    save_model(&empty, &m1, &ModelMeta::for_model(&m1, 3, [0.0; 3])).unwrap();
    // Nested destinations are created.
    save_model(&dir.join("a/b/c"), &m1, &ModelMeta::for_model(&m1, 3, [0.0; 3])).unwrap();
    assert_only(&dir, &["model", "photos", "a-file", "empty", "a"]);
    assert_only(&dir.join("a/b"), &["c"]);
    fs::remove_dir_all(&dir).unwrap();
}

/// Writes a valid model to `dir/name`, applies `edit` to `file` inside, and loads it.
fn load_edited(
    dir: &Path,
    name: &str,
    file: &str,
    edit: impl FnOnce(&mut Vec<u8>),
) -> Result<RawBillboards, ModelFileError> {
    let m = fresh_model(20, 16, 3);
    let path = dir.join(name);
    save_model(&path, &m, &ModelMeta::for_model(&m, 3, [0.0; 3])).unwrap();
    let mut bytes = fs::read(path.join(file)).unwrap();
    edit(&mut bytes);
    fs::write(path.join(file), bytes).unwrap();
    let r = load_model(&path).map(|(m, _)| m);
    fs::remove_dir_all(&path).unwrap();
    r
}

fn replace(bytes: &mut Vec<u8>, from: &str, to: &str) {
    let text = String::from_utf8_lossy(bytes).into_owned();
    assert!(text.contains(from), "{from:?} not found");
    *bytes = text.replacen(from, to, 1).into_bytes();
}

#[test]
fn every_bad_file_gives_the_right_typed_error() {
    let dir = scratch("errors");
    let m = fresh_model(20, 16, 3);
    let path = dir.join("m");
    for file in FILES {
        save_model(&path, &m, &ModelMeta::for_model(&m, 3, [0.0; 3])).unwrap();
        fs::remove_file(path.join(file)).unwrap();
        match load_model(&path) {
            Err(ModelFileError::MissingFile { path: p }) => assert!(p.ends_with(file)),
            other => panic!("missing {file}: {other:?}"),
        }
    }
    // Wrong PLY fields: an opacity field (3DGS), a missing field, a double.
    let ply_header_edit = |from: &'static str, to: &'static str| {
        move |b: &mut Vec<u8>| {
            let end = b.windows(10).position(|w| w == b"end_header").unwrap();
            let mut head = b[..end].to_vec();
            replace(&mut head, from, to);
            head.extend_from_slice(&b[end..]);
            *b = head;
        }
    };
    type Edit = Box<dyn FnOnce(&mut Vec<u8>)>;
    let cases: Vec<(&str, Edit, &str)> = vec![
        (
            "opacity",
            Box::new(ply_header_edit(
                "property float scale_0",
                "property float opacity\nproperty float scale_0",
            )),
            "opacity",
        ),
        (
            "renamed",
            Box::new(ply_header_edit("property float rot_3\n", "property float rot_x\n")),
            "rot_x",
        ),
        (
            "double",
            Box::new(ply_header_edit("property float x\n", "property double x\n")),
            "double",
        ),
        (
            "ascii",
            Box::new(ply_header_edit("binary_little_endian", "ascii")),
            "ascii",
        ),
        (
            "big-endian",
            Box::new(ply_header_edit("binary_little_endian", "binary_big_endian")),
            "big",
        ),
        (
            "count",
            Box::new(ply_header_edit("element vertex 20", "element vertex 21")),
            "vertex data",
        ),
        (
            "face",
            Box::new(ply_header_edit(
                "property float rot_3\n",
                "property float rot_3\nelement face 0\nproperty list uchar int vertex_indices\n",
            )),
            "face",
        ),
        ("not-ply", Box::new(|b: &mut Vec<u8>| b[0] = b'P'), "ply"),
    ];
    for (name, edit, needle) in cases {
        match load_edited(&dir, name, PLY_FILE, edit) {
            Err(e @ ModelFileError::Ply { .. }) => {
                let msg = e.to_string();
                assert!(msg.contains(PLY_FILE) && msg.contains(needle), "{name}: {msg}");
            }
            other => panic!("{name}: {other:?}"),
        }
    }
    // Metadata: version, format, count, texture size, garbage.
    match load_edited(&dir, "version", META_FILE, |b| {
        replace(b, "\"version\": 1", "\"version\": 2")
    }) {
        Err(ModelFileError::Version { version: 2, path, .. }) => assert!(path.ends_with(META_FILE)),
        other => panic!("version: {other:?}"),
    }
    match load_edited(&dir, "format", META_FILE, |b| replace(b, "bbsplat-model", "other")) {
        Err(ModelFileError::Version { .. }) => {}
        other => panic!("format: {other:?}"),
    }
    match load_edited(&dir, "count", META_FILE, |b| {
        replace(b, "\"billboards\": 20", "\"billboards\": 19")
    }) {
        Err(ModelFileError::CountMismatch { found: 19, ply: 20, .. }) => {}
        other => panic!("count: {other:?}"),
    }
    match load_edited(&dir, "ts", META_FILE, |b| {
        replace(b, "\"texture_size\": 16", "\"texture_size\": 8")
    }) {
        Err(ModelFileError::Shape {
            found, expected, path, ..
        }) => {
            assert!(path.ends_with(COLOUR_FILE));
            assert_eq!((found, expected), (vec![20, 3, 16, 16], vec![20, 3, 8, 8]));
        }
        other => panic!("texture size: {other:?}"),
    }
    match load_edited(&dir, "sh", META_FILE, |b| {
        replace(b, "\"sh_degree\": 3", "\"sh_degree\": 4")
    }) {
        Err(ModelFileError::Meta { reason, .. }) => assert!(reason.contains("sh_degree"), "{reason}"),
        other => panic!("sh degree: {other:?}"),
    }
    match load_edited(&dir, "json", META_FILE, |b| b.truncate(b.len() / 2)) {
        Err(ModelFileError::Meta { .. }) => {}
        other => panic!("truncated json: {other:?}"),
    }
    // Textures of another model (count mismatch between the PLY and the arrays).
    let other = fresh_model(21, 16, 4);
    let other_path = dir.join("other");
    save_model(&other_path, &other, &ModelMeta::for_model(&other, 3, [0.0; 3])).unwrap();
    let alpha21 = fs::read(other_path.join(ALPHA_FILE)).unwrap();
    match load_edited(&dir, "alpha21", ALPHA_FILE, |b| *b = alpha21) {
        Err(ModelFileError::Shape {
            found, expected, array, ..
        }) => {
            assert_eq!(array, "texture_alpha.npy");
            assert_eq!((found, expected), (vec![21, 16, 16], vec![20, 16, 16]));
        }
        other => panic!("alpha of 21: {other:?}"),
    }
    // The colour archive in place of the alpha one: the array is not there.
    let colour = fs::read(other_path.join(COLOUR_FILE)).unwrap();
    match load_edited(&dir, "swapped", ALPHA_FILE, |b| *b = colour) {
        Err(ModelFileError::Npz { reason, path }) => {
            assert!(
                path.ends_with(ALPHA_FILE) && reason.contains("texture_alpha.npy"),
                "{reason}"
            )
        }
        other => panic!("swapped: {other:?}"),
    }
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn truncated_and_flipped_files_never_panic() {
    let seed = 0xC0FFEE;
    let dir = scratch("fuzz");
    let m = random_model(12, 16, 5);
    let path = dir.join("m");
    save_model(&path, &m, &ModelMeta::for_model(&m, 3, [0.0; 3])).unwrap();
    let original = folder_bytes(&path);
    let mut rng = Rng::new(seed);
    for (f, file) in FILES.iter().enumerate() {
        let len = original[f].len();
        for trial in 0..60 {
            let mut bytes = original[f].clone();
            let truncate = trial % 2 == 0;
            if truncate {
                bytes.truncate(rng.below(len as u64) as usize);
            } else {
                for _ in 0..1 + rng.below(4) {
                    let k = rng.below(len as u64) as usize;
                    bytes[k] ^= 1 << rng.below(8);
                }
            }
            fs::write(path.join(file), &bytes).unwrap();
            let result = std::panic::catch_unwind(|| load_model(&path));
            let result = result.unwrap_or_else(|_| panic!("panic: {file}, trial {trial}, seed {seed:#x}"));
            match result {
                Err(e) => {
                    let named = match &e {
                        ModelFileError::Shape { path, .. }
                        | ModelFileError::Npz { path, .. }
                        | ModelFileError::Ply { path, .. } => path.ends_with(file),
                        ModelFileError::Meta { path, .. }
                        | ModelFileError::Version { path, .. }
                        | ModelFileError::CountMismatch { path, .. } => path.ends_with(META_FILE),
                        other => panic!("unexpected {other:?}"),
                    };
                    assert!(named, "{file}, trial {trial}, seed {seed:#x}: {e}");
                }
                Ok(_) => {
                    // Only whitespace at the end of the JSON may go, and a flip may land in data.
                    let harmless = !truncate || (*file == META_FILE && bytes.len() + 1 >= len);
                    assert!(
                        harmless,
                        "{file} truncated to {} of {len} bytes loaded (seed {seed:#x})",
                        bytes.len()
                    );
                }
            }
        }
        fs::write(path.join(file), &original[f]).unwrap();
    }
    load_model(&path).unwrap();
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn size_report() {
    let dir = scratch("size");
    let n = 2000;
    for (what, m) in [("fresh", fresh_model(n, 16, 9)), ("random", random_model(n, 16, 9))] {
        let path = dir.join(what);
        let total = save_model(&path, &m, &ModelMeta::for_model(&m, 3, [0.0; 3])).unwrap();
        let size = |f: &str| fs::metadata(path.join(f)).unwrap().len();
        let ply = size(PLY_FILE);
        assert_eq!(
            ply,
            (bbsplat::model_file::ply::header_len(n) + 240 * n) as u64,
            "PLY size"
        );
        let (colour, alpha) = (size(COLOUR_FILE), size(ALPHA_FILE));
        let raw = (4 * 256 * n) as f64;
        println!(
            "{what}: {:.1} B/billboard in total ({:.1} PLY, {:.1} colour, {:.1} alpha); textures deflate {:.1}x \
             ({:.0} of {:.0} raw bytes)",
            total as f64 / n as f64,
            ply as f64 / n as f64,
            colour as f64 / n as f64,
            alpha as f64 / n as f64,
            raw / (colour + alpha) as f64,
            (colour + alpha) as f64,
            raw
        );
        // A fresh model's textures are constant per texel: deflate removes nearly everything.
        if what == "fresh" {
            assert!(colour + alpha < (raw / 50.0) as u64);
        } else {
            assert!(colour + alpha > (raw / 2.0) as u64);
        }
    }
    fs::remove_dir_all(&dir).unwrap();
}

/// Failure 6: a model with a NaN or infinite parameter is never saved, and a model file holding
/// one (here a NaN written into the PLY) is refused on loading, naming the vertex and field.
#[test]
fn non_finite_values_are_never_saved_and_refused_on_loading() {
    let dir = scratch("non-finite");
    let mut m = fresh_model(5, 4, 1);
    m.colour_logits[3 * 16 * 2 + 7] = f32::NAN;
    let meta = ModelMeta::for_model(&m, 3, [0.0; 3]);
    let err = save_model(&dir.join("bad"), &m, &meta).unwrap_err();
    assert!(
        matches!(&err, ModelFileError::InvalidModel { reason, .. } if reason.contains("billboard 2") && reason.contains("colour")),
        "{err}"
    );
    assert!(!dir.join("bad").exists(), "nothing written");
    let good = fresh_model(5, 4, 1);
    save_model(&dir.join("good"), &good, &meta).unwrap();
    let ply = dir.join("good").join(PLY_FILE);
    let mut bytes = fs::read(&ply).unwrap();
    let header = bbsplat::model_file::ply::header_len(5);
    // Vertex 1, field 1 (y).
    let at = header + (bbsplat::model_file::ply::PLY_FLOATS + 1) * 4;
    bytes[at..at + 4].copy_from_slice(&f32::INFINITY.to_le_bytes());
    fs::write(&ply, bytes).unwrap();
    let err = load_model(&dir.join("good")).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("vertex 1") && text.contains("non-finite") && text.contains(" y"),
        "{text}"
    );
    fs::remove_dir_all(&dir).unwrap();
}

/// Failure 4: a texture side above what the loader reads (1024) is refused by `save_model`
/// before anything is written, instead of a model the loader then refuses.
#[test]
fn a_texture_larger_than_the_loader_reads_is_never_saved() {
    let dir = scratch("ts-1025");
    let m = fresh_model(1, bbsplat::model_file::MAX_TEXTURE_SIZE + 1, 2);
    let meta = ModelMeta::for_model(&m, 3, [0.0; 3]);
    let err = save_model(&dir.join("model"), &m, &meta).unwrap_err();
    assert!(
        matches!(&err, ModelFileError::InvalidModel { reason, .. } if reason.contains("1025")),
        "{err}"
    );
    assert!(!dir.join("model").exists());
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn quantisation_is_the_reference_one() {
    // Masked texels (G = 0, alpha 0) store 128 (127.5 rounds half to even).
    assert_eq!(encode_alpha(0.0, 0.0), 128);
    assert_eq!(encode_alpha(1.0, 0.0), 255);
    assert_eq!(encode_alpha(0.0, 1.0), 0);
    assert_eq!(encode_colour(0.5), 128);
    assert_eq!(encode_colour(0.1), 26);
    assert_eq!(decode_alpha(0, 0.5), 0.0);
    assert_eq!(decode_alpha(255, 0.5), 1.0);
    assert!((decode_alpha(128, 0.0) - 1.0 / 255.0).abs() < 1e-7);
}

#[test]
fn stable_logit_reencodes_every_byte() {
    for g in alpha_asset(16) {
        for q in 0..=255u8 {
            let a = decode_alpha(q, g);
            // Only bytes a real alpha in [0, 1] can produce need to be stable.
            let reachable = (0..=1000).any(|k| encode_alpha(k as f32 / 1000.0, g) == q);
            let l = stable_logit(a, q, |x| encode_alpha(x, g));
            if reachable {
                assert_eq!(encode_alpha(sigmoid(l), g), q, "g {g}, q {q}");
            }
        }
    }
    for q in 0..=255u8 {
        let l = stable_logit(decode_colour(q), q, encode_colour);
        assert_eq!(encode_colour(sigmoid(l)), q);
        assert!(l.abs() < 14.0);
    }
}
