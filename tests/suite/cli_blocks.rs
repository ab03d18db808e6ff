//! `bbsplat blocks run` on a small street: the chain's stages run in order, each block keeps its
//! own cell's billboards, a second run does nothing, the chain is the same bits on 1 and 2
//! threads, `--slurm` writes the jobs; bad inputs of the stages are refused by name.

use crate::cli::{run, run_ok, temp};
use bbsplat::blocks::Partition;
use std::path::Path;

/// The model files of a model folder (the PLY and the textures; not `bbsplat.json`, which
/// names its folder).
pub(crate) fn model_files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x != "json"))
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    files.sort();
    files
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn chain(data: &Path, out: &Path, threads: &str, extra: &[&str]) -> String {
    let mut args = vec![
        "blocks",
        "run",
        data.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--grid",
        "2x1",
        "--coarse-iterations",
        "100",
        "--block-iterations",
        "150",
        "--polish-iterations",
        "50",
        "--threads",
        threads,
    ];
    args.extend_from_slice(extra);
    run_ok(&args)
}

#[test]
fn a_street_trained_as_blocks_merges_each_blocks_own_cell() {
    let root = temp("blocks-chain");
    let data = root.join("street");
    run_ok(&[
        "demo",
        "--export",
        data.to_str().unwrap(),
        "--street",
        "6",
        "--resolution",
        "32",
    ]);
    let out = root.join("one");
    let out_s = out.to_str().unwrap();
    let printed = chain(&data, &out, "1", &[]);
    for stage in [
        "coarse run:",
        "split:",
        "block 0:",
        "block 1:",
        "merge:",
        "polish:",
        "report:",
    ] {
        assert!(printed.contains(stage), "{stage} did not run: {printed}");
    }
    // The plan: two cells along the street, both trained, the views shared a little.
    let plan = json(&out.join("blocks/blocks.json"));
    let partition: Partition = serde_json::from_value(plan["partition"].clone()).unwrap();
    assert_eq!(partition.cell_count(), 2);
    assert!(
        partition.frame.along.x.abs() > 0.99,
        "the street runs along x: {:?}",
        partition.frame
    );
    let overlap = plan["overlap_factor"].as_f64().unwrap();
    assert!((1.0..2.0).contains(&overlap), "overlap factor {overlap}");
    // Each block's views keep their split: its run's test views are its test views.
    for k in 0..2 {
        let block = &plan["blocks"][k];
        let summary = json(&out.join(format!("blocks/block_{k}/run/summary.json")));
        assert_eq!(summary["test_views"], block["test_views"].as_array().unwrap().len());
        let listed = std::fs::read_to_string(out.join(format!("blocks/block_{k}/views.txt"))).unwrap();
        let names = listed.lines().filter(|l| !l.starts_with('#')).count();
        let in_plan = block["train_views"].as_array().unwrap().len() + block["test_views"].as_array().unwrap().len();
        assert_eq!(names, in_plan);
    }
    // The merge: block k's kept rows come k-th, and every one lies in cell k.
    let merge = json(&out.join("blocks/merge.json"));
    let kept: Vec<usize> = merge["kept"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    let (merged, _) = bbsplat::load_model(&out.join("merged")).unwrap();
    assert_eq!(merged.len(), kept.iter().sum::<usize>());
    let mut row = 0;
    for (k, &n) in kept.iter().enumerate() {
        assert!(n > 0, "block {k} kept nothing");
        for p in &merged.positions[row..row + n] {
            assert_eq!(partition.cell_of_point(*p), k, "a billboard of block {k} at {p:?}");
        }
        row += n;
    }
    // The polish starts from the merged model; the report holds the chain.
    let polish = json(&out.join("polish/summary.json"));
    assert!(polish["test_psnr"].as_f64().unwrap() > 12.0, "{polish}");
    let report = json(&out.join("report.json"));
    assert_eq!(report["merged_billboards"], merged.len());
    let wall = report["wall_time"].as_array().unwrap();
    let (one, two) = (
        wall[0]["seconds"].as_f64().unwrap(),
        wall[1]["seconds"].as_f64().unwrap(),
    );
    // One machine: every stage in turn (the model rounds each block to the microsecond).
    let total = report["total_seconds"].as_f64().unwrap();
    assert!(two < one && (one - total).abs() < 1e-5, "{report}");
    // The seam band: the polished model and, as another model, the coarse one, on one band.
    let printed = run_ok(&[
        "blocks",
        "seams",
        out_s,
        "--model",
        out.join("coarse").to_str().unwrap(),
    ]);
    assert!(printed.contains("seam band: within"), "{printed}");
    let seams = json(&out.join("seams.json"));
    let share = seams["band_share"].as_f64().unwrap();
    assert!(share > 0.0 && share < 1.0, "{seams}");
    assert!(seams["views_with_band"].as_u64().unwrap() > 0, "{seams}");
    let models = seams["models"].as_array().unwrap();
    assert_eq!(models.len(), 2, "{seams}");
    assert!(
        models[0]["model"].as_str().unwrap().ends_with("polish/model"),
        "{seams}"
    );
    // The whole-view PSNR is the one the polish's own evaluation found.
    let whole = models[0]["psnr"].as_f64().unwrap();
    assert!(
        (whole - polish["test_psnr"].as_f64().unwrap()).abs() < 1e-6,
        "{seams} {polish}"
    );
    for m in models {
        assert!(
            m["band_psnr"].as_f64().unwrap() > 5.0 && m["off_band_psnr"].as_f64().unwrap() > 5.0,
            "{seams}"
        );
    }
    let (ok, err) = run(&["blocks", "seams", out_s, "--width", "0"]);
    assert!(!ok && err.contains("give --width"), "{err}");
    // Run again: nothing to do, nothing changed.
    let before = model_files(&out.join("polish/model"));
    let again = chain(&data, &out, "1", &[]);
    assert!(
        again.contains("coarse run: done earlier") && again.contains("polish: done earlier"),
        "{again}"
    );
    assert!(
        again.contains("split: done earlier") && again.contains("merge: done earlier"),
        "{again}"
    );
    assert_eq!(model_files(&out.join("polish/model")), before);
    // The same chain on 2 threads: the same bits.
    let two_threads = root.join("two");
    chain(&data, &two_threads, "2", &[]);
    for stage in ["coarse/model", "merged", "polish/model"] {
        assert_eq!(
            model_files(&two_threads.join(stage)),
            model_files(&out.join(stage)),
            "{stage} differs on 2 threads"
        );
    }
    // --slurm writes the jobs and runs nothing.
    let jobs = root.join("jobs");
    // With scene flags, which every stage that loads the scene gets.
    let printed = chain(
        &data,
        &jobs,
        "1",
        &[
            "--slurm",
            "--cpus-per-task",
            "1",
            "--test-every",
            "4",
            "--background",
            "white",
        ],
    );
    assert!(printed.contains("submit them with"), "{printed}");
    assert!(!jobs.join("coarse").exists(), "--slurm trained");
    let submit = std::fs::read_to_string(jobs.join("slurm/submit.sh")).unwrap();
    assert_eq!(submit.matches("sbatch --parsable").count(), 6, "{submit}");
    let blocks = std::fs::read_to_string(jobs.join("slurm/blocks/blocks.sbatch")).unwrap();
    assert!(
        blocks.contains("#SBATCH --array=0-1") && blocks.contains("--init-model"),
        "{blocks}"
    );
    let split = std::fs::read_to_string(jobs.join("slurm/coarse/collect.sbatch")).unwrap();
    let coarse = std::fs::read_to_string(jobs.join("slurm/coarse/coarse.sbatch")).unwrap();
    for (what, script) in [("split", &split), ("coarse", &coarse), ("blocks", &blocks)] {
        assert!(
            script.contains("--test-every 4 --background white")
                || script.contains("--background white --test-every 4"),
            "{what}: {script}"
        );
    }
    let merge = std::fs::read_to_string(jobs.join("slurm/blocks/collect.sbatch")).unwrap();
    let exe = env!("CARGO_BIN_EXE_bbsplat");
    assert!(merge.contains(&format!("exec {exe} blocks merge")), "{merge}");
    // A report of a chain missing a stage's summary names the file.
    std::fs::remove_file(out.join("polish/summary.json")).unwrap();
    let (ok, err) = run(&["blocks", "report", out_s]);
    assert!(!ok && err.contains("polish/summary.json"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn the_block_stages_refuse_bad_inputs_by_name() {
    let root = temp("blocks-bad");
    let data = crate::cli::export_demo(&root, 16, 60);
    let data_s = data.to_str().unwrap();
    // --views naming no view of the scene.
    let list = root.join("views.txt");
    std::fs::write(&list, "# a list\nview_001.png\nno_such_view.png\n").unwrap();
    let out = root.join("run");
    let (ok, err) = run(&[
        "train",
        data_s,
        "-o",
        out.to_str().unwrap(),
        "--views",
        list.to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("views.txt") && err.contains("no_such_view.png"),
        "{err}"
    );
    // --views keeping only test views (view_000 is held out: every 8th from 0).
    std::fs::write(&list, "view_000.png\n").unwrap();
    let (ok, err) = run(&[
        "train",
        data_s,
        "-o",
        out.to_str().unwrap(),
        "--views",
        list.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("none of its 1 views is a training view"), "{err}");
    // --init-model of another texture size.
    let first = root.join("first");
    let f = first.to_str().unwrap();
    run_ok(&[
        "train",
        data_s,
        "-o",
        f,
        "--iterations",
        "5",
        "--texture-size",
        "4",
        "--quiet",
    ]);
    let model = first.join("model");
    let (ok, err) = run(&[
        "train",
        data_s,
        "-o",
        out.to_str().unwrap(),
        "--init-model",
        model.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("--texture-size 4"), "{err}");
    // ... and of the right one trains from it.
    let printed = run_ok(&[
        "train",
        data_s,
        "-o",
        out.to_str().unwrap(),
        "--init-model",
        model.to_str().unwrap(),
        "--texture-size",
        "4",
        "--iterations",
        "5",
    ]);
    let (start, _) = bbsplat::load_model(&model).unwrap();
    assert!(
        printed.contains(&format!("initial billboards: {} from", start.len())),
        "{printed}"
    );
    // Merging a folder that is no blocks folder; a grid without cells.
    let (ok, err) = run(&[
        "blocks",
        "merge",
        root.to_str().unwrap(),
        "-o",
        root.join("m").to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("blocks.json"), "{err}");
    // `blocks split` with one bad flag.
    let b = root.join("b");
    let split_with = |extra: &[&str]| {
        let mut args = vec![
            "blocks",
            "split",
            data_s,
            "--coarse",
            model.to_str().unwrap(),
            "-o",
            b.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let (ok, err) = split_with(&["--grid", "0x1"]);
    assert!(!ok && err.contains("from 1 to 64"), "{err}");
    let (ok, err) = split_with(&["--min-share", "2"]);
    assert!(
        !ok && err.contains("--min-share must be a fraction from 0 to 1 (got 2)"),
        "{err}"
    );
    let (ok, err) = split_with(&["--turn", "NaN"]);
    assert!(
        !ok && err.contains("--turn must be a finite angle in degrees (got NaN)"),
        "{err}"
    );
    // An --init-model folder that holds no model names the folder and the file it lacks.
    let empty = root.join("empty_model");
    std::fs::create_dir_all(&empty).unwrap();
    let (ok, err) = run(&[
        "train",
        data_s,
        "-o",
        root.join("from_empty").to_str().unwrap(),
        "--init-model",
        empty.to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("--init-model") && err.contains("empty_model"),
        "{err}"
    );
    assert!(!root.join("from_empty").join("summary.json").exists());
    // A report of a folder that holds no chain names the plan it looked for.
    let (ok, err) = run(&["blocks", "report", root.to_str().unwrap()]);
    assert!(!ok && err.contains("blocks.json"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}
