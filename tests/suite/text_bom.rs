//! Issue 60 item 11: a UTF-8 byte-order mark at the start of a text file (as Windows editors
//! write) is ignored, in transforms files, COLMAP text models and `bbsplat.json`; it was
//! "malformed JSON".

use crate::scene_support::*;
use bbsplat::model::RawBillboards;
use bbsplat::model_file::{META_FILE, ModelMeta, load_model, save_model};
use bbsplat::scene::{LoadOptions, load};
use std::path::Path;

fn prefix_bom(file: &Path) {
    let mut bytes = b"\xEF\xBB\xBF".to_vec();
    bytes.extend(std::fs::read(file).unwrap());
    std::fs::write(file, bytes).unwrap();
}

#[test]
fn a_byte_order_mark_is_ignored() {
    let quiet = LoadOptions {
        print_warnings: false,
        ..Default::default()
    };
    // COLMAP text.
    let d = temp_dir("bom_colmap");
    colmap_dataset(&d, 4, false);
    let plain = load(&d, &quiet).unwrap();
    for f in ["cameras.txt", "images.txt", "points3D.txt"] {
        prefix_bom(&d.join("sparse/0").join(f));
    }
    let marked = load(&d, &quiet).unwrap();
    assert_eq!(marked.train.len(), plain.train.len());
    assert_eq!(marked.train[0].camera, plain.train[0].camera);
    // transforms.json.
    let d = temp_dir("bom_transforms");
    let json = format!(
        r#"{{"fl_x": 30, "frames": [{}, {}]}}"#,
        frame("a.png", 4.0),
        frame("b.png", 5.0)
    );
    std::fs::write(d.join("transforms.json"), json).unwrap();
    write_png(&d.join("a.png"), 8, 6);
    write_png(&d.join("b.png"), 8, 6);
    prefix_bom(&d.join("transforms.json"));
    let s = load(
        &d,
        &LoadOptions {
            test_every: 0,
            ..quiet.clone()
        },
    )
    .unwrap();
    assert_eq!(s.train.len(), 2);
    // bbsplat.json.
    let d = temp_dir("bom_model");
    let model = RawBillboards::from_points(&[glam::Vec3::ZERO], &[[0.5; 3]], 4, 0);
    let meta = ModelMeta::for_model(&model, 3, [0.0; 3]);
    save_model(&d.join("model"), &model, &meta).unwrap();
    prefix_bom(&d.join("model").join(META_FILE));
    assert_eq!(load_model(&d.join("model")).unwrap().1, meta);
}
