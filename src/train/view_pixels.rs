//! The pixels of a training view: kept as the 8-bit values a scene loads (3 bytes a pixel) and
//! converted to floats (`byte / 255`, exactly as [`crate::scene::Image::to_f32_rgb`]) only for
//! the view a step or an evaluation uses, into a buffer the caller recycles; or, for images that
//! are floats to begin with (the demo scene, coarse-to-fine downscales), floats.
//!
//! A view of a scene too large for memory is decoded from its file when it is used
//! ([`ViewPixels::OnDemand`], [`crate::scene::on_demand`]): the same values, fetched through the
//! scene's bounded cache, so reading them can fail (the file changed or went away).
//!
//! A float copy of every view costs 12 bytes a pixel: 576 MB for the 300 views of
//! NeRF-synthetic lego at 800×800, next to their 8-bit images. Converting one view per step
//! costs a pass over its pixels, small beside the render.
//!
//! ```
//! use bbsplat::train::ViewPixels;
//! let bytes = ViewPixels::from(vec![0u8, 51, 255]);
//! let mut buffer = Vec::new();
//! assert_eq!(bytes.as_f32(&mut buffer).unwrap(), &[0.0, 0.2, 1.0]);
//! let floats = ViewPixels::from(vec![0.5f32, 0.25, 1.0]);
//! assert_eq!(floats.to_f32().unwrap().as_ref(), &[0.5, 0.25, 1.0]);
//! assert_eq!(bytes.len(), 3);
//! ```

use crate::scene::SceneError;
use crate::scene::image_io::resize_area;
use crate::scene::on_demand::OnDemandImage;
use std::borrow::Cow;

/// Interleaved RGB values of a view (module docs).
#[derive(Clone, Debug, PartialEq)]
pub enum ViewPixels {
    /// 8-bit values; the float value is `byte / 255`.
    U8(Vec<u8>),
    /// Values in `[0, 1]`.
    F32(Vec<f32>),
    /// Decoded from its file when used.
    OnDemand(OnDemandPixels),
}

/// The values of an on-demand image ([`crate::scene::on_demand`]): its bytes `/ 255`, then
/// area-downscaled to `width × height` when that is smaller than the image (the coarse views of
/// a coarse-to-fine run, [`super::resolution`]), exactly as the same steps on an image held in
/// memory.
#[derive(Clone, Debug, PartialEq)]
pub struct OnDemandPixels {
    image: OnDemandImage,
    width: u32,
    height: u32,
}

impl OnDemandPixels {
    /// The values of `image` at its own size.
    pub fn new(image: OnDemandImage) -> Self {
        let (width, height) = (image.width(), image.height());
        OnDemandPixels { image, width, height }
    }

    /// The same image area-downscaled to `width × height` (from its own size).
    pub fn downscaled(&self, width: u32, height: u32) -> Self {
        OnDemandPixels {
            image: self.image.clone(),
            width,
            height,
        }
    }

    /// The image decoded.
    pub fn image(&self) -> &OnDemandImage {
        &self.image
    }

    /// Width and height of the values.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The values, decoded (through the cache) into `buffer`.
    fn decode_into(&self, buffer: &mut Vec<f32>) -> Result<(), SceneError> {
        let image = self.image.load()?;
        buffer.clear();
        if (self.width, self.height) == (image.width(), image.height()) {
            buffer.extend(image.as_bytes().iter().map(|&b| b as f32 / 255.0));
        } else {
            let (w, h) = (image.width() as usize, image.height() as usize);
            *buffer = resize_area(&image.to_f32_rgb(), w, h, self.width as usize, self.height as usize);
        }
        Ok(())
    }
}

impl ViewPixels {
    /// Number of values (`width · height · 3`).
    pub fn len(&self) -> usize {
        match self {
            ViewPixels::U8(v) => v.len(),
            ViewPixels::F32(v) => v.len(),
            ViewPixels::OnDemand(p) => p.width as usize * p.height as usize * 3,
        }
    }

    /// True when there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values as floats: borrowed when they are floats, otherwise converted (decoded first
    /// when on demand) into `buffer` (resized, its storage reused).
    ///
    /// # Errors
    /// Only on demand: the image's file no longer gives its pixels
    /// ([`crate::scene::on_demand::OnDemandImage::load`]).
    pub fn as_f32<'a>(&'a self, buffer: &'a mut Vec<f32>) -> Result<&'a [f32], SceneError> {
        match self {
            ViewPixels::F32(v) => Ok(v),
            ViewPixels::U8(v) => {
                buffer.clear();
                buffer.extend(v.iter().map(|&b| b as f32 / 255.0));
                Ok(buffer)
            }
            ViewPixels::OnDemand(p) => {
                p.decode_into(buffer)?;
                Ok(buffer)
            }
        }
    }

    /// The values as floats, borrowed or converted (decoded first when on demand).
    ///
    /// # Errors
    /// As [`ViewPixels::as_f32`].
    pub fn to_f32(&self) -> Result<Cow<'_, [f32]>, SceneError> {
        match self {
            ViewPixels::F32(v) => Ok(Cow::Borrowed(v)),
            ViewPixels::U8(v) => Ok(Cow::Owned(v.iter().map(|&b| b as f32 / 255.0).collect())),
            ViewPixels::OnDemand(p) => {
                let mut buffer = Vec::new();
                p.decode_into(&mut buffer)?;
                Ok(Cow::Owned(buffer))
            }
        }
    }

    /// Bytes held by the view itself (an on-demand view holds none: its scene's cache does).
    pub fn bytes(&self) -> usize {
        match self {
            ViewPixels::U8(v) => v.len(),
            ViewPixels::F32(v) => 4 * v.len(),
            ViewPixels::OnDemand(_) => 0,
        }
    }
}

impl From<Vec<u8>> for ViewPixels {
    fn from(v: Vec<u8>) -> Self {
        ViewPixels::U8(v)
    }
}

impl From<Vec<f32>> for ViewPixels {
    fn from(v: Vec<f32>) -> Self {
        ViewPixels::F32(v)
    }
}
