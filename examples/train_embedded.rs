//! Training from another program through the library: the embedded demo scene, 300 steps at
//! 48 px, the model saved to a folder, one test view rendered to a PNG.
//!
//! `cargo run --release --example train_embedded [output folder]` (default: a folder in the
//! system's temporary directory).

use bbsplat::demo::{DemoConfig, generate};
use bbsplat::model::RawBillboards;
use bbsplat::raster::{RenderSettings, render};
use bbsplat::scene::split::camera_extent;
use bbsplat::train::{RunConfig, RunOutcome, StopSignal, TrainConfig, TrainEvent, TrainView, Trainer};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .map_or_else(|| std::env::temp_dir().join("bbsplat-embedded"), Into::into);
    let scene = generate(&DemoConfig {
        resolution: 48,
        points: 800,
        ..DemoConfig::default()
    });
    let train: Vec<TrainView> = scene.train.iter().map(TrainView::from_demo).collect();
    let test: Vec<TrainView> = scene.test.iter().map(TrainView::from_demo).collect();
    let cameras: Vec<_> = train.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        iterations: 300,
        background: glam::Vec3::from_array(scene.background),
        extent: camera_extent(&cameras),
        ..TrainConfig::default()
    };
    let mut trainer = Trainer::new(RawBillboards::from_points(&scene.points, &scene.colours, 8, 0), config);
    let settings = RunConfig {
        eval_every: 100,
        output: Some(out.clone()),
        ..RunConfig::default()
    };
    let outcome = bbsplat::train::run(&mut trainer, &train, &test, &settings, &StopSignal::new(), |event| {
        if let TrainEvent::Evaluation { step, psnr, .. } = event {
            println!("step {step}: test PSNR {psnr:.2} dB");
        }
    })?;
    let RunOutcome::Finished(summary) = outcome else {
        return Err("stopped early".into());
    };
    println!(
        "{:.2} dB after {} steps ({:.1} s); model in {}",
        summary.test_psnr,
        summary.iterations,
        summary.train_seconds,
        out.display()
    );
    let (cam, settings) = (
        &test[0].camera,
        RenderSettings {
            background: config.background,
            ..RenderSettings::default()
        },
    );
    let rgb: Vec<u8> = render(&trainer.activated().borrowed(), cam, &settings)
        .rgb
        .iter()
        .map(|&c| bbsplat::loss::psnr::quantize_u8(c))
        .collect();
    image::save_buffer(
        out.join("test_0.png"),
        &rgb,
        cam.width,
        cam.height,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(())
}
