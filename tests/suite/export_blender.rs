//! The exported glTF in Blender: `tools/blender_check.py` imports it with Blender's own importer
//! and renders the scene camera with Cycles; the image must match the renderer's.

use super::export_browser::{byte_scene, psnr_bytes, render_expected};
use super::external_tool::find_tool;
use bbsplat::billboards::random_scene_camera;
use bbsplat::export::glb::{NamedCamera, write_glb};
use bbsplat::export::planes::plane_mesh;
use glam::Vec3;
use std::process::Command;

/// Lowest PSNR (dB) accepted between Blender's render (32 samples, raw colour) and the renderer's.
/// Measured: 27.4 dB on this scene (Blender 3.4.1, Debian 12). What remains: Cycles' sampling
/// noise (stochastic transparency, 32 samples) and the quads' borders (the export's pixel-edge
/// UVs and transparent gaps against the renderer's align-corners fade). With the random scene's
/// full textures and SH it measured 17.7 dB: texture + SH DC above 1 is clamped in the 8-bit
/// atlas but not by the renderer.
const MIN_PSNR: f64 = 24.0;

#[test]
fn the_glb_rendered_by_blender_matches_the_renderer() {
    let Some(blender) = find_tool("the_glb_rendered_by_blender_matches_the_renderer", &["blender"]) else {
        return;
    };
    let (width, height) = (96, 72);
    // Flat textures (each billboard one colour and one alpha, its first texel's), colours low
    // enough that texture + SH DC stays in [0, 1] (the 8-bit atlas clamps), no view-dependent
    // SH: what the export keeps of them is then exact but at the quads' borders.
    let mut set = byte_scene(width, height);
    let texels = set.texture_size * set.texture_size;
    for row in set.textures.chunks_exact_mut(texels) {
        let first = row[0];
        row.fill([0.3 * first[0], 0.3 * first[1], 0.3 * first[2], first[3].clamp(0.3, 0.9)]);
    }
    for sh in set.sh.chunks_exact_mut(bbsplat::raster::SH_FLOATS) {
        sh[3..].fill(0.0);
        for dc in &mut sh[..3] {
            *dc = dc.clamp(-1.0, 0.5);
        }
    }
    let background = Vec3::new(0.2, 0.3, 0.4);
    let camera = random_scene_camera(width, height);
    let dir = std::env::temp_dir().join(format!("bbsplat-blender-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let kept: Vec<usize> = (0..set.len()).collect();
    let mesh = plane_mesh(&set.borrowed(), &kept).unwrap();
    let glb = dir.join("scene.glb");
    write_glb(
        &glb,
        &mesh,
        &[NamedCamera {
            name: "scene",
            camera: &camera,
        }],
        background,
    )
    .unwrap();
    let out = dir.join("blender.png");
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/blender_check.py");
    let run = Command::new(blender)
        .args(["--background", "--factory-startup", "--python"])
        .arg(&script)
        .arg("--")
        .arg(&glb)
        .arg("0")
        .arg(&out)
        .args(["--samples", "32", "--raw"])
        .output()
        .expect("blender runs");
    let log = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success() && out.exists(),
        "{log}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let shot = image::open(&out).unwrap().to_rgb8();
    assert_eq!(shot.dimensions(), (width, height));
    let expected = render_expected(&dir, &set, &camera, background);
    let psnr = psnr_bytes(shot.as_raw(), &expected);
    eprintln!("blender (cycles, 32 spp, raw) vs renderer: {psnr:.2} dB");
    assert!(psnr > MIN_PSNR, "blender vs renderer: {psnr:.2} dB");
    let blank: Vec<u8> = (0..expected.len())
        .map(|i| bbsplat::loss::psnr::quantize_u8(background[i % 3]))
        .collect();
    assert!(psnr_bytes(&expected, &blank) < psnr, "the billboards are there");
    std::fs::remove_dir_all(&dir).ok();
}
