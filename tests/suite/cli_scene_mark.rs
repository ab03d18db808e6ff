//! Issue 60 item 10: a model records the scene it was trained on (`bbsplat.json` `scene`), and
//! the commands that read a model with a scene warn when it is another one; the same scene
//! loaded at another resolution or split is not another scene.

use super::cli::{run_ok, temp, train_five_steps};
use bbsplat::model_file::load_model;
use std::path::Path;
use std::process::Command;

fn stderr_of(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat")).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn export(dir: &Path, resolution: &str, seed: &str) {
    run_ok(&[
        "demo",
        "--export",
        dir.to_str().unwrap(),
        "--resolution",
        resolution,
        "--billboards",
        "100",
        "--seed",
        seed,
    ]);
}

#[test]
fn a_model_met_with_another_scene_is_warned_about() {
    let root = temp("scene-mark");
    let (a, a_large, b) = (root.join("a"), root.join("a-large"), root.join("b"));
    export(&a, "24", "0");
    export(&a_large, "32", "0");
    export(&b, "24", "5");
    let model = train_five_steps(&a, &root.join("out"), 100);
    let (_, meta) = load_model(&model).unwrap();
    let mark = meta.scene.expect("the model records its scene");
    assert_eq!(mark.views, 40);
    let m = model.to_str().unwrap();
    let warning = "is it the model of another scene?";
    // The same scene: no warning, whatever its resolution or split.
    for (scene, extra) in [(&a, None), (&a_large, None), (&a, Some("--test-every=3"))] {
        let mut args = vec!["eval", m, scene.to_str().unwrap()];
        args.extend(extra);
        let err = stderr_of(&args);
        assert!(!err.contains(warning), "{args:?}: {err}");
    }
    // Another scene: every command that reads the model with it warns.
    let other = b.to_str().unwrap();
    let page = root.join("page.html");
    let renders = root.join("renders");
    let commands: Vec<Vec<&str>> = vec![
        vec!["eval", m, other],
        vec!["render", m, other, "-o", renders.to_str().unwrap()],
        vec!["view", m, other, "-o", page.to_str().unwrap()],
    ];
    for args in commands {
        let err = stderr_of(&args);
        assert!(
            err.contains(warning) && err.contains("camera poses differ"),
            "{args:?}: {err}"
        );
    }
    std::fs::remove_dir_all(&root).ok();
}
