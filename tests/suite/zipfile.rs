//! The npz container (`bbsplat::zipfile`): written and read back, read from what Python's numpy
//! and `zipfile` write (deflate, stored, zip64 records, data descriptors), and damaged archives
//! refused with an error, never a panic.

use crate::external_tool::find_tool;
use bbsplat::rng::Rng;
use bbsplat::zipfile::{Method, ZipArchive, ZipError, write_zip};
use std::process::Command;

fn members() -> Vec<(String, Vec<u8>)> {
    let mut rng = Rng::new(5);
    let noisy: Vec<u8> = (0..5000).map(|_| ((rng.next_u64() as u32) & 0xff) as u8).collect();
    vec![
        ("empty.npy".to_string(), Vec::new()),
        ("small.npy".to_string(), b"hello zip".to_vec()),
        ("noisy.npy".to_string(), noisy),
        ("runs.npy".to_string(), vec![3u8; 100_000]),
    ]
}

fn refs(m: &[(String, Vec<u8>)]) -> Vec<(&str, &[u8])> {
    m.iter().map(|(n, b)| (n.as_str(), b.as_slice())).collect()
}

#[test]
fn archives_read_back_what_was_written_and_the_same_bytes_each_time() {
    let m = members();
    for method in [Method::Stored, Method::Deflated] {
        let bytes = write_zip(&refs(&m), method).unwrap();
        assert_eq!(
            bytes,
            write_zip(&refs(&m), method).unwrap(),
            "{method:?}: not the same bytes"
        );
        let archive = ZipArchive::parse(&bytes).unwrap();
        let names: Vec<&str> = archive.names().collect();
        assert_eq!(names, m.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>());
        for (name, data) in &m {
            assert_eq!(&archive.read(name, 1 << 20).unwrap(), data, "{method:?} {name}");
            assert_eq!(archive.size(name), Some(data.len() as u64));
        }
        assert_eq!(archive.read("nothing", 10), Err(ZipError::NotFound("nothing".into())));
        // The head of a member without the rest (what a too-large member's header is read with).
        for (name, data) in &m {
            for n in [0, 1, 50, 4096, 200_000] {
                let head = archive.read_prefix(name, n).unwrap();
                assert_eq!(head, data[..n.min(data.len())], "{method:?} {name} prefix {n}");
            }
        }
        assert!(matches!(
            archive.read("runs.npy", 99_999),
            Err(ZipError::TooLarge {
                size: 100_000,
                limit: 99_999,
                ..
            })
        ));
    }
    // Deflate does shrink the runs.
    let stored = write_zip(&refs(&m), Method::Stored).unwrap().len();
    let deflated = write_zip(&refs(&m), Method::Deflated).unwrap().len();
    assert!(deflated < stored / 5, "{deflated} against {stored}");
}

#[test]
fn damaged_archives_are_refused_not_panicked_on() {
    let m = members();
    let bytes = write_zip(&refs(&m)[1..3], Method::Deflated).unwrap();
    // Every prefix: an error, or (never) a wrong member.
    for cut in 0..bytes.len() {
        if let Ok(a) = ZipArchive::parse(&bytes[..cut]) {
            for name in ["small.npy", "noisy.npy"] {
                if let Ok(data) = a.read(name, 1 << 20) {
                    assert_eq!(data, m.iter().find(|(n, _)| n == name).unwrap().1, "cut {cut}");
                }
            }
        }
    }
    // A flipped bit in a member's data: refused as damaged (checksum or inflate).
    let at = bytes.windows(9).position(|w| w == b"noisy.npy").unwrap() + 9 + 100;
    let mut flipped = bytes.clone();
    flipped[at] ^= 0x10;
    let archive = ZipArchive::parse(&flipped).unwrap();
    assert!(
        matches!(archive.read("noisy.npy", 1 << 20), Err(ZipError::Damaged { .. })),
        "{:?}",
        archive.read("noisy.npy", 1 << 20)
    );
    // Random byte changes anywhere: never a panic.
    let mut rng = Rng::new(11);
    for _ in 0..3000 {
        let mut b = bytes.clone();
        for _ in 0..1 + ((rng.next_u64() as u32) % 4) {
            let i = (rng.next_u64() as u32) as usize % b.len();
            b[i] = ((rng.next_u64() as u32) & 0xff) as u8;
        }
        if let Ok(a) = ZipArchive::parse(&b) {
            let names: Vec<String> = a.names().map(str::to_string).collect();
            for n in names {
                let _ = a.read(&n, 1 << 20);
            }
        }
    }
    assert!(matches!(ZipArchive::parse(b"PK"), Err(ZipError::Malformed(_))));
}

