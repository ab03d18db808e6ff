//! Pieces shared by the subcommands: scene-loading flags, thread pool, atomic PNG writes.

use anyhow::{Context, Result};
use bbsplat::file_io::FileKind;
use bbsplat::model::RawBillboards;
use bbsplat::model_file::scene_mark::SceneMark;
use bbsplat::model_file::{ModelMeta, load_model};
use bbsplat::scene::data_background::{BackgroundChoice, load_with_data_background};
use bbsplat::scene::mask::MaskMode;
use bbsplat::scene::{Background, LoadOptions, Scene, View};
use clap::{Args, ValueEnum};
use std::path::Path;

/// Reads the model folder `path`, its errors prefixed with the folder's name.
pub fn read_model(path: &Path) -> Result<(RawBillboards, ModelMeta)> {
    load_model(path).with_context(|| format!("loading the model {}", path.display()))
}

/// Background colour flag.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum BackgroundArg {
    /// `[0, 0, 0]` (the reference's default).
    Black,
    /// `[1, 1, 1]` (`--white_background`, used for NeRF-synthetic figures).
    White,
}

impl From<BackgroundArg> for Background {
    fn from(b: BackgroundArg) -> Self {
        match b {
            BackgroundArg::Black => Background::Black,
            BackgroundArg::White => Background::White,
        }
    }
}

/// How a scene folder is read (shared by `train`, `render` and `eval`).
#[derive(Args, Clone, Debug)]
pub struct SceneArgs {
    /// Background composited behind transparent pixels and the billboards. Default: `train`
    /// takes it from the data (white for NeRF-synthetic images with alpha, black otherwise) and
    /// stores it in the model; `render` and `eval` use the model's.
    #[arg(long, value_enum)]
    pub background: Option<BackgroundArg>,
    /// Integer image downscale factor (1, 2, 4, 8, ...).
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Maximum image width in pixels after `--downscale` (wider images are area-downscaled).
    #[arg(long)]
    pub max_width: Option<u32>,
    /// Without a test list, hold out every n-th view (0: none), as the reference's `--eval`.
    #[arg(long, default_value_t = 8)]
    pub test_every: usize,
    /// Train on damaged images (a JPEG cut short, whose missing part decodes grey) with a
    /// warning, instead of refusing them.
    #[arg(long)]
    pub allow_damaged_images: bool,
    /// Keep a COLMAP registration that looks folded (passes of an orbit video turned by about
    /// 180 degrees onto the rest) as given, instead of turning its passes back (docs/scene.md).
    #[arg(long)]
    pub keep_folded: bool,
    /// A folder of object masks (8-bit images, white = keep), one per image, matched by file
    /// stem (`<stem>.png` or `.jpg`; docs/scene.md, "Masks"). Replaces a NeuS dataset's own
    /// `mask/`.
    #[arg(long, value_name = "DIR")]
    pub masks: Option<std::path::PathBuf>,
    /// What training does with the masks: `composite` the photographs onto the background
    /// outside them (NeuS/2DGS practice on DTU), `weight` the loss by them (pixels outside are
    /// left out of training, as nerfstudio's splatfacto), or `ignore` them (they still serve
    /// `eval --masked`).
    #[arg(long, value_enum, default_value_t = MaskModeArg::Composite)]
    pub mask_mode: MaskModeArg,
    /// Memory for the 8-bit images (K, M or G; a bare number is MiB). When all the scene's
    /// images fit they are held in memory; otherwise each is decoded from its file when used,
    /// through a cache of this size (same pixels, same result; docs/scene.md, "Large captures").
    #[arg(long, value_name = "SIZE", default_value = "2G", value_parser = super::flag_parsers::byte_size)]
    pub image_memory: u64,
}

/// `--mask-mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MaskModeArg {
    /// Composite the photographs onto the background outside the mask at load.
    Composite,
    /// Leave the photographs as they are.
    Ignore,
    /// Leave the photographs as they are and weight the loss by the mask (pixels outside it
    /// are left out of training).
    Weight,
}

impl From<MaskModeArg> for MaskMode {
    fn from(m: MaskModeArg) -> Self {
        match m {
            MaskModeArg::Composite => MaskMode::Composite,
            MaskModeArg::Ignore => MaskMode::Ignore,
            MaskModeArg::Weight => MaskMode::Weight,
        }
    }
}

