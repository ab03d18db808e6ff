//! The sweep tool: grids, the grid runner, the subprocess runner, Pareto fronts, tables and plots.

mod fake {
    //! A deterministic stand-in for `bbsplat train` used by the tests of this file.
    use bbsplat::report::{CurvePoint, SUMMARY_VERSION, TrainSummary};
    use bbsplat::sweep::{Setting, SweepGrid};
    use bbsplat::train::TextureMode;

    /// Rounds to 1e-6 so that values survive serde_json's (not exactly round-tripping) float
    /// parser bit for bit.
    fn r6(x: f64) -> f64 {
        (x * 1e6).round() / 1e6
    }

    /// More billboards and iterations: slower, bigger and better, with diminishing returns;
    /// `gaussian` mode is faster, smaller and 1.5 dB worse. Model size does not depend on the
    /// iterations.
    pub fn summary(s: &Setting) -> TrainSummary {
        let it = s.iterations.unwrap_or(1000);
        let bb = s.billboards.unwrap_or(1000);
        let ts = s.texture_size.unwrap_or(16);
        let gaussian = s.texture_mode == Some(TextureMode::Gaussian);
        let texels = if gaussian { 0 } else { ts * ts * 4 };
        let seconds = it as f64 * bb as f64 * (1.0 + texels as f64 / 256.0) * 1e-6;
        let psnr = 25.0 + 2.0 * (bb as f64 / 500.0).log2() + 1.5 * (it as f64 / 250.0).log2()
            - if gaussian { 1.5 } else { 0.0 }
            + 0.01 * s.seed.unwrap_or(0) as f64;
        let curve = (1..=4)
            .map(|k| CurvePoint {
                step: it * k / 4,
                seconds: r6(seconds * k as f64 / 4.0),
                psnr: r6(psnr - 4.0 / k as f64 + 1.0),
                ssim: 0.5 + 0.1 * k as f64,
            })
            .collect();
        TrainSummary {
            version: SUMMARY_VERSION,
            scene: "fake".into(),
            iterations: it,
            billboards: bb,
            alive: bb * 9 / 10,
            texture_size: ts,
            sh_degree: 3,
            resolution: [s.max_width.unwrap_or(200), s.max_width.unwrap_or(200) * 3 / 4],
            train_seconds: r6(seconds),
            render_ms_per_frame: bb as f64 * 1e-3,
            test_psnr: r6(psnr),
            test_ssim: 0.9,
            test_views: 4,
            model_bytes: (bb * (64 + 4 * (48 + texels))) as u64,
            peak_rss_bytes: 100_000_000 + bb as u64 * 1000,
            estimated_peak_bytes: None,
            seed: s.seed.unwrap_or(0),
            threads: 2,
            curve,
            command: Vec::new(),
            lpips_network: None,
            test_lpips: None,
            lpips_note: None,
        }
    }

    /// A small grid of 2 × 2 × 2 settings.
    pub fn grid() -> SweepGrid {
        let mut g = SweepGrid::default();
        g.set_axis("iterations", "500,2000").unwrap();
        g.set_axis("billboards", "1000,3000").unwrap();
        g.set_axis("texture-mode", "full,gaussian").unwrap();
        g
    }
}

mod grid_runner {
    use super::fake;
    use bbsplat::sweep::*;

    #[test]
    fn run_grid_collects_in_order_and_keeps_going_after_failures() {
        let grid = fake::grid();
        let mut calls = Vec::new();
        let outcome = run_grid(&grid, |s| {
            calls.push(s.slug());
            if s.billboards == Some(3000) && s.iterations == Some(2000) {
                Err(SweepError::Other("out of memory".into()))
            } else {
                Ok(fake::summary(s))
            }
        })
        .unwrap();
        assert_eq!(calls.len(), 8);
        assert_eq!(outcome.records.len(), 6);
        assert_eq!(outcome.failures.len(), 2);
        let expected: Vec<String> = grid
            .settings()
            .unwrap()
            .iter()
            .filter(|s| !(s.billboards == Some(3000) && s.iterations == Some(2000)))
            .map(Setting::slug)
            .collect();
        let got: Vec<String> = outcome.records.iter().map(|r| r.setting.slug()).collect();
        assert_eq!(got, expected);
        assert_eq!(outcome.failures[0].error.to_string(), "out of memory");
    }