/// Python 3 with numpy, or `None` when absent (a failure under `BBSPLAT_REQUIRE_TOOLS`).
fn python_with_numpy(test: &str) -> Option<std::path::PathBuf> {
    let python = find_tool(test, &["python3"])?;
    let ok = Command::new(&python)
        .args(["-c", "import numpy"])
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    assert!(
        ok || std::env::var_os("BBSPLAT_REQUIRE_TOOLS").is_none(),
        "{test}: python3 has no numpy"
    );
    ok.then_some(python)
}

#[test]
fn what_numpy_and_python_write_reads_and_what_we_write_numpy_reads() {
    let Some(python) = python_with_numpy("zipfile::numpy") else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("bbsplat-zipfile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // numpy's savez and savez_compressed; zipfile with its zip64 limits lowered, so that sizes,
    // offsets and the entry count go through the zip64 records; and a write to an unseekable
    // stream (sizes in a data descriptor after the data, zeros in the local header).
    let script = r#"
import io, sys, zipfile, numpy as np
d = sys.argv[1]
a = np.arange(3000, dtype=np.uint8).reshape(30, 100)
b = np.linspace(0, 1, 77)
np.savez(d + "/plain.npz", a=a, b=b)
np.savez_compressed(d + "/compressed.npz", a=a, b=b)
zipfile.ZIP64_LIMIT = 16
zipfile.ZIP_FILECOUNT_LIMIT = 1
with zipfile.ZipFile(d + "/zip64.zip", "w", zipfile.ZIP_DEFLATED) as z:
    z.writestr("one", bytes(range(256)) * 10)
    z.writestr("two", b"second member")
class Unseekable(io.RawIOBase):
    def __init__(self): self.data = bytearray()
    def writable(self): return True
    def write(self, b): self.data += b; return len(b)
zipfile.ZIP64_LIMIT = (1 << 31) - 1
zipfile.ZIP_FILECOUNT_LIMIT = (1 << 16) - 1
s = Unseekable()
with zipfile.ZipFile(s, "w", zipfile.ZIP_DEFLATED) as z:
    with z.open("streamed", "w") as f:
        f.write(b"streamed data " * 50)
open(d + "/streamed.zip", "wb").write(bytes(s.data))
"#;
    let status = Command::new(&python)
        .args(["-c", script, dir.to_str().unwrap()])
        .status()
        .unwrap();
    assert!(status.success());
    let a_npy_len = |bytes: &[u8]| {
        let archive = ZipArchive::parse(bytes).unwrap();
        let a = archive.read("a.npy", 1 << 20).unwrap();
        assert_eq!(
            &a[a.len() - 3000..],
            &(0..3000).map(|i| i as u8).collect::<Vec<_>>()[..]
        );
        assert_eq!(
            archive.size("b.npy"),
            Some(archive.read("b.npy", 1 << 20).unwrap().len() as u64)
        );
        a.len()
    };
    let plain = a_npy_len(&std::fs::read(dir.join("plain.npz")).unwrap());
    assert_eq!(plain, a_npy_len(&std::fs::read(dir.join("compressed.npz")).unwrap()));
    let zip64 = std::fs::read(dir.join("zip64.zip")).unwrap();
    assert!(
        zip64.windows(4).any(|w| w == [0x50, 0x4b, 0x06, 0x06]),
        "no zip64 end record was written"
    );
    let archive = ZipArchive::parse(&zip64).unwrap();
    let one: Vec<u8> = (0..2560).map(|i| (i % 256) as u8).collect();
    assert_eq!(archive.read("one", 1 << 20).unwrap(), one);
    assert_eq!(archive.read("two", 1 << 20).unwrap(), b"second member");
    let streamed = std::fs::read(dir.join("streamed.zip")).unwrap();
    assert_eq!(
        ZipArchive::parse(&streamed).unwrap().read("streamed", 1 << 20).unwrap(),
        b"streamed data ".repeat(50)
    );
    // Ours, read by numpy.
    let ours = write_zip(
        &[(
            "x.npy",
            &bbsplat::scene::npy::write_npy_f64(&[2, 2], &[1.0, 2.0, 3.0, 4.5]),
        )],
        Method::Deflated,
    )
    .unwrap();
    std::fs::write(dir.join("ours.npz"), ours).unwrap();
    let check =
        "import sys, numpy as np; x = np.load(sys.argv[1])['x']; assert x.shape == (2, 2) and x[1, 1] == 4.5, x";
    let status = Command::new(&python)
        .args(["-c", check, dir.join("ours.npz").to_str().unwrap()])
        .status()
        .unwrap();
    assert!(status.success(), "numpy cannot read our archive");
    std::fs::remove_dir_all(&dir).ok();
}
