//! What a checkpoint records about the run that wrote it, so that `--resume` can continue the
//! same run or refuse: the run's arguments (the settings that change the model or the
//! optimisation, as `flag → value` text) and a fingerprint of the dataset (every view's name,
//! image size and camera). Stored in the checkpoint's run-record section (format version 4,
//! [`super::checkpoint`]); empty for checkpoints of earlier versions and for trainers that were
//! never given one.
//!
//! ```
//! use bbsplat::camera::Camera;
//! use bbsplat::train::run_record::{DatasetFingerprint, RunRecord};
//! let cam = Camera::identity(8, 8);
//! let a = RunRecord {
//!     arguments: [("--sh-degree".to_string(), "3".to_string())].into(),
//!     dataset: Some(DatasetFingerprint::of_views([("a.png", &cam)])),
//! };
//! let mut b = a.clone();
//! b.arguments.insert("--sh-degree".into(), "2".into());
//! assert_eq!(a.differences(&b), vec!["--sh-degree: the checkpoint's run has 3, this one 2".to_string()]);
//! ```

use crate::camera::Camera;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The arguments and dataset of a run (module docs).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RunRecord {
    /// Settings that change the model or the optimisation, `flag → value` as text (e.g.
    /// `"--sh-degree" → "3"`); settings that do not (threads, evaluation, output) are left out.
    pub arguments: BTreeMap<String, String>,
    /// The dataset trained on.
    pub dataset: Option<DatasetFingerprint>,
}

/// One view of a dataset fingerprint.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ViewPrint {
    /// The view's name.
    pub name: String,
    /// Image width, pixels (after downscaling).
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// FNV-1a 64 of the camera's pose and intrinsics (the f32 bits, little-endian).
    pub camera: u64,
}

/// The views of a dataset, in order: names, image sizes and cameras.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DatasetFingerprint {
    /// Every view (training views, then test views).
    pub views: Vec<ViewPrint>,
}

/// FNV-1a 64 of the camera's pose, intrinsics and size.
fn camera_hash(c: &Camera) -> u64 {
    let floats = c
        .rotation
        .to_cols_array()
        .into_iter()
        .chain(c.translation.to_array())
        .chain([c.fx, c.fy, c.cx, c.cy]);
    let mut bytes: Vec<u8> = floats.flat_map(f32::to_le_bytes).collect();
    bytes.extend(c.width.to_le_bytes());
    bytes.extend(c.height.to_le_bytes());
    crate::fnv::fnv1a(&bytes)
}

impl DatasetFingerprint {
    /// The fingerprint of `(name, camera)` pairs, in order.
    pub fn of_views<'a>(views: impl IntoIterator<Item = (&'a str, &'a Camera)>) -> Self {
        DatasetFingerprint {
            views: views
                .into_iter()
                .map(|(name, camera)| ViewPrint {
                    name: name.to_string(),
                    width: camera.width,
                    height: camera.height,
                    camera: camera_hash(camera),
                })
                .collect(),
        }
    }

    /// How `other` differs from `self` (the first difference, naming the view), or `None`.
    pub fn difference(&self, other: &DatasetFingerprint) -> Option<String> {
        if self.views.len() != other.views.len() {
            return Some(format!(
                "the checkpoint's dataset has {} views, this one {}",
                self.views.len(),
                other.views.len()
            ));
        }
        self.views.iter().zip(&other.views).find_map(|(a, b)| {
            if a.name != b.name {
                Some(format!(
                    "view {:?} of the checkpoint's dataset is {:?} in this one",
                    a.name, b.name
                ))
            } else if (a.width, a.height) != (b.width, b.height) {
                Some(format!(
                    "view {:?} is {}x{} in the checkpoint's dataset, {}x{} in this one",
                    a.name, a.width, a.height, b.width, b.height
                ))
            } else if a.camera != b.camera {
                Some(format!(
                    "view {:?} has another camera (pose or intrinsics) than in the checkpoint's dataset",
                    a.name
                ))
            } else {
                None
            }
        })
    }
}

impl RunRecord {
    /// Every way `now` differs from this (the checkpoint's) record: each argument whose value
    /// differs (an argument only one of them has is compared with `"(absent)"`) and the dataset.
    /// Empty when `now` continues the same run. A record without a dataset (an older
    /// checkpoint) does not compare datasets.
    pub fn differences(&self, now: &RunRecord) -> Vec<String> {
        let absent = "(absent)".to_string();
        let mut keys: Vec<&String> = self.arguments.keys().chain(now.arguments.keys()).collect();
        keys.sort();
        keys.dedup();
        let mut out: Vec<String> = keys
            .into_iter()
            .filter_map(|k| {
                let (a, b) = (
                    self.arguments.get(k).unwrap_or(&absent),
                    now.arguments.get(k).unwrap_or(&absent),
                );
                (a != b).then(|| format!("{k}: the checkpoint's run has {a}, this one {b}"))
            })
            .collect();
        if let (Some(a), Some(b)) = (&self.dataset, &now.dataset)
            && let Some(d) = a.difference(b)
        {
            out.push(format!("dataset: {d}"));
        }
        out
    }

    /// True for the empty record of an older checkpoint (nothing to compare).
    pub fn is_empty(&self) -> bool {
        self.arguments.is_empty() && self.dataset.is_none()
    }
}
