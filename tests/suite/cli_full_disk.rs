//! Commands on a really full disk: a tiny tmpfs mounted for the test (needs root, as CI has;
//! elsewhere the tests say SKIPPED, and fail under CI). A command that runs out of space fails
//! with a message and leaves no empty or cut file, no temporary file and no folder it created.

use super::cli::{export_demo, run, temp, train_five_steps};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A tmpfs of `kib` KiB mounted at a fresh folder; unmounted when dropped.
struct TinyDisk(PathBuf);

impl TinyDisk {
    fn mount(test: &str, kib: u32) -> Option<Self> {
        let dir = temp(&format!("{test}-disk"));
        std::fs::create_dir_all(&dir).unwrap();
        let mounted = Command::new("mount")
            .args([
                "-t",
                "tmpfs",
                "-o",
                &format!("size={kib}k"),
                "tmpfs",
                dir.to_str().unwrap(),
            ])
            .output()
            .is_ok_and(|o| o.status.success());
        if mounted {
            return Some(Self(dir));
        }
        assert!(
            std::env::var_os("CI").is_none(),
            "{test}: could not mount a tmpfs (CI runs as root and must)"
        );
        let _ = writeln!(std::io::stderr(), "SKIPPED {test}: mounting a tmpfs needs root");
        None
    }
}

impl Drop for TinyDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
        let _ = std::fs::remove_dir(&self.0);
    }
}

/// Every file below `dir`, with its size.
fn files(dir: &Path) -> Vec<(PathBuf, u64)> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        if path.is_dir() {
            out.extend(files(&path));
        } else {
            out.push((path.clone(), entry.metadata().unwrap().len()));
        }
    }
    out
}

/// A model trained on a 48-pixel demo scene: `(scene, model)`.
fn small_model(root: &Path) -> (PathBuf, PathBuf) {
    let data = export_demo(root, 48, 60);
    let model = train_five_steps(&data, &root.join("run"), 60);
    (data, model)
}

#[test]
fn render_and_orbit_on_a_full_disk_fail_and_leave_nothing_behind() {
    let root = temp("full-render");
    let (data, model) = small_model(&root);
    let (data_s, model_s) = (data.to_str().unwrap(), model.to_str().unwrap());
    // 8 KiB: two pages, room for about two renders of the eight.
    let Some(disk) = TinyDisk::mount("render_on_a_full_disk", 8) else {
        return;
    };
    // Into a folder it creates, with a parent it creates too: both are removed.
    let out = disk.0.join("renders");
    let nested = out.join("nested");
    let (ok, err) = run(&["render", model_s, data_s, "-o", nested.to_str().unwrap()]);
    assert!(!ok, "render on a full disk exited 0");
    assert!(err.contains("No space left"), "{err}");
    assert!(!out.exists(), "the folders render created are left: {:?}", files(&out));
    // Into a folder that exists: the renders written before the disk filled are whole PNGs,
    // and nothing else is there.
    std::fs::create_dir(&out).unwrap();
    let (ok, _) = run(&["render", model_s, data_s, "-o", out.to_str().unwrap()]);
    assert!(!ok);
    for (path, size) in files(&out) {
        assert!(path.extension().is_some_and(|e| e == "png"), "{path:?} left");
        assert!(size > 0 && image::open(&path).is_ok(), "{path:?} is cut ({size} bytes)");
    }
    std::fs::remove_dir_all(&out).unwrap();
    // The orbit is refused before anything is rendered: the free-space check sees the disk.
    let orbit = disk.0.join("orbit");
    let orbit_args = [
        "render",
        model_s,
        data_s,
        "-o",
        orbit.to_str().unwrap(),
        "--orbit",
        "12",
    ];
    let (ok, err) = run(&orbit_args);
    assert!(!ok, "render --orbit on a full disk exited 0");
    assert!(
        err.contains("free on its file system") && err.contains("8.2 kB free"),
        "{err}"
    );
    assert!(!orbit.exists(), "{:?}", files(&orbit));
    // With the check told there is room, the disk fills while frames are written: the command
    // fails and removes its folder, the GIF's temporary file with it.
    let out = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(orbit_args)
        .env("BBSPLAT_DISK_LIMIT", "1000000000000")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "render --orbit on a full disk exited 0");
    assert!(err.contains("No space left"), "{err}");
    assert!(!orbit.exists(), "{:?}", files(&orbit));
    drop(disk);
    std::fs::remove_dir_all(&root).ok();
}
