//! The exporters (`bbsplat::export`): pruning, quads, atlas, OBJ, the viewer page, the orbit path.
//! The GLB read back with the `gltf` crate is a test crate of its own, `tests/gltf_readback.rs`.

use crate::export_fixtures::{scene, test_cameras};
use bbsplat::camera::Camera;
use bbsplat::export::atlas::{AtlasLayout, build_atlas, texel_rgba};
use bbsplat::export::obj::{obj_text, write_obj};
use bbsplat::export::orbit::{look_target, orbit_cameras};
use bbsplat::export::planes::{QUAD_TRIANGLES, plane_mesh, quad_corners};
use bbsplat::export::prune::{PruneRule, kept_billboards};
use bbsplat::export::viewer::{ViewerCamera, viewer_html};
use bbsplat::export::{ExportError, write_file};
use bbsplat::stages::rotation::quat_to_rotation;
use glam::{Vec2, Vec3};

fn temp(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("bbsplat-export-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn pruning_needs_both_an_impact_share_and_an_opaque_texel() {
    // Four one-texel billboards: kept, too transparent, too little impact, exactly at the alpha
    // threshold (not above it: dropped).
    let textures = [
        [0.0, 0.0, 0.0, 0.9],
        [0.0, 0.0, 0.0, 0.1],
        [0.0, 0.0, 0.0, 0.9],
        [0.0, 0.0, 0.0, 0.2],
    ];
    let impact = [10.0, 10.0, 1e-6, 10.0];
    let rule = PruneRule::default();
    assert_eq!((rule.min_impact_share, rule.min_max_alpha), (1e-6, 0.2));
    assert_eq!(kept_billboards(&impact, &textures, 1, &rule), vec![0]);
    // The largest texel counts, not the mean.
    let two_texels = [[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.5]];
    assert_eq!(kept_billboards(&[1.0], &two_texels, 2, &rule), vec![0]);
    // No impact at all: nothing passes.
    assert!(kept_billboards(&[0.0, 0.0], &textures[..2], 1, &rule).is_empty());
    let loose = PruneRule {
        min_impact_share: 0.0,
        min_max_alpha: 0.0,
    };
    assert_eq!(kept_billboards(&impact, &textures, 1, &loose), vec![0, 1, 2, 3]);
}

#[test]
fn quads_span_the_billboard_square_and_face_its_normal() {
    let q = [0.8, -0.3, 0.45, 0.2];
    let (p, s) = (Vec3::new(0.5, -1.0, 2.0), Vec2::new(0.3f32.ln(), 0.7f32.ln()));
    let c = quad_corners(p, q, s);
    let r = quat_to_rotation(q);
    let local = [(-1.0, -1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, 1.0)];
    for (corner, (u, v)) in c.iter().zip(local) {
        let expected = p + u * 0.3 * r.x_axis + v * 0.7 * r.y_axis;
        assert!((*corner - expected).length() < 1e-6, "{corner} {expected}");
    }
    for [a, b, d] in QUAD_TRIANGLES {
        let n = (c[b as usize] - c[a as usize]).cross(c[d as usize] - c[a as usize]);
        assert!(
            n.normalize().dot(r.z_axis) > 0.999,
            "triangle ({a}, {b}, {d}) faces away"
        );
    }
}

#[test]
fn the_atlas_holds_each_tile_flipped_with_transparent_gaps() {
    let set = scene(5, 4, 3);
    let set = set.borrowed();
    let kept = [4, 0, 2];
    let atlas = build_atlas(&set, &kept).unwrap();
    let l = atlas.layout;
    assert_eq!(
        (l.per_row, l.width, l.height),
        (1, 6, 18),
        "⌊√3⌋ = 1 tile per row, pitch 6"
    );
    let at = |x: usize, y: usize| {
        let i = (y * l.width + x) * 4;
        [atlas.rgba[i], atlas.rgba[i + 1], atlas.rgba[i + 2], atlas.rgba[i + 3]]
    };
    for (k, &b) in kept.iter().enumerate() {
        let (x0, y0) = l.tile_origin(k);
        for row in 0..4 {
            for col in 0..4 {
                assert_eq!(
                    at(x0 + col, l.height - 1 - (y0 + row)),
                    texel_rgba(&set, b, row * 4 + col)
                );
            }
        }
    }
    // Gap columns 4-5 and the two gap rows after each tile are transparent black.
    for y in 0..l.height {
        assert_eq!(at(4, y), [0; 4]);
        assert_eq!(at(5, y), [0; 4]);
    }
    for x in 0..l.width {
        assert_eq!(at(x, l.height - 1 - 4), [0; 4]);
    }
    // Texel colour = texture + SH DC colour.
    let dc = set.sh_of(2);
    let t = set.texture_of(2)[5];
    let expect =
        |c: usize| bbsplat::loss::psnr::quantize_u8(t[c] + (dc[c] * bbsplat::stages::sh::SH_C0 + 0.5).max(0.0));
    assert_eq!(texel_rgba(&set, 2, 5)[..3], [expect(0), expect(1), expect(2)]);
    // Texture coordinates: the tile's texel edges, origin at the bottom of the stored image.
    let uv = l.uv(1, Vec2::new(-1.0, -1.0));
    assert_eq!(uv, Vec2::new(0.0, 6.0 / 18.0));
    assert_eq!(l.uv(1, Vec2::new(1.0, 1.0)), Vec2::new(4.0 / 6.0, 10.0 / 18.0));
}

#[test]
fn an_atlas_too_large_is_a_typed_error() {
    match AtlasLayout::new(2_000_000, 16) {
        Err(ExportError::AtlasTooLarge { tiles, .. }) => assert_eq!(tiles, 2_000_000),
        other => panic!("{other:?}"),
    }
}

#[test]
fn the_obj_lists_every_corner_uv_and_triangle() {
    let set = scene(7, 4, 1);
    let set = set.borrowed();
    let kept: Vec<usize> = (0..7).filter(|i| i % 3 != 1).collect();
    let mesh = plane_mesh(&set, &kept).unwrap();
    let text = obj_text(&mesh, "m.mtl");
    let (mut v, mut vt, mut f) = (Vec::new(), Vec::new(), Vec::new());
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => v.push(it.map(|x| x.parse::<f32>().unwrap()).collect::<Vec<_>>()),
            Some("vt") => vt.push(it.map(|x| x.parse::<f32>().unwrap()).collect::<Vec<_>>()),
            Some("f") => f.push(
                it.map(|x| {
                    let (a, b) = x.split_once('/').unwrap();
                    (a.parse::<usize>().unwrap(), b.parse::<usize>().unwrap())
                })
                .collect::<Vec<_>>(),
            ),
            _ => {}
        }
    }
    assert_eq!(
        (v.len(), vt.len(), f.len()),
        (4 * kept.len(), 4 * kept.len(), 2 * kept.len())
    );
    assert!(text.contains("mtllib m.mtl") && text.contains("usemtl planes"));
    for (k, &b) in kept.iter().enumerate() {
        let c = quad_corners(set.positions[b], set.quaternions[b], set.log_scales[b]);
        for j in 0..4 {
            // Shortest round-trip float formatting: exact.
            assert_eq!(v[4 * k + j], c[j].to_array().to_vec());
            assert_eq!(vt[4 * k + j], mesh.uvs[k][j].to_array().to_vec());
        }
        assert_eq!(
            f[2 * k],
            vec![(4 * k + 1, 4 * k + 1), (4 * k + 3, 4 * k + 3), (4 * k + 2, 4 * k + 2)]
        );
        assert_eq!(
            f[2 * k + 1],
            vec![(4 * k + 1, 4 * k + 1), (4 * k + 2, 4 * k + 2), (4 * k + 4, 4 * k + 4)]
        );
    }

    let dir = temp("obj");
    let files = write_obj(&dir, "planes_mesh", &mesh).unwrap();
    assert_eq!(files.len(), 3);
    let mtl = std::fs::read_to_string(dir.join("planes_mesh.mtl")).unwrap();
    assert!(mtl.contains("map_Kd planes_mesh.png") && mtl.contains("map_d planes_mesh.png"));
    let png = image::open(dir.join("planes_mesh.png")).unwrap().to_rgba8();
    assert_eq!(
        png.dimensions(),
        (mesh.atlas.layout.width as u32, mesh.atlas.layout.height as u32)
    );
    assert_eq!(png.as_raw(), &mesh.atlas.rgba);
    for (path, size) in files {
        assert_eq!(std::fs::metadata(&path).unwrap().len(), size);
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn writing_into_a_missing_folder_names_the_file() {
    let path = std::env::temp_dir().join("bbsplat-no-such-folder-4711/planes_mesh.obj");
    let err = write_file(&path, b"x").unwrap_err();
    assert!(matches!(err, ExportError::Io { .. }));
    assert!(err.to_string().contains("planes_mesh.obj"), "{err}");
}

#[test]
fn the_viewer_page_embeds_the_model_and_needs_no_network() {
    let set = scene(6, 4, 5);
    let set = set.borrowed();
    let cams = test_cameras();
    let views = [
        ViewerCamera {
            name: "a</script>b",
            camera: &cams[0],
        },
        ViewerCamera {
            name: "b",
            camera: &cams[1],
        },
    ];
    let html = viewer_html(&set, 3, Vec3::ZERO, &views);
    assert!(!html.contains("/*BBSPLAT_DATA*/"));
    assert!(
        !html.contains("http://") && !html.contains("https://"),
        "no network resource"
    );
    let start = html.find("id=\"bbsplat-data\">").unwrap() + "id=\"bbsplat-data\">".len();
    let end = start + html[start..].find("</script>").unwrap();
    let data: serde_json::Value = serde_json::from_str(&html[start..end]).unwrap();
    assert_eq!(data["count"], 6);
    assert_eq!(data["texture_size"], 4);
    assert_eq!(data["cameras"][0]["name"], "a</script>b", "the escaped name survives");
    assert_eq!(data["cameras"][1]["fy"].as_f64().unwrap() as f32, 70.0);
    // Base64 sizes: 3 floats of position per billboard, 16 texels × 4 bytes of texture.
    let decoded_len = |key: &str| {
        let s = data[key].as_str().unwrap();
        s.len() / 4 * 3 - s.chars().rev().take_while(|&c| c == '=').count()
    };
    assert_eq!(decoded_len("positions"), 6 * 3 * 4);
    assert_eq!(decoded_len("axes"), 6 * 6 * 4);
    assert_eq!(decoded_len("sh"), 6 * 48 * 4);
    assert_eq!(decoded_len("textures"), 6 * 16 * 4);
    let degree0 = viewer_html(&set, 0, Vec3::ZERO, &views);
    assert!(degree0.len() < html.len(), "degree 0 embeds 3 SH floats per billboard");
}

#[test]
fn the_orbit_circles_the_target_at_the_cameras_distance() {
    // A ring of cameras (their mean up vector is the ring's axis).
    let cams: Vec<Camera> = (0..5)
        .map(|k| {
            let a = std::f32::consts::TAU * k as f32 / 5.0;
            Camera::look_at(
                Vec3::new(1.0 + 3.0 * a.cos(), 2.0 + 3.0 * a.sin(), 1.5),
                Vec3::new(1.0, 2.0, 0.0),
                Vec3::Z,
                80.0,
                80.0,
                40,
                30,
            )
        })
        .collect();
    let target = look_target(&cams).unwrap();
    assert!((target - Vec3::new(1.0, 2.0, 0.0)).length() < 1e-4, "{target}");
    let orbit = orbit_cameras(&cams, 12).unwrap();
    assert_eq!(orbit.len(), 12);
    for cam in &orbit {
        let offset = cam.centre() - target;
        assert!((offset.z - 1.5).abs() < 1e-3 && (offset.truncate().length() - 3.0).abs() < 1e-3);
        // Looking at the target: it projects to the image centre.
        let (x, y) = cam.project(target).unwrap();
        assert!((x - 20.0).abs() < 1e-3 && (y - 15.0).abs() < 1e-3);
    }
    assert!(matches!(orbit_cameras(&[], 4), Err(ExportError::NoOrbitCamera)));
    assert!(matches!(orbit_cameras(&cams, 0), Err(ExportError::NoOrbitCamera)));
}
