//! Waiting on what a running `bbsplat` prints, not on the clock: a test that signals a run does
//! so once the run has printed that it reached the phase under test, however loaded the machine.

use std::io::{BufRead, BufReader};
use std::process::Child;

/// A generous bound on how long a signalled run takes to stop, for the tests that check that
/// it stops at all: a run that ignored the signal would go on for its 1 000 000 steps (minutes
/// at 24 px), while a stop measured here takes 10-70 ms (the figure each test prints; 2026-12-02). Thirty
/// seconds leaves room for a machine under load without letting an ignored signal pass.
pub(crate) const STOP_BOUND_SECONDS: f64 = 30.0;

/// Reads `child`'s standard output until a line contains every one of `needles` in order, the
/// first needle's line first (e.g. `["views at", "test PSNR"]`: training started, then an
/// evaluation was printed), and returns the last line found. The rest of the output is drained on
/// a thread so that the child never blocks on a full pipe.
///
/// # Panics
/// When the output ends before every needle was found (the child exited early: its standard
/// error is then in the child's output).
pub(crate) fn wait_for_lines(child: &mut Child, needles: &[&str]) -> String {
    let stdout = child.stdout.take().expect("the child's standard output is piped");
    let mut lines = BufReader::new(stdout).lines();
    let mut last = String::new();
    for needle in needles {
        last = lines
            .by_ref()
            .map_while(Result::ok)
            .find(|l| l.contains(needle))
            .unwrap_or_else(|| panic!("the output ended before a line with {needle:?}"));
    }
    std::thread::spawn(move || lines.for_each(drop));
    last
}
