//! Issue 60 item 12: a JPEG whose EXIF orientation asks to be shown turned is loaded as stored
//! (the cameras of structure from motion fit the stored pixels), and the loader says so: it
//! trained as stored without a word.

use crate::scene_support::*;
use bbsplat::scene::{LoadOptions, load};
use std::path::Path;

/// A JPEG of a gradient with an EXIF APP1 segment whose orientation tag is `orientation`.
fn write_jpeg_with_orientation(path: &Path, orientation: u16) {
    let img = image::RgbImage::from_fn(16, 12, |x, y| image::Rgb([(x * 15) as u8, (y * 20) as u8, 60]));
    let mut jpeg = Vec::new();
    image::DynamicImage::ImageRgb8(img)
        .write_to(&mut std::io::Cursor::new(&mut jpeg), image::ImageFormat::Jpeg)
        .unwrap();
    // TIFF, big-endian: header, one IFD entry (0x0112 orientation, SHORT, count 1), no next IFD.
    let mut tiff = b"MM\0\x2a\0\0\0\x08\0\x01\x01\x12\0\x03\0\0\0\x01".to_vec();
    tiff.extend(orientation.to_be_bytes());
    tiff.extend([0, 0, 0, 0, 0, 0]);
    let mut app1 = b"Exif\0\0".to_vec();
    app1.extend(tiff);
    let mut segment = vec![0xFF, 0xE1];
    segment.extend(((app1.len() + 2) as u16).to_be_bytes());
    segment.extend(app1);
    jpeg.splice(2..2, segment);
    std::fs::write(path, jpeg).unwrap();
}

#[test]
fn an_exif_orientation_is_reported_and_not_applied() {
    let d = temp_dir("exif");
    let json = format!(
        r#"{{"fl_x": 15, "frames": [{}, {}]}}"#,
        frame("a.jpg", 4.0),
        frame("b.jpg", 5.0)
    );
    std::fs::write(d.join("transforms.json"), json).unwrap();
    write_jpeg_with_orientation(&d.join("a.jpg"), 3);
    write_jpeg_with_orientation(&d.join("b.jpg"), 1);
    let options = LoadOptions {
        print_warnings: false,
        test_every: 0,
        ..Default::default()
    };
    let s = load(&d, &options).unwrap();
    let turned: Vec<&String> = s.warnings.iter().filter(|w| w.contains("EXIF orientation")).collect();
    assert_eq!(turned.len(), 1, "{:?}", s.warnings);
    assert!(
        turned[0].starts_with("1 of 2 images")
            && turned[0].contains("a.jpg turned 180°")
            && turned[0].contains("not applied"),
        "{}",
        turned[0]
    );
    // As stored: the two files hold the same pixels and load the same.
    let a = s.train.iter().find(|v| v.name == "a.jpg").unwrap();
    let b = s.train.iter().find(|v| v.name == "b.jpg").unwrap();
    assert_eq!(a.image, b.image);
    // Without the tag, no warning.
    write_jpeg_with_orientation(&d.join("a.jpg"), 1);
    assert!(load(&d, &options).unwrap().warnings.iter().all(|w| !w.contains("EXIF")));
}
