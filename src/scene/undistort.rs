//! Undistorting images to pinhole cameras.
//!
//! Each output pixel centre `(u, v)` of the new pinhole camera is mapped to normalised
//! coordinates `((u − cx')/fx, (v − cy')/fy)`, *distorted* with the forward model (exact, no
//! iteration) and mapped to the source image with the original intrinsics, where the source is
//! sampled bilinearly (pixel centres at `i + 0.5`; within half a pixel of the border the edge
//! pixel is repeated). The iterative inverse ([`Distortion::undistort`]) is only needed to
//! choose the output rectangle.
//!
//! The new camera keeps the focal lengths `fx, fy` (so the scale at the principal point is
//! unchanged). Its image rectangle depends on [`UndistortMode`]:
//! - [`UndistortMode::Crop`] (default): the largest axis-aligned rectangle of the undistorted
//!   image plane that is entirely covered by the source image, found by undistorting the source
//!   border (every half pixel along the four edges): left edge `L` = the largest undistorted x
//!   of the source's left border, right `R` = the smallest x of its right border, and likewise
//!   top and bottom. The size is `floor(R − L)` × `floor(B − T)` (the fraction is split evenly
//!   on both sides), the principal point moves to `(cx − L, cy − T)`, and a check maps the new
//!   border forward and shrinks the rectangle until it lies inside the source. No pixel is blank.
//!   This is what COLMAP's `image_undistorter` does with `blank_pixels = 0` (which also keeps
//!   `fx, fy`), except that COLMAP scales the principal point with the size instead of shifting
//!   it. As in COLMAP, the rectangle is limited to twice the source size on each side of the
//!   principal point. With pincushion distortion (k1 > 0, e.g. the beer and fox scenes) the
//!   result is a few pixels smaller than the source; with barrel distortion it can be larger.
//! - [`UndistortMode::KeepSize`]: the same `fx, fy, cx, cy` and the same size as the source;
//!   output pixels whose source position falls outside the source image are filled with the
//!   background colour.

use super::Image;
use super::colmap::Intrinsics;
use super::distortion::Distortion;

/// How the rectangle of an undistorted image is chosen (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum UndistortMode {
    /// Largest rectangle without blank pixels; focal lengths kept, principal point shifted.
    #[default]
    Crop,
    /// Same intrinsics and size as the source; uncovered pixels take the background colour.
    KeepSize,
}

/// The pinhole camera an image is undistorted to, with the source camera it comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UndistortPlan {
    /// Source intrinsics (with distortion) and size.
    pub source: Intrinsics,
    /// Source width in pixels.
    pub source_width: u32,
    /// Source height in pixels.
    pub source_height: u32,
    /// New focal length along x (pixels).
    pub fx: f64,
    /// New focal length along y (pixels).
    pub fy: f64,
    /// New principal point x (pixels).
    pub cx: f64,
    /// New principal point y (pixels).
    pub cy: f64,
    /// New width in pixels.
    pub width: u32,
    /// New height in pixels.
    pub height: u32,
}

impl UndistortPlan {
    /// The source pixel position that output pixel position `(u, v)` (continuous pixel
    /// coordinates of the new camera) samples.
    pub fn source_position(&self, u: f64, v: f64) -> [f64; 2] {
        let s = &self.source;
        let d = s.distortion.distort([(u - self.cx) / self.fx, (v - self.cy) / self.fy]);
        [s.fx * d[0] + s.cx, s.fy * d[1] + s.cy]
    }

    /// The output pixel position that shows source pixel position `(x, y)`; `None` when the
    /// distortion cannot be inverted there.
    pub fn output_position(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        let s = &self.source;
        let p = s.distortion.undistort([(x - s.cx) / s.fx, (y - s.cy) / s.fy])?;
        Some([self.fx * p[0] + self.cx, self.fy * p[1] + self.cy])
    }
}