impl SceneArgs {
    /// These flags written back as command-line words, those that differ from their defaults
    /// only, for the stages of a chain that load the same scene (`bbsplat blocks run`): parsing
    /// them gives these flags again.
    pub fn to_flags(&self) -> Vec<String> {
        let name = |v: Option<clap::builder::PossibleValue>| v.map_or(String::new(), |v| v.get_name().to_string());
        let mut flags = Vec::new();
        if let Some(b) = self.background {
            flags.extend(["--background".to_string(), name(b.to_possible_value())]);
        }
        if self.downscale != 1 {
            flags.extend(["--downscale".to_string(), self.downscale.to_string()]);
        }
        if let Some(w) = self.max_width {
            flags.extend(["--max-width".to_string(), w.to_string()]);
        }
        if self.test_every != 8 {
            flags.extend(["--test-every".to_string(), self.test_every.to_string()]);
        }
        if self.allow_damaged_images {
            flags.push("--allow-damaged-images".into());
        }
        if self.keep_folded {
            flags.push("--keep-folded".into());
        }
        if let Some(dir) = &self.masks {
            flags.extend(["--masks".to_string(), dir.display().to_string()]);
        }
        if self.mask_mode != MaskModeArg::Composite {
            flags.extend(["--mask-mode".to_string(), name(self.mask_mode.to_possible_value())]);
        }
        if self.image_memory != 2 << 30 {
            // Whole KiB: what `byte_size` parses back to the same count.
            flags.extend(["--image-memory".to_string(), format!("{}K", self.image_memory / 1024)]);
        }
        flags
    }

    /// The load options of these flags. Warnings (a folded registration turned back, damaged
    /// images, ...) are always printed to stderr, `--quiet` or not, and recorded in the run's
    /// summary.
    fn options(&self, background: Background) -> LoadOptions {
        LoadOptions {
            background,
            downscale: self.downscale,
            max_width: self.max_width,
            test_every: self.test_every,
            print_warnings: true,
            allow_damaged_images: self.allow_damaged_images,
            unfold: !self.keep_folded,
            masks_dir: self.masks.clone(),
            mask_mode: self.mask_mode.into(),
            image_memory: self.image_memory,
            ..LoadOptions::default()
        }
    }

    /// Loads `path` with these options and `--background` if given, else `default`; warnings go
    /// to stderr.
    pub fn load(&self, path: &Path, default: Background) -> Result<Scene> {
        let background = self.background.map_or(default, Background::from);
        bbsplat::scene::load(path, &self.options(background))
            .with_context(|| format!("loading the scene {}", path.display()))
    }

    /// Loads `path` for a model read from `model` whose metadata is `meta`: with `--background`
    /// if given, else with the model's background (the truth images are composited on the
    /// background the model was trained on). Warns when the model records another scene
    /// ([`SceneMark`]).
    pub fn load_for_model(&self, path: &Path, model: &Path, meta: &ModelMeta) -> Result<Scene> {
        let stored = meta.background;
        let background = match self.background {
            Some(arg) => arg.into(),
            None => Background::from_rgb(stored).ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: background {stored:?} is neither black nor white; give --background",
                    model.display()
                )
            })?,
        };
        let scene = self.load(path, background)?;
        if let Some(warning) = scene_mismatch(model, meta, path, &scene) {
            eprintln!("warning: {warning}");
        }
        Ok(scene)
    }

    /// Reads the model folder `model` and loads the scene `scene` for it
    /// ([`SceneArgs::load_for_model`]: with the model's background unless `--background`).
    pub fn load_model_and_scene(&self, model: &Path, scene: &Path) -> Result<(RawBillboards, ModelMeta, Scene)> {
        let (raw, meta) = read_model(model)?;
        let scene = self.load_for_model(scene, model, &meta)?;
        Ok((raw, meta, scene))
    }

    /// Loads `path` for training: with `--background` if given, else with the background of
    /// the data ([`load_with_data_background`]); returns the choice and why.
    pub fn load_for_training(&self, path: &Path) -> Result<(Scene, BackgroundChoice)> {
        let context = || format!("loading the scene {}", path.display());
        match self.background {
            Some(arg) => {
                let scene = self.load(path, arg.into())?;
                let choice = BackgroundChoice {
                    background: arg.into(),
                    reason: format!("{}: given by --background", format!("{arg:?}").to_lowercase()),
                };
                Ok((scene, choice))
            }
            None => load_with_data_background(path, &self.options(Background::Black)).with_context(context),
        }
    }
}

/// Which views of a scene a command works on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Split {
    /// The training views.
    Train,
    /// The held-out views.
    Test,
}

/// The views of `split`.
pub fn split_views(scene: &Scene, split: Split) -> &[View] {
    match split {
        Split::Train => &scene.train,
        Split::Test => &scene.test,
    }
}

/// Largest `--threads`.
pub const MAX_THREADS: usize = 4096;

/// `--threads`: 1 to [`MAX_THREADS`].
pub fn check_threads(n: Option<usize>) -> Result<()> {
    if let Some(n) = n {
        anyhow::ensure!(
            (1..=MAX_THREADS).contains(&n),
            "--threads must be between 1 and {MAX_THREADS} (got {n})"
        );
    }
    Ok(())
}

/// Starts the global rayon pool with `threads` workers (all cores when `None`); returns the
/// number of workers.
pub fn start_threads(threads: Option<usize>) -> Result<usize> {
    if let Some(n) = threads {
        check_threads(Some(n))?;
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("starting the thread pool")?;
    }
    Ok(rayon::current_num_threads())
}

