//! Duplicate frames: views whose images are the same, pixel for pixel (after undistortion,
//! downscaling and background compositing), taken from the same pose ([`same_pose`]). A copy
//! among the training views trains its frame twice and skews the camera statistics; a test view
//! that is also a training view inflates the test score. [`find`] names them, the loader keeps the first of each set (a training view
//! before a test view) and removes the others with a warning.
//!
//! Equal images from different poses are not copies (two empty frames, or a symmetric synthetic
//! object seen alike from two places, are both true observations), nor are images of a single
//! colour. Only exact copies are found: a re-encoded copy of a frame differs in its pixels and is
//! not.
//!
//! Cost: one hash of at most [`SAMPLES`] bytes per view, then a full comparison only of the views
//! whose sizes and hashes agree.

use super::{Image, SceneError, View, ViewImage};
use crate::camera::Camera;
use std::collections::HashMap;

/// Largest distance between the centres of two copies, as a share of the views' spread (the
/// largest distance of a camera centre from their mean).
pub const SAME_CENTRE: f32 = 1e-3;

/// Largest Frobenius norm of the difference of two copies' rotation matrices (about 0.08°).
pub const SAME_ROTATION: f32 = 2e-3;

/// True when cameras `a` and `b` have the same pose: centres within [`SAME_CENTRE`] · `spread`,
/// rotations within [`SAME_ROTATION`].
pub fn same_pose(a: &Camera, b: &Camera, spread: f32) -> bool {
    let rotation = (a.rotation - b.rotation)
        .to_cols_array()
        .iter()
        .map(|d| d * d)
        .sum::<f32>()
        .sqrt();
    a.centre().distance(b.centre()) <= SAME_CENTRE * spread && rotation <= SAME_ROTATION
}

/// Bytes of an image hashed to group candidate copies.
pub const SAMPLES: usize = 4096;

/// Which list a view is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// [`super::Scene::train`].
    Train,
    /// [`super::Scene::test`].
    Test,
}

/// A view whose image is the same as an earlier one's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Duplicate {
    /// The copy's list and index in it.
    pub copy: (Split, usize),
    /// The view it copies (the first of its set: a training view when there is one).
    pub original: (Split, usize),
}

/// FNV-1a 64 of the size and of at most [`SAMPLES`] evenly spaced bytes of `image`.
pub(crate) fn sample_hash(image: &Image) -> u64 {
    let bytes = image.as_bytes();
    let stride = bytes.len().div_ceil(SAMPLES).max(1);
    let size = [image.width().to_le_bytes(), image.height().to_le_bytes()].concat();
    let sampled: Vec<u8> = bytes.iter().step_by(stride).copied().collect();
    crate::fnv::update(crate::fnv::fnv1a(&size), &sampled)
}

/// True when every pixel of `image` has the first pixel's colour.
fn single_colour(image: &Image) -> bool {
    let bytes = image.as_bytes();
    bytes.chunks_exact(3).all(|p| p == &bytes[..3])
}

/// [`sample_hash`] of a view's image (an on-demand image's, kept from its first decode).
fn sample_hash_of(image: &ViewImage) -> u64 {
    match image {
        ViewImage::InMemory(image) => sample_hash(image),
        ViewImage::OnDemand(image) => image.sample_hash(),
    }
}

/// Every view of `train` then `test` whose image equals an earlier one's, in that order.
///
/// # Errors
/// An on-demand image ([`super::on_demand`]) that cannot be decoded again for the comparison.
pub fn find(train: &[View], test: &[View]) -> Result<Vec<Duplicate>, SceneError> {
    let all: Vec<((Split, usize), &View)> = train
        .iter()
        .enumerate()
        .map(|(i, v)| ((Split::Train, i), v))
        .chain(test.iter().enumerate().map(|(i, v)| ((Split::Test, i), v)))
        .collect();
    let spread = {
        let n = all.len().max(1) as f32;
        let mean = all.iter().map(|(_, v)| v.camera.centre()).sum::<glam::Vec3>() / n;
        let far = all
            .iter()
            .map(|(_, v)| v.camera.centre().distance(mean))
            .fold(0.0, f32::max);
        far.max(f32::MIN_POSITIVE)
    };
    // Earlier views of each sample hash (the first seen of each distinct image).
    let mut seen: HashMap<u64, Vec<usize>> = HashMap::new();
    let mut out = Vec::new();
    for (k, &(at, view)) in all.iter().enumerate() {
        let firsts = seen.entry(sample_hash_of(&view.image)).or_default();
        let mut original = None;
        for &j in firsts.iter() {
            let other = all[j].1;
            let same_size = (other.image.width(), other.image.height()) == (view.image.width(), view.image.height());
            if same_size
                && same_pose(&other.camera, &view.camera, spread)
                && other.image.get()?.as_bytes() == view.image.get()?.as_bytes()
            {
                original = Some(j);
                break;
            }
        }
        match original {
            Some(j) if !single_colour(&*view.image.get()?) => out.push(Duplicate {
                copy: at,
                original: all[j].0,
            }),
            Some(_) => {}
            None => firsts.push(k),
        }
    }
    Ok(out)
}

