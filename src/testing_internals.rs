//! Crate-private helpers reached by the test suite (`tests/suite`) only (feature `testing`).
//!
//! The suite checks some internal kernels and their references directly (bit-exactness of a
//! SIMD path, a private bound, a chunk boundary). These wrappers call the `pub(crate)` items
//! unchanged, so that the items stay out of the public API. Not for use outside the tests: no
//! stability promise.

/// Bilinear stage internals (`stages::bilinear`).
pub mod bilinear {
    use crate::stages::bilinear::RowTaps;
    use crate::stages::ray_plane::LANES;

    /// The forward pass's row taps: `taps_row` without the weights' derivatives (for sampling
    /// only; debug builds refuse to differentiate them).
    pub fn sampling_taps_row(u: &[f32; LANES], v: &[f32; LANES], ts: usize) -> RowTaps {
        crate::stages::bilinear::taps_row_with::<false>(u, v, ts)
    }

    /// `previous` refilled in place with the taps of `(u, v)` (`RowTaps::refill`, as the tile
    /// loops make their taps), with the weights' derivatives when `derivatives`.
    pub fn refilled_taps_row(
        mut previous: RowTaps,
        derivatives: bool,
        u: &[f32; LANES],
        v: &[f32; LANES],
        ts: usize,
    ) -> RowTaps {
        if derivatives {
            previous.refill::<true>(u, v, ts);
        } else {
            previous.refill::<false>(u, v, ts);
        }
        previous
    }

    /// The tile backward's texel backward of a chunk of lanes on one texture
    /// (`RowTaps::vjp_rgba_lanes`): `RowTaps::vjp_rgba` of each active lane, in lane order.
    pub fn vjp_rgba_lanes(
        taps: &RowTaps,
        texels: &[[f32; 4]],
        d_rgba: &[[f32; 4]; LANES],
        active: &[bool; LANES],
        emit: impl FnMut(u32, [f32; 4]),
    ) -> ([f32; LANES], [f32; LANES]) {
        taps.vjp_rgba_lanes(texels, d_rgba, active, emit)
    }
}

/// Farthest-point sampling internals (`init::fps`).
pub mod fps {
    use glam::Vec3;

    /// The better of two candidates (larger squared distance, then lower index).
    pub fn better(a: (f64, usize), b: (f64, usize)) -> (f64, usize) {
        crate::init::fps::better(a, b)
    }

    /// Spreads the low 21 bits of `x` to every third bit (the Morton code's interleave).
    pub fn spread_bits(x: u64) -> u64 {
        crate::init::fps::spread_bits(x)
    }

    /// The point in double precision, as the sampler converts it.
    pub fn to_f64(p: Vec3) -> [f64; 3] {
        crate::init::fps::to_f64(p)
    }

    /// The sampler's squared distance expression.
    pub fn squared(dx: f64, dy: f64, dz: f64) -> f64 {
        crate::init::fps::squared(dx, dy, dz)
    }

    /// The lower bound on the squared distance from `c` to the points `order` of `coords`, as
    /// the bucket of those points computes it.
    pub fn bucket_lower_bound(coords: &[[f64; 3]], order: &[usize], c: [f64; 3]) -> f64 {
        crate::init::fps::Bucket::new(coords, order).lower_bound(c)
    }
}

/// The exponential's internals (`exp_f32`).
pub mod exp_f32 {
    /// `round(x·log₂e)` as a float and as the integer read from its bits.
    pub fn exponent(x: f32) -> (f32, i32) {
        crate::exp_f32::exponent(x)
    }
}

/// Visual hull internals (`init::hull`).
pub mod hull {
    /// The square max filter of radius `radius` applied to a `width × height` mask.
    pub fn dilate_mask(coverage: &[u8], width: usize, height: usize, radius: usize) -> Vec<u8> {
        crate::init::hull::dilate_mask(coverage, width, height, radius)
    }
}

/// SSIM internals (`loss::ssim`).
pub mod ssim {
    use crate::loss::LossError;
    use crate::loss::ssim::{Cotangent, Geometry, Padding, Real};

    /// `(A1, A2, B1, B2)` of the SSIM formula.
    pub fn terms(ma: f64, mb: f64, saa: f64, sbb: f64, sab: f64) -> (f64, f64, f64, f64) {
        crate::loss::ssim::terms(ma, mb, saa, sbb, sab)
    }

    /// `[S, ∂S/∂μa, ∂S/∂Saa, ∂S/∂Sab]` for one map value.
    pub fn ssim_partials(ma: f64, mb: f64, saa: f64, sbb: f64, sab: f64) -> [f64; 4] {
        crate::loss::ssim::ssim_partials(ma, mb, saa, sbb, sab)
    }

