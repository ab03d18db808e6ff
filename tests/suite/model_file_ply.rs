//! The model PLY: a written header reads back, bad headers say where.

use bbsplat::model_file::ModelFileError;
use bbsplat::model_file::ply::{PLY_FLOATS, header_len};
use bbsplat::testing_internals::model_file::{parse_ply as parse, ply_header as header};
use std::path::Path;

fn reason(bytes: &[u8]) -> String {
    match parse(Path::new("m/point_cloud.ply"), bytes) {
        Err(ModelFileError::Ply { path, reason }) => {
            assert!(path.ends_with("point_cloud.ply"));
            reason
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_written_header_reads_back_and_bad_headers_say_where() {
    let mut file = header(2).into_bytes();
    file.extend(std::iter::repeat_n(0u8, 2 * PLY_FLOATS * 4));
    assert_eq!(parse(Path::new("p.ply"), &file).unwrap(), vec![0.0; 2 * PLY_FLOATS]);
    // The shared reader's errors keep their line; the model's own checks name the field.
    let truncated = &file[..30];
    assert!(
        reason(truncated).starts_with("line 2: file ends inside the header"),
        "{}",
        reason(truncated)
    );
    let ascii = String::from_utf8_lossy(&file[..header_len(2)]).replace("binary_little_endian", "ascii");
    assert!(reason(ascii.as_bytes()).contains("`ascii 1.0` is not binary_little_endian"));
    let list = header(0).replace("property float x\n", "property list uchar float x\n");
    assert!(reason(list.as_bytes()).contains("`x` has type `list`"));
    let points =
        "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nelement face 0\nend_header\n";
    assert!(reason(points.as_bytes()).contains("unexpected element `face`"));
}
