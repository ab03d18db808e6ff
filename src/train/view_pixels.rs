//! The pixels of a training view: kept as the 8-bit values a scene loads (3 bytes a pixel) and
//! converted to floats (`byte / 255`, exactly as [`crate::scene::Image::to_f32_rgb`]) only for
//! the view a step or an evaluation uses, into a buffer the caller recycles; or, for images that
//! are floats to begin with (the demo scene, coarse-to-fine downscales), floats.
//!
//! A float copy of every view costs 12 bytes a pixel: 576 MB for the 300 views of
//! NeRF-synthetic lego at 800×800, next to their 8-bit images. Converting one view per step
//! costs a pass over its pixels, small beside the render.
//!
//! ```
//! use bbsplat::train::ViewPixels;
//! let bytes = ViewPixels::from(vec![0u8, 51, 255]);
//! let mut buffer = Vec::new();
//! assert_eq!(bytes.as_f32(&mut buffer), &[0.0, 0.2, 1.0]);
//! let floats = ViewPixels::from(vec![0.5f32, 0.25, 1.0]);
//! assert_eq!(floats.to_f32().as_ref(), &[0.5, 0.25, 1.0]);
//! assert_eq!(bytes.len(), 3);
//! ```

use std::borrow::Cow;

/// Interleaved RGB values of a view (module docs).
#[derive(Clone, Debug, PartialEq)]
pub enum ViewPixels {
    /// 8-bit values; the float value is `byte / 255`.
    U8(Vec<u8>),
    /// Values in `[0, 1]`.
    F32(Vec<f32>),
}

impl ViewPixels {
    /// Number of values (`width · height · 3`).
    pub fn len(&self) -> usize {
        match self {
            ViewPixels::U8(v) => v.len(),
            ViewPixels::F32(v) => v.len(),
        }
    }

    /// True when there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values as floats: borrowed when they are floats, otherwise converted into `buffer`
    /// (resized, its storage reused).
    pub fn as_f32<'a>(&'a self, buffer: &'a mut Vec<f32>) -> &'a [f32] {
        match self {
            ViewPixels::F32(v) => v,
            ViewPixels::U8(v) => {
                buffer.clear();
                buffer.extend(v.iter().map(|&b| b as f32 / 255.0));
                buffer
            }
        }
    }

    /// The values as floats, borrowed or converted.
    pub fn to_f32(&self) -> Cow<'_, [f32]> {
        match self {
            ViewPixels::F32(v) => Cow::Borrowed(v),
            ViewPixels::U8(v) => Cow::Owned(v.iter().map(|&b| b as f32 / 255.0).collect()),
        }
    }

    /// Value `i` as a float.
    pub fn value(&self, i: usize) -> f32 {
        match self {
            ViewPixels::U8(v) => v[i] as f32 / 255.0,
            ViewPixels::F32(v) => v[i],
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        match self {
            ViewPixels::U8(v) => v.len(),
            ViewPixels::F32(v) => 4 * v.len(),
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
