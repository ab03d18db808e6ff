//! Which scene a model was trained on: the number of its views and a hash of their poses,
//! recorded in `bbsplat.json` (`"scene": {"views": 40, "poses": "9f0c…"}`) so that `eval`,
//! `render`, `export`, `mesh` and `view` warn when a model meets another scene.
//!
//! The mark holds what does not change when the same scene is loaded another way: the camera
//! poses (rotation and translation, f32 bits) of the training and test views together, as a set
//! (sorted, so the split of `--test-every` does not matter), without the intrinsics or image
//! sizes (which `--downscale` and `--max-width` change). Another registration of the same photos
//! (`--keep-folded`) is another scene.
//!
//! ```
//! use bbsplat::camera::Camera;
//! use bbsplat::model_file::scene_mark::SceneMark;
//! let (a, mut b) = (Camera::identity(8, 8), Camera::identity(8, 8));
//! b.translation.x = 1.0;
//! let mark = SceneMark::of_cameras([&a, &b]);
//! assert_eq!(mark, SceneMark::of_cameras([&b, &a]));
//! let mut small = b.clone();
//! small.width = 4;
//! assert_eq!(mark, SceneMark::of_cameras([&small, &a]));
//! assert!(mark.difference(&SceneMark::of_cameras([&a])).is_some());
//! ```

use crate::camera::Camera;
use serde::{Deserialize, Serialize};

/// The mark of a scene (module docs).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneMark {
    /// Training and test views.
    pub views: usize,
    /// FNV-1a 64 of the sorted per-view pose hashes, 16 hex digits.
    pub poses: String,
}

/// FNV-1a 64 of a camera's rotation and translation (the f32 bits, little-endian).
fn pose_hash(c: &Camera) -> u64 {
    let bytes: Vec<u8> = c
        .rotation
        .to_cols_array()
        .into_iter()
        .chain(c.translation.to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    crate::fnv::fnv1a(&bytes)
}

impl SceneMark {
    /// The mark of the scene whose views have `cameras` (training and test, in any order).
    pub fn of_cameras<'a>(cameras: impl IntoIterator<Item = &'a Camera>) -> Self {
        let mut hashes: Vec<u64> = cameras.into_iter().map(pose_hash).collect();
        hashes.sort_unstable();
        let bytes: Vec<u8> = hashes.iter().flat_map(|h| h.to_le_bytes()).collect();
        SceneMark {
            views: hashes.len(),
            poses: format!("{:016x}", crate::fnv::fnv1a(&bytes)),
        }
    }

    /// How the scene marked `now` differs from this (the model's) one, or `None` when it is
    /// the same.
    pub fn difference(&self, now: &SceneMark) -> Option<String> {
        if self.views != now.views {
            Some(format!(
                "the model was trained on a scene of {} views, this one has {}",
                self.views, now.views
            ))
        } else if self.poses != now.poses {
            Some(format!(
                "the model was trained on a scene whose {} camera poses differ from this one's",
                self.views
            ))
        } else {
            None
        }
    }
}
