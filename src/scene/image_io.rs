//! Image decoding (through the `image` crate), alpha compositing and area downscaling.
//!
//! Pixel values are the stored 8-bit values divided by 255: no sRGB decoding is applied, as in
//! 3DGS/BBSplat, and resampling (undistortion, downscaling) works on these values.

use super::Image;
use super::error::{Location, SceneError};
use std::path::Path;

/// A decoded image, its alpha channel (if it has one), the warning naming its damage (if
/// accepted damaged) and its EXIF orientation when that is not the normal one ([`exif_turn`]).
pub(crate) type Decoded = (Image, Option<Vec<u8>>, Option<String>, Option<&'static str>);

/// What an EXIF orientation other than the normal one asks a viewer to do, or `None` for the
/// normal one. The loader does not do it: structure from motion (COLMAP) registers the stored
/// pixels, so the poses and the camera's size are those of the image as stored.
pub fn exif_turn(orientation: image::metadata::Orientation) -> Option<&'static str> {
    use image::metadata::Orientation as O;
    match orientation {
        O::NoTransforms => None,
        O::Rotate90 => Some("turned 90° clockwise"),
        O::Rotate180 => Some("turned 180°"),
        O::Rotate270 => Some("turned 90° anticlockwise"),
        O::FlipHorizontal => Some("mirrored left to right"),
        O::FlipVertical => Some("mirrored top to bottom"),
        O::Rotate90FlipH => Some("turned 90° clockwise and mirrored"),
        O::Rotate270FlipH => Some("turned 90° anticlockwise and mirrored"),
    }
}

/// Decodes an image file into 8-bit RGB, compositing any alpha channel onto `background`
/// (values in `[0, 1]`): `c = c_rgb·a + background·(1 − a)`, rounded to 8 bits, and returns the
/// alpha channel (8 bits, row-major) of an image that has one. 16-bit images are reduced to 8
/// bits. The format is guessed from the file contents. A damaged image ([`jpeg_damage`]) is an
/// error unless `allow_damaged`, when it is decoded and the third value is the warning naming
/// it.
pub(crate) fn decode_with_alpha(
    image_path: &Path,
    referenced_by: &Path,
    location: &Location,
    background: [f32; 3],
    allow_damaged: bool,
) -> Result<Decoded, SceneError> {
    let bytes = crate::file_io::read_bounded(image_path, crate::file_io::IMAGE)?;
    let error = |message| SceneError::ImageDecode {
        image: image_path.to_path_buf(),
        file: referenced_by.to_path_buf(),
        location: location.clone(),
        message,
    };
    let damage = jpeg_damage(&bytes);
    if let Some(message) = &damage
        && !allow_damaged
    {
        return Err(error(format!(
            "{message} (refused: LoadOptions::allow_damaged_images, bbsplat's --allow-damaged-images, accepts it with a warning)"
        )));
    }
    let (image, alpha, orientation) = decode_oriented(&bytes, background).map_err(error)?;
    Ok((
        image,
        alpha,
        damage.map(|d| format!("{}: {d}", image_path.display())),
        exif_turn(orientation),
    ))
}

/// Why a JPEG stream is incomplete, or `None` when it is whole (or not a JPEG). A JPEG whose
/// file was cut short decodes without an error, its missing rows grey; such a stream has no end
/// marker (`FF D9`) after the start of its last scan (`FF DA`). Neither marker can occur inside
/// entropy-coded data (a `FF` data byte is followed by `00`), and an embedded thumbnail's end
/// marker lies before the main image's scans, so the test is exact for truncation.
pub(crate) fn jpeg_damage(bytes: &[u8]) -> Option<String> {
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return None;
    }
    let last = |marker: u8| bytes.windows(2).rposition(|w| w == [0xFF, marker]);
    match (last(0xDA), last(0xD9)) {
        (None, _) => Some("truncated JPEG: no image scan (start-of-scan marker)".into()),
        (Some(scan), end) if end.is_none_or(|e| e < scan) => Some(format!(
            "truncated JPEG: the file ends ({} bytes) inside its last scan, without an end-of-image marker; the missing part would be grey",
            bytes.len()
        )),
        _ => None,
    }
}

/// Decodes image bytes (PNG or JPEG), with the image's EXIF orientation (not applied); see
/// [`decode_with_alpha`].
fn decode_oriented(
    bytes: &[u8],
    background: [f32; 3],
) -> Result<(Image, Option<Vec<u8>>, image::metadata::Orientation), String> {
    use image::ImageDecoder;
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    let mut decoder = reader.into_decoder().map_err(|e| e.to_string())?;
    let orientation = decoder
        .orientation()
        .unwrap_or(image::metadata::Orientation::NoTransforms);
    let dynamic = image::DynamicImage::from_decoder(decoder).map_err(|e| e.to_string())?;
    let (width, height) = (dynamic.width(), dynamic.height());
    if width == 0 || height == 0 {
        return Err(format!("image has zero size {width}x{height}"));
    }
    if !dynamic.color().has_alpha() {
        return Ok((
            Image::from_raw(width, height, dynamic.into_rgb8().into_raw()),
            None,
            orientation,
        ));
    }
    let rgba = dynamic.into_rgba8();
    let bg = background.map(|b| b.clamp(0.0, 1.0) * 255.0);
    let mut data = Vec::with_capacity(width as usize * height as usize * 3);
    let mut alpha = Vec::with_capacity(width as usize * height as usize);
    for px in rgba.as_raw().chunks_exact(4) {
        let a = px[3] as f32 / 255.0;
        for c in 0..3 {
            let v = px[c] as f32 * a + bg[c] * (1.0 - a);
            data.push(v.round().clamp(0.0, 255.0) as u8);
        }
        alpha.push(px[3]);
    }
    Ok((Image::from_raw(width, height, data), Some(alpha), orientation))
}

