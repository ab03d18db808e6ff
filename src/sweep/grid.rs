//! The sweep grid: a list of values per budget axis, expanded to [`Setting`]s in a stable order.

use super::SweepError;
use crate::train::TextureMode;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;
use std::str::FromStr;

/// One point of the grid: the budget flags of one `bbsplat train` run. `None` means the flag is
/// not passed, so the trainer's default applies.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Setting {
    /// Optimisation steps (`--iterations`).
    pub iterations: Option<usize>,
    /// Billboard budget (`--billboards`).
    pub billboards: Option<usize>,
    /// Texture side in texels (`--texture-size`).
    pub texture_size: Option<usize>,
    /// Largest training image width in pixels (`--max-width`).
    pub max_width: Option<u32>,
    /// Texture-threshold σ of Eq. 9 (`--texture-threshold`), dimensionless.
    pub texture_threshold: Option<f32>,
    /// Textures on or off (`--texture-mode`).
    pub texture_mode: Option<TextureMode>,
    /// Seed (`--seed`).
    pub seed: Option<u64>,
}

impl Setting {
    /// A short, file-name-safe, unique name of the setting, made of the axes that are set, e.g.
    /// `it2000_bb3000_ts16_w800_tt0.5_full_s0`; `default` when no axis is set.
    ///
    /// ```
    /// use bbsplat::sweep::Setting;
    /// use bbsplat::train::TextureMode;
    /// let s = Setting {
    ///     iterations: Some(500),
    ///     billboards: Some(1000),
    ///     texture_size: None,
    ///     max_width: None,
    ///     texture_threshold: Some(0.5),
    ///     texture_mode: Some(TextureMode::Gaussian),
    ///     seed: Some(1),
    /// };
    /// assert_eq!(s.slug(), "it500_bb1000_tt0.5_gaussian_s1");
    /// ```
    pub fn slug(&self) -> String {
        let mut parts = Vec::new();
        if let Some(v) = self.iterations {
            parts.push(format!("it{v}"));
        }
        if let Some(v) = self.billboards {
            parts.push(format!("bb{v}"));
        }
        if let Some(v) = self.texture_size {
            parts.push(format!("ts{v}"));
        }
        if let Some(v) = self.max_width {
            parts.push(format!("w{v}"));
        }
        if let Some(v) = self.texture_threshold {
            parts.push(format!("tt{v}"));
        }
        if let Some(v) = self.texture_mode {
            parts.push(v.as_str().to_string());
        }
        if let Some(v) = self.seed {
            parts.push(format!("s{v}"));
        }
        if parts.is_empty() {
            "default".into()
        } else {
            parts.join("_")
        }
    }

    /// The `bbsplat train` flags of the setting (without the scene, `-o` and `--quiet`).
    pub fn train_args(&self) -> Vec<String> {
        let mut args = Vec::new();
        let mut push = |flag: &str, value: Option<String>| {
            if let Some(v) = value {
                args.push(flag.to_string());
                args.push(v);
            }
        };
        push("--iterations", self.iterations.map(|v| v.to_string()));
        push("--billboards", self.billboards.map(|v| v.to_string()));
        push("--texture-size", self.texture_size.map(|v| v.to_string()));
        push("--max-width", self.max_width.map(|v| v.to_string()));
        push("--texture-threshold", self.texture_threshold.map(|v| v.to_string()));
        push("--texture-mode", self.texture_mode.map(|v| v.to_string()));
        push("--seed", self.seed.map(|v| v.to_string()));
        args
    }
}

/// Values per axis. An empty list leaves the flag out (trainer default). Read from JSON such as
/// `{"iterations": [500, 2000], "billboards": [1000, 3000], "seeds": [0]}`; unknown keys are
/// refused.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SweepGrid {
    /// Optimisation steps.
    pub iterations: Vec<usize>,
    /// Billboard budgets.
    pub billboards: Vec<usize>,
    /// Fixed texel budgets per texture channel (the supplement's Table 7): each run gets
    /// `⌊texels / TS²⌋` billboards for its texture size `TS` (16 when the texture-size axis is
    /// empty), so texture size and billboard count move together. Exclusive with `billboards`.
    pub texels: Vec<u64>,
    /// Texture sides in texels (each ≥ 2).
    pub texture_size: Vec<usize>,
    /// Largest training image widths in pixels (each ≥ 1).
    pub max_width: Vec<u32>,
    /// Texture-threshold σ values (finite, ≥ 0).
    pub texture_threshold: Vec<f32>,
    /// Texture modes.
    pub texture_mode: Vec<TextureMode>,
    /// Seeds.
    pub seeds: Vec<u64>,
}