/// Chooses the undistorted camera for a source camera of size `width × height`. `Err` says why
/// the distortion cannot be handled (it is not invertible inside the image, or it would leave
/// less than a fifth of the image).
pub fn plan(source: &Intrinsics, width: u32, height: u32, mode: UndistortMode) -> Result<UndistortPlan, String> {
    let mut plan = UndistortPlan {
        source: *source,
        source_width: width,
        source_height: height,
        fx: source.fx,
        fy: source.fy,
        cx: source.cx,
        cy: source.cy,
        width,
        height,
    };
    if mode == UndistortMode::KeepSize || source.distortion.is_none() {
        return Ok(plan);
    }
    let (w, h) = (width as f64, height as f64);
    let undist = |x: f64, y: f64| {
        plan.output_position(x, y).ok_or_else(|| {
            format!(
                "the lens distortion {:?} cannot be inverted at the image border point ({x}, {y}): \
                 the model folds over inside the image",
                source.distortion
            )
        })
    };
    // Undistorted positions along each border, every half pixel.
    let steps = |n: f64| (0..=(2.0 * n) as usize).map(|i| i as f64 * 0.5);
    let (mut left, mut right, mut top, mut bottom) = (f64::MIN, f64::MAX, f64::MIN, f64::MAX);
    for y in steps(h) {
        left = left.max(undist(0.0, y)?[0]);
        right = right.min(undist(w, y)?[0]);
    }
    for x in steps(w) {
        top = top.max(undist(x, 0.0)?[1]);
        bottom = bottom.min(undist(x, h)?[1]);
    }
    // At most twice the source extent on each side of the principal point (as COLMAP).
    let (cx, cy) = (source.cx, source.cy);
    left = left.max(cx - 2.0 * cx.max(0.0));
    right = right.min(cx + 2.0 * (w - cx).max(0.0));
    top = top.max(cy - 2.0 * cy.max(0.0));
    bottom = bottom.min(cy + 2.0 * (h - cy).max(0.0));
    // Shrink until the new border maps inside the source (within 0.01 pixel).
    const SLACK: f64 = 0.01;
    for _ in 0..200 {
        let nw = (right - left + SLACK).floor();
        let nh = (bottom - top + SLACK).floor();
        if !(nw >= (w / 5.0).max(1.0) && nh >= (h / 5.0).max(1.0)) {
            return Err(format!(
                "undistorting with {:?} leaves a {:.1}x{:.1} pixel image out of {width}x{height}: \
                 the distortion is too strong for this loader",
                source.distortion,
                (right - left).max(0.0),
                (bottom - top).max(0.0)
            ));
        }
        let l = left + 0.5 * (right - left - nw).max(0.0);
        let t = top + 0.5 * (bottom - top - nh).max(0.0);
        plan.cx = cx - l;
        plan.cy = cy - t;
        plan.width = nw as u32;
        plan.height = nh as u32;
        let inside = |p: [f64; 2]| (-SLACK..=w + SLACK).contains(&p[0]) && (-SLACK..=h + SLACK).contains(&p[1]);
        let mut bad = [false; 4];
        for v in steps(nh) {
            bad[0] |= !inside(plan.source_position(0.0, v));
            bad[1] |= !inside(plan.source_position(nw, v));
        }
        for u in steps(nw) {
            bad[2] |= !inside(plan.source_position(u, 0.0));
            bad[3] |= !inside(plan.source_position(u, nh));
        }
        if bad == [false; 4] {
            return Ok(plan);
        }
        let shrink = 0.25;
        if bad[0] {
            left += shrink;
        }
        if bad[1] {
            right -= shrink;
        }
        if bad[2] {
            top += shrink;
        }
        if bad[3] {
            bottom -= shrink;
        }
    }
    Err(format!(
        "could not find an image rectangle covered by the source for distortion {:?}",
        source.distortion
    ))
}

/// Bilinear sample of an 8-bit image at continuous pixel position `(x, y)` (pixel centres at
/// `i + 0.5`, edge pixels repeated), as values in `[0, 1]`.
fn sample(src: &Image, x: f64, y: f64) -> [f32; 3] {
    let (w, h) = (src.width() as usize, src.height() as usize);
    let fx = (x - 0.5).clamp(0.0, (w - 1) as f64);
    let fy = (y - 0.5).clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (ax, ay) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
    let data = src.as_bytes();
    let px = |x: usize, y: usize, c: usize| data[(y * w + x) * 3 + c] as f32;
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let top = px(x0, y0, c) * (1.0 - ax) + px(x1, y0, c) * ax;
        let bottom = px(x0, y1, c) * (1.0 - ax) + px(x1, y1, c) * ax;
        *o = (top * (1.0 - ay) + bottom * ay) / 255.0;
    }
    out
}

/// Resamples `src` (the source image of `plan`) into the undistorted image, as interleaved RGB
/// values in `[0, 1]` of size `plan.width × plan.height`. Pixels whose source position lies
/// outside the source image (only with [`UndistortMode::KeepSize`]) take `background`.
pub fn resample(plan: &UndistortPlan, src: &Image, background: [f32; 3]) -> Vec<f32> {
    let (w, h) = (plan.width as usize, plan.height as usize);
    let (sw, sh) = (src.width() as f64, src.height() as f64);
    let mut out = Vec::with_capacity(w * h * 3);
    for j in 0..h {
        for i in 0..w {
            let [x, y] = plan.source_position(i as f64 + 0.5, j as f64 + 0.5);
            let inside = (-0.01..=sw + 0.01).contains(&x) && (-0.01..=sh + 0.01).contains(&y);
            let c = if inside { sample(src, x, y) } else { background };
            out.extend_from_slice(&c);
        }
    }
    out
}

/// True when the distortion needs resampling (any coefficient non-zero).
pub(crate) fn needs_undistortion(d: &Distortion) -> bool {
    !d.is_none()
}
