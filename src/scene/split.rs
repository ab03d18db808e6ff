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

/// [`camera_extent`] of `cameras` without the [`outlying_cameras`] among them, and those.
pub fn extent_without_outliers<'a>(cameras: impl IntoIterator<Item = &'a Camera>) -> (f32, Vec<OutlyingCamera>) {
    let cameras: Vec<&Camera> = cameras.into_iter().collect();
    let outliers = outlying_cameras(cameras.iter().copied());
    let extent = camera_extent(
        cameras
            .iter()
            .enumerate()
            .filter(|(i, _)| !outliers.iter().any(|o| o.index == *i))
            .map(|(_, c)| *c),
    );
    (extent, outliers)
}

/// A camera far from all others: see [`outlying_cameras`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutlyingCamera {
    /// Index of the camera in the list given.
    pub index: usize,
    /// Its centre's distance from the median camera centre, world units.
    pub distance: f64,
    /// The median of all centres' distances from the median centre.
    pub median_distance: f64,
}

/// How many times the median distance a camera centre must lie from the median centre (the
/// component-wise median of all centres) to be an outlier.
pub const OUTLIER_FACTOR: f64 = 10.0;

/// The cameras whose centre lies more than [`OUTLIER_FACTOR`] times the median distance from the
/// median camera centre: a pose far from all others (typically a misregistered image), which
/// would inflate [`camera_extent`] and with it the position learning rate. Medians ignore a
/// minority of such poses. Needs at least 4 cameras and a positive median distance; otherwise
/// none is an outlier.
///
/// ```
/// use bbsplat::camera::Camera;
/// use bbsplat::scene::split::outlying_cameras;
/// use glam::Vec3;
/// let mut eyes: Vec<Vec3> = (0..8).map(|k| Vec3::new((k as f32).cos(), 0.0, (k as f32).sin()) * 3.0).collect();
/// eyes.push(Vec3::new(500.0, 0.0, 0.0));
/// let cams: Vec<Camera> = eyes.iter().map(|&e| Camera::look_at(e, Vec3::ZERO, Vec3::Y, 50.0, 50.0, 8, 8)).collect();
/// let out = outlying_cameras(&cams);
/// assert_eq!(out.len(), 1);
/// assert_eq!(out[0].index, 8);
/// ```
pub fn outlying_cameras<'a>(cameras: impl IntoIterator<Item = &'a Camera>) -> Vec<OutlyingCamera> {
    let centres: Vec<DVec3> = cameras.into_iter().map(|c| c.centre().as_dvec3()).collect();
    if centres.len() < 4 {
        return Vec::new();
    }
    let median = |mut xs: Vec<f64>| {
        xs.sort_by(f64::total_cmp);
        let n = xs.len();
        if n % 2 == 1 {
            xs[n / 2]
        } else {
            0.5 * (xs[n / 2 - 1] + xs[n / 2])
        }
    };
    let centre = DVec3::new(
        median(centres.iter().map(|c| c.x).collect()),
        median(centres.iter().map(|c| c.y).collect()),
        median(centres.iter().map(|c| c.z).collect()),
    );
    let distances: Vec<f64> = centres.iter().map(|c| (*c - centre).length()).collect();
    let median_distance = median(distances.clone());
    if median_distance.is_nan() || median_distance <= 1e-9 {
        return Vec::new();
    }
    distances
        .iter()
        .enumerate()
        .filter(|(_, d)| d.is_nan() || **d > OUTLIER_FACTOR * median_distance)
        .map(|(index, &distance)| OutlyingCamera {
            index,
            distance,
            median_distance,
        })
        .collect()
}