    /// The length of the SSIM map and `∂(Σ S over the map)/∂a`, computed by the loss's own
    /// forward and backward with `partials` in place of [`ssim_partials`] (to inject faults).
    pub fn map_len_and_sum_grad<P>(
        a: &[f32],
        b: &[f32],
        w: usize,
        h: usize,
        c: usize,
        padding: Padding,
        partials: P,
    ) -> Result<(usize, Vec<f32>), LossError>
    where
        P: Fn(f64, f64, f64, f64, f64) -> [f64; 4] + Sync,
    {
        let (map_len, _, grad) = sums(a, b, (w, h, c), padding, partials)?;
        Ok((map_len, grad))
    }

    /// `[S, ∂S/∂μa, ∂S/∂Saa, ∂S/∂Sab]` for one map value in f32 (the same generic code as
    /// [`ssim_partials`]).
    pub fn ssim_partials_f32(ma: f32, mb: f32, saa: f32, sbb: f32, sab: f32) -> [f32; 4] {
        crate::loss::ssim::ssim_partials(ma, mb, saa, sbb, sab)
    }

    /// `(Σ S over the map, ∂(Σ S)/∂a)` computed in f32 (as
    /// [`crate::loss::ssim::ssim_with_grad_f32`]) with `partials` in place of the f32
    /// [`ssim_partials_f32`] (to inject faults).
    pub fn sum_and_sum_grad_f32<P>(
        a: &[f32],
        b: &[f32],
        w: usize,
        h: usize,
        c: usize,
        padding: Padding,
        partials: P,
    ) -> Result<(f64, Vec<f32>), LossError>
    where
        P: Fn(f32, f32, f32, f32, f32) -> [f32; 4] + Sync,
    {
        let (_, sum, grad) = sums(a, b, (w, h, c), padding, partials)?;
        Ok((sum, grad))
    }

    /// The map length, `Σ S` and `∂(Σ S)/∂a` in precision `R` with `partials`.
    fn sums<R: Real, P>(
        a: &[f32],
        b: &[f32],
        (w, h, c): (usize, usize, usize),
        padding: Padding,
        partials: P,
    ) -> Result<(usize, f64, Vec<f32>), LossError>
    where
        P: Fn(R, R, R, R, R) -> [R; 4] + Sync,
    {
        let geo = Geometry::new(w, h, c, padding)?;
        let pass = crate::loss::ssim::Pass {
            cot: Cotangent::Uniform(1.0),
            simd: crate::cpu::Simd::detect(),
        };
        let (sum, grad) = crate::loss::ssim::value_and_grad(a, b, &geo, pass, partials, &mut Vec::new());
        Ok((geo.map_len(), sum, grad))
    }
}

/// Spherical-harmonics kernels (`stages::sh`): the dispatched ones (SSE on x86-64) and their
/// scalar references.
pub mod sh {
    /// The dispatched coefficient pass of the colour VJP.
    pub fn coefficient_pass(
        n: usize,
        coeffs: &[f32],
        basis: &[f32; 16],
        g: [f32; 3],
        d_coeffs: &mut [f32],
        d_basis: &mut [f32; 16],
    ) {
        crate::stages::sh::coefficient_pass(n, coeffs, basis, g, d_coeffs, d_basis)
    }

    /// The scalar reference of [`coefficient_pass`].
    pub fn coefficient_pass_scalar(
        n: usize,
        coeffs: &[f32],
        basis: &[f32; 16],
        g: [f32; 3],
        d_coeffs: &mut [f32],
        d_basis: &mut [f32; 16],
    ) {
        crate::stages::sh::coefficient_pass_scalar(n, coeffs, basis, g, d_coeffs, d_basis)
    }

    /// The dispatched batched raw colours.
    pub fn raw_colours<const L: usize>(n: usize, coeffs: [&[f32]; L], basis: &[[f32; 16]; L]) -> [[f32; 3]; L] {
        crate::stages::sh::raw_colours(n, coeffs, basis)
    }

    /// The scalar reference of [`raw_colours`].
    pub fn raw_colours_scalar<const L: usize>(n: usize, coeffs: [&[f32]; L], basis: &[[f32; 16]; L]) -> [[f32; 3]; L] {
        crate::stages::sh::raw_colours_scalar(n, coeffs, basis)
    }
}

/// Model folder internals (`model_file`).
pub mod model_file {
    use crate::model_file::ModelFileError;
    use std::path::Path;

