//! Undoing a folded registration of an orbit video.
//!
//! When a camera circles a nearly symmetric object (a can on a square-tiled floor), structure
//! from motion can register part of the orbit on top of the rest, turned by about 180° about the
//! object's axis ([`super::registration`] finds the sharp turns this leaves between consecutive
//! frames). [`plan`] explains those turns as such folds or says why it cannot; [`Unfolding`]
//! turns each pass back.
//!
//! Frames are taken in capture order (names). A *pass* starts at every turn of more than
//! [`super::registration::SHARP_TURN_DEG`] between consecutive frames. At a boundary, the pose of
//! the pass's first frame is predicted from the previous pass's last two (the same turn and move
//! again: `R₊ = (R₁R₀ᵀ)R₁`, `C₊ = 2C₁ − C₀`, world-to-camera rotations `R`, centres `C`); the
//! *fold* is the rotation `R₊ᵀR` between prediction and registration. The folds' mean axis `a`
//! is the object's axis; the pivot `p` is the least-squares point nearest to every frame's
//! optical axis (what the orbit looks at). Each pass after the first (in order, each against the
//! previous one already turned) is turned about the line `(p, a)` by the angle `θ` that brings
//! its first frame's rotation closest to the prediction, in closed form: with `M = R₊ᵀR` and
//! `[a]×` the cross-product matrix, `θ = atan2(tr([a]×ᵀM), tr M − aᵀMa)` maximises
//! `tr(Rot(a, θ)ᵀ M)`. A frame's pose becomes `R' = R·Rot(a, θ)ᵀ`, `C' = p + Rot(a, θ)(C − p)`.
//!
//! The explanation is accepted only if every boundary looks like a fold of one orbit (thresholds
//! below; beer_colmap shows folds of 177-180°, axes within a few degrees of each other, and
//! residuals of 1.3-2.9° and 1.1-1.4 steps): a fold angle near 180°, an axis near the mean, and
//! after the turn a first frame within a few degrees of the prediction and within a few of the
//! previous pass's steps of its predicted centre. A jump to another video or a photo
//! collection in no order fails these, and the poses are then left alone (the warning of
//! [`super::registration`] remains).
//!
//! The folds are looked for only where the frames show that they are an ordered video: within
//! each pass, consecutive frames turn by at most [`MAX_VIDEO_TURN_DEG`] and no step is longer
//! than [`MAX_VIDEO_STEP_RATIO`] times the pass's median step ([`video_evidence`]; beer_colmap's
//! passes turn by at most 13.8° a frame and step at most 1.88 times their median,
//! `tests/suite/scene_real_data.rs`). A collection of
//! photographs, even one whose sharp turns happen to sit where folds would, moves unevenly
//! between its neighbours and is left as registered (with the warning).
//!
//! All arithmetic in f64.

use glam::{DMat3, DVec3};
use std::ops::Range;

/// A boundary's fold must turn by at least this much (degrees); a symmetric fold turns by 180.
pub const MIN_FOLD_DEG: f64 = 150.0;
/// A fold's axis must lie within this angle (degrees) of the folds' mean axis.
pub const MAX_AXIS_SPREAD_DEG: f64 = 15.0;
/// After its turn, a pass's first frame must face within this (degrees) of the prediction.
pub const MAX_RESIDUAL_TURN_DEG: f64 = 10.0;
/// ... and its centre lie within this many of the previous pass's last steps of the predicted one.
pub const MAX_RESIDUAL_STEPS: f64 = 3.0;

/// Consecutive frames of one pass of a video turn by at most this much (degrees).
pub const MAX_VIDEO_TURN_DEG: f64 = 30.0;
/// ... and no step of a pass (its centre's move between consecutive frames) is longer than this
/// many times the pass's median step.
pub const MAX_VIDEO_STEP_RATIO: f64 = 5.0;

