//! Issue 60 item 8: a frame given twice, and a test view that is also a training view, are left
//! out at load with a warning naming both (they were trained and scored on in silence).

use crate::scene_support::*;
use bbsplat::scene::{LoadOptions, load};

#[test]
fn copies_of_a_frame_are_left_out_with_a_warning() {
    let d = temp_dir("duplicates");
    colmap_dataset(&d, 10, true);
    let quiet = LoadOptions {
        print_warnings: false,
        ..Default::default()
    };
    let clean = load(&d, &quiet).unwrap();
    assert_eq!((clean.train.len(), clean.test.len()), (8, 2));
    assert!(clean.warnings.is_empty(), "{:?}", clean.warnings);
    // img_5 (training) a copy of img_3; img_8 (test, every 8th) a copy of img_2 (training, the same camera model).
    let images = d.join("images");
    std::fs::copy(images.join("img_3.png"), images.join("img_5.png")).unwrap();
    std::fs::copy(images.join("img_2.png"), images.join("img_8.png")).unwrap();
    let s = load(&d, &quiet).unwrap();
    let names = |v: &[bbsplat::scene::View]| v.iter().map(|v| v.name.clone()).collect::<Vec<_>>();
    assert_eq!(s.train.len(), 7);
    assert!(!names(&s.train).contains(&"img_5.png".to_string()));
    assert_eq!(names(&s.test), ["img_0.png"]);
    assert_eq!(s.warnings.len(), 2, "{:?}", s.warnings);
    assert!(
        s.warnings[0].contains("training view \"img_5.png\" is the same image as training view \"img_3.png\""),
        "{}",
        s.warnings[0]
    );
    assert!(
        s.warnings[1].contains("test view \"img_8.png\" is the same image as training view \"img_2.png\"")
            && s.warnings[1].contains("inflates the test score"),
        "{}",
        s.warnings[1]
    );
}
