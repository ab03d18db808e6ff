//! Per-billboard preprocessing: transform, normal, depth, SH colour and a tight screen box.

use super::input::{ActivatedRef, RenderSettings};
use crate::camera::{Camera, offset_from};
use crate::memory::resize_for_overwrite;
use crate::stages::ray_plane::ViewPlane;
use crate::stages::sh::{ShColour, sh_colour, sh_colour_batch};
use crate::stages::splat_transform::{
    SplatFrame, SplatTransform, splat_frame, splat_frames_x4, square_screen_bounds, support_half_side, view_plane,
};
use glam::Vec3;
use rayon::prelude::*;

/// What the per-pixel passes need of one visible billboard.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prepared {
    /// Rows of the ray-splat matrix `T`.
    pub transform: SplatTransform,
    /// Unit normal in view space, flipped to face the camera ([`view_plane`]: the f64 normal of
    /// the raw parameters, rounded once).
    pub normal: Vec3,
    /// `normal · p_view` in f64, rounded once ([`view_plane`]): with `normal` the plane of the
    /// hit depths ([`Prepared::view_plane`]).
    pub plane_offset: f32,
    /// View-space depth of the centre, the sort key.
    pub depth: f32,
    /// SH colour (`Σ + 0.5`, clamped at 0), added to the sampled colour texture.
    pub rgb: Vec3,
    /// Per channel: the SH colour was clamped to 0 ([`crate::stages::sh::ShColour::clamped`]),
    /// kept for the backward pass.
    pub sh_clamped: [bool; 3],
    /// The plane's normal was flipped to face the camera (`normal_sign = −1` of
    /// [`crate::stages::splat_transform::SplatFrame`]), kept for the backward pass.
    pub normal_flipped: bool,
    /// First pixel column and row whose centre lies in the screen box (inclusive).
    pub pixel_min: [u32; 2],
    /// Last pixel column and row whose centre lies in the screen box (inclusive).
    pub pixel_max: [u32; 2],
}

/// Prepares one billboard; `None` when it cannot contribute to any pixel of this view (behind
/// the near plane, exactly edge-on, degenerate, or off screen).
///
/// The plain per-billboard reference of [`preprocess`] (which gives the same records bit for
/// bit, its SH colours evaluated several billboards at a time).
pub fn prepare_one(set: &ActivatedRef<'_>, i: usize, camera: &Camera, settings: &RenderSettings) -> Option<Prepared> {
    let mut prepared = prepare_geometry(set, i, camera)?;
    let colour = sh_colour(settings.sh_degree, set.sh_of(i), camera.view_offset(set.positions[i]));
    set_colour(&mut prepared, colour);
    Some(prepared)
}

/// [`prepare_one`] without the SH colour (`rgb` zero, no channel clamped).
fn prepare_geometry(set: &ActivatedRef<'_>, i: usize, camera: &Camera) -> Option<Prepared> {
    let projected = splat_frame(set.positions[i], set.log_scales[i], set.quaternions[i], camera)?;
    geometry_record(&projected, support_half_side(set.texture_size), set, i, camera)
}

impl Prepared {
    /// The billboard's plane for hit depths ([`ViewPlane`]).
    #[inline(always)]
    pub fn view_plane(&self) -> ViewPlane {
        ViewPlane {
            normal: self.normal,
            offset: self.plane_offset,
        }
    }
}

/// The record of billboard `i` of `set`, whose frame is `projected` (SH colour unset), or
/// `None` when the tight box of its texture support square (half side `half_side`, clipped by
/// the near plane) holds no pixel centre of the image. The plane ([`view_plane`]) replaces the
/// frame's normal.
///
/// Every field is computed before the record is made, so that the caller can write it straight
/// into its slot: built in steps and passed by value, the 88-byte record was copied through the
/// stack with loads that overlapped the halves of earlier stores, each a stall of the store
/// forwarding (about a fifth of the preprocess on the 256²/50k scene, `docs/perf.md`).
#[inline(always)]
fn geometry_record(
    projected: &SplatFrame,
    half_side: f32,
    set: &ActivatedRef<'_>,
    i: usize,
    camera: &Camera,
) -> Option<Prepared> {
    let rect = square_screen_bounds(&projected.transform, half_side)?.pixel_rect(camera.width, camera.height)?;
    let normal_flipped = projected.normal_sign < 0.0;
    let sign = if normal_flipped { -1.0 } else { 1.0 };
    let (normal, plane_offset) = view_plane(set.positions[i], set.quaternions[i], camera, sign);
    Some(Prepared {
        transform: projected.transform,
        normal,
        plane_offset,
        depth: projected.view_depth,
        rgb: Vec3::ZERO,
        sh_clamped: [false; 3],
        normal_flipped,
        pixel_min: [rect.x_min, rect.y_min],
        pixel_max: [rect.x_max - 1, rect.y_max - 1],
    })
}

#[inline]
fn set_colour(prepared: &mut Prepared, colour: ShColour) {
    prepared.rgb = colour.rgb;
    prepared.sh_clamped = colour.clamped;
}

/// Billboards per task of [`preprocess_into`].
pub(crate) const PREPROCESS_CHUNK: usize = 256;

