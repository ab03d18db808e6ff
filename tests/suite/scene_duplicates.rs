//! Issue 60 item 8: a frame given twice, and a test view that is also a training view, are left
//! out at load with a warning naming both (they were trained and scored on in silence).

use crate::scene_support::*;
use bbsplat::scene::{LoadOptions, load};

#[test]
fn copies_of_a_frame_are_left_out_with_a_warning() {
    let d = temp_dir("duplicates");
    let mut m = colmap_dataset(&d, 10, true);
    let quiet = LoadOptions {
        print_warnings: false,
        ..Default::default()
    };
    let clean = load(&d, &quiet).unwrap();
    assert_eq!((clean.train.len(), clean.test.len()), (8, 2));
    assert!(clean.warnings.is_empty(), "{:?}", clean.warnings);
    // img_5 (training) a copy of img_3 and img_8 (test, every 8th) a copy of img_2 (training,
    // the same camera model).
    let images = d.join("images");
    std::fs::copy(images.join("img_3.png"), images.join("img_5.png")).unwrap();
    std::fs::copy(images.join("img_2.png"), images.join("img_8.png")).unwrap();
    // From other poses they are not copies (a symmetric object seen alike from two places).
    assert!(load(&d, &quiet).unwrap().warnings.is_empty());
    // Registered at the pose of their originals, they are.
    for (copy, original) in [(5, 3), (8, 2)] {
        let (q, t) = (m.images[original].qvec, m.images[original].tvec);
        m.images[copy].qvec = q;
        m.images[copy].tvec = t;
    }
    bbsplat::scene::colmap_binary::write_model(&m, &d.join("sparse/0")).unwrap();
    let s = load(&d, &quiet).unwrap();
    let names = |v: &[bbsplat::scene::View]| v.iter().map(|v| v.name.clone()).collect::<Vec<_>>();
    assert_eq!(s.train.len(), 7);
    assert!(!names(&s.train).contains(&"img_5.png".to_string()));
    assert_eq!(names(&s.test), ["img_0.png"]);
    // (The moved poses also make the fold detector note a turn; only the copies matter here.)
    let copies: Vec<&String> = s
        .warnings
        .iter()
        .filter(|w| w.contains("is the same image as"))
        .collect();
    assert_eq!(copies.len(), 2, "{:?}", s.warnings);
    assert!(
        copies[0].contains("training view \"img_5.png\" is the same image as training view \"img_3.png\""),
        "{}",
        copies[0]
    );
    assert!(
        copies[1].contains("test view \"img_8.png\" is the same image as training view \"img_2.png\"")
            && copies[1].contains("inflates the test score"),
        "{}",
        copies[1]
    );
}
