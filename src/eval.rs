//! Evaluation of a billboard model on posed images, as the reference's `render.py` + `metrics.py`
//! do it: renders and ground truth are both quantised to 8 bits (`⌊clamp(x, 0, 1)·255 + 0.5⌋`)
//! before PSNR and SSIM are computed.
//!
//! - PSNR: `−10·log10(MSE)` over all channels and pixels of one image, in dB; the mean over
//!   views is the arithmetic mean of the per-view values (as the reference averages them).
//! - SSIM: the training SSIM (11×11 Gaussian window, σ = 1.5, zero "same" padding,
//!   `C1 = 0.01²`, `C2 = 0.03²`), mean over the map and channels.
//! - LPIPS (optional, [`crate::lpips`]: VGG as the reference evaluates, or AlexNet): of the same
//!   8-bit images, mean over views as PSNR's ([`lpips_u8`], [`EvalReport::with_lpips`]).
//! - Render time: wall-clock milliseconds of [`render_with`] (the full forward pass with its
//!   auxiliary outputs, on storage recycled from the previous view), per view.
//! - Masked PSNR / SSIM ([`masked_image_metrics`], for views with a mask, e.g. DTU's object
//!   masks or an RGBA image's alpha): over the pixels whose mask is at least 128 only. Masked
//!   PSNR is `−10·log10` of the mean squared error over those pixels' channels; masked SSIM the
//!   mean of the SSIM map (computed on the whole images, as above) over those pixels. They are
//!   reported beside the whole-image figures, labelled as masked, never in their place.
//!
//! ```
//! use bbsplat::eval::image_metrics;
//! let truth = vec![0.5f32; 16 * 16 * 3];
//! let m = image_metrics(&truth, &truth, 16, 16).unwrap();
//! assert!(m.psnr.is_infinite() && (m.ssim - 1.0).abs() < 1e-9);
//! ```

use crate::camera::Camera;
use crate::loss::LossError;
use crate::loss::psnr::{psnr_u8, quantize_u8};
use crate::loss::ssim::{Padding, ssim, ssim_map};
use crate::lpips::{Lpips, LpipsError};
use crate::raster::{ActivatedRef, RenderBuffers, RenderSettings, render_with};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// PSNR and SSIM of one image pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageMetrics {
    /// PSNR in dB of the 8-bit images (`+∞` when identical).
    pub psnr: f64,
    /// SSIM of the 8-bit images.
    pub ssim: f64,
}

/// PSNR and SSIM of `render` against `truth` (interleaved RGB, `width × height`, values in
/// `[0, 1]`), both quantised to 8 bits first.
///
/// # Errors
///
/// [`LossError`] when a buffer does not hold `width·height·3` values or the image is empty.
pub fn image_metrics(render: &[f32], truth: &[f32], width: usize, height: usize) -> Result<ImageMetrics, LossError> {
    let psnr = psnr_u8(render, truth)?;
    let q = |x: &[f32]| -> Vec<f32> { x.iter().map(|&v| quantize_u8(v) as f32 / 255.0).collect() };
    let ssim = ssim(&q(render), &q(truth), width, height, 3, Padding::Same)?;
    Ok(ImageMetrics { psnr, ssim })
}

/// The LPIPS distance of `render` and `truth` (interleaved RGB, `width × height`, values in
/// `[0, 1]`), both quantised to 8 bits first, as [`image_metrics`] does.
///
/// # Errors
///
/// [`LpipsError`] when a buffer does not hold `width·height·3` values or the image is smaller
/// than the network needs.
pub fn lpips_u8(net: &Lpips, render: &[f32], truth: &[f32], width: usize, height: usize) -> Result<f64, LpipsError> {
    let q = |x: &[f32]| -> Vec<f32> { x.iter().map(|&v| quantize_u8(v) as f32 / 255.0).collect() };
    net.distance(&q(render), &q(truth), width, height)
}