/// A frame's registered pose: world-to-camera rotation and camera centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// World-to-camera rotation (rows are the camera axes in world coordinates).
    pub rotation: DMat3,
    /// Camera centre in world coordinates.
    pub centre: DVec3,
}

/// What happened at one pass boundary.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Boundary {
    /// The first frame of the new pass.
    pub first: usize,
    /// Angle of the fold (degrees).
    pub fold_deg: f64,
    /// Angle between the fold's axis and the mean axis (degrees).
    pub axis_spread_deg: f64,
    /// The turn given to the pass (degrees, 0 to 360).
    pub turn_deg: f64,
    /// After the turn: the first frame's rotation against the prediction (degrees).
    pub residual_turn_deg: f64,
    /// After the turn: its centre's distance from the prediction, in the previous pass's last
    /// steps.
    pub residual_steps: f64,
}

/// How to turn the passes of a folded registration back.
#[derive(Clone, Debug, PartialEq)]
pub struct Unfolding {
    /// The passes, as ranges of frame indices.
    pub passes: Vec<Range<usize>>,
    /// The object's axis (unit).
    pub axis: DVec3,
    /// A point on it: what the orbit looks at.
    pub pivot: DVec3,
    /// The turn of each pass, radians (0 for the first).
    pub turns: Vec<f64>,
    /// The boundaries, in order.
    pub boundaries: Vec<Boundary>,
}

/// The result of [`plan`].
#[derive(Clone, Debug, PartialEq)]
pub enum Plan {
    /// No sharp turn between consecutive frames: one pass, nothing to do.
    OnePass,
    /// Sharp turns that are not folds of one orbit (the reason).
    NotFolds(String),
    /// Folds, and how to undo them.
    Unfold(Unfolding),
}

/// The angle (radians, 0 to π) of the rotation `m`, from its trace.
pub fn angle_of(m: DMat3) -> f64 {
    ((m.x_axis.x + m.y_axis.y + m.z_axis.z - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
}

/// The unit axis of the rotation `m` (any unit vector for the identity). Near 180° the
/// antisymmetric part vanishes and the axis is the longest column of `(m + I)/2`.
fn axis_of(m: DMat3) -> DVec3 {
    let v = DVec3::new(
        m.y_axis.z - m.z_axis.y,
        m.z_axis.x - m.x_axis.z,
        m.x_axis.y - m.y_axis.x,
    );
    if v.length() > 1e-6 {
        return v.normalize();
    }
    let s = (m + DMat3::IDENTITY) * 0.5;
    [s.x_axis, s.y_axis, s.z_axis]
        .into_iter()
        .max_by(|a, b| a.length().total_cmp(&b.length()))
        .filter(|c| c.length() > 1e-9)
        .map_or(DVec3::X, |c| c.normalize())
}

/// The pose predicted after `b` if the frames go on turning and moving as from `a` to `b`.
fn predicted(a: &Pose, b: &Pose) -> Pose {
    Pose {
        rotation: b.rotation * a.rotation.transpose() * b.rotation,
        centre: 2.0 * b.centre - a.centre,
    }
}

/// The least-squares point nearest to every frame's optical axis; `None` when the axes are
/// (nearly) parallel.
fn pivot(poses: &[Pose]) -> Option<DVec3> {
    crate::camera::nearest_to_lines(poses.iter().map(|p| (p.centre, p.rotation.row(2))))
}

/// The angle `θ` maximising `tr(Rot(axis, θ)ᵀ m)`, in `[0, 2π)`.
fn best_turn(axis: DVec3, m: DMat3) -> f64 {
    let aa = axis.dot(m * axis);
    let trace = m.x_axis.x + m.y_axis.y + m.z_axis.z;
    // tr([a]×ᵀ M) for [a]× = [[0, −a_z, a_y], [a_z, 0, −a_x], [−a_y, a_x, 0]] (rows).
    let cross =
        axis.x * (m.y_axis.z - m.z_axis.y) + axis.y * (m.z_axis.x - m.x_axis.z) + axis.z * (m.x_axis.y - m.y_axis.x);
    cross.atan2(trace - aa).rem_euclid(std::f64::consts::TAU)
}

/// The passes of `poses` (capture order): a new one starts after every turn of more than
/// [`super::registration::SHARP_TURN_DEG`] between consecutive frames.
pub fn passes(poses: &[Pose]) -> Vec<Range<usize>> {
    let rotations: Vec<DMat3> = poses.iter().map(|p| p.rotation).collect();
    let starts = super::registration::sharp_turns_of(&rotations)
        .into_iter()
        .map(|t| t.index + 1);
    let bounds: Vec<usize> = std::iter::once(0).chain(starts).chain([poses.len()]).collect();
    bounds.windows(2).map(|w| w[0]..w[1]).collect()
}

/// How one pass moves from frame to frame: its sharpest turn between consecutive frames and
/// its longest step over its median step, each with the frame that starts it (indices into
/// the pass).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PassMotion {
    /// The largest turn between consecutive frames (degrees) and the frame before it.
    pub sharpest_turn: (f64, usize),
    /// The longest step over the median step (0 for a pass of fewer than three frames) and the
    /// frame before it.
    pub longest_step: (f64, usize),
}

/// The [`PassMotion`] of `frames` (one pass, capture order).
pub fn pass_motion(frames: &[Pose]) -> PassMotion {
    let largest = |values: &[f64]| {
        values
            .iter()
            .copied()
            .enumerate()
            .fold((0.0, 0), |best, (i, v)| if v > best.0 { (v, i) } else { best })
    };
    let turns: Vec<f64> = frames
        .windows(2)
        .map(|w| angle_of(w[0].rotation * w[1].rotation.transpose()).to_degrees())
        .collect();
    let steps: Vec<f64> = frames
        .windows(2)
        .map(|w| (w[1].centre - w[0].centre).length())
        .collect();
    let longest_step = if steps.len() < 2 {
        (0.0, 0)
    } else {
        let mut sorted = steps.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2].max(f64::MIN_POSITIVE);
        let (longest, at) = largest(&steps);
        (longest / median, at)
    };
    PassMotion {
        sharpest_turn: largest(&turns),
        longest_step,
    }
}

