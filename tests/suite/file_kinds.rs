//! Files that are not regular files (issue 60): outputs are written through symbolic links and
//! never over a device, a FIFO or a folder; inputs that are devices (a link to `/dev/zero`),
//! FIFOs or symlink loops are refused at once, saying what they are, with memory bounded; the
//! `--resume` checkpoint is checked before the scene loads. The commands run through the built
//! binary with `ulimit -v` and a deadline, so a read that never ends fails the test instead of
//! filling the machine's memory or hanging.

use super::cli::{export_demo, temp, train_five_steps};
use bbsplat::scene::{LoadOptions, load};
use std::io::{Read, Write};
use std::os::unix::fs::{FileTypeExt, symlink};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// Virtual memory a command may use (KiB): a read of `/dev/zero` exhausts it in a moment.
const MEMORY_KIB: u64 = 4 << 20;
/// Longest a command may take (a FIFO's open blocks for ever).
const DEADLINE: Duration = Duration::from_secs(180);

/// Runs the binary with [`MEMORY_KIB`] of address space, killed after [`DEADLINE`] (which fails
/// the test): whether it succeeded and its standard error.
fn run_bounded(args: &[&str]) -> (bool, String) {
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(format!("ulimit -v {MEMORY_KIB} && exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_bbsplat"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("sh runs");
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > DEADLINE {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?} still ran after {DEADLINE:?}: a read that does not end");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    (status.success(), reader.join().unwrap())
}

/// A demo scene and a model trained on it for five steps, made once for the tests of this file
/// (which copy what they change).
fn shared() -> &'static (PathBuf, PathBuf) {
    static SHARED: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    SHARED.get_or_init(|| {
        let root = temp("file-kinds-shared");
        let data = export_demo(&root, 16, 30);
        let model = train_five_steps(&data, &root.join("run"), 30);
        (data, model)
    })
}

/// A copy of the shared model folder in `dir`.
fn copy_model(dir: &Path) -> PathBuf {
    let (_, model) = shared();
    let copy = dir.join("model");
    std::fs::create_dir_all(&copy).unwrap();
    for entry in std::fs::read_dir(model).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), copy.join(entry.file_name())).unwrap();
    }
    copy
}

fn mkfifo(path: &Path) {
    let ok = Command::new("mkfifo").arg(path).status().unwrap().success();
    assert!(ok, "mkfifo {}", path.display());
}

/// A character device like `/dev/full` (1, 7) at `path`, private to the test: `None` (the
/// test says SKIPPED) when the system refuses (`mknod` needs root; CI runs as root and must).
fn full_device(path: &Path, test: &str) -> Option<()> {
    let made = Command::new("mknod")
        .arg(path)
        .args(["c", "1", "7"])
        .output()
        .is_ok_and(|o| o.status.success());
    if made {
        return Some(());
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{test}: mknod failed (CI runs as root)"
    );
    let _ = writeln!(std::io::stderr(), "SKIPPED {test}: mknod needs root");
    None
}

