//! Train/test split and scene extent.

use crate::camera::Camera;
use glam::DVec3;

/// Splits `items` (already in the desired order) into `(train, test)`: the items at indices
/// `0, n, 2n, ...` go to the test set (the 3DGS "every 8th image" rule with `n = 8`). With
/// `n = 0` every item is a training item.
///
/// ```
/// use bbsplat::scene::split::split_every;
/// let (train, test) = split_every((0..10).collect(), 4);
/// assert_eq!(test, vec![0, 4, 8]);
/// assert_eq!(train, vec![1, 2, 3, 5, 6, 7, 9]);
/// ```
pub fn split_every<T>(items: Vec<T>, n: usize) -> (Vec<T>, Vec<T>) {
    let mut train = Vec::new();
    let mut test = Vec::new();
    for (i, item) in items.into_iter().enumerate() {
        if n > 0 && i % n == 0 {
            test.push(item);
        } else {
            train.push(item);
        }
    }
    (train, test)
}

/// Scene extent `E`, the spatial scale of the position learning rate: `1.1 ×` the largest
/// distance of a camera centre from the mean camera centre, computed in f64 (as 3DGS's
/// `getNerfppNorm`, whose numpy arithmetic is float64). When there are no cameras, or all
/// centres coincide (radius ≤ 1e-9), the radius is taken as 1 (extent 1.1), so that positions
/// still train. The one definition: [`crate::scene::load`] fills `Scene::extent` with it from the
/// training cameras, and callers that build a [`crate::train::TrainConfig`] from their own
/// cameras call it directly.
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::scene::split::camera_extent;
/// use glam::Vec3;
/// let cams: Vec<Camera> = [-2.0f32, 2.0].iter()
///     .map(|&x| Camera::look_at(Vec3::new(x, 0.0, -3.0), Vec3::ZERO, Vec3::Y, 50.0, 50.0, 8, 8))
///     .collect();
/// assert!((camera_extent(&cams) - 2.2).abs() < 1e-5);
/// assert_eq!(camera_extent(&cams[..1]), 1.1); // one camera: radius 1
/// assert_eq!(camera_extent(std::iter::empty()), 1.1);
/// ```
pub fn camera_extent<'a>(cameras: impl IntoIterator<Item = &'a Camera>) -> f32 {
    let centres: Vec<DVec3> = cameras.into_iter().map(|c| c.centre().as_dvec3()).collect();
    if centres.is_empty() {
        return 1.1;
    }
    let mean = centres.iter().copied().sum::<DVec3>() / centres.len() as f64;
    let radius = centres.iter().map(|c| (*c - mean).length()).fold(0.0, f64::max);
    let radius = if radius > 1e-9 { radius } else { 1.0 };
    (1.1 * radius) as f32
}
