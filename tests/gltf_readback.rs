//! The GLB exporter read back by an independent reader, the `gltf` crate: geometry, texture
//! coordinates, the atlas, the material and the cameras.
//!
//! A test crate of its own, not a module of `tests/suite`: the `gltf` crates are built without
//! optimisation (Cargo.toml, `[profile.test.package.gltf]`: they read one small file here) and a
//! crate built so shares its unoptimised copies of generic std code (`Range::next`, ...) with the
//! test crates that link it. Linked into the suite, they made its numeric tests twice as slow.

#[path = "suite/export_fixtures.rs"]
mod export_fixtures;

use bbsplat::export::glb::{NamedCamera, glb_bytes};
use bbsplat::export::planes::plane_mesh;
use export_fixtures::{scene, test_cameras};
use glam::Vec3;

/// Projects a world point with a glTF camera node read back by the `gltf` crate: world → node
/// frame (inverse of the node transform), then the perspective camera (looking along −z, y up).
fn gltf_project(node: &gltf::Node<'_>, width: f32, height: f32, p: Vec3) -> (f32, f32) {
    let m = glam::Mat4::from_cols_array_2d(&node.transform().matrix());
    let local = m.inverse().transform_point3(p);
    let camera = node.camera().unwrap();
    let gltf::camera::Projection::Perspective(persp) = camera.projection() else {
        panic!("not a perspective camera")
    };
    let tan_y = (persp.yfov() / 2.0).tan();
    let tan_x = tan_y * persp.aspect_ratio().unwrap();
    let (ndc_x, ndc_y) = (local.x / (-local.z) / tan_x, local.y / (-local.z) / tan_y);
    ((ndc_x + 1.0) * 0.5 * width, (1.0 - ndc_y) * 0.5 * height)
}

#[test]
fn the_glb_reads_back_with_the_gltf_crate() {
    let set = scene(9, 4, 7);
    let set = set.borrowed();
    let kept = vec![0, 1, 3, 4, 8];
    let mesh = plane_mesh(&set, &kept).unwrap();
    let cams = test_cameras();
    let named: Vec<NamedCamera> = cams
        .iter()
        .zip(["front", "side"])
        .map(|(camera, name)| NamedCamera { name, camera })
        .collect();
    let bytes = glb_bytes(&mesh, &named, Vec3::ONE).unwrap();
    assert_eq!(&bytes[..4], b"glTF");
    let (doc, buffers, images) = gltf::import_slice(&bytes).expect("a valid glTF binary");

    // Geometry and texture coordinates.
    let gl_mesh = doc.meshes().next().unwrap();
    let prim = gl_mesh.primitives().next().unwrap();
    let reader = prim.reader(|b| Some(&buffers[b.index()]));
    let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
    let uvs: Vec<[f32; 2]> = reader.read_tex_coords(0).unwrap().into_f32().collect();
    let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
    assert_eq!((positions.len(), uvs.len(), indices.len()), (20, 20, 30));
    for k in 0..kept.len() {
        for j in 0..4 {
            assert_eq!(positions[4 * k + j], mesh.corners[k][j].to_array());
            let t = mesh.uvs[k][j];
            assert_eq!(uvs[4 * k + j], [t.x, 1.0 - t.y]);
        }
    }
    assert_eq!(&indices[6..12], &[4, 6, 5, 4, 5, 7]);
    let bounds = prim.bounding_box();
    let all: Vec<Vec3> = mesh.corners.iter().flatten().copied().collect();
    let lo = all.iter().fold(Vec3::splat(f32::INFINITY), |a, b| a.min(*b));
    assert_eq!(bounds.min, lo.to_array());

    // Material: the atlas with alpha blending, double-sided, unlit.
    let material = prim.material();
    assert_eq!(material.alpha_mode(), gltf::material::AlphaMode::Blend);
    assert!(material.double_sided() && material.unlit());
    let tex = material
        .pbr_metallic_roughness()
        .base_color_texture()
        .unwrap()
        .texture();
    assert_eq!(tex.sampler().mag_filter(), Some(gltf::texture::MagFilter::Linear));
    let image = &images[tex.source().index()];
    assert_eq!(image.format, gltf::image::Format::R8G8B8A8);
    assert_eq!(
        (image.width as usize, image.height as usize),
        (mesh.atlas.layout.width, mesh.atlas.layout.height)
    );
    assert_eq!(image.pixels, mesh.atlas.rgba);

    // Cameras: a world point lands on the same pixel through our camera and through the glTF one.
    let camera_nodes: Vec<gltf::Node> = doc.nodes().filter(|n| n.camera().is_some()).collect();
    assert_eq!(camera_nodes.len(), 2);
    assert_eq!(camera_nodes[1].name(), Some("side"));
    for (node, cam) in camera_nodes.iter().zip(&cams) {
        let extras: serde_json::Value = serde_json::from_str(node.extras().as_ref().unwrap().get()).unwrap();
        assert_eq!(extras["fx"].as_f64().unwrap() as f32, cam.fx);
        for p in [Vec3::new(0.3, -0.2, 5.0), Vec3::new(-1.0, 0.5, 4.0), set.positions[3]] {
            let ours = cam.project(p).unwrap();
            let theirs = gltf_project(node, cam.width as f32, cam.height as f32, p);
            assert!(
                (ours.0 - theirs.0).abs() < 1e-3 && (ours.1 - theirs.1).abs() < 1e-3,
                "{ours:?} {theirs:?}"
            );
        }
    }
    let scene_extras: serde_json::Value =
        serde_json::from_str(doc.scenes().next().unwrap().extras().as_ref().unwrap().get()).unwrap();
    assert_eq!(scene_extras["background"], serde_json::json!([1.0, 1.0, 1.0]));
}