    #[test]
    fn run_grid_refuses_an_invalid_grid_without_running() {
        let grid = SweepGrid {
            billboards: vec![0],
            ..Default::default()
        };
        let mut ran = false;
        assert!(
            run_grid(&grid, |s| {
                ran = true;
                Ok(fake::summary(s))
            })
            .is_err()
        );
        assert!(!ran);
    }
}

mod grid {
    use bbsplat::sweep::*;
    use bbsplat::train::TextureMode;

    #[test]
    fn expansion_order_is_nested_with_seed_innermost() {
        let mut g = SweepGrid::default();
        g.set_axis("iterations", "500,2000").unwrap();
        g.set_axis("billboards", "1000,3000").unwrap();
        g.set_axis("seeds", "0,1").unwrap();
        let s = g.settings().unwrap();
        assert_eq!(s.len(), 8);
        assert_eq!(g.len(), 8);
        let slugs: Vec<String> = s.iter().map(Setting::slug).collect();
        assert_eq!(
            slugs,
            [
                "it500_bb1000_s0",
                "it500_bb1000_s1",
                "it500_bb3000_s0",
                "it500_bb3000_s1",
                "it2000_bb1000_s0",
                "it2000_bb1000_s1",
                "it2000_bb3000_s0",
                "it2000_bb3000_s1"
            ]
        );
    }

    #[test]
    fn a_texel_budget_pairs_texture_size_and_billboard_count() {
        let mut g = SweepGrid::default();
        g.set_axis("texels", "2560000").unwrap();
        g.set_axis("texture-size", "8,16,32,64").unwrap();
        let s = g.settings().unwrap();
        assert_eq!(g.len(), 4);
        let pairs: Vec<(usize, usize)> = s
            .iter()
            .map(|s| (s.texture_size.unwrap(), s.billboards.unwrap()))
            .collect();
        assert_eq!(pairs, [(8, 40_000), (16, 10_000), (32, 2_500), (64, 625)]);
        // Exclusive with billboards; a budget below one texture is refused.
        assert!(g.set_axis("billboards", "10").is_err());
        let err = g.set_axis("texels", "100").unwrap_err().to_string();
        assert!(err.contains("texture size 16"), "{err}");
        let mut d = SweepGrid::default();
        d.set_axis("texels", "2560").unwrap();
        assert_eq!(d.settings().unwrap()[0].billboards, Some(10), "TS 16 by default");
    }

    #[test]
    fn empty_grid_is_one_default_run() {
        let s = SweepGrid::default().settings().unwrap();
        assert_eq!(s.len(), 1);
        assert_eq!(s[0].slug(), "default");
        assert!(s[0].train_args().is_empty());
    }

    #[test]
    fn train_args_cover_every_axis() {
        let s = Setting {
            iterations: Some(7),
            billboards: Some(8),
            texture_size: Some(4),
            max_width: Some(320),
            texture_threshold: Some(0.25),
            texture_mode: Some(TextureMode::Full),
            seed: Some(3),
        };
        assert_eq!(
            s.train_args().join(" "),
            "--iterations 7 --billboards 8 --texture-size 4 --max-width 320 --texture-threshold 0.25 \
             --texture-mode full --seed 3"
        );
    }