/// The axis names accepted by [`SweepGrid::set_axis`] (they match the CLI flags; `seed` is an
/// alias of `seeds`).
pub const AXES: [&str; 8] = [
    "iterations",
    "billboards",
    "texels",
    "texture-size",
    "max-width",
    "texture-threshold",
    "texture-mode",
    "seeds",
];

/// Parses a comma-separated list (`"1000, 3000"`); blanks around items are ignored, empty items
/// are refused.
///
/// ```
/// use bbsplat::sweep::parse_list;
/// assert_eq!(parse_list::<usize>("billboards", "1000, 3000").unwrap(), vec![1000, 3000]);
/// assert!(parse_list::<usize>("billboards", "1000,,3000").is_err());
/// ```
pub fn parse_list<T>(axis: &str, text: &str) -> Result<Vec<T>, SweepError>
where
    T: FromStr,
    T::Err: fmt::Display,
{
    text.split(',')
        .map(|item| {
            let item = item.trim();
            item.parse::<T>().map_err(|e| SweepError::BadValue {
                axis: axis.to_string(),
                value: item.to_string(),
                reason: if item.is_empty() {
                    "empty item".into()
                } else {
                    e.to_string()
                },
            })
        })
        .collect()
}

impl SweepGrid {
    /// Reads a grid from a JSON file and validates it.
    pub fn from_json_file(path: &Path) -> Result<Self, SweepError> {
        let text = crate::file_io::read_text_bounded(path, crate::file_io::JSON_FILE)?;
        let grid: SweepGrid = serde_json::from_str(&text).map_err(|source| SweepError::Json {
            path: path.to_path_buf(),
            source,
        })?;
        grid.validate()?;
        Ok(grid)
    }

    /// Sets one axis from a CLI-style comma-separated list; `axis` is one of [`AXES`] (with
    /// `_` accepted for `-`). On error the grid is left unchanged.
    ///
    /// ```
    /// use bbsplat::sweep::SweepGrid;
    /// let mut grid = SweepGrid::default();
    /// grid.set_axis("billboards", "1000,3000").unwrap();
    /// grid.set_axis("iterations", "500").unwrap();
    /// assert_eq!(grid.settings().unwrap().len(), 2);
    /// assert!(grid.set_axis("texture-size", "1").is_err());
    /// ```
    pub fn set_axis(&mut self, axis: &str, list: &str) -> Result<(), SweepError> {
        let mut next = self.clone();
        match axis {
            "iterations" => next.iterations = parse_list(axis, list)?,
            "billboards" => next.billboards = parse_list(axis, list)?,
            "texels" => next.texels = parse_list(axis, list)?,
            "texture-size" | "texture_size" => next.texture_size = parse_list(axis, list)?,
            "max-width" | "max_width" => next.max_width = parse_list(axis, list)?,
            "texture-threshold" | "texture_threshold" => next.texture_threshold = parse_list(axis, list)?,
            "texture-mode" | "texture_mode" => next.texture_mode = parse_list(axis, list)?,
            "seeds" | "seed" => next.seeds = parse_list(axis, list)?,
            _ => return Err(SweepError::UnknownAxis(axis.to_string())),
        }
        next.validate()?;
        *self = next;
        Ok(())
    }