/// PSNR and SSIM of `render` against `truth` over the pixels where `mask` (one 8-bit value per
/// pixel, `width × height`) is at least 128; `None` when no pixel is. Both images are quantised
/// to 8 bits first, as [`image_metrics`].
///
/// # Errors
///
/// [`LossError`] when a buffer does not hold `width·height·3` values (the mask `width·height`).
///
/// ```
/// use bbsplat::eval::masked_image_metrics;
/// let truth = vec![0.5f32; 16 * 16 * 3];
/// let mut render = truth.clone();
/// render[..8 * 16 * 3].fill(0.0); // the top half is wrong
/// let mut mask = vec![0u8; 16 * 16];
/// mask[8 * 16..].fill(255); // only the bottom half counts
/// let m = masked_image_metrics(&render, &truth, &mask, 16, 16).unwrap().unwrap();
/// assert!(m.psnr.is_infinite());
/// assert!(masked_image_metrics(&render, &truth, &[0; 256], 16, 16).unwrap().is_none());
/// ```
pub fn masked_image_metrics(
    render: &[f32],
    truth: &[f32],
    mask: &[u8],
    width: usize,
    height: usize,
) -> Result<Option<ImageMetrics>, LossError> {
    crate::loss::check_pair(render, truth, ["render", "truth"])?;
    if mask.len() * 3 != render.len() {
        return Err(LossError::BadLength {
            which: "mask",
            expected: render.len() / 3,
            got: mask.len(),
        });
    }
    let keep: Vec<usize> = (0..mask.len()).filter(|&i| mask[i] >= 128).collect();
    if keep.is_empty() {
        return Ok(None);
    }
    let q = |x: &[f32]| -> Vec<f32> { x.iter().map(|&v| quantize_u8(v) as f32 / 255.0).collect() };
    let (qr, qt) = (q(render), q(truth));
    let squared: f64 = keep
        .iter()
        .flat_map(|&i| (0..3).map(move |c| 3 * i + c))
        .map(|k| {
            let d = (qr[k] - qt[k]) as f64;
            d * d
        })
        .sum();
    let mse = squared / (3 * keep.len()) as f64;
    let psnr = if mse == 0.0 { f64::INFINITY } else { -10.0 * mse.log10() };
    let map = ssim_map(&qr, &qt, width, height, 3, Padding::Same)?;
    let map = &map;
    let ssim = keep
        .iter()
        .flat_map(|&i| (0..3).map(move |c| map[3 * i + c] as f64))
        .sum::<f64>()
        / (3 * keep.len()) as f64;
    Ok(Some(ImageMetrics { psnr, ssim }))
}

/// The metrics of one evaluated view.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewMetrics {
    /// The view's name.
    pub name: String,
    /// PSNR in dB (8-bit images).
    pub psnr: f64,
    /// SSIM (8-bit images).
    pub ssim: f64,
    /// Wall-clock render time, milliseconds.
    pub render_ms: f64,
    /// LPIPS of the 8-bit images, when asked for ([`EvalReport::with_lpips`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
    /// PSNR in dB over the view's mask pixels ([`masked_image_metrics`]), when it has a mask
    /// with a pixel at least 128 and masked figures were asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub masked_psnr: Option<f64>,
    /// SSIM over the view's mask pixels, as `masked_psnr`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub masked_ssim: Option<f64>,
}

/// Per-view metrics and their means.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// One entry per view, in the order given.
    pub views: Vec<ViewMetrics>,
    /// Arithmetic mean of the per-view PSNR values (dB).
    pub mean_psnr: f64,
    /// Mean SSIM.
    pub mean_ssim: f64,
    /// Mean render time, milliseconds.
    pub mean_render_ms: f64,
    /// The LPIPS network (`vgg` or `alex`), when LPIPS was computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips_network: Option<String>,
    /// Mean LPIPS over the views, when computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_lpips: Option<f64>,
    /// Mean masked PSNR (dB) over the views that have one; `None` when none has.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_masked_psnr: Option<f64>,
    /// Mean masked SSIM, as `mean_masked_psnr`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_masked_ssim: Option<f64>,
}