/// Writes an interleaved RGB float image as an 8-bit PNG, atomically
/// ([`bbsplat::file_io::write_atomic`]: encoded in memory, written to a temporary file beside
/// `path`, flushed to disk and renamed, so that a full disk fails the write instead of leaving an
/// empty or cut PNG; through links, a device or a FIFO at `path` refused and left as it is).
pub fn write_png_atomic(path: &Path, rgb: &[f32], width: u32, height: u32) -> Result<()> {
    let bytes: Vec<u8> = rgb.iter().map(|&c| bbsplat::loss::psnr::quantize_u8(c)).collect();
    let mut png = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut png),
        &bytes,
        width,
        height,
        image::ExtendedColorType::Rgb8,
    )
    .with_context(|| format!("encoding {}", path.display()))?;
    bbsplat::file_io::write_atomic(path, &png)?;
    Ok(())
}

/// An output folder a command creates: removed, with what the command wrote into it and the
/// parent folders it had to create, unless [`OutputDir::keep`] is called, so that a command
/// that fails leaves no empty or half-filled folder behind. Folders that already existed are
/// left alone.
pub struct OutputDir {
    /// The outermost folder this created (`None`: the folder existed).
    created: Option<std::path::PathBuf>,
}

/// An output folder's path that names something else (a file, a device, a dangling link) is
/// refused naming what it is (`create_dir_all` would say only "File exists").
pub fn refuse_non_folder(path: &Path) -> Result<()> {
    match bbsplat::file_io::kind_of(path) {
        Ok(FileKind::Missing | FileKind::Directory) | Err(_) => Ok(()),
        Ok(kind) => anyhow::bail!("cannot write into {}: it {kind}, not a folder", path.display()),
    }
}

impl OutputDir {
    /// Creates `path` (and missing parents) if it does not exist.
    pub fn create(path: &Path) -> Result<Self> {
        refuse_non_folder(path)?;
        let mut created = None;
        let mut missing = Some(path);
        while let Some(p) = missing.filter(|p| !p.as_os_str().is_empty() && !p.exists()) {
            created = Some(p.to_path_buf());
            missing = p.parent();
        }
        std::fs::create_dir_all(path).with_context(|| format!("creating {}", path.display()))?;
        Ok(Self { created })
    }

    /// The command succeeded: the folder stays.
    pub fn keep(mut self) {
        self.created = None;
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if let Some(dir) = &self.created {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

/// Writes `text` to `path` atomically ([`bbsplat::file_io::write_atomic`]: a temporary file in
/// the same folder, flushed to disk, renamed over `path`; through links, a device or a FIFO at
/// `path` refused).
pub fn write_text_atomic(path: &Path, text: &str) -> Result<()> {
    bbsplat::file_io::write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// A file name for a view's render: its name with path separators and the extension replaced.
pub fn render_file_name(index: usize, name: &str) -> String {
    let stem = Path::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let clean: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("{index:04}_{clean}.png")
}

/// The warning when the model at `model` (metadata `meta`) records another scene than `scene`
/// (loaded from `path`); `None` when it is the same or the model records none.
pub fn scene_mismatch(model: &Path, meta: &ModelMeta, path: &Path, scene: &Scene) -> Option<String> {
    let trained_on = meta.scene.as_ref()?;
    let now = SceneMark::of_cameras(scene.train.iter().chain(&scene.test).map(|v| &v.camera));
    trained_on.difference(&now).map(|d| {
        format!(
            "{}: {d} ({}): is it the model of another scene? Its renders and scores compare it with images it was not trained on",
            model.display(),
            path.display()
        )
    })
}

/// The LPIPS networks of `--lpips=NETWORK` (`bbsplat eval`, `bbsplat train`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LpipsNetwork {
    /// VGG16, images in [0, 1] as given (the reference's evaluation).
    Vgg,
    /// AlexNet, images mapped to [-1, 1].
    Alex,
}

impl From<LpipsNetwork> for bbsplat::lpips::Variant {
    fn from(n: LpipsNetwork) -> bbsplat::lpips::Variant {
        match n {
            LpipsNetwork::Vgg => bbsplat::lpips::Variant::Vgg,
            LpipsNetwork::Alex => bbsplat::lpips::Variant::Alex,
        }
    }
}

/// The Slurm flags of the commands that can write their runs as Slurm jobs (`benchmark`,
/// `blocks run`), each valid with `--slurm` only.
#[derive(Args, Clone, Debug)]
pub struct SlurmFlags {
    /// With --slurm: CPUs per task (each run gets as many threads).
    #[arg(long, default_value_t = 2, requires = "slurm")]
    pub cpus_per_task: u32,
    /// With --slurm: memory per task in MB.
    #[arg(long, requires = "slurm")]
    pub mem: Option<u64>,
    /// With --slurm: time limit per task, in Slurm's syntax (e.g. `45:00`).
    #[arg(long, requires = "slurm")]
    pub time: Option<String>,
    /// With --slurm: the partition.
    #[arg(long, requires = "slurm")]
    pub partition: Option<String>,
}

impl SlurmFlags {
    /// What the jobs ask of Slurm.
    pub fn options(&self) -> bbsplat::sweep::SlurmOptions {
        bbsplat::sweep::SlurmOptions {
            cpus_per_task: self.cpus_per_task,
            mem_mb: self.mem,
            time: self.time.clone(),
            partition: self.partition.clone(),
        }
    }
}