/// Removes every [`find`] copy from `train` and `test`, with a warning naming it and its
/// original.
pub(crate) fn leave_out(
    train: &mut Vec<View>,
    test: &mut Vec<View>,
    warnings: &mut Vec<String>,
) -> Result<(), SceneError> {
    let found = find(train, test)?;
    if found.is_empty() {
        return Ok(());
    }
    let name = |(split, i): (Split, usize)| match split {
        Split::Train => format!("training view {:?}", train[i].name),
        Split::Test => format!("test view {:?}", test[i].name),
    };
    for d in &found {
        let why = match (d.copy.0, d.original.0) {
            (Split::Test, Split::Train) => {
                "left out of the test views (a test view seen in training inflates the test score)"
            }
            (Split::Test, Split::Test) => "left out of the test views (it would count twice)",
            _ => "left out of the training views (a copy trains its frame twice)",
        };
        warnings.push(format!(
            "{} is the same image as {}: {why}",
            name(d.copy),
            name(d.original)
        ));
    }
    let drop = |split: Split, views: &mut Vec<View>| {
        let mut index = 0;
        views.retain(|_| {
            let keep = !found.iter().any(|d| d.copy == (split, index));
            index += 1;
            keep
        });
    };
    drop(Split::Train, train);
    drop(Split::Test, test);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

    fn view(name: &str, pixels: &[u8]) -> View {
        View {
            name: name.into(),
            path: name.into(),
            camera: Camera::identity(2, 1),
            image: Image::new(2, 1, pixels.to_vec()).unwrap().into(),
            coverage: None,
            mask: None,
        }
    }

    #[test]
    fn copies_are_found_and_left_out_with_the_first_kept() {
        let a = [1, 2, 3, 4, 5, 6];
        let b = [9, 2, 3, 4, 5, 6];
        let mut train = vec![view("a", &a), view("b", &b), view("a2", &a)];
        let mut test = vec![
            view("t", &b),
            view("u", &[7, 7, 7, 1, 1, 1]),
            view("u2", &[7, 7, 7, 1, 1, 1]),
        ];
        let found = find(&train, &test).unwrap();
        assert_eq!(
            found,
            vec![
                Duplicate {
                    copy: (Split::Train, 2),
                    original: (Split::Train, 0)
                },
                Duplicate {
                    copy: (Split::Test, 0),
                    original: (Split::Train, 1)
                },
                Duplicate {
                    copy: (Split::Test, 2),
                    original: (Split::Test, 1)
                },
            ]
        );
        let mut warnings = Vec::new();
        leave_out(&mut train, &mut test, &mut warnings).unwrap();
        let names = |v: &[View]| v.iter().map(|v| v.name.clone()).collect::<Vec<_>>();
        assert_eq!(names(&train), ["a", "b"]);
        assert_eq!(names(&test), ["u"]);
        assert_eq!(warnings.len(), 3);
        assert!(
            warnings[1].contains("test view \"t\" is the same image as training view \"b\""),
            "{warnings:?}"
        );
    }

    #[test]
    fn single_colour_frames_and_different_sizes_are_not_copies() {
        let blank = [5, 5, 5, 5, 5, 5];
        let train = vec![view("a", &blank), view("b", &blank)];
        assert!(find(&train, &[]).unwrap().is_empty());
        let wide = View {
            image: Image::new(1, 2, vec![1, 2, 3, 4, 5, 6]).unwrap().into(),
            ..view("c", &[1, 2, 3, 4, 5, 6])
        };
        assert!(find(&[view("d", &[1, 2, 3, 4, 5, 6]), wide], &[]).unwrap().is_empty());
    }

    #[test]
    fn equal_images_from_other_poses_are_not_copies() {
        let a = [1, 2, 3, 4, 5, 6];
        let mut moved = view("b", &a);
        moved.camera.translation.x = 1.0;
        let mut turned = view("c", &a);
        turned.camera.rotation = glam::Mat3::from_rotation_y(0.01);
        assert!(
            find(&[view("a", &a), moved.clone(), turned.clone()], &[])
                .unwrap()
                .is_empty()
        );
        // A hair's breadth away is the same pose (spread 2/3 from the moved view).
        let mut near = view("d", &a);
        near.camera.translation.x = 1e-4;
        assert_eq!(find(&[view("a", &a), moved, near], &[]).unwrap().len(), 1);
    }
}