    #[test]
    fn json_grid_parses_and_refuses_unknown_keys() {
        let g: SweepGrid =
            serde_json::from_str(r#"{"billboards": [10, 20], "texture_mode": ["full", "gaussian"]}"#).unwrap();
        assert_eq!(g.billboards, vec![10, 20]);
        assert_eq!(g.texture_mode, vec![TextureMode::Full, TextureMode::Gaussian]);
        assert_eq!(g.settings().unwrap().len(), 4);
        assert!(serde_json::from_str::<SweepGrid>(r#"{"billbords": [10]}"#).is_err());
    }

    #[test]
    fn json_file_errors_name_the_file() {
        let dir = std::env::temp_dir().join(format!("bbsplat-sweep-grid-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("grid.json");
        std::fs::write(&path, r#"{"iterations": [5, 5]}"#).unwrap();
        let err = SweepGrid::from_json_file(&path).unwrap_err().to_string();
        assert!(err.contains("listed twice"), "{err}");
        std::fs::write(&path, "{not json").unwrap();
        let err = SweepGrid::from_json_file(&path).unwrap_err().to_string();
        assert!(err.contains("grid.json"), "{err}");
        let missing = dir.join("missing.json");
        let err = SweepGrid::from_json_file(&missing).unwrap_err().to_string();
        assert!(err.contains("missing.json"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_lists_name_axis_and_value() {
        let mut g = SweepGrid::default();
        let err = g.set_axis("billboards", "1000,abc").unwrap_err().to_string();
        assert!(err.contains("billboards") && err.contains("abc"), "{err}");
        let err = g.set_axis("texture-mode", "full,none").unwrap_err().to_string();
        assert!(err.contains("none"), "{err}");
        let err = g.set_axis("texture-threshold", "-1").unwrap_err().to_string();
        assert!(err.contains("non-negative"), "{err}");
        let err = g.set_axis("texture-threshold", "NaN").unwrap_err().to_string();
        assert!(err.contains("texture-threshold"), "{err}");
        assert!(matches!(g.set_axis("colour", "1"), Err(SweepError::UnknownAxis(_))));
    }
}

mod output {
    use super::fake;
    use bbsplat::report::TrainSummary;
    use bbsplat::sweep::*;
    use bbsplat::testing_internals::sweep::{csv_field, fronts};
    use std::path::PathBuf;

    fn records() -> Vec<SweepRecord> {
        run_grid(&fake::grid(), |s| Ok(fake::summary(s))).unwrap().records
    }

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("bbsplat-sweep-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn csv_has_one_parsable_row_per_record_and_marks_fronts() {
        let recs = records();
        let csv = csv_table(&recs);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], CSV_HEADER);
        assert_eq!(lines.len(), recs.len() + 1);
        let header: Vec<&str> = CSV_HEADER.split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        let time_points: Vec<(f64, f64)> = recs
            .iter()
            .map(|r| (r.summary.train_seconds, r.summary.test_psnr))
            .collect();
        let front = pareto_front(&time_points);
        for (i, (line, r)) in lines[1..].iter().zip(&recs).enumerate() {
            let f: Vec<&str> = line.split(',').collect();
            assert_eq!(f.len(), header.len());
            assert_eq!(f[col("slug")], r.setting.slug());
            assert_eq!(f[col("test_psnr")].parse::<f64>().unwrap(), r.summary.test_psnr);
            assert_eq!(f[col("model_bytes")].parse::<u64>().unwrap(), r.summary.model_bytes);
            assert_eq!(f[col("texture_mode")], r.setting.texture_mode.unwrap().as_str());
            assert_eq!(f[col("max_width")], "");
            assert_eq!(f[col("pareto_time")] == "1", front.contains(&i));
        }
    }

    #[test]
    fn lpips_is_a_column_of_both_tables_when_a_run_has_it() {
        let mut recs = records();
        recs[1].summary.test_lpips = Some(0.123456);
        recs[1].summary.lpips_network = Some("vgg".into());
        let csv = csv_table(&recs);
        let header: Vec<&str> = CSV_HEADER.split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
        assert_eq!(rows[1][col("test_lpips")], "0.123456");
        assert_eq!(rows[1][col("lpips_network")], "vgg");
        assert_eq!((rows[0][col("test_lpips")], rows[0][col("lpips_network")]), ("", ""));
        let table = markdown_table(&recs);
        let lines: Vec<&str> = table.lines().collect();
        let lpips_col = lines[0].split('|').position(|c| c.trim() == "LPIPS").unwrap();
        assert_eq!(
            lines[3].split('|').nth(lpips_col).unwrap().trim(),
            "0.1235 vgg",
            "{table}"
        );
        assert_eq!(lines[2].split('|').nth(lpips_col).unwrap().trim(), "-", "{table}");
    }

    #[test]
    fn csv_quotes_fields_that_need_it() {
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(csv_field("plain"), "plain");
    }

    #[test]
    fn markdown_table_rows_and_pareto_column() {
        let recs = records();
        let table = markdown_table(&recs);
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), recs.len() + 2);
        // Every row has the header's column count.
        let cols = lines[0].matches('|').count();
        assert!(lines.iter().all(|l| l.matches('|').count() == cols));
        // The fastest run is on the time front; it has the smallest model, but so has the longer
        // run with the same budget, which is better: only that one is on the size front.
        let row = |slug: &str| *lines.iter().find(|l| l.starts_with(&format!("| {slug} |"))).unwrap();
        assert!(row("it500_bb1000_gaussian").ends_with("| time |"), "{table}");
        assert!(row("it2000_bb1000_gaussian").ends_with("size |"), "{table}");
        // A run that is slower and worse than another is not on the time front.
        let get = |slug: &str| &recs.iter().find(|r| r.setting.slug() == slug).unwrap().summary;
        let (slow, fast) = (get("it2000_bb1000_full"), get("it500_bb3000_full"));
        assert!(fast.train_seconds < slow.train_seconds && fast.test_psnr > slow.test_psnr);
        assert!(!row("it2000_bb1000_full").contains("time"), "{table}");
        // PSNR with two decimals, model size in MB.
        let r = get("it2000_bb3000_full");
        assert!(row("it2000_bb3000_full").contains(&format!("| {:.2} |", r.test_psnr)));
        assert!(row("it2000_bb3000_full").contains(&format!("| {:.2} |", r.model_bytes as f64 / 1e6)));
    }

    #[test]
    fn unknown_model_size_is_on_no_size_front() {
        let mut recs = records();
        // The best run by PSNR saved no model.
        let best = (0..recs.len())
            .max_by(|&a, &b| recs[a].summary.test_psnr.total_cmp(&recs[b].summary.test_psnr))
            .unwrap();
        recs[best].summary.model_bytes = 0;
        recs[best].summary.peak_rss_bytes = 0;
        let (time, size) = fronts(&recs);
        assert!(time[best] && !size[best]);
        let table = markdown_table(&recs);
        let row = table.lines().nth(best + 2).unwrap();
        assert!(row.ends_with("| n/a | n/a | time |"), "{row}");
    }

    #[test]
    fn write_outputs_writes_every_file_atomically() {
        let dir = temp_dir("outputs");
        let recs = records();
        let files = write_outputs(&dir.join("report"), &recs).unwrap();
        for p in [
            &files.csv,
            &files.json,
            &files.markdown,
            &files.psnr_vs_time,
            &files.psnr_vs_size,
            &files.curves,
        ] {
            assert!(std::fs::metadata(p).unwrap().len() > 100, "{}", p.display());
        }
        let leftovers: Vec<_> = std::fs::read_dir(dir.join("report"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp"))
            .collect();
        assert!(leftovers.is_empty(), "{leftovers:?}");
        assert_eq!(std::fs::read_to_string(&files.csv).unwrap(), csv_table(&recs));
        assert_eq!(std::fs::read_to_string(&files.markdown).unwrap(), markdown_table(&recs));
        // The JSON reads back into the same records.
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&files.json).unwrap()).unwrap();
        let rows = v["records"].as_array().unwrap();
        assert_eq!(rows.len(), recs.len());
        for (row, r) in rows.iter().zip(&recs) {
            assert_eq!(row["slug"], r.setting.slug());
            let setting: Setting = serde_json::from_value(row["setting"].clone()).unwrap();
            let summary: TrainSummary = serde_json::from_value(row["summary"].clone()).unwrap();
            assert_eq!(&setting, &r.setting);
            assert_eq!(&summary, &r.summary);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn write_errors_name_the_file() {
        let dir = temp_dir("blocked");
        std::fs::create_dir_all(&dir).unwrap();
        // A directory where the CSV goes is refused (not replaced by the file).
        std::fs::create_dir_all(dir.join("sweep.csv")).unwrap();
        let err = write_outputs(&dir, &records()).unwrap_err().to_string();
        assert!(err.contains("sweep.csv") && err.contains("is a directory"), "{err}");
        assert!(dir.join("sweep.csv").is_dir());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

mod pareto {
    use bbsplat::sweep::*;
    use proptest::prelude::*;

    fn brute_force(points: &[(f64, f64)]) -> Vec<usize> {
        let ok = |p: (f64, f64)| !p.0.is_nan() && !p.1.is_nan();
        let mut front: Vec<usize> = (0..points.len())
            .filter(|&i| ok(points[i]))
            .filter(|&i| {
                let (ci, qi) = points[i];
                !(0..points.len()).any(|j| {
                    let (cj, qj) = points[j];
                    ok(points[j]) && cj <= ci && qj >= qi && (cj < ci || qj > qi)
                })
            })
            .collect();
        front.sort_by(|&a, &b| points[a].0.partial_cmp(&points[b].0).unwrap().then(a.cmp(&b)));
        front
    }

    #[test]
    fn empty_and_single() {
        assert!(pareto_front(&[]).is_empty());
        assert_eq!(pareto_front(&[(1.0, 1.0)]), vec![0]);
        assert!(pareto_front(&[(f64::NAN, 1.0)]).is_empty());
        assert!(pareto_front(&[(1.0, f64::NAN)]).is_empty());
    }

    #[test]
    fn duplicates_are_all_kept() {
        assert_eq!(pareto_front(&[(1.0, 5.0), (1.0, 5.0), (2.0, 4.0)]), vec![0, 1]);
    }

    #[test]
    fn equal_cost_keeps_best_quality_only() {
        assert_eq!(pareto_front(&[(1.0, 4.0), (1.0, 5.0), (2.0, 6.0)]), vec![1, 2]);
    }

    #[test]
    fn equal_quality_keeps_cheapest_only() {
        assert_eq!(pareto_front(&[(3.0, 5.0), (1.0, 5.0), (2.0, 5.0)]), vec![1]);
    }

    #[test]
    fn nan_neither_joins_nor_dominates() {
        // The NaN-cost point has the best quality but must not hide (2, 3).
        assert_eq!(pareto_front(&[(f64::NAN, 99.0), (2.0, 3.0), (1.0, f64::NAN)]), vec![1]);
    }

    #[test]
    fn infinities_compare_as_usual() {
        let pts = [(1.0, f64::NEG_INFINITY), (2.0, 10.0), (f64::INFINITY, f64::INFINITY)];
        assert_eq!(pareto_front(&pts), vec![0, 1, 2]);
    }

    proptest! {
        #[test]
        fn matches_brute_force(
            raw in prop::collection::vec((0u8..8, 0u8..8, 0u8..20), 0..40)
        ) {
            // Small integer grids force many ties and duplicates; code 0 of the third value
            // injects a NaN.
            let points: Vec<(f64, f64)> = raw
                .iter()
                .map(|&(c, q, n)| match n {
                    0 => (f64::NAN, q as f64),
                    1 => (c as f64, f64::NAN),
                    _ => (c as f64, q as f64),
                })
                .collect();
            prop_assert_eq!(pareto_front(&points), brute_force(&points));
        }
    }
}

mod plot {
    use super::fake;
    use bbsplat::sweep::*;
    use bbsplat::testing_internals::sweep::padded_range;

    fn records() -> Vec<SweepRecord> {
        run_grid(&fake::grid(), |s| Ok(fake::summary(s))).unwrap().records
    }

    #[test]
    fn padded_range_handles_degenerate_input() {
        assert_eq!(padded_range([].into_iter()), 0.0..1.0);
        assert_eq!(padded_range([f64::NAN, f64::INFINITY].into_iter()), 0.0..1.0);
        assert_eq!(padded_range([3.0].into_iter()), 2.0..4.0);
        let r = padded_range([0.0, 10.0, f64::NAN].into_iter());
        assert!((r.start + 0.5).abs() < 1e-12 && (r.end - 10.5).abs() < 1e-12);
    }

    #[test]
    fn scatter_marks_every_run_and_the_front() {
        let recs = records();
        let svg = plot_psnr_vs_time_svg(&recs).unwrap();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("training time (s)") && svg.contains("Pareto front"));
        let points: Vec<(f64, f64)> = recs
            .iter()
            .map(|r| (r.summary.train_seconds, r.summary.test_psnr))
            .collect();
        let front = pareto_front(&points).len();
        // One hollow circle per run plus the legend's, one filled circle per front point.
        assert_eq!(svg.matches("<circle").count(), recs.len() + 1 + front);
        assert!(front >= 2 && front < recs.len());
        // Front points are labelled with their slugs, the others are not.
        for (i, r) in recs.iter().enumerate() {
            let on = pareto_front(&points).contains(&i);
            assert_eq!(
                svg.contains(&format!("\n{}\n", r.setting.slug())),
                on,
                "{}",
                r.setting.slug()
            );
        }
        let svg = plot_psnr_vs_size_svg(&recs).unwrap();
        assert!(svg.contains("model size (MB)"));
    }

    #[test]
    fn curves_have_one_line_per_run_and_skip_nan() {
        let mut recs = records();
        recs[0].summary.curve[1].psnr = f64::NAN;
        recs[1].summary.curve.clear();
        let svg = plot_curves_svg(&recs).unwrap();
        // Run 1 has no curve: not in the legend.
        assert!(!svg.contains(&recs[1].setting.slug()));
        for r in recs.iter().skip(2) {
            assert!(svg.contains(&r.setting.slug()));
        }
        // Four points per curve, one NaN left out.
        assert_eq!(svg.matches("<circle").count(), 4 * (recs.len() - 1) - 1);
        assert!(!svg.contains("NaN"));
    }

    #[test]
    fn empty_sweeps_still_plot() {
        for svg in [
            plot_psnr_vs_time_svg(&[]).unwrap(),
            plot_psnr_vs_size_svg(&[]).unwrap(),
            plot_curves_svg(&[]).unwrap(),
        ] {
            assert!(svg.starts_with("<svg"));
        }
    }
}

#[cfg(unix)]
mod runner {
    use super::fake;
    use bbsplat::sweep::*;
    use std::os::unix::fs::PermissionsExt;
    use std::path::{Path, PathBuf};

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("bbsplat-sweep-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A shell script standing in for `bbsplat`: logs its arguments to `<out>/args.txt`, copies
    /// `<out>.json` (prepared by the test) to `<out>/summary.json`, fails when `<out>.fail`
    /// exists.
    fn fake_exe(dir: &Path) -> PathBuf {
        let exe = dir.join("fake-bbsplat");
        std::fs::write(
            &exe,
            "#!/bin/sh\nout=$4\necho \"$@\" >> \"$out/args.txt\"\necho training\n\
             if [ -e \"$out.fail\" ]; then echo boom >&2; exit 3; fi\ncp \"$out.json\" \"$out/summary.json\"\n",
        )
        .unwrap();
        std::fs::set_permissions(&exe, std::fs::Permissions::from_mode(0o755)).unwrap();
        exe
    }

    #[test]
    fn runs_each_setting_once_then_resumes() {
        let dir = temp_dir("runner");
        let exe = fake_exe(&dir);
        let out = dir.join("runs");
        std::fs::create_dir_all(&out).unwrap();
        let mut grid = SweepGrid::default();
        grid.set_axis("billboards", "10,20").unwrap();
        grid.set_axis("iterations", "5").unwrap();
        grid.set_axis("seeds", "7").unwrap();
        let settings = grid.settings().unwrap();
        for s in &settings {
            let json = serde_json::to_string(&fake::summary(s)).unwrap();
            std::fs::write(out.join(format!("{}.json", s.slug())), json).unwrap();
        }
        // The second setting fails the first time.
        let fail_marker = out.join(format!("{}.fail", settings[1].slug()));
        std::fs::write(&fail_marker, "").unwrap();

        let mut runner = SubprocessRunner::new(exe.clone(), PathBuf::from("scenes/x"), out.clone());
        runner.extra_args = vec!["--threads".into(), "1".into()];
        let first = run_grid(&grid, |s| runner.run(s)).unwrap();
        assert_eq!(first.records.len(), 1);
        assert_eq!(first.records[0].summary, fake::summary(&settings[0]));
        let err = first.failures[0].error.to_string();
        assert!(err.contains("it5_bb20_s7") && err.contains("train.log"), "{err}");
        let log = std::fs::read_to_string(out.join("it5_bb20_s7/train.log")).unwrap();
        assert!(log.contains("boom") && log.contains("training"), "{log}");

        let args = std::fs::read_to_string(out.join("it5_bb10_s7/args.txt")).unwrap();
        assert_eq!(
            args.trim(),
            format!(
                "train scenes/x -o {} --iterations 5 --billboards 10 --seed 7 --threads 1 --quiet",
                out.join("it5_bb10_s7").display()
            )
        );

        std::fs::remove_file(&fail_marker).unwrap();
        let second = run_grid(&grid, subprocess_runner(exe, "scenes/x".into(), out.clone())).unwrap();
        assert_eq!(second.records.len(), 2);
        assert!(second.failures.is_empty());
        // The finished run was not started again; the failed one ran a second time.
        let count = |slug: &str| {
            std::fs::read_to_string(out.join(slug).join("args.txt"))
                .unwrap()
                .lines()
                .count()
        };
        assert_eq!(count("it5_bb10_s7"), 1);
        assert_eq!(count("it5_bb20_s7"), 2);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn stale_or_missing_summaries_are_reported_with_their_path() {
        let dir = temp_dir("stale");
        let exe = fake_exe(&dir);
        let setting = Setting {
            iterations: Some(100),
            billboards: None,
            texture_size: None,
            max_width: None,
            texture_threshold: None,
            texture_mode: None,
            seed: None,
        };
        let runner = SubprocessRunner::new(exe, "s".into(), dir.clone());
        // A folder left by a run with other flags.
        let run_dir = runner.run_dir(&setting);
        std::fs::create_dir_all(&run_dir).unwrap();
        let mut stale = fake::summary(&setting);
        stale.iterations = 50;
        std::fs::write(run_dir.join("summary.json"), serde_json::to_string(&stale).unwrap()).unwrap();
        let err = runner.run(&setting).unwrap_err();
        assert!(
            matches!(
                err,
                SweepError::Mismatch {
                    field: "iterations",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("summary.json"));
        // A truncated summary.
        std::fs::write(run_dir.join("summary.json"), "{\"version\": 1").unwrap();
        assert!(matches!(runner.run(&setting), Err(SweepError::Json { .. })));
        // A child that succeeds without writing one: the script's `cp` fails, so use `true`.
        std::fs::remove_file(run_dir.join("summary.json")).unwrap();
        let quiet = SubprocessRunner::new("true".into(), "s".into(), dir.clone());
        assert!(matches!(quiet.run(&setting), Err(SweepError::MissingSummary { .. })));
        // A missing executable.
        let missing = SubprocessRunner::new(dir.join("nope"), "s".into(), dir.clone());
        assert!(matches!(missing.run(&setting), Err(SweepError::Spawn { .. })));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
