//! The model an example measures: a model folder written by `bbsplat train` or a checkpoint
//! file (`checkpoint.bin`), shared by the examples that take one (`#[path]`-included).

use bbsplat::model::RawBillboards;
use bbsplat::model_file::load_model;
use bbsplat::train::Trainer;
use std::path::Path;

/// The model, its SH degree and its background, from a model folder or a checkpoint.
pub fn load_any(path: &Path) -> Result<(RawBillboards, u32, [f32; 3]), Box<dyn std::error::Error>> {
    if path.is_dir() {
        let (model, meta) = load_model(path)?;
        Ok((model, meta.sh_degree, meta.background))
    } else {
        let trainer = Trainer::load_checkpoint(path)?;
        let settings = trainer.settings();
        Ok((
            trainer.model().clone(),
            settings.sh_degree,
            settings.background.to_array(),
        ))
    }
}
