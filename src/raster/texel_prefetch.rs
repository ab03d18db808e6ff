//! The texel prefetches of the entry-by-entry tile walks: the rectangle of an entry's texture
//! that its pixels in a tile read ([`texel_footprint`]), asked into the caches a few entries
//! ahead of its use ([`TexelPrefetch`] in the forward; the backward keeps its own ring). No
//! effect on values.

use super::input::ActivatedRef;
use super::prefetch::{prefetch_ptr, prefetch_ptr_l2, prefetch_record};
use super::preprocess::Prepared;
use super::tile_spans::EntrySpans;

/// A texel rectangle `(c0, r0, c1, r1)` (inclusive columns and rows) of a `ts × ts` texture.
pub(crate) type TexelRect = (usize, usize, usize, usize);

/// The texel prefetches of the forward tile loops: before entry `k` of a tile, the texels of
/// the entry [`Self::L2_AHEAD`] ahead into the second-level cache, and those of the next entry
/// into the first level, from the rectangle found then (kept in a ring). Texels fetched into
/// the first level six entries ahead were presumably evicted again by the entries in between
/// (this form is 7 % faster, docs/perf.md; the eviction itself was not measured). No effect
/// on values.
#[derive(Default)]
pub(crate) struct TexelPrefetch {
    /// Slot `k % RING`: entry `k`'s billboard and texel rectangle (none when not prefetched).
    footprints: [Option<(usize, TexelRect)>; Self::RING],
}

impl TexelPrefetch {
    const L2_AHEAD: usize = 6;
    const RING: usize = 8;

    /// The prefetches before entry `k` of a tile at `(i0, j0)` with list `list` and spans
    /// `spans` (`k` from 0 up, in order; a new tile starts at `k = 0`): the record of the
    /// entry 12 ahead, the texels of the one [`Self::L2_AHEAD`] ahead into the second level
    /// (and at `k = 0` those of the entries before it), and those of entry `k + 1` into the
    /// first level.
    #[inline(always)]
    pub(crate) fn ahead(
        &mut self,
        set: &ActivatedRef<'_>,
        prepared: &[Option<Prepared>],
        list: &[u32],
        spans: &[EntrySpans],
        k: usize,
        (i0, j0): (u32, u32),
    ) {
        const { assert!(Self::L2_AHEAD < Self::RING, "the ring holds the entries in flight") };
        let ts = set.texture_size;
        if let Some(&ahead) = list.get(k + 12) {
            prefetch_record(&prepared[ahead as usize]);
        }
        let footprint = |e: usize| {
            let (&b, span) = (list.get(e)?, spans.get(e)?);
            let pa = prepared[b as usize].as_ref()?;
            let rect = span_rect(span).and_then(|r| texel_footprint(pa, r, (i0, j0), ts, usize::from(span.pixels)))?;
            prefetch_texel_rect_l2(set.texture_of(b as usize).as_ptr(), ts, rect);
            Some((b as usize, rect))
        };
        let first = if k == 0 { 1 } else { k + Self::L2_AHEAD };
        for e in first..=k + Self::L2_AHEAD {
            self.footprints[e % Self::RING] = footprint(e);
        }
        if let Some((b, rect)) = self.footprints[(k + 1) % Self::RING] {
            prefetch_texel_rect(set.texture_of(b).as_ptr(), ts, rect);
        }
    }
}

/// The tile-local pixel rectangle `(x0, y0, x1, y1)` (inclusive) holding an entry's span, or
/// `None` when the span is empty.
fn span_rect(span: &EntrySpans) -> Option<(u8, u8, u8, u8)> {
    let ([x0, x1], [y0, y1]) = (span.columns, span.rows);
    (x0 <= x1).then_some((x0, y0, x1, y1))
}

