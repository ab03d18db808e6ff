//! A check of a capture's registration that frames of one video allow: consecutive frames turn
//! by a few degrees, never by more than a right angle.
//!
//! Structure-from-motion can register part of an orbit around a nearly symmetric object (a can on
//! a square-tiled floor) on top of the rest, turned by about 180° about the object's axis. Every
//! image then fits its own points well, and nothing in the reconstruction's errors shows it, but
//! views placed side by side see opposite sides of the room, and no static model fits both: on
//! beer_colmap this cost 3.5 dB (`docs/quality-log.md`, "beer_colmap: the registration is folded").
//! Where such a registration meets the rest, two frames taken a moment apart are registered facing
//! nearly opposite ways, which [`sharp_turns`] finds in the frames' order. The COLMAP loader then
//! tries to turn the folded passes back ([`super::unfold`]) and warns with these words when it
//! cannot (or is told not to).
//!
//! Images named in capture order are what a video gives; a collection of photographs in no order
//! turns sharply between many of its neighbours, so [`folded_registration_warning`] speaks only when
//! sharp turns are rare (at most one pair in [`MAX_SHARP_SHARE`]).

use crate::camera::Camera;

/// Consecutive frames turning by more than this (degrees) cannot be neighbours in one video.
pub const SHARP_TURN_DEG: f64 = 90.0;

/// A warning needs the sharp turns to be at most one consecutive pair in this many (more, and the
/// images are not in capture order).
pub const MAX_SHARP_SHARE: usize = 10;

/// Two consecutive frames registered facing directions more than [`SHARP_TURN_DEG`] apart.
#[derive(Clone, Debug, PartialEq)]
pub struct SharpTurn {
    /// Index of the first frame of the pair (the second is `index + 1`).
    pub index: usize,
    /// The rotation between the two frames' orientations, in degrees (0 to 180).
    pub degrees: f64,
}

/// The angle in degrees (0 to 180) of the rotation between two world-to-camera rotations, in f64.
pub fn turn_degrees(a: &Camera, b: &Camera) -> f64 {
    super::unfold::angle_of(a.rotation.as_dmat3() * b.rotation.as_dmat3().transpose()).to_degrees()
}

/// The consecutive pairs of `cameras` (in capture order) that turn by more than
/// [`SHARP_TURN_DEG`].
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::scene::registration::sharp_turns;
/// use glam::Mat3;
/// let facing = |angle: f32| Camera { rotation: Mat3::from_rotation_y(angle), ..Camera::identity(100, 100) };
/// let cams = [facing(0.0), facing(0.1), facing(0.2), facing(3.3), facing(3.4)];
/// let turns = sharp_turns(&cams);
/// assert_eq!(turns.len(), 1);
/// assert_eq!(turns[0].index, 2);
/// assert!((turns[0].degrees - 3.1f64.to_degrees()).abs() < 1e-3);
/// ```
pub fn sharp_turns(cameras: &[Camera]) -> Vec<SharpTurn> {
    let rotations: Vec<glam::DMat3> = cameras.iter().map(|c| c.rotation.as_dmat3()).collect();
    sharp_turns_of(&rotations)
}

/// [`sharp_turns`] of world-to-camera rotations in f64 (what [`super::unfold::plan`] splits
/// passes at).
pub fn sharp_turns_of(rotations: &[glam::DMat3]) -> Vec<SharpTurn> {
    rotations
        .windows(2)
        .enumerate()
        .filter_map(|(index, pair)| {
            let degrees = super::unfold::angle_of(pair[0] * pair[1].transpose()).to_degrees();
            (degrees > SHARP_TURN_DEG).then_some(SharpTurn { index, degrees })
        })
        .collect()
}

/// The warning for a capture whose frames, in the order of `names` and `cameras`, turn sharply
/// between a few neighbours; `None` when no pair does, or when so many do (more than one pair in
/// [`MAX_SHARP_SHARE`]) that the images are not frames in capture order.
///
/// # Panics
/// If `names` and `cameras` differ in length.
pub fn folded_registration_warning(names: &[&str], cameras: &[Camera]) -> Option<String> {
    assert_eq!(names.len(), cameras.len(), "a name per camera");
    let turns = sharp_turns(cameras);
    let pairs = cameras.len().saturating_sub(1);
    if turns.is_empty() || turns.len() * MAX_SHARP_SHARE > pairs.max(MAX_SHARP_SHARE) {
        return None;
    }
    let listed: Vec<String> = turns
        .iter()
        .map(|t| format!("{} -> {} by {:.0} deg", names[t.index], names[t.index + 1], t.degrees))
        .collect();
    Some(format!(
        "{} of {pairs} consecutive image pairs (in name order) are registered facing more than \
         {SHARP_TURN_DEG:.0} deg apart: {}. If the images are frames of one video, the \
         registration may have folded part of the capture onto the rest (a nearly symmetric \
         object), and no model fits both halves (docs/scene.md, \"Folded registrations\")",
        turns.len(),
        listed.join(", ")
    ))
}
