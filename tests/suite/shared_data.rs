//! The real scenes of `../shared/data` beside the repository, for the tests that read them.
//!
//! When the data is absent: under CI (`CI` set in the environment) the test **fails**, since CI
//! always has the data beside the checkout; elsewhere the test is skipped with a line written
//! straight to the terminal's standard error (not captured by the test harness), so a skip is
//! never mistaken for a pass.

use std::io::Write;
use std::path::{Path, PathBuf};

/// `../shared/data/<relative>` if it exists; `None` (after saying "SKIPPED" on the terminal)
/// when it does not and `CI` is unset.
///
/// # Panics
/// When the data is absent and `CI` is set.
pub fn shared_data(test: &str, relative: &str) -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(relative);
    if path.exists() {
        return Some(path);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{test}: the test data {} is missing (CI must have ../shared/data)",
        path.display()
    );
    let _ = writeln!(
        std::io::stderr(),
        "SKIPPED {test}: the test data {} is not there",
        path.display()
    );
    None
}
