//! Programs outside the crate that some tests drive (Blender, Chromium), found on `PATH`.
//!
//! When a program is absent the test is skipped with a line written straight to the terminal's
//! standard error ("SKIPPED ..."), so a skip is never mistaken for a pass; when
//! `BBSPLAT_REQUIRE_TOOLS` is set (`.ci/run` sets it after installing them) the test fails instead.

use std::io::Write;
use std::path::PathBuf;

/// The first of `names` found on `PATH`; `None` (after saying "SKIPPED" on the terminal) when
/// none is.
///
/// # Panics
/// When none is found and `BBSPLAT_REQUIRE_TOOLS` is set.
pub fn find_tool(test: &str, names: &[&str]) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    for dir in std::env::split_paths(&path) {
        for name in names {
            let candidate = dir.join(name);
            if candidate.is_file() {
                return Some(candidate);
            }
        }
    }
    assert!(
        std::env::var_os("BBSPLAT_REQUIRE_TOOLS").is_none(),
        "{test}: none of {names:?} is on PATH (BBSPLAT_REQUIRE_TOOLS is set)"
    );
    let _ = writeln!(std::io::stderr(), "SKIPPED {test}: none of {names:?} is installed");
    None
}