/// `Ok` when every pass of `poses` moves as frames of a video do (module documentation), else
/// the first pass and step that does not.
///
/// # Errors
/// The reason, naming the frames.
pub fn video_evidence(poses: &[Pose], passes: &[Range<usize>]) -> Result<(), String> {
    for pass in passes {
        let motion = pass_motion(&poses[pass.clone()]);
        let (turn, k) = motion.sharpest_turn;
        if turn > MAX_VIDEO_TURN_DEG {
            return Err(format!(
                "frames {} and {} turn by {turn:.0} deg: not neighbours in a video",
                pass.start + k,
                pass.start + k + 1
            ));
        }
        let (ratio, k) = motion.longest_step;
        if ratio > MAX_VIDEO_STEP_RATIO {
            return Err(format!(
                "frames {} and {} are {ratio:.1} median steps apart: the images are not frames of a video in capture order",
                pass.start + k,
                pass.start + k + 1,
            ));
        }
    }
    Ok(())
}

/// Explains the sharp turns between consecutive `poses` (capture order) as folds of one orbit,
/// or says why not. See the module documentation.
pub fn plan(poses: &[Pose]) -> Plan {
    let passes = passes(poses);
    if passes.len() == 1 {
        return Plan::OnePass;
    }
    if let Some(short) = passes[..passes.len() - 1].iter().find(|p| p.len() < 2) {
        return Plan::NotFolds(format!(
            "the pass of frames {}..{} is too short to predict the next one from",
            short.start, short.end
        ));
    }
    if let Err(reason) = video_evidence(poses, &passes) {
        return Plan::NotFolds(reason);
    }
    let Some(pivot) = pivot(poses) else {
        return Plan::NotFolds("the cameras' optical axes are parallel: no object they circle".into());
    };
    // The folds, against the registered (not yet turned) passes.
    let mut folds = Vec::new();
    for k in 1..passes.len() {
        let prev = &passes[k - 1];
        let guess = predicted(&poses[prev.end - 2], &poses[prev.end - 1]);
        let fold = guess.rotation.transpose() * poses[passes[k].start].rotation;
        folds.push((angle_of(fold), axis_of(fold)));
    }
    let mut axis_sum = DVec3::ZERO;
    for (_, a) in &folds {
        axis_sum += if a.dot(axis_sum) < 0.0 { -*a } else { *a };
    }
    let axis = axis_sum.normalize();
    let mut turned: Vec<Pose> = poses.to_vec();
    let mut turns = vec![0.0];
    let mut boundaries = Vec::new();
    for k in 1..passes.len() {
        let prev = passes[k - 1].clone();
        let guess = predicted(&turned[prev.end - 2], &turned[prev.end - 1]);
        let step = (turned[prev.end - 1].centre - turned[prev.end - 2].centre).length();
        let first = passes[k].start;
        let turn = best_turn(axis, guess.rotation.transpose() * turned[first].rotation);
        let rot = DMat3::from_axis_angle(axis, turn);
        for pose in &mut turned[passes[k].clone()] {
            pose.rotation *= rot.transpose();
            pose.centre = pivot + rot * (pose.centre - pivot);
        }
        let (fold, fold_axis) = folds[k - 1];
        boundaries.push(Boundary {
            first,
            fold_deg: fold.to_degrees(),
            axis_spread_deg: fold_axis.dot(axis).abs().clamp(0.0, 1.0).acos().to_degrees(),
            turn_deg: turn.to_degrees(),
            residual_turn_deg: angle_of(turned[first].rotation * guess.rotation.transpose()).to_degrees(),
            residual_steps: (turned[first].centre - guess.centre).length() / step.max(1e-12),
        });
        turns.push(turn);
    }
    for b in &boundaries {
        let at = format!("at frame {}", b.first);
        if b.fold_deg < MIN_FOLD_DEG {
            return Plan::NotFolds(format!(
                "{at} the registration turns by {:.0} deg, not about 180",
                b.fold_deg
            ));
        }
        if b.axis_spread_deg > MAX_AXIS_SPREAD_DEG {
            return Plan::NotFolds(format!(
                "{at} the turn's axis is {:.0} deg off the others'",
                b.axis_spread_deg
            ));
        }
        if b.residual_turn_deg > MAX_RESIDUAL_TURN_DEG || b.residual_steps > MAX_RESIDUAL_STEPS {
            return Plan::NotFolds(format!(
                "{at} no turn about the orbit's axis continues the previous frames ({:.1} deg and {:.1} steps off)",
                b.residual_turn_deg, b.residual_steps
            ));
        }
    }
    Plan::Unfold(Unfolding {
        passes,
        axis,
        pivot,
        turns,
        boundaries,
    })
}

impl Unfolding {
    /// The pass of frame `frame`.
    pub fn pass_of(&self, frame: usize) -> usize {
        self.passes.iter().position(|p| p.contains(&frame)).unwrap_or(0)
    }

    /// The rotation turning pass `pass` back.
    fn rotation(&self, pass: usize) -> DMat3 {
        DMat3::from_axis_angle(self.axis, self.turns[pass])
    }

    /// Frame `frame`'s pose turned back with its pass.
    pub fn pose(&self, frame: usize, pose: &Pose) -> Pose {
        let rot = self.rotation(self.pass_of(frame));
        Pose {
            rotation: pose.rotation * rot.transpose(),
            centre: self.pivot + rot * (pose.centre - self.pivot),
        }
    }

    /// A point registered with pass `pass`, turned back with it.
    pub fn point(&self, pass: usize, p: DVec3) -> DVec3 {
        self.pivot + self.rotation(pass) * (p - self.pivot)
    }
}