/// The texel rectangle `(c0, r0, c1, r1)` (inclusive) that the pixels of the tile-local
/// rectangle `(x0, y0, x1, y1)` of the tile at `(i0, j0)` read from the texture of `p`: the
/// rectangle of the plane coordinates of its corners (a projective map sends the rectangle into
/// the hull of its corners' images while the plane stays in front of the camera), widened by
/// the second tap. For prefetches only: a wrong rectangle only wastes them. `None` when a
/// corner has no finite plane coordinates, or when the rectangle holds more than
/// [`FOOTPRINT_TEXELS_PER_PIXEL`] texels per sampling pixel (`pixels` of them): a billboard a
/// few pixels wide has a footprint of the whole texture of which its pixels read a few texels,
/// and fetching all of it costs more than the misses it saves.
pub(crate) fn texel_footprint(
    p: &Prepared,
    (x0, y0, x1, y1): (u8, u8, u8, u8),
    (i0, j0): (u32, u32),
    ts: usize,
    pixels: usize,
) -> Option<TexelRect> {
    let t = &p.transform;
    let (mut u_lo, mut u_hi, mut v_lo, mut v_hi) = (f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY);
    // One corner when the rectangle is a single pixel (the common case of small billboards).
    let corners = if (x0, y0) == (x1, y1) { 1 } else { 4 };
    for (x, y) in [(x0, y0), (x1, y0), (x0, y1), (x1, y1)].into_iter().take(corners) {
        let px = (i0 + u32::from(x)) as f32 + 0.5;
        let py = (j0 + u32::from(y)) as f32 + 0.5;
        let h = (px * t.tw - t.tu).cross(py * t.tw - t.tv);
        let (u, v) = (h.x / h.z, h.y / h.z);
        u_lo = u_lo.min(u);
        u_hi = u_hi.max(u);
        v_lo = v_lo.min(v);
        v_hi = v_hi.max(v);
    }
    if !(u_lo.is_finite() && u_hi.is_finite() && v_lo.is_finite() && v_hi.is_finite()) {
        return None;
    }
    let last = (ts - 1) as f32;
    let texel = |c: f32| (((c.clamp(-1.0, 1.0) + 1.0) * 0.5 * last) as usize).min(ts - 1);
    let (c0, r0) = (texel(u_lo), texel(v_lo));
    let (c1, r1) = ((texel(u_hi) + 1).min(ts - 1), (texel(v_hi) + 1).min(ts - 1));
    ((c1 - c0 + 1) * (r1 - r0 + 1) <= FOOTPRINT_TEXELS_PER_PIXEL * pixels).then_some((c0, r0, c1, r1))
}

/// See [`texel_footprint`]: a bilinear sample reads 4 texels, so 8 per pixel allows for the
/// rectangle's slack around the pixels' samples.
pub(crate) const FOOTPRINT_TEXELS_PER_PIXEL: usize = 8;

/// Hints the CPU to fetch the cache lines of the texel rectangle `(c0, r0, c1, r1)` of a
/// row-major `ts × ts` per-texel array starting at `texels` (a texture, a gradient row, a cell
/// index). `texels` is never dereferenced.
#[inline]
pub(crate) fn prefetch_texel_rect<T>(texels: *const T, ts: usize, rect: TexelRect) {
    prefetch_rect_with(texels, ts, rect, prefetch_ptr);
}

/// [`prefetch_texel_rect`] into the second-level cache only ([`prefetch_ptr_l2`]).
#[inline]
pub(crate) fn prefetch_texel_rect_l2<T>(texels: *const T, ts: usize, rect: TexelRect) {
    prefetch_rect_with(texels, ts, rect, prefetch_ptr_l2);
}

/// `prefetch` on the first byte of every cache line of the rectangle (see
/// [`prefetch_texel_rect`]).
#[inline(always)]
fn prefetch_rect_with<T>(texels: *const T, ts: usize, (c0, r0, c1, r1): TexelRect, prefetch: fn(*const u8)) {
    let per_line = (64 / size_of::<T>().max(1)).max(1);
    for r in r0..=r1 {
        let row = texels.wrapping_add(r * ts);
        let mut c = c0;
        while c <= c1 {
            prefetch(row.wrapping_add(c).cast::<u8>());
            c += per_line;
        }
        prefetch(row.wrapping_add(c1).cast::<u8>());
    }
}
