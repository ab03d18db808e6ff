//! `bbsplat export`, `bbsplat view` and `bbsplat render --orbit` through the built binary, on a
//! model trained for a few steps on the exported demo scene.

use super::cli::{export_demo, run, run_ok, temp, train_five_steps};

#[test]
fn export_view_and_orbit_write_their_files() {
    let root = temp("export");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let data_s = data.to_str().unwrap();
    let model = train_five_steps(&data, &out, 80);
    let model_s = model.to_str().unwrap();

    // OBJ: the three files, sizes printed, the kept count no more than the model's.
    let obj_dir = root.join("obj");
    let printed = run_ok(&[
        "export",
        model_s,
        data_s,
        "-o",
        obj_dir.to_str().unwrap(),
        "--format",
        "obj",
    ]);
    let kept: usize = printed
        .strip_prefix("kept ")
        .and_then(|s| s.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{printed}"));
    assert!(kept > 0 && kept <= 80, "{printed}");
    for name in ["planes_mesh.obj", "planes_mesh.mtl", "planes_mesh.png"] {
        let size = std::fs::metadata(obj_dir.join(name)).unwrap().len();
        assert!(printed.contains(&format!("{name} ({size} bytes)")), "{printed}");
    }
    let obj = std::fs::read_to_string(obj_dir.join("planes_mesh.obj")).unwrap();
    assert_eq!(obj.lines().filter(|l| l.starts_with("f ")).count(), 2 * kept);

    // Stricter thresholds keep fewer billboards; impossible ones are a clear error.
    let strict = run_ok(&[
        "export",
        model_s,
        data_s,
        "-o",
        obj_dir.to_str().unwrap(),
        "--format",
        "obj",
        "--min-impact-share",
        "0.0125",
    ]);
    let strict_kept: usize = strict.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!(strict_kept < kept, "{strict}");
    let (ok, err) = run(&[
        "export",
        model_s,
        data_s,
        "-o",
        obj_dir.to_str().unwrap(),
        "--min-max-alpha",
        "1",
    ]);
    assert!(!ok && err.contains("no billboard left"), "{err}");

    // glTF: parses, one camera per dataset view (5 train + 1 test views at this size).
    let glb_dir = root.join("glb");
    run_ok(&[
        "export",
        model_s,
        data_s,
        "-o",
        glb_dir.to_str().unwrap(),
        "--format",
        "glb",
    ]);
    // The GLB's JSON chunk (the container is read back in full by tests/gltf_readback.rs).
    let glb = std::fs::read(glb_dir.join("planes_mesh.glb")).unwrap();
    assert_eq!(&glb[..4], b"glTF");
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    assert_eq!(&glb[16..20], b"JSON");
    let doc: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let scene = bbsplat::scene::load(&data, &bbsplat::scene::LoadOptions::default()).unwrap();
    assert_eq!(
        doc["cameras"].as_array().unwrap().len(),
        scene.train.len() + scene.test.len()
    );

    // The viewer page, with and without the dataset's cameras.
    let page = root.join("view.html");
    let printed = run_ok(&["view", model_s, data_s, "-o", page.to_str().unwrap()]);
    assert!(printed.contains("80 billboards"), "{printed}");
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.contains("\"count\":80"));
    let printed = run_ok(&["view", model_s, "-o", page.to_str().unwrap()]);
    assert!(printed.contains("1 cameras"), "{printed}");

    // --serve: the page over HTTP on a free port, as written.
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_bbsplat"))
        .args(["view", model_s, "-o", page.to_str().unwrap(), "--serve", "--port", "0"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufRead::lines(std::io::BufReader::new(child.stdout.take().unwrap()));
    let address = lines
        .by_ref()
        .map(|l| l.unwrap())
        .find_map(|l| {
            l.strip_prefix("serving on http://")
                .map(|rest| rest.split('/').next().unwrap().to_string())
        })
        .expect("the server prints its address");
    let mut stream = std::net::TcpStream::connect(&address).unwrap();
    std::io::Write::write_all(&mut stream, b"GET / HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
    let mut response = Vec::new();
    std::io::Read::read_to_end(&mut stream, &mut response).unwrap();
    child.kill().unwrap();
    child.wait().unwrap();
    let page_bytes = std::fs::read(&page).unwrap();
    assert!(response.starts_with(b"HTTP/1.1 200 OK"));
    assert!(response.ends_with(&page_bytes), "the body is the page");

    // The orbit: N frames and a GIF of N frames.
    let orbit = root.join("orbit");
    let printed = run_ok(&["render", model_s, data_s, "-o", orbit.to_str().unwrap(), "--orbit", "6"]);
    assert!(printed.contains("wrote 6 orbit frames"), "{printed}");
    for k in 0..6 {
        assert!(orbit.join(format!("orbit_{k:04}.png")).exists());
    }
    let gif = std::fs::File::open(orbit.join("orbit.gif")).unwrap();
    let decoder = image::codecs::gif::GifDecoder::new(std::io::BufReader::new(gif)).unwrap();
    use image::AnimationDecoder;
    assert_eq!(decoder.into_frames().count(), 6);
    std::fs::remove_dir_all(&root).ok();
}

#[test]
fn export_writes_the_gaussian_formats() {
    let root = temp("export-splat");
    let data = export_demo(&root, 24, 100);
    let out = root.join("out");
    let data_s = data.to_str().unwrap();
    let model = train_five_steps(&data, &out, 80);
    let model_s = model.to_str().unwrap();
    let dir = root.join("splat");
    let dir_s = dir.to_str().unwrap();
    // The command line's default cap is the library's.
    assert_eq!(bbsplat::export::gaussians::FitRule::default().max_gaussians, 8);
    let printed = run_ok(&["export", model_s, data_s, "-o", dir_s, "--format", "splat-ply"]);
    let count: usize = printed
        .lines()
        .find_map(|l| l.split(" Gaussians: ").next()?.parse().ok())
        .unwrap_or_else(|| panic!("{printed}"));
    assert!(printed.contains("(at most 8)"), "{printed}");
    let ply = std::fs::read(dir.join("gaussians.ply")).unwrap();
    assert!(
        printed.contains(&format!("gaussians.ply ({} bytes)", ply.len())),
        "{printed}"
    );
    let header = String::from_utf8_lossy(&ply[..200]).to_string();
    assert!(header.contains(&format!("element vertex {count}\n")), "{header}");
    // One Gaussian per billboard at most: no more Gaussians than kept billboards.
    let one = run_ok(&[
        "export",
        model_s,
        data_s,
        "-o",
        dir_s,
        "--format",
        "splat-ply",
        "--max-gaussians",
        "1",
    ]);
    let kept: usize = one.split_whitespace().nth(1).unwrap().parse().unwrap();
    let one_count: usize = one
        .lines()
        .find_map(|l| l.split(" Gaussians: ").next()?.parse().ok())
        .unwrap();
    assert!(one_count <= kept && one_count <= count, "{one}");
    // The glTF: the extension, POINTS, one camera per dataset view.
    run_ok(&["export", model_s, data_s, "-o", dir_s, "--format", "gltf-splat"]);
    let glb = std::fs::read(dir.join("gaussians.glb")).unwrap();
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let doc: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    assert_eq!(doc["extensionsUsed"], serde_json::json!(["KHR_gaussian_splatting"]));
    assert_eq!(doc["meshes"][0]["primitives"][0]["mode"], 0);
    assert_eq!(
        doc["scenes"][0]["extras"]["gaussians"].as_u64().unwrap() as usize,
        count
    );
    let scene = bbsplat::scene::load(&data, &bbsplat::scene::LoadOptions::default()).unwrap();
    assert_eq!(
        doc["cameras"].as_array().unwrap().len(),
        scene.train.len() + scene.test.len()
    );
    // Bad fit flags are refused before anything is written.
    for (flag, value) in [
        ("--max-gaussians", "0"),
        ("--max-fit-error", "-1"),
        ("--max-fit-error", "NaN"),
    ] {
        let arg = format!("{flag}={value}");
        let (ok, err) = run(&["export", model_s, data_s, "-o", dir_s, "--format", "gltf-splat", &arg]);
        assert!(!ok && err.contains(flag), "{arg}: {err}");
    }
    std::fs::remove_dir_all(&root).ok();
}
