//! Deterministic fuzz-style property test: random mutations of the seed corpus in `fuzz/corpus`
//! run through the same entry points as the cargo-fuzz targets (`bbsplat::scene::fuzz`), which
//! must not panic (and check their round-trip invariants on inputs that parse).

use bbsplat::scene::fuzz;
use bbsplat::strategies::seeded_config;
use proptest::prelude::*;
use std::path::Path;

/// The hand-written seeds of `fuzz/corpus/<target>`: valid files with names. The inputs a fuzz
/// campaign added beside them are named by their SHA-1 (40 hex digits) and are left out: most
/// of them are not valid files, and they are many.
fn seeds(target: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus").join(target);
    let is_campaign_unit = |name: &str| name.len() == 40 && name.bytes().all(|b| b.is_ascii_hexdigit());
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| !p.file_name().and_then(|n| n.to_str()).is_some_and(is_campaign_unit))
        .collect();
    files.sort();
    files.into_iter().map(|p| std::fs::read(p).unwrap()).collect()
}

/// One mutation: kind, position (fraction of the length), a value and a length.
type Op = (u8, f64, u64, usize);

/// Tokens spliced into inputs: numbers at the edges, separators, JSON and PLY syntax.
const TOKENS: [&str; 20] = [
    "nan",
    "-1",
    "inf",
    "1e400",
    "\n",
    "#",
    " ",
    "\0",
    "18446744073709551615",
    "-0",
    "{",
    "]",
    "\"",
    ",",
    ":",
    "null",
    "NaN",
    "end_header\n",
    "property list uchar int x\n",
    "4294967296",
];

fn mutate(seed: &[u8], ops: &[Op]) -> Vec<u8> {
    let mut d = seed.to_vec();
    for &(kind, at, value, len) in ops {
        let pos = ((at * d.len() as f64) as usize).min(d.len());
        match kind % 9 {
            0 if pos < d.len() => d[pos] ^= 1 << (value % 8),
            1 if pos < d.len() => d[pos] = value as u8,
            2 => {
                let bytes = [0u64, 1, u64::MAX, 1 << 32, 1 << 63, value][len % 6].to_le_bytes();
                let end = (pos + 8).min(d.len());
                d[pos..end].copy_from_slice(&bytes[..end - pos]);
            }
            3 => d.truncate(pos),
            4 => {
                let end = (pos + len % 16).min(d.len());
                d.drain(pos..end);
            }
            5 => {
                let chunk: Vec<u8> = d[pos..(pos + len % 32).min(d.len())].to_vec();
                d.splice(pos..pos, chunk);
            }
            6 => {
                let t = TOKENS[value as usize % TOKENS.len()].as_bytes();
                d.splice(pos..pos, t.iter().copied());
            }
            7 => {
                let end = (pos + len % 8).min(d.len());
                let t = TOKENS[value as usize % TOKENS.len()].as_bytes();
                d.splice(pos..end, t.iter().copied());
            }
            _ => d
                .splice(pos..pos, value.to_le_bytes().into_iter().take(len % 9))
                .for_each(drop),
        }
    }
    d
}

fn ops() -> impl Strategy<Value = Vec<Op>> {
    prop::collection::vec((any::<u8>(), 0.0f64..1.0, any::<u64>(), any::<usize>()), 1..8)
}

#[test]
fn seeds_parse_cleanly() {
    use bbsplat::scene::{colmap_binary as bin, colmap_text as txt, nerf_json, ply};
    let f = Path::new("seed");
    for s in seeds("colmap_binary") {
        let ok = match s[0] % 3 {
            0 => bin::parse_cameras(&s[1..], f).is_ok(),
            1 => bin::parse_images(&s[1..], f).is_ok(),
            _ => bin::parse_points(&s[1..], f).is_ok(),
        };
        assert!(ok);
    }
    for s in seeds("colmap_text") {
        let t = std::str::from_utf8(&s[1..]).unwrap();
        let ok = match s[0] % 3 {
            0 => txt::parse_cameras(t, f).map(|_| ()),
            1 => txt::parse_images(t, f).map(|_| ()),
            _ => txt::parse_points(t, f).map(|_| ()),
        };
        ok.unwrap();
    }
    for s in seeds("transforms_json") {
        nerf_json::parse_transforms(std::str::from_utf8(&s).unwrap(), f).unwrap();
    }
    for s in seeds("ply") {
        assert!(!ply::parse_point_cloud(&s, f).unwrap().positions.is_empty());
    }
    let npy = seeds("npy");
    assert_eq!(npy.len(), 3);
    for s in &npy {
        bbsplat::scene::npy::parse_npy(s).unwrap();
    }
    for s in seeds("npz") {
        let archive = bbsplat::scene::npy::Npz::parse(&s).unwrap();
        assert_eq!(archive.names().count(), 4);
        let world = archive.array("world_mat_1").unwrap().unwrap();
        assert_eq!(world.shape, vec![4, 4]);
    }
}

proptest! {
    #![proptest_config(seeded_config(2000))]

    #[test]
    fn colmap_binary_mutations_never_panic(i in any::<prop::sample::Index>(), ops in ops()) {
        let s = seeds("colmap_binary");
        let seed = &s[i.index(s.len())];
        let mut m = mutate(&seed[1..], &ops);
        m.insert(0, seed[0]);
        fuzz::colmap_binary(&m);
    }

    #[test]
    fn colmap_text_mutations_never_panic(i in any::<prop::sample::Index>(), ops in ops()) {
        let s = seeds("colmap_text");
        let seed = &s[i.index(s.len())];
        let mut m = mutate(&seed[1..], &ops);
        m.insert(0, seed[0]);
        fuzz::colmap_text(&m);
    }

    #[test]
    fn transforms_json_mutations_never_panic(i in any::<prop::sample::Index>(), ops in ops()) {
        let s = seeds("transforms_json");
        fuzz::transforms(&mutate(&s[i.index(s.len())], &ops));
    }

    #[test]
    fn ply_mutations_never_panic(i in any::<prop::sample::Index>(), ops in ops()) {
        let s = seeds("ply");
        fuzz::ply(&mutate(&s[i.index(s.len())], &ops));
    }

    #[test]
    fn npy_mutations_never_panic(i in any::<prop::sample::Index>(), ops in ops()) {
        let s = seeds("npy");
        fuzz::npy(&mutate(&s[i.index(s.len())], &ops));
    }

    #[test]
    fn npz_mutations_never_panic(i in any::<prop::sample::Index>(), ops in ops()) {
        let s = seeds("npz");
        fuzz::npz(&mutate(&s[i.index(s.len())], &ops));
    }

    /// Arbitrary bytes, not derived from seeds.
    #[test]
    fn random_bytes_never_panic(data in prop::collection::vec(any::<u8>(), 0..300)) {
        fuzz::colmap_binary(&data);
        fuzz::colmap_text(&data);
        fuzz::transforms(&data);
        fuzz::ply(&data);
        fuzz::npy(&data);
        fuzz::npz(&data);
    }
}