impl EvalReport {
    /// Means of `views` (NaN for an empty list).
    pub fn from_views(views: Vec<ViewMetrics>) -> Self {
        let n = views.len() as f64;
        let mean = |f: fn(&ViewMetrics) -> f64| views.iter().map(f).sum::<f64>() / n;
        let masked_mean = |f: fn(&ViewMetrics) -> Option<f64>| {
            let values: Vec<f64> = views.iter().filter_map(f).collect();
            (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
        };
        EvalReport {
            mean_psnr: mean(|v| v.psnr),
            mean_ssim: mean(|v| v.ssim),
            mean_render_ms: mean(|v| v.render_ms),
            lpips_network: None,
            mean_lpips: None,
            mean_masked_psnr: masked_mean(|v| v.masked_psnr),
            mean_masked_ssim: masked_mean(|v| v.masked_ssim),
            views,
        }
    }

    /// The report with each view's LPIPS (`values`, one per view in order, by `network`) and
    /// their mean.
    ///
    /// # Panics
    ///
    /// When `values` does not hold one value per view.
    pub fn with_lpips(mut self, network: crate::lpips::Variant, values: &[f64]) -> Self {
        assert_eq!(values.len(), self.views.len(), "one LPIPS value per view");
        for (view, &v) in self.views.iter_mut().zip(values) {
            view.lpips = Some(v);
        }
        self.lpips_network = Some(network.name().to_string());
        self.mean_lpips = Some(values.iter().sum::<f64>() / values.len() as f64);
        self
    }

    /// A plain-text table: one line per view, then the mean; with masked figures, two more
    /// columns headed "masked PSNR" and "masked SSIM" (`-` for a view without a mask), and with
    /// LPIPS one headed by its network.
    pub fn table(&self) -> String {
        let width = self.views.iter().map(|v| v.name.len()).max().unwrap_or(4).max(4);
        let masked = self.mean_masked_psnr.is_some();
        let extra = |p: Option<f64>, s: Option<f64>| match (masked, p, s) {
            (false, _, _) => String::new(),
            (true, Some(p), Some(s)) => format!("  {p:>11.3}  {s:>11.4}"),
            (true, _, _) => format!("  {:>11}  {:>11}", "-", "-"),
        };
        let lpips_head = match &self.lpips_network {
            Some(net) => format!("  {:>10}", format!("LPIPS-{net}")),
            None => String::new(),
        };
        let lpips = |v: Option<f64>| v.map_or(String::new(), |v| format!("  {v:>10.4}"));
        let mut out = format!(
            "{:<width$}  {:>9}  {:>7}  {:>9}{}{lpips_head}\n",
            "view",
            "PSNR (dB)",
            "SSIM",
            "render ms",
            if masked {
                format!("  {:>11}  {:>11}", "masked PSNR", "masked SSIM")
            } else {
                String::new()
            }
        );
        for v in &self.views {
            out += &format!(
                "{:<width$}  {:>9.3}  {:>7.4}  {:>9.1}{}{}\n",
                v.name,
                v.psnr,
                v.ssim,
                v.render_ms,
                extra(v.masked_psnr, v.masked_ssim),
                lpips(v.lpips)
            );
        }
        out += &format!(
            "{:<width$}  {:>9.3}  {:>7.4}  {:>9.1}{}{}\n",
            "mean",
            self.mean_psnr,
            self.mean_ssim,
            self.mean_render_ms,
            extra(self.mean_masked_psnr, self.mean_masked_ssim),
            lpips(self.mean_lpips)
        );
        out
    }
}

/// A view to evaluate: its name, camera and ground-truth image (interleaved RGB in `[0, 1]`).
#[derive(Clone, Debug)]
pub struct EvalView<'a> {
    /// Name printed in the table.
    pub name: &'a str,
    /// The camera.
    pub camera: &'a Camera,
    /// `width·height·3` values (borrowed, or converted from 8-bit ones for this view).
    pub rgb: std::borrow::Cow<'a, [f32]>,
    /// The view's mask (`width·height` values, 255 = keep) when masked figures are wanted
    /// ([`masked_image_metrics`]); `None` gives none.
    pub mask: Option<&'a [u8]>,
}

/// The items of `items` up to the first error, which is left in `failure`: to evaluate views
/// whose images are read one by one as they are evaluated (decoded on demand,
/// [`crate::scene::on_demand`]) and stop at the first that cannot be read.
///
/// ```
/// use bbsplat::eval::until_error;
/// let mut failure = None;
/// let read: Vec<i32> = until_error([Ok(1), Ok(2), Err("gone"), Ok(4)], &mut failure).collect();
/// assert_eq!((read, failure), (vec![1, 2], Some("gone")));
/// ```
pub fn until_error<'a, T, E>(
    items: impl IntoIterator<Item = Result<T, E>> + 'a,
    failure: &'a mut Option<E>,
) -> impl Iterator<Item = T> + 'a {
    items.into_iter().map_while(move |item| match item {
        Ok(value) => Some(value),
        Err(e) => {
            *failure = Some(e);
            None
        }
    })
}

/// Renders every view and measures it; `on_render` sees each render (e.g. to save it).
///
/// # Errors
///
/// [`LossError`] when a ground-truth image does not match its camera's size.
pub fn evaluate_views<'a>(
    set: &ActivatedRef<'_>,
    views: impl IntoIterator<Item = EvalView<'a>>,
    settings: &RenderSettings,
    mut on_render: impl FnMut(&EvalView<'a>, &[f32]),
) -> Result<EvalReport, LossError> {
    let mut out = Vec::new();
    // Storage recycled from view to view, as a viewer would (see `RenderBuffers`).
    let mut buffers = RenderBuffers::default();
    for view in views {
        let start = Instant::now();
        let rendered = render_with(set, view.camera, settings, std::mem::take(&mut buffers));
        let render_ms = start.elapsed().as_secs_f64() * 1e3;
        let (w, h) = (view.camera.width as usize, view.camera.height as usize);
        let m = image_metrics(&rendered.rgb, &view.rgb, w, h)?;
        let masked = match view.mask {
            Some(mask) => masked_image_metrics(&rendered.rgb, &view.rgb, mask, w, h)?,
            None => None,
        };
        on_render(&view, &rendered.rgb);
        buffers = rendered.into_buffers();
        out.push(ViewMetrics {
            name: view.name.to_string(),
            psnr: m.psnr,
            ssim: m.ssim,
            render_ms,
            lpips: None,
            masked_psnr: masked.map(|m| m.psnr),
            masked_ssim: masked.map(|m| m.ssim),
        });
    }
    Ok(EvalReport::from_views(out))
}
