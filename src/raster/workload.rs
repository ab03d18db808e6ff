//! The shape of a render's work: how many billboards a pixel evaluates and blends, how large
//! billboards are on screen, how their alpha textures are distributed. These statistics say
//! whether a benchmark scene looks like the work training does (issue: "a benchmark must look
//! like the work it stands for"); `examples/model_stats.rs` prints them for trained models and
//! `benches/raster.rs` for its generated scenes.

use super::input::ActivatedRef;
use super::output::RenderOutput;

/// Statistics of one render (see the [module documentation](self)). Quantiles are nearest-rank.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WorkloadStats {
    /// Pixels of the image.
    pub pixels: u64,
    /// Mean (pixel, billboard) pairs evaluated per pixel, over all pixels.
    pub evaluated_per_pixel: f64,
    /// Mean (pixel, billboard) pairs blended per pixel, over all pixels.
    pub blended_per_pixel: f64,
    /// Fraction of pixels with at least one blended billboard.
    pub covered_fraction: f64,
    /// Median and 90th percentile of the blended billboards per covered pixel.
    pub blended_covered_p50_p90: [u32; 2],
    /// Billboards not culled by preprocessing.
    pub visible: u64,
    /// Tile entries per visible billboard.
    pub tiles_per_visible: f64,
    /// 10th, 50th and 90th percentile over visible billboards of the screen size: the square
    /// root of the pixel count of the billboard's screen box (clipped to the image).
    pub screen_px_p10_p50_p90: [f32; 3],
    /// Fractions of the alpha texels of the visible billboards in the bins cut at
    /// [`ALPHA_CUTS`]: below 0.05, `[0.05, 0.3)`, `[0.3, 0.7)`, `[0.7, 0.95)`, at least 0.95.
    pub alpha_bins: [f64; 5],
}

/// The alpha values cutting [`WorkloadStats::alpha_bins`].
pub const ALPHA_CUTS: [f32; 4] = [0.05, 0.3, 0.7, 0.95];

/// Nearest-rank quantile `q` of sorted `values` (0 when empty).
pub(crate) fn quantile<T: Copy + Default>(sorted: &[T], q: f64) -> T {
    if sorted.is_empty() {
        return T::default();
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

impl WorkloadStats {
    /// The statistics of `out`, a render of `set`.
    pub fn of(set: &ActivatedRef<'_>, out: &RenderOutput) -> Self {
        let state = &out.state;
        let pixels = u64::from(out.width) * u64::from(out.height);
        let per_pixel = |n: u64| if pixels == 0 { 0.0 } else { n as f64 / pixels as f64 };
        // Per covered pixel, its blended pairs: the runs of equal pixels in each tile's list.
        let mut blended_counts: Vec<u32> = state
            .tiles
            .iter()
            .flat_map(|tile| {
                tile.pairs_by_pixel()
                    .chunk_by(|a, b| a.0 == b.0)
                    .map(|run| run.len() as u32)
                    .collect::<Vec<u32>>()
            })
            .collect();
        blended_counts.sort_unstable();
        let mut sizes = Vec::new();
        let mut alpha_bins = [0u64; 5];
        for (b, prepared) in state.prepared.iter().enumerate() {
            let Some(p) = prepared else { continue };
            // A visible billboard's box holds at least one pixel centre (`pixel_min ≤ pixel_max`).
            let w = f64::from(p.pixel_max[0] - p.pixel_min[0] + 1);
            let h = f64::from(p.pixel_max[1] - p.pixel_min[1] + 1);
            sizes.push((w * h).sqrt() as f32);
            for texel in set.texture_of(b) {
                let a = texel[3];
                alpha_bins[ALPHA_CUTS.iter().filter(|&&cut| a >= cut).count()] += 1;
            }
        }
        sizes.sort_unstable_by(f32::total_cmp);
        let visible = sizes.len() as u64;
        let texels = alpha_bins.iter().sum::<u64>().max(1) as f64;
        Self {
            pixels,
            evaluated_per_pixel: per_pixel(out.stats.evaluated_pairs),
            blended_per_pixel: per_pixel(out.stats.blended_pairs),
            covered_fraction: per_pixel(blended_counts.len() as u64),
            blended_covered_p50_p90: [quantile(&blended_counts, 0.5), quantile(&blended_counts, 0.9)],
            visible,
            tiles_per_visible: out.stats.tile_entries as f64 / visible.max(1) as f64,
            screen_px_p10_p50_p90: [quantile(&sizes, 0.1), quantile(&sizes, 0.5), quantile(&sizes, 0.9)],
            alpha_bins: alpha_bins.map(|n| n as f64 / texels),
        }
    }

    /// The mean of several renders' statistics (quantiles and fractions averaged too).
    pub fn mean(all: &[WorkloadStats]) -> Self {
        let n = all.len().max(1) as f64;
        let avg = |f: &dyn Fn(&WorkloadStats) -> f64| all.iter().map(f).sum::<f64>() / n;
        Self {
            pixels: avg(&|s| s.pixels as f64).round() as u64,
            evaluated_per_pixel: avg(&|s| s.evaluated_per_pixel),
            blended_per_pixel: avg(&|s| s.blended_per_pixel),
            covered_fraction: avg(&|s| s.covered_fraction),
            blended_covered_p50_p90: [0, 1].map(|i| avg(&|s| f64::from(s.blended_covered_p50_p90[i])).round() as u32),
            visible: avg(&|s| s.visible as f64).round() as u64,
            tiles_per_visible: avg(&|s| s.tiles_per_visible),
            screen_px_p10_p50_p90: [0, 1, 2].map(|i| avg(&|s| f64::from(s.screen_px_p10_p50_p90[i])) as f32),
            alpha_bins: [0, 1, 2, 3, 4].map(|i| avg(&|s| s.alpha_bins[i])),
        }
    }

    /// A Markdown table header matching [`WorkloadStats::table_row`].
    pub fn table_header() -> &'static str {
        "| scene | pixels | evaluated / px | blended / px | covered | blended per covered px p50 / p90 | visible | tiles / visible | screen px p10 / p50 / p90 | alpha bins < 0.05 / 0.3 / 0.7 / 0.95 / above |\n|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|"
    }

    /// One Markdown table row named `name`.
    pub fn table_row(&self, name: &str) -> String {
        let [s10, s50, s90] = self.screen_px_p10_p50_p90;
        let [a0, a1, a2, a3, a4] = self.alpha_bins;
        format!(
            "| {name} | {} | {:.1} | {:.1} | {:.2} | {} / {} | {} | {:.1} | {s10:.1} / {s50:.1} / {s90:.1} | {a0:.2} / {a1:.2} / {a2:.2} / {a3:.2} / {a4:.2} |",
            self.pixels,
            self.evaluated_per_pixel,
            self.blended_per_pixel,
            self.covered_fraction,
            self.blended_covered_p50_p90[0],
            self.blended_covered_p50_p90[1],
            self.visible,
            self.tiles_per_visible,
        )
    }
}