    /// Checks value ranges and that no axis repeats a value (repeats would give two runs with
    /// the same output folder).
    pub fn validate(&self) -> Result<(), SweepError> {
        fn bad(axis: &str, value: impl fmt::Display, reason: &str) -> SweepError {
            SweepError::BadValue {
                axis: axis.into(),
                value: value.to_string(),
                reason: reason.into(),
            }
        }
        fn unique<T: PartialEq + fmt::Display>(axis: &str, values: &[T]) -> Result<(), SweepError> {
            for (i, v) in values.iter().enumerate() {
                if values[..i].contains(v) {
                    return Err(bad(axis, v, "listed twice"));
                }
            }
            Ok(())
        }
        unique("iterations", &self.iterations)?;
        unique("billboards", &self.billboards)?;
        unique("texels", &self.texels)?;
        if !self.texels.is_empty() && !self.billboards.is_empty() {
            return Err(bad(
                "texels",
                self.texels[0],
                "fixes the billboard count per texture size: do not also list billboards",
            ));
        }
        for &texels in &self.texels {
            for ts in self.texture_sizes() {
                if texels < (ts * ts) as u64 {
                    return Err(bad(
                        "texels",
                        texels,
                        &format!("gives no billboard at texture size {ts}"),
                    ));
                }
            }
        }
        unique("texture-size", &self.texture_size)?;
        unique("max-width", &self.max_width)?;
        unique("texture-threshold", &self.texture_threshold)?;
        unique("texture-mode", &self.texture_mode)?;
        unique("seeds", &self.seeds)?;
        if let Some(v) = self.iterations.iter().find(|&&v| v == 0) {
            return Err(bad("iterations", v, "must be at least 1"));
        }
        if let Some(v) = self.billboards.iter().find(|&&v| v == 0) {
            return Err(bad("billboards", v, "must be at least 1"));
        }
        if let Some(v) = self.texture_size.iter().find(|&&v| v < 2) {
            return Err(bad("texture-size", v, "must be at least 2"));
        }
        if let Some(v) = self.max_width.iter().find(|&&v| v == 0) {
            return Err(bad("max-width", v, "must be at least 1"));
        }
        if let Some(v) = self.texture_threshold.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return Err(bad("texture-threshold", v, "must be finite and non-negative"));
        }
        Ok(())
    }

    /// The texture sizes the runs use: the axis, or the trainer's default 16 when it is empty.
    fn texture_sizes(&self) -> Vec<usize> {
        if self.texture_size.is_empty() {
            vec![16]
        } else {
            self.texture_size.clone()
        }
    }

    /// Number of settings: the product of the axis lengths, an empty axis counting as one
    /// (`texels` takes the place of `billboards`).
    pub fn len(&self) -> usize {
        [
            self.iterations.len(),
            self.billboards.len().max(self.texels.len()),
            self.texture_size.len(),
            self.max_width.len(),
            self.texture_threshold.len(),
            self.texture_mode.len(),
            self.seeds.len(),
        ]
        .iter()
        .map(|&n| n.max(1))
        .product()
    }

    /// Always false: a grid with no values is one run with the trainer's defaults.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The settings of the grid after [`validate`](Self::validate), in a stable order: nested
    /// loops over iterations (outermost), billboards, texture size, max width, texture
    /// threshold, texture mode and seed (innermost), each in the order listed.
    pub fn settings(&self) -> Result<Vec<Setting>, SweepError> {
        self.validate()?;
        fn axis<T: Copy>(values: &[T]) -> Vec<Option<T>> {
            if values.is_empty() {
                vec![None]
            } else {
                values.iter().copied().map(Some).collect()
            }
        }
        let mut out = Vec::with_capacity(self.len());
        // The billboard axis: the listed counts, or one entry per texel budget resolved below.
        let budgets: Vec<(Option<usize>, Option<u64>)> = if self.texels.is_empty() {
            axis(&self.billboards).into_iter().map(|b| (b, None)).collect()
        } else {
            self.texels.iter().map(|&t| (None, Some(t))).collect()
        };
        for &iterations in &axis(&self.iterations) {
            for &(listed, texels) in &budgets {
                for &texture_size in &axis(&self.texture_size) {
                    let billboards = match texels {
                        Some(t) => {
                            let ts = texture_size.unwrap_or(16) as u64;
                            Some((t / (ts * ts)) as usize)
                        }
                        None => listed,
                    };
                    for &max_width in &axis(&self.max_width) {
                        for &texture_threshold in &axis(&self.texture_threshold) {
                            for &texture_mode in &axis(&self.texture_mode) {
                                for &seed in &axis(&self.seeds) {
                                    out.push(Setting {
                                        iterations,
                                        billboards,
                                        texture_size,
                                        max_width,
                                        texture_threshold,
                                        texture_mode,
                                        seed,
                                    });
                                }
                            }
                        }
                    }
                }
            }
        }
        Ok(out)
    }
}