    /// The logit of a decoded probability `p` whose re-encoding by `encode` gives back `q`.
    pub fn stable_logit(p: f32, q: u8, encode: impl Fn(f32) -> u8) -> f32 {
        crate::model_file::stable_logit(p, q, encode)
    }

    /// A `.npy` file of `u8` values with the given shape.
    pub fn npy_u8(shape: &[usize], data: &[u8]) -> Vec<u8> {
        crate::model_file::npz::npy_u8(shape, data)
    }

    /// The shape and data offset of a `.npy` file of `u8` values.
    pub fn parse_npy_header(npy: &[u8]) -> Result<(Vec<usize>, usize), String> {
        crate::model_file::npz::parse_npy_header(npy)
    }

    /// The model PLY header for `count` vertices.
    pub fn ply_header(count: usize) -> String {
        crate::model_file::ply::header(count)
    }

    /// Parses a model PLY into its vertex rows.
    pub fn parse_ply(path: &Path, bytes: &[u8]) -> Result<Vec<f32>, ModelFileError> {
        crate::model_file::ply::parse(path, bytes)
    }
}

/// Rasterizer internals (`raster`).
pub mod raster {
    use crate::camera::Camera;
    use crate::raster::binning::{BinScratch, TileBins, bin_into, tile_pixels};
    use crate::raster::preprocess::Prepared;
    use crate::raster::preprocess::preprocess_into;
    use crate::raster::row_spans::BillboardRows;
    use crate::raster::tile_spans::{TileSpans, box_meets_tile, entry_spans_direct, local_spans};
    use crate::raster::{ActivatedRef, RenderSettings};
    use crate::stages::splat_transform::support_half_side;

    /// Billboards per chunk of the parallel binning.
    pub const MIN_BIN_CHUNK: usize = crate::raster::binning::MIN_BIN_CHUNK;

    /// Billboards per task of the preprocess.
    pub const PREPROCESS_CHUNK: usize = crate::raster::preprocess::PREPROCESS_CHUNK;

    /// The first and last tile `[x, y]` covered by a prepared billboard.
    pub fn tile_rect(p: &Prepared) -> ([u32; 2], [u32; 2]) {
        crate::raster::binning::tile_rect(p)
    }

    /// A `u32` whose unsigned order is [`f32::total_cmp`]'s order of `x`.
    pub fn total_order_key(x: f32) -> u32 {
        crate::raster::binning::total_order_key(x)
    }

    /// Nearest-rank quantile `q` of sorted `values` (0 when empty).
    pub fn quantile<T: Copy + Default>(sorted: &[T], q: f64) -> T {
        crate::raster::workload::quantile(sorted, q)
    }

    /// One tile entry's spans: its first and last tile row and, per tile row, its first and
    /// last column (empty when the first exceeds the last; `[1, 0]` outside the entry's rows).
    pub type Spans = ([u8; 2], [[u8; 2]; crate::raster::TILE_SIZE as usize]);

    /// One tile entry's spans computed both ways ([`entry_spans_both_ways`]).
    #[derive(Clone, Copy, Debug)]
    pub struct SpansBothWays {
        /// As the forward pass computes them: the billboard's rows cut to the tile (or, for a
        /// box that misses the tile, the per-entry computation).
        pub fast: Spans,
        /// As computed for the tile alone (the reference).
        pub reference: Spans,
        /// The pixel count the forward pass keeps with `fast`.
        pub pixels: u16,
        /// The column range the forward pass keeps with `fast`.
        pub columns: [u8; 2],
        /// Whether the billboard's pixel box meets the tile (always, for a binned entry).
        pub box_meets_tile: bool,
    }

