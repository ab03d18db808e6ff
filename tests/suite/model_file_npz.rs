//! The npz texture arrays: the `.npy` header written and parsed back, other dtypes refused.

use bbsplat::testing_internals::model_file::{npy_u8, parse_npy_header};

#[test]
fn header_is_aligned_and_parses_back() {
    for shape in [vec![0usize, 3, 16, 16], vec![7, 16, 16], vec![5]] {
        let n: usize = shape.iter().product();
        let npy = npy_u8(&shape, &vec![9u8; n]);
        let (parsed, offset) = parse_npy_header(&npy).unwrap();
        assert_eq!(parsed, shape);
        assert_eq!(offset % 64, 0);
        assert_eq!(npy.len(), offset + n);
    }
    let npy = npy_u8(&[2, 3], &[0; 6]);
    let text = std::str::from_utf8(&npy[10..npy.len() - 6]).unwrap();
    assert_eq!(
        text.trim_end(),
        "{'descr': '|u1', 'fortran_order': False, 'shape': (2, 3), }"
    );
}

#[test]
fn rejects_other_dtypes() {
    let mut npy = npy_u8(&[2], &[0; 2]);
    let pos = npy.windows(3).position(|w| w == b"|u1").unwrap();
    npy[pos..pos + 3].copy_from_slice(b"<f4");
    assert!(parse_npy_header(&npy).unwrap_err().contains("not uint8"));
}