fn is_link(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
}

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// `view -o` and `export -o` through links: the link stays a link (relative, absolute, in a
/// chain, dangling) and the file it names holds the new output.
#[test]
fn outputs_are_written_through_links_which_stay_links() {
    let (data, model) = shared();
    let root = temp("file-kinds-links");
    std::fs::create_dir_all(root.join("real")).unwrap();
    let real = root.join("real/page.html");
    std::fs::write(&real, "old").unwrap();
    let (link, chain) = (root.join("link.html"), root.join("chain.html"));
    symlink("real/page.html", &link).unwrap();
    symlink(&link, &chain).unwrap();
    for out in [&link, &chain] {
        let (ok, err) = run_bounded(&["view", s(model), "-o", s(out)]);
        assert!(ok, "{err}");
        assert!(is_link(&link) && is_link(&chain), "the links stay links");
        let page = std::fs::read_to_string(&real).unwrap();
        assert!(
            page.len() > 1000 && page.contains("<html"),
            "the page is written through the link"
        );
        std::fs::write(&real, "old").unwrap();
    }
    // A dangling link: the file it names is created.
    let dangling = root.join("dangling.html");
    symlink(root.join("real/new.html"), &dangling).unwrap();
    let (ok, err) = run_bounded(&["view", s(model), "-o", s(&dangling)]);
    assert!(ok, "{err}");
    assert!(is_link(&dangling) && std::fs::metadata(root.join("real/new.html")).unwrap().len() > 1000);

    // export: a link in the output folder.
    let out = root.join("export");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(root.join("real/planes.glb"), "old").unwrap();
    symlink(root.join("real/planes.glb"), out.join("planes_mesh.glb")).unwrap();
    let (ok, err) = run_bounded(&["export", s(model), s(data), "-o", s(&out)]);
    assert!(ok, "{err}");
    assert!(is_link(&out.join("planes_mesh.glb")));
    assert!(
        std::fs::read(root.join("real/planes.glb"))
            .unwrap()
            .starts_with(b"glTF")
    );
    let temporaries: Vec<_> = std::fs::read_dir(root.join("real"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp"))
        .collect();
    assert!(temporaries.is_empty(), "{temporaries:?}");
    std::fs::remove_dir_all(&root).ok();
}

/// `view -o` onto a device node (like `/dev/full`), a FIFO, a link to the device, or a folder:
/// refused, saying what is there, and the node is still what it was (the old writes renamed a
/// regular file over it).
#[test]
fn an_output_that_is_a_device_a_fifo_or_a_folder_is_refused_and_left_as_it_is() {
    let (_, model) = shared();
    let root = temp("file-kinds-nodes");
    std::fs::create_dir_all(&root).unwrap();
    let (device, fifo, link, folder) = (
        root.join("full"),
        root.join("fifo"),
        root.join("link"),
        root.join("folder"),
    );
    let Some(()) = full_device(&device, "an_output_that_is_a_device_is_refused") else {
        return;
    };
    mkfifo(&fifo);
    symlink(&device, &link).unwrap();
    std::fs::create_dir_all(&folder).unwrap();
    for (out, what) in [
        (&device, "is a character device"),
        (&fifo, "is a FIFO"),
        (&link, "is a character device"),
        (&folder, "is a directory"),
    ] {
        let (ok, err) = run_bounded(&["view", s(model), "-o", s(out)]);
        assert!(!ok, "{}: written", out.display());
        assert!(err.contains(s(out)) && err.contains(what), "{err}");
    }
    let kind = |p: &Path| std::fs::symlink_metadata(p).unwrap().file_type();
    assert!(kind(&device).is_char_device(), "the device node is still one");
    assert!(kind(&fifo).is_fifo(), "the FIFO is still one");
    assert!(kind(&link).is_symlink() && kind(&folder).is_dir());
    let names: Vec<_> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 4, "nothing else written: {names:?}");
    std::fs::remove_dir_all(&root).ok();
}

/// An output *folder* (`render -o`, `export -o`) that is a device, a FIFO or a regular file is
/// refused naming what it is, not a folder (before: "creating …: File exists").
#[test]
fn an_output_folder_that_is_something_else_is_named() {
    let (data, model) = shared();
    let root = temp("file-kinds-folders");
    std::fs::create_dir_all(&root).unwrap();
    let (device, fifo, file) = (root.join("full"), root.join("fifo"), root.join("file"));
    let Some(()) = full_device(&device, "an_output_folder_that_is_something_else_is_named") else {
        return;
    };
    mkfifo(&fifo);
    std::fs::write(&file, b"mine").unwrap();
    for (out, what) in [
        (&device, "is a character device, not a folder"),
        (&fifo, "is a FIFO (named pipe), not a folder"),
        (&file, "is a regular file, not a folder"),
    ] {
        for command in ["render", "export"] {
            let (ok, err) = run_bounded(&[command, s(model), s(data), "-o", s(out)]);
            assert!(!ok, "{command} {}: written", out.display());
            assert!(err.contains(s(out)) && err.contains(what), "{command}: {err}");
        }
    }
    assert_eq!(std::fs::read(&file).unwrap(), b"mine");
    std::fs::remove_dir_all(&root).ok();
}

/// Every file of a model folder replaced by a link to `/dev/zero` (or a FIFO): `eval` fails
/// at once naming the file and what it is (before, it read until memory ran out, or blocked).
#[test]
fn model_files_that_are_devices_or_fifos_are_refused_quickly() {
    let (data, _) = shared();
    let root = temp("file-kinds-model");
    for name in [
        "point_cloud.ply",
        "bbsplat.json",
        "texture_color.npz",
        "texture_alpha.npz",
    ] {
        let dir = root.join(name);
        let model = copy_model(&dir);
        std::fs::remove_file(model.join(name)).unwrap();
        symlink("/dev/zero", model.join(name)).unwrap();
        let (ok, err) = run_bounded(&["eval", s(&model), s(data)]);
        assert!(!ok, "{name}");
        assert!(
            err.contains(name) && err.contains("is a character device"),
            "{name}: {err}"
        );
        assert!(err.contains("(a link to /dev/zero)"), "{err}");
    }
    let model = copy_model(&root.join("fifo"));
    std::fs::remove_file(model.join("texture_color.npz")).unwrap();
    mkfifo(&model.join("texture_color.npz"));
    let (ok, err) = run_bounded(&["render", s(&model), s(data), "-o", s(&root.join("renders"))]);
    assert!(
        !ok && err.contains("texture_color.npz") && err.contains("is a FIFO"),
        "{err}"
    );
    std::fs::remove_dir_all(&root).ok();
}

/// `train --resume` with a checkpoint that is a link to `/dev/zero` or a FIFO is refused before
/// the scene is loaded: even with a scene that does not exist, the checkpoint is what is named.
#[test]
fn resume_checks_the_checkpoint_before_loading_the_scene() {
    let (data, _) = shared();
    let root = temp("file-kinds-resume");
    std::fs::create_dir_all(&root).unwrap();
    let (zero, fifo) = (root.join("zero.bin"), root.join("fifo.bin"));
    symlink("/dev/zero", &zero).unwrap();
    mkfifo(&fifo);
    for (checkpoint, what) in [(&zero, "is a character device"), (&fifo, "is a FIFO")] {
        for scene in [Path::new("/no/such/scene"), data.as_path()] {
            let out = root.join("out");
            let (ok, err) = run_bounded(&["train", s(scene), "-o", s(&out), "--resume", s(checkpoint)]);
            assert!(!ok);
            assert!(err.contains(s(checkpoint)) && err.contains(what), "{err}");
            assert!(!err.contains("/no/such/scene"), "the scene was not looked at: {err}");
        }
    }
    std::fs::remove_dir_all(&root).ok();
}

/// A dataset's image or `transforms.json` that is a link to a device is named with what it is
/// (before: "does not exist", and "no dataset found").
#[test]
fn dataset_files_that_are_devices_are_named() {
    let (data, _) = shared();
    let root = temp("file-kinds-dataset");
    let copy = root.join("data");
    for sub in ["sparse/0", "images"] {
        std::fs::create_dir_all(copy.join(sub)).unwrap();
        for entry in std::fs::read_dir(data.join(sub)).unwrap() {
            let entry = entry.unwrap();
            std::fs::copy(entry.path(), copy.join(sub).join(entry.file_name())).unwrap();
        }
    }
    let image = copy.join("images/view_003.png");
    std::fs::remove_file(&image).unwrap();
    symlink("/dev/zero", &image).unwrap();
    let err = load(&copy, &LoadOptions::default()).unwrap_err().to_string();
    assert!(
        err.contains("view_003.png") && err.contains("is a character device"),
        "{err}"
    );
    assert!(!err.contains("does not exist"), "{err}");

    let json = root.join("json");
    std::fs::create_dir_all(&json).unwrap();
    symlink("/dev/zero", json.join("transforms.json")).unwrap();
    let err = load(&json, &LoadOptions::default()).unwrap_err().to_string();
    assert!(
        err.contains("transforms.json") && err.contains("is a character device"),
        "{err}"
    );

    // COLMAP's images file as a symlink loop.
    let colmap = root.join("colmap/sparse/0");
    std::fs::create_dir_all(&colmap).unwrap();
    std::fs::copy(data.join("sparse/0/cameras.bin"), colmap.join("cameras.bin")).unwrap();
    symlink("images.bin", colmap.join("images.bin")).unwrap();
    let err = load(&root.join("colmap"), &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("images.bin") && err.contains("symlink loop"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}

/// A scene path that is a symlink loop, a FIFO or a device says so, not "does not exist".
#[test]
fn a_scene_path_that_is_a_loop_a_fifo_or_a_device_says_so() {
    let root = temp("file-kinds-scene-path");
    std::fs::create_dir_all(&root).unwrap();
    let (a, b, fifo, zero) = (root.join("a"), root.join("b"), root.join("fifo"), root.join("zero"));
    symlink(&b, &a).unwrap();
    symlink(&a, &b).unwrap();
    mkfifo(&fifo);
    symlink("/dev/zero", &zero).unwrap();
    for (path, what) in [
        (&a, "is a symlink loop"),
        (&fifo, "is a FIFO"),
        (&zero, "is a character device"),
    ] {
        let err = load(path, &LoadOptions::default()).unwrap_err().to_string();
        assert!(err.contains(s(path)) && err.contains(what), "{err}");
        assert!(!err.contains("No such file"), "{err}");
    }
    let (ok, err) = run_bounded(&["train", s(&a), "-o", s(&root.join("out"))]);
    assert!(!ok && err.contains("is a symlink loop"), "{err}");
    std::fs::remove_dir_all(&root).ok();
}