    /// For every entry of every tile of the view, in tile order, its spans both ways. With
    /// `every_billboard` each tile's list is every prepared billboard instead of the binned
    /// ones, so that boxes missing the tile (which the forward pass never lists, and handles
    /// exactly anyway) are compared too.
    pub fn entry_spans_both_ways(
        set: &ActivatedRef<'_>,
        camera: &Camera,
        settings: &RenderSettings,
        every_billboard: bool,
    ) -> Vec<SpansBothWays> {
        let mut prepared = Vec::new();
        preprocess_into(set, camera, settings, &mut prepared);
        let (mut bins, mut scratch) = (TileBins::default(), BinScratch::default());
        bin_into(&prepared, camera.width, camera.height, &mut bins, &mut scratch);
        let half_side = support_half_side(set.texture_size);
        let mut rows = BillboardRows::default();
        rows.build(&prepared, half_side, crate::cpu::Simd::detect());
        let all: Vec<u32> = (0..prepared.len() as u32)
            .filter(|&b| prepared[b as usize].is_some())
            .collect();
        let (mut spans, mut reference) = (TileSpans::default(), TileSpans::default());
        let mut out = Vec::new();
        for t in 0..bins.tile_count() {
            let list = if every_billboard {
                &all[..]
            } else {
                &bins.entries[bins.tile_range(t)]
            };
            let (i0, j0, _, _) = tile_pixels(&bins, t, camera.width, camera.height);
            local_spans(&prepared, &rows, list, (i0, j0), half_side, &mut spans);
            reference.clear();
            for &b in list {
                let p = prepared[b as usize].as_ref().expect("listed billboards are prepared");
                entry_spans_direct(p, (i0, j0), half_side, &mut reference);
            }
            // Both as full tile rows (rows outside an entry's range left empty).
            let full = |spans: &TileSpans, k: usize| {
                let e = &spans.entries[k];
                let mut cols = [[1, 0]; crate::raster::TILE_SIZE as usize];
                for (y, &c) in (e.rows[0]..).zip(spans.row_cols(e)) {
                    cols[usize::from(y)] = c;
                }
                (e.rows, cols)
            };
            for (k, (fast, &b)) in spans.entries.iter().zip(list).enumerate() {
                let p = prepared[b as usize].as_ref().expect("listed billboards are prepared");
                out.push(SpansBothWays {
                    fast: full(&spans, k),
                    reference: full(&reference, k),
                    pixels: fast.pixels,
                    columns: fast.columns,
                    box_meets_tile: box_meets_tile(p, (i0, j0)),
                });
            }
        }
        out
    }

    /// The backward pass's per-tile texture-gradient accumulator, with a texel list it reuses
    /// across tiles as the backward does.
    #[derive(Default)]
    pub struct TexelSums(crate::raster::tile_gradients::TexelSums, Vec<(u32, [f32; 4])>);

    impl TexelSums {
        /// Prepares for a tile of `slots` entries with `texels` texels per channel.
        pub fn start(&mut self, slots: usize, texels: usize) {
            self.0.start(slots, texels)
        }

        /// Adds `g` to the cell (`slot`, `texel`).
        pub fn add(&mut self, slot: u32, texel: u32, g: [f32; 4]) {
            self.0.mark(slot);
            self.0.add(slot, texel, g)
        }

        /// The per-slot offsets and the (texel, sum) lists of the tile, resetting the cells.
        pub fn finish(&mut self, slots: usize) -> (Vec<u32>, Vec<(u32, [f32; 4])>) {
            let mut offsets = vec![0];
            self.0.finish(slots, &mut self.1, |k, (start, end)| {
                assert_eq!(
                    (k, start),
                    (offsets.len() - 1, offsets[k]),
                    "slots in order, back to back"
                );
                offsets.push(end);
            });
            (offsets, self.1.clone())
        }

        /// Whether every cell and every slot is marked untouched and every cell holds `−0.0`
        /// in each channel (the state `finish` must leave for the next tile).
        pub fn is_clean(&self) -> bool {
            use crate::raster::tile_gradients::UNTOUCHED;
            let sums = &self.0;
            sums.touched.iter().all(|&t| t == 0)
                && sums.slot_touched.iter().all(|&t| !t)
                && sums
                    .sums
                    .iter()
                    .all(|c| c.map(f32::to_bits) == UNTOUCHED.map(f32::to_bits))
        }
    }
}

/// Training internals (`train`).
pub mod train {
    /// Elements per parallel task of the non-finite scans.
    pub const FINITE_SCAN_CHUNK: usize = crate::train::finite::CHUNK;

    /// `edit` applied to the trainer's raw parameters **without** refreshing its activated copy
    /// (what [`Trainer::edit_model`](crate::train::Trainer::edit_model) does): the next step
    /// renders the previous values and its optimiser step carries the edited ones on. The tests
    /// of the after-step parameter check use it to make a value turn non-finite inside a step.
    pub fn edit_model_unsynced(
        trainer: &mut crate::train::Trainer,
        edit: impl FnOnce(&mut crate::model::RawBillboards),
    ) {
        edit(trainer.model_unsynced_mut());
    }
}

/// Sweep tool internals (`sweep`, feature `tools`).
#[cfg(feature = "tools")]
pub mod sweep {
    use crate::sweep::SweepRecord;

    /// Pareto flags per record: (PSNR vs training time, PSNR vs model size).
    pub fn fronts(records: &[SweepRecord]) -> (Vec<bool>, Vec<bool>) {
        crate::sweep::output::fronts(records)
    }

