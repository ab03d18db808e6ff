//! Per-view object masks: 8-bit maps, 255 = keep (object), 0 = leave out (background).
//!
//! Where they come from ([`crate::scene::View::mask`]): NeuS/IDR datasets' `mask/` folder
//! (loaded automatically), or [`crate::scene::LoadOptions::masks_dir`] (`--masks DIR`) for any
//! format, each mask matched to its image by file stem ([`find_mask`]). A mask file is an image
//! of the same size as its photograph; its value is the largest of its R, G and B (a grey or
//! colour PNG/JPEG both work; an alpha channel is composited on black first, so transparent is
//! "leave out"). Masks are resampled with the images (undistortion, downscale).
//!
//! How training uses them ([`MaskMode`]): by default the photograph is composited onto the
//! background outside the mask at load, `c' = c·m + background·(1 − m)` with `m = mask / 255`
//! (what NeuS/2DGS-class tools do for DTU): the billboards then learn the object in front of
//! the background colour. [`MaskMode::Ignore`] loads the masks (for masked evaluation) and leaves
//! the photographs as they are. [`MaskMode::Weight`] leaves the photographs as they are and
//! weights the loss by the mask instead (pixels outside it are left out of training). An image's own alpha channel is not a mask here: RGBA images are
//! composited onto the background whatever the mode (as before), and their alpha is kept as
//! [`crate::scene::View::coverage`].
//!
//! ```
//! use bbsplat::scene::mask::composite_outside;
//! let mut rgb = vec![200u8, 100, 50, 200, 100, 50];
//! composite_outside(&mut rgb, &[255, 0], [1.0, 1.0, 1.0]);
//! assert_eq!(rgb, vec![200, 100, 50, 255, 255, 255]);
//! ```

use super::error::{Location, SceneError};
use super::image_io;
use crate::file_io::names_a_file;
use std::path::{Path, PathBuf};

/// What training does with a view's mask.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum MaskMode {
    /// Composite the photograph onto the background outside the mask at load (the default).
    #[default]
    Composite,
    /// Keep the photograph as it is (the mask still serves masked evaluation).
    Ignore,
    /// Keep the photograph as it is and weight the training loss by the mask: render and
    /// target multiplied by `mask / 255` before the loss ([`crate::loss::masked`]), so pixels
    /// outside it count for nothing and what the billboards draw there is free. The trainer
    /// reads the mask from [`crate::train::TrainView::loss_mask`]
    /// (`TrainView::from_view(&view).with_loss_mask(view.mask.clone())`).
    Weight,
}

/// Extensions tried, in order, for a mask file.
pub const MASK_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "PNG", "JPG", "JPEG"];

/// The mask of the image `image_name` (a file name, possibly with folders) in `dir`: the file
/// with the image's stem and one of [`MASK_EXTENSIONS`], else (for a stem that is a number) one
/// whose stem is the same number written with other leading zeros (DTU's `image/000012.png`
/// and `mask/012.png`), else `image_name.png` itself (`image.jpg.png`, as some tools write).
/// `None` when none exists.
pub fn find_mask(dir: &Path, image_name: &str) -> Option<PathBuf> {
    let relative = Path::new(image_name);
    let stem = relative.file_stem()?.to_str()?;
    let folder = dir.join(relative.parent().unwrap_or(Path::new("")));
    for ext in MASK_EXTENSIONS {
        let p = folder.join(format!("{stem}.{ext}"));
        if names_a_file(&p) {
            return Some(p);
        }
    }
    let by_number = stem.parse::<u64>().ok().and_then(|number| {
        let entries = std::fs::read_dir(&folder).ok()?;
        let mut found: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                let ext_ok = p
                    .extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| MASK_EXTENSIONS.contains(&e));
                let num = p
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .and_then(|s| s.parse::<u64>().ok());
                ext_ok && num == Some(number)
            })
            .collect();
        found.sort();
        found.into_iter().next()
    });
    by_number.or_else(|| {
        let p = folder.join(format!("{}.png", relative.file_name()?.to_str()?));
        names_a_file(&p).then_some(p)
    })
}

/// Decodes the mask file `path` (referenced by `file` at `location`, for messages) into 8-bit
/// values, row-major, and checks that it is `width × height`.
///
/// # Errors
/// [`SceneError::ImageDecode`] for an undecodable file, [`SceneError::ImageSize`] naming the mask
/// when its size differs from its image's.
pub(crate) fn decode_mask(
    path: &Path,
    file: &Path,
    location: &Location,
    width: u32,
    height: u32,
) -> Result<Vec<u8>, SceneError> {
    let (image, _alpha, _damage, _turn) = image_io::decode_with_alpha(path, file, location, [0.0; 3], false)?;
    if (image.width(), image.height()) != (width, height) {
        return Err(SceneError::ImageSize {
            image: path.to_path_buf(),
            actual: (image.width() as u64, image.height() as u64),
            expected: (width as u64, height as u64),
            file: file.to_path_buf(),
            location: Location::Record(format!("{location}: the mask of a {width}x{height} image")),
        });
    }
    Ok(image
        .as_bytes()
        .chunks_exact(3)
        .map(|px| px[0].max(px[1]).max(px[2]))
        .collect())
}

/// Composites interleaved 8-bit RGB `rgb` onto `background` (RGB in `[0, 1]`) outside `mask`
/// (one value per pixel, 255 = keep): `c' = c·m + background·(1 − m)`, `m = mask / 255`, rounded.
pub fn composite_outside(rgb: &mut [u8], mask: &[u8], background: [f32; 3]) {
    debug_assert_eq!(rgb.len(), mask.len() * 3);
    let bg = background.map(|b| b.clamp(0.0, 1.0) * 255.0);
    for (px, &m) in rgb.chunks_exact_mut(3).zip(mask) {
        if m == 255 {
            continue;
        }
        let a = m as f32 / 255.0;
        for c in 0..3 {
            px[c] = (px[c] as f32 * a + bg[c] * (1.0 - a)).round().clamp(0.0, 255.0) as u8;
        }
    }
}
