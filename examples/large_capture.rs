//! Writes a capture of the demo world as large as a user's ([`bbsplat::demo::export_capture`]):
//! `N` JPEG photographs of `W×H` on a dome of cameras with a COLMAP model, to measure memory and
//! loading at the sizes of real captures (docs/scene.md, "Large captures"). 3 000 photos of
//! 1000×750 take 2 minutes and 200 MB of disk on 2 cores.
//!
//! `cargo run --release --features examples --example large_capture -- DIR [N [W [H]]]` (default 3000 1000 750)

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = std::path::PathBuf::from(args.next().ok_or("usage: large_capture DIR [N [W [H]]]")?);
    let n: usize = args.next().map_or(Ok(3000), |a| a.parse())?;
    let width: u32 = args.next().map_or(Ok(1000), |a| a.parse())?;
    let height: u32 = args.next().map_or(Ok(750), |a| a.parse())?;
    bbsplat::demo::export_capture(&dir, n, width, height)?;
    println!(
        "wrote {n} photos of {width}x{height} and a COLMAP model to {}",
        dir.display()
    );
    Ok(())
}