/// Area-downscales an 8-bit single-channel map (an alpha channel) from `w × h` to `nw × nh`
/// with the same box filter as the images, rounding to 8 bits.
pub(crate) fn resize_area_u8(src: &[u8], w: usize, h: usize, nw: usize, nh: usize) -> Vec<u8> {
    if (w, h) == (nw, nh) {
        return src.to_vec();
    }
    let rgb: Vec<f32> = src.iter().flat_map(|&a| [a as f32; 3]).collect();
    resize_area(&rgb, w, h, nw, nh)
        .chunks_exact(3)
        .map(|px| px[0].round().clamp(0.0, 255.0) as u8)
        .collect()
}

/// Quantises interleaved RGB values in `[0, 1]` to 8 bits (rounding).
pub(crate) fn quantise(width: u32, height: u32, data: &[f32]) -> Image {
    let bytes = data
        .iter()
        .map(|v| (v * 255.0).round().clamp(0.0, 255.0) as u8)
        .collect();
    Image::from_raw(width, height, bytes)
}

/// Box-filter weights of a 1D area resampling from `n` to `m` samples: output sample `i`
/// covers the input interval `[i·n/m, (i+1)·n/m)` and averages the input samples over it,
/// weighted by their overlap. Returns, per output sample, the first input index and weights.
fn area_weights(n: usize, m: usize) -> Vec<(usize, Vec<f32>)> {
    let scale = n as f64 / m as f64;
    (0..m)
        .map(|i| {
            let a = i as f64 * scale;
            let b = (i + 1) as f64 * scale;
            let first = (a.floor() as usize).min(n - 1);
            let last = ((b.ceil() as usize).max(first + 1)).min(n);
            let weights = (first..last)
                .map(|k| {
                    let overlap = (b.min(k as f64 + 1.0) - a.max(k as f64)).max(0.0);
                    (overlap / scale) as f32
                })
                .collect();
            (first, weights)
        })
        .collect()
}

/// Area-resamples interleaved RGB values from `w × h` to `nw × nh` (all positive). Each output
/// pixel is the overlap-weighted mean of the input pixels its footprint covers, so that pixel
/// edges map exactly: the input point `x` lands at `x · nw / w` (and likewise in y).
pub(crate) fn resize_area(src: &[f32], w: usize, h: usize, nw: usize, nh: usize) -> Vec<f32> {
    if (w, h) == (nw, nh) {
        return src.to_vec();
    }
    let wx = area_weights(w, nw);
    let wy = area_weights(h, nh);
    // Horizontal pass: h rows of nw pixels.
    let mut tmp = vec![0.0f32; h * nw * 3];
    for y in 0..h {
        let row = &src[y * w * 3..(y + 1) * w * 3];
        let out = &mut tmp[y * nw * 3..(y + 1) * nw * 3];
        for (x, (first, ws)) in wx.iter().enumerate() {
            let mut acc = [0.0f32; 3];
            for (k, wt) in ws.iter().enumerate() {
                let p = &row[(first + k) * 3..(first + k) * 3 + 3];
                for c in 0..3 {
                    acc[c] += wt * p[c];
                }
            }
            out[x * 3..x * 3 + 3].copy_from_slice(&acc);
        }
    }
    // Vertical pass.
    let mut dst = vec![0.0f32; nh * nw * 3];
    for (y, (first, ws)) in wy.iter().enumerate() {
        let out = &mut dst[y * nw * 3..(y + 1) * nw * 3];
        for (k, wt) in ws.iter().enumerate() {
            let row = &tmp[(first + k) * nw * 3..(first + k + 1) * nw * 3];
            for (o, v) in out.iter_mut().zip(row) {
                *o += wt * v;
            }
        }
    }
    dst
}

/// The output size for downscale factor `factor` (rounded, at least 1 pixel) and an optional
/// maximum width (the height follows the aspect ratio, rounded).
pub(crate) fn target_size(w: u32, h: u32, factor: u32, max_width: Option<u32>) -> (u32, u32) {
    let div = |v: u32| ((v as u64 + factor as u64 / 2) / factor as u64).max(1) as u32;
    let (mut nw, mut nh) = (div(w), div(h));
    if let Some(m) = max_width
        && nw > m
    {
        nh = ((nh as f64 * m as f64 / nw as f64).round() as u32).max(1);
        nw = m;
    }
    (nw, nh)
}
