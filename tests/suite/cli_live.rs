//! `train --view`: the live view serves the training's status, model and page to a loopback
//! client only, its numbers move with the training, a browser draws it, and the run with it is
//! the run without it, bit for bit.

use super::cli::{export_demo, run_ok, temp, tiny_train_args};
use super::export_browser::screenshot_url;
use super::external_tool::find_tool;
use super::progress::wait_for_lines;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A running `train --view`; killed when dropped.
struct Training {
    child: Child,
    address: String,
}

impl Drop for Training {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `train --view` on `data` for a million steps (the test kills it) and waits for the
/// printed address.
fn start(data: &std::path::Path, out: &std::path::Path, billboards: &str, view_every: &str) -> Training {
    let mut child = Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(["train", data.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .args([
            "--iterations",
            "1000000",
            "--billboards",
            billboards,
            "--texture-size",
            "4",
        ])
        .args(["--eval-every", "0", "--quiet", "--view", "--view-every", view_every])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let line = wait_for_lines(&mut child, &["live view at http://"]);
    let address = line
        .split("http://")
        .nth(1)
        .and_then(|r| r.split('/').next())
        .expect("an address after http://")
        .to_string();
    Training { child, address }
}

/// The status line and the body of `GET path` with `Host: host`.
fn get(address: &str, path: &str, host: &str) -> (String, Vec<u8>) {
    let mut stream = TcpStream::connect(address).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    write!(stream, "GET {path} HTTP/1.1\r\nHost: {host}\r\n\r\n").unwrap();
    let mut response = Vec::new();
    stream.read_to_end(&mut response).unwrap();
    let end = response
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a response head");
    let head = String::from_utf8_lossy(&response[..end]).into_owned();
    let status = head.lines().next().unwrap_or_default().to_string();
    (status, response[end + 4..].to_vec())
}

fn get_json(address: &str, path: &str) -> serde_json::Value {
    let (status, body) = get(address, path, "localhost");
    assert_eq!(status, "HTTP/1.1 200 OK", "GET {path}");
    serde_json::from_slice(&body).unwrap_or_else(|e| panic!("GET {path}: not JSON ({e})"))
}

/// Fetches `/status` until `done` holds of it (at most a minute: a stalled training fails).
fn status_until(address: &str, done: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let status = get_json(address, "/status");
        if done(&status) {
            return status;
        }
        assert!(
            Instant::now() < deadline,
            "the status did not move in a minute: {status}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn train_view_serves_status_model_and_page_to_loopback_only() {
    let root = temp("live");
    let data = export_demo(&root, 16, 40);
    let training = start(&data, &root.join("run"), "40", "5");
    let address = training.address.clone();

    let first = status_until(&address, |s| s["step"].as_u64().unwrap() >= 1);
    let step = first["step"].as_u64().unwrap();
    assert!(first["loss"].as_f64().unwrap().is_finite(), "{first}");
    assert!(first["running_psnr"].as_f64().unwrap() > 0.0, "{first}");
    let camera = &first["camera"];
    assert!(
        camera["name"].is_string() && camera["fx"].as_f64().unwrap() > 0.0,
        "{first}"
    );
    assert_eq!(camera["width"], 16);
    // The step advances, and a newer model is encoded (every 5 steps).
    let later = status_until(&address, |s| {
        s["step"].as_u64().unwrap() > step && s["model_version"].as_u64().unwrap() > 1
    });
    assert!(later["model_step"].as_u64().unwrap() >= 5, "{later}");
    assert_eq!(later["iterations"], 1_000_000);

    // The model is the viewer's JSON of the training's billboards, with its cameras.
    let model = get_json(&address, "/model");
    assert!(model["count"].as_u64().unwrap() >= 40, "{}", model["count"]);
    assert_eq!(model["texture_size"], 4);
    assert!(model["cameras"].as_array().unwrap().len() >= 2);
    assert!(!model["textures"].as_str().unwrap().is_empty());
    // The page is the viewer, told it is live.
    let (status, page) = get(&address, "/", "127.0.0.1");
    assert_eq!(status, "HTTP/1.1 200 OK");
    let page = String::from_utf8(page).unwrap();
    assert!(page.contains("\"live\":true") && page.contains("startLive"));

    // Another Host is refused on every path, as by `view --serve`.
    for path in ["/", "/status", "/model", "/refresh"] {
        for host in ["attacker.example", "localhost.attacker.example", "127.0.0.1.nip.io"] {
            let (status, body) = get(&address, path, host);
            assert_eq!(status, "HTTP/1.1 403 Forbidden", "{path} with Host {host}");
            assert!(!String::from_utf8_lossy(&body).contains("count"));
        }
    }
    let (status, _) = get(&address, "/checkpoint.bin", "localhost");
    assert_eq!(status, "HTTP/1.1 404 Not Found");
    drop(training);
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn train_view_refreshes_the_model_on_request() {
    let root = temp("live-refresh");
    let data = export_demo(&root, 16, 40);
    // A scheduled refresh never comes within the test: only the request brings a new model.
    let training = start(&data, &root.join("run"), "40", "100000000");
    let address = training.address.clone();
    let step = |s: &serde_json::Value| s["step"].as_u64().unwrap();
    let before = status_until(&address, |s| step(s) >= 3);
    assert_eq!(before["model_version"], 1, "{before}");
    // Progress, not time: 20 more steps and still the first model.
    let still = status_until(&address, |s| step(s) >= step(&before) + 20);
    assert_eq!(still["model_version"], 1, "no request, no new model: {still}");

    assert_eq!(get_json(&address, "/refresh")["requested"], true);
    let after = status_until(&address, |s| s["model_version"].as_u64().unwrap() > 1);
    assert_eq!(after["model_version"], 2, "{after}");
    assert!(
        after["model_step"].as_u64().unwrap() > step(&still),
        "the model of a step after the request: {after}"
    );
    // One request, one model: 20 steps later still the second.
    let later = status_until(&address, |s| step(s) >= step(&after) + 20);
    assert_eq!(later["model_version"], 2, "{later}");
    drop(training);
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn train_view_changes_nothing_in_the_run() {
    let root = temp("live-same");
    let data = export_demo(&root, 16, 40);
    let data = data.to_str().unwrap();
    let (plain, viewed) = (root.join("plain"), root.join("viewed"));
    run_ok(&tiny_train_args(data, plain.to_str().unwrap(), &[]));
    run_ok(&tiny_train_args(
        data,
        viewed.to_str().unwrap(),
        &["--view", "--view-every", "3"],
    ));
    let checkpoint = |dir: &std::path::Path| std::fs::read(dir.join("checkpoint.bin")).unwrap();
    assert!(checkpoint(&plain) == checkpoint(&viewed), "the checkpoints differ");
    let files = |dir: &std::path::Path| {
        let folder = dir.join("model");
        let mut files: Vec<_> = walk(&folder)
            .into_iter()
            .map(|p| {
                (
                    p.strip_prefix(&folder).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                )
            })
            .collect();
        files.sort();
        files
    };
    let (a, b) = (files(&plain), files(&viewed));
    assert!(!a.is_empty());
    assert_eq!(a.len(), b.len());
    for ((name, x), (other, y)) in a.iter().zip(&b) {
        assert_eq!(name, other);
        assert!(x == y, "{} differs", name.display());
    }
    std::fs::remove_dir_all(&root).ok();
}

/// Every file under `dir`.
fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files.extend(walk(&path));
        } else {
            files.push(path);
        }
    }
    files
}

#[test]
fn the_live_view_in_headless_chromium_draws_the_training() {
    let Some(chromium) = find_tool(
        "the_live_view_in_headless_chromium_draws_the_training",
        &["chromium", "chromium-browser"],
    ) else {
        return;
    };
    let root = temp("live-browser");
    let data = export_demo(&root, 48, 200);
    let training = start(&data, &root.join("run"), "200", "10");
    status_until(&training.address, |s| s["model_version"].as_u64().unwrap() > 1);
    let model = get_json(&training.address, "/model");
    let background: Vec<u8> = model["background"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| bbsplat::loss::psnr::quantize_u8(c.as_f64().unwrap() as f32))
        .collect();
    let url = format!("http://{}/#camera=0&ui=0", training.address);
    let shot = screenshot_url(&chromium, &url, 48, 48, &root.join("shot.png"));
    drop(training);
    assert_eq!(shot.dimensions(), (48, 48));
    let drawn = shot
        .pixels()
        .filter(|p| p.0.iter().zip(&background).any(|(&a, &b)| a.abs_diff(b) > 8))
        .count();
    eprintln!("live view in chromium: {drawn} of 2304 pixels not background");
    assert!(drawn > 2304 / 10, "the live page drew {drawn} of 2304 pixels");
    // And an image, not a flat fill (the demo's sky billboards cover every pixel, so the
    // background need not show; a page that failed shows one colour or its message on grey).
    let colours: std::collections::HashSet<[u8; 3]> = shot.pixels().map(|p| p.0).collect();
    eprintln!("live view in chromium: {} distinct colours", colours.len());
    assert!(
        colours.len() > 200,
        "the live page drew {} distinct colours",
        colours.len()
    );
    std::fs::remove_dir_all(&root).ok();
}