/// SH colours evaluated together by [`preprocess_into`] ([`sh_colour_batch`]).
const SH_BATCH: usize = 4;

/// Prepares every billboard in parallel; entry `i` belongs to billboard `i`.
pub fn preprocess(set: &ActivatedRef<'_>, camera: &Camera, settings: &RenderSettings) -> Vec<Option<Prepared>> {
    let mut prepared = Vec::new();
    preprocess_into(set, camera, settings, &mut prepared);
    prepared
}

/// [`preprocess`] into `prepared`, reusing its storage (its old values are all replaced).
/// Returns the number of billboards with a non-finite position, log-scale or quaternion
/// component (all of them culled; counted among the culled ones only, so the check costs nothing
/// for the billboards that are kept).
///
/// Each task takes `PREPROCESS_CHUNK` (256) billboards: first their geometry, the splat frames four
/// at a time ([`splat_frames_x4`], in vector lanes: 6-17 % less time for the whole preprocess
/// on the benchmark scene, depending on the host's phase, `docs/perf-log.md`), then the SH colours
/// of those that
/// survived, `SH_BATCH` (4) at a time ([`sh_colour_batch`], whose interleaved dependency chains
/// take 21.8 ns a colour against 36.5 ns one at a time, `cargo bench --features bench --bench appearance --
/// eval`). Every record equals [`prepare_one`]'s bit for bit (tested).
pub fn preprocess_into(
    set: &ActivatedRef<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    prepared: &mut Vec<Option<Prepared>>,
) -> u64 {
    let degree = settings.sh_degree;
    let centre = camera.centre_f64();
    let half_side = support_half_side(set.texture_size);
    resize_for_overwrite(prepared, set.len(), None)
        .par_chunks_mut(PREPROCESS_CHUNK)
        .enumerate()
        .map_init(Vec::new, |live: &mut Vec<usize>, (c, out)| {
            let first = c * PREPROCESS_CHUNK;
            live.clear();
            let mut non_finite = 0u64;
            let whole = out.len() / 4 * 4;
            for (g, group) in out[..whole].chunks_exact_mut(4).enumerate() {
                let i0 = first + 4 * g;
                let four = i0..i0 + 4;
                let frames = splat_frames_x4(
                    set.positions[four.clone()].try_into().expect("four positions"),
                    set.log_scales[four.clone()].try_into().expect("four log-scales"),
                    set.quaternions[four].try_into().expect("four quaternions"),
                    camera,
                );
                for (l, (slot, frame)) in group.iter_mut().zip(&frames).enumerate() {
                    *slot = frame
                        .as_ref()
                        .and_then(|f| geometry_record(f, half_side, set, i0 + l, camera));
                    if slot.is_some() {
                        live.push(4 * g + l);
                    } else {
                        non_finite += u64::from(has_non_finite_geometry(set, i0 + l));
                    }
                }
            }
            for k in whole..out.len() {
                out[k] = prepare_geometry(set, first + k, camera);
                if out[k].is_some() {
                    live.push(k);
                } else {
                    non_finite += u64::from(has_non_finite_geometry(set, first + k));
                }
            }
            let mut groups = live.chunks_exact(SH_BATCH);
            for group in &mut groups {
                let index: [usize; SH_BATCH] = std::array::from_fn(|l| first + group[l]);
                let colours = sh_colour_batch(
                    degree,
                    index.map(|i| set.sh_of(i)),
                    index.map(|i| offset_from(centre, set.positions[i])),
                );
                for (&k, colour) in group.iter().zip(colours) {
                    if let Some(p) = out[k].as_mut() {
                        set_colour(p, colour);
                    }
                }
            }
            for &k in groups.remainder() {
                if let Some(p) = out[k].as_mut() {
                    set_colour(
                        p,
                        sh_colour(
                            degree,
                            set.sh_of(first + k),
                            offset_from(centre, set.positions[first + k]),
                        ),
                    );
                }
            }
            non_finite
        })
        .sum()
}

/// Per billboard of `set`, whether [`preprocess`] keeps it for `camera` (it has a record: the
/// view can read its textures and send it a gradient), into `kept` (resized to one flag per
/// billboard). The geometry of [`prepare_one`] without the SH colour: the same decisions as
/// [`preprocess_into`], which gives the records of [`prepare_one`] bit for bit.
pub fn kept_rows_into(set: &ActivatedRef<'_>, camera: &Camera, kept: &mut Vec<bool>) {
    resize_for_overwrite(kept, set.len(), false)
        .par_chunks_mut(PREPROCESS_CHUNK)
        .enumerate()
        .for_each(|(c, out)| {
            for (k, slot) in out.iter_mut().enumerate() {
                *slot = prepare_geometry(set, c * PREPROCESS_CHUNK + k, camera).is_some();
            }
        });
}

/// Billboard `i` of `set` has a non-finite position, log-scale or quaternion component.
#[inline]
fn has_non_finite_geometry(set: &ActivatedRef<'_>, i: usize) -> bool {
    !(set.positions[i].is_finite() && set.log_scales[i].is_finite() && set.quaternions[i].iter().all(|x| x.is_finite()))
}