    /// A CSV field, quoted when it needs to be.
    pub fn csv_field(f: &str) -> String {
        crate::sweep::output::csv_field(f)
    }

    /// The padded plot range of the finite values.
    pub fn padded_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
        crate::sweep::plot::padded_range(values)
    }
}

/// Scene input internals (`scene`).
pub mod scene {
    /// Area-average resize of an interleaved RGB image from `w × h` to `nw × nh`.
    pub fn resize_area(src: &[f32], w: usize, h: usize, nw: usize, nh: usize) -> Vec<f32> {
        crate::scene::image_io::resize_area(src, w, h, nw, nh)
    }

    /// The loaded size of a `w × h` image for a downscale `factor` and an optional maximum width.
    pub fn target_size(w: u32, h: u32, factor: u32, max_width: Option<u32>) -> (u32, u32) {
        crate::scene::image_io::target_size(w, h, factor, max_width)
    }
}

/// Marching-cubes internals (`mesh::marching_cubes`).
pub mod marching_cubes {
    /// The triangles of one case (bit `c` set when corner `c` is inside), as local cell edges
    /// (`corner · 3 + axis`, `corner` the edge's end with the lower coordinate).
    pub fn case_triangles(case: u8) -> Vec<[u8; 3]> {
        crate::mesh::marching_cubes::triangulate_case(case)
    }
}

/// The explicit AVX2 build of the forward tile (`raster::tile_forward_avx2`): its lane-wise
/// decision and sample, to test against the scalar stages. Each gives `None` on a CPU without
/// AVX2 and FMA (or with the baseline build forced).
pub mod forward_avx2 {
    use crate::stages::bilinear::RowTaps;
    use crate::stages::composite::{CompositeParams, Step};
    use crate::stages::ray_plane::LANES;

    /// The decision of eight lanes (transmittance in front, raw alpha) as `classify`'s steps.
    #[cfg(target_arch = "x86_64")]
    pub fn classify_lanes(
        transmittance: &[f32; LANES],
        a: &[f32; LANES],
        params: &CompositeParams,
    ) -> Option<[Step; LANES]> {
        crate::raster::tile_forward_avx2::classify_lanes(transmittance, a, params)
    }

    /// The RGBA samples of every lane of `taps` (lanes without taps included: their values are
    /// unspecified).
    #[cfg(target_arch = "x86_64")]
    pub fn sample_rgba_lanes(taps: &RowTaps, texture: &[[f32; 4]]) -> Option<[[f32; 4]; LANES]> {
        crate::raster::tile_forward_avx2::sample_rgba_lanes(taps, texture)
    }

    /// The AVX2 forward's packed push of a run's blended pairs: `pairs` (each as pixel, column,
    /// row and transmittance bits) with the pairs of the lanes set in `bits` appended, the run's
    /// first lane at tile-local pixel, column and row `first` and `fronts` the lanes'
    /// transmittances; `None` without AVX2.
    #[cfg(target_arch = "x86_64")]
    pub fn push_pairs_lanes(
        pairs: &[(u16, u8, u8, u32)],
        bits: u32,
        first: (usize, usize, u8),
        fronts: &[f32; LANES],
    ) -> Option<Vec<(u16, u8, u8, u32)>> {
        crate::raster::tile_forward_avx2::push_pairs_lanes(pairs, bits, first, fronts)
    }

    /// The runs the AVX2 forward makes of an entry's spans (`rows`: the columns `[first, last]`
    /// of rows `first_row, first_row + 1, …`, a row empty when its first exceeds its last) in
    /// a tile `tw` pixels wide: per run, its lanes' tile-local pixels in lane order, and
    /// whether it has two parts.
    #[cfg(target_arch = "x86_64")]
    pub fn entry_runs(rows: &[[u8; 2]], first_row: u8, tw: usize) -> Vec<(Vec<usize>, bool)> {
        crate::raster::tile_forward_avx2::entry_runs(rows, first_row, tw)
    }
}

/// The tile passes' scheduling (`raster::schedule`).
pub mod schedule {
    /// `map_heaviest_first`: `work(scratch, index, item)` on every item, on the current rayon
    /// pool, handed out in order of decreasing `cost` (ties by index); results in item order.
    pub fn map_heaviest_first<T: Send, R: Send, S>(
        items: Vec<T>,
        cost: impl Fn(usize) -> u64,
        init: impl Fn() -> S + Sync,
        work: impl Fn(&mut S, usize, T) -> R + Sync,
    ) -> Vec<R> {
        crate::raster::schedule::map_heaviest_first(items, cost, init, work)
    }
}
