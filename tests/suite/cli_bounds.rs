//! Numeric flags whose size turns into memory or disk are bounded before anything is loaded:
//! huge values are refused by name with the range, never a huge allocation, an abort or a
//! capacity-overflow panic (issue: `render --orbit 1000000000` asked for 72 GB, `--orbit` at
//! `u64::MAX` panicked, `mesh --compare-demo 1e12` allocated after the mesh was built).

use super::cli::run;

/// Each bad value: the flag, the value, what the message must say.
const BAD: [(&str, &str, &str, &str); 7] = [
    ("render", "--orbit", "1000000000", "not between 1 and 100000"),
    ("render", "--orbit", "18446744073709551615", "not between 1 and 100000"),
    (
        "render",
        "--orbit",
        "340282366920938463463374607431768211456",
        "not a whole number",
    ),
    ("render", "--orbit", "0", "not between 1 and 100000"),
    ("render", "--frame-ms", "5", "not a multiple of 10"),
    ("render", "--frame-ms", "1000000", "not between 10 and 655350"),
    ("mesh", "--compare-demo", "1000000000000", "not between 1 and 10000000"),
];

#[test]
fn huge_counts_are_refused_by_name_before_anything_is_loaded() {
    for (command, flag, value, says) in BAD {
        // The model and scene do not exist: the flag is refused before they are looked at.
        let (ok, err) = run(&[
            command,
            "no-such-model",
            "no-such-scene",
            "-o",
            "no-such-output",
            flag,
            value,
        ]);
        assert!(!ok, "{command} {flag} {value} was accepted");
        assert!(
            err.contains(flag) && err.contains(says),
            "{command} {flag} {value}: {err}"
        );
        assert!(!err.contains("panicked") && !err.contains("memory allocation"), "{err}");
        assert!(!std::path::Path::new("no-such-output").exists());
    }
}

#[test]
fn counts_at_their_bounds_are_accepted_by_the_parser() {
    // At the bound the flag parses, and the run fails later, on the missing model.
    for (command, flag, value) in [
        ("render", "--orbit", "100000"),
        ("render", "--frame-ms", "655350"),
        ("mesh", "--compare-demo", "10000000"),
    ] {
        let (ok, err) = run(&[
            command,
            "no-such-model",
            "no-such-scene",
            "-o",
            "no-such-output",
            flag,
            value,
        ]);
        assert!(!ok);
        assert!(err.contains("no-such-model"), "{command} {flag} {value}: {err}");
    }
}

/// `train --eval-views 0` meant "all test views" in silence; it is refused naming the range.
#[test]
fn zero_evaluation_views_are_refused() {
    let (ok, err) = run(&["train", "no-such-scene", "-o", "no-such-output", "--eval-views", "0"]);
    assert!(
        !ok && err.contains("--eval-views") && err.contains("not between 1 and"),
        "{err}"
    );
    assert!(!std::path::Path::new("no-such-output").exists());
}
