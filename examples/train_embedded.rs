//! Training from another program through the library: the embedded demo scene (48 px, written
//! as a COLMAP folder), planned as `bbsplat train` plans it, 300 steps, the model saved to a
//! folder, one test view rendered to a PNG.
//!
//! `cargo run --release --features examples --example train_embedded [output folder]` (default: a folder in the
//! system's temporary directory).

use bbsplat::demo::{DemoConfig, export_colmap, generate};
use bbsplat::raster::{RenderSettings, render};
use bbsplat::{
    LoadOptions, RunConfig, RunLength, RunOutcome, StopSignal, TrainEvent, TrainPlan, TrainRequest, TrainView,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .map_or_else(|| std::env::temp_dir().join("bbsplat-embedded"), Into::into);
    let demo = generate(&DemoConfig {
        resolution: 48,
        points: 800,
        ..DemoConfig::default()
    });
    export_colmap(&demo, &out.join("data"))?;
    let (scene, background) = bbsplat::load_with_data_background(&out.join("data"), &LoadOptions::default())?;
    let request = TrainRequest {
        length: RunLength::Steps(300),
        texture_size: 8,
        ..TrainRequest::default()
    };
    let plan = TrainPlan::new(&scene, Some(&background), &request)?;
    for c in &plan.choices {
        println!("{}: {} ({})", c.setting, c.value, c.reason);
    }
    let (model, init) = plan.init_model(&scene)?;
    println!("initial billboards: {init}");
    let mut trainer = plan.trainer(model);
    let (train, test) = (TrainView::from_views(&scene.train), TrainView::from_views(&scene.test));
    let settings = RunConfig {
        eval_every: 100,
        output: Some(out.join("run")),
        ..plan.run_config()
    };
    let outcome = bbsplat::run(&mut trainer, &train, &test, &settings, &StopSignal::new(), |event| {
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
        out.join("run").display()
    );
    let camera = &test[0].camera;
    let render_settings = RenderSettings {
        background: plan.config.background,
        ..RenderSettings::default()
    };
    let rgb: Vec<u8> = render(&trainer.activated().borrowed(), camera, &render_settings)
        .rgb
        .iter()
        .map(|&c| bbsplat::loss::psnr::quantize_u8(c))
        .collect();
    image::save_buffer(
        out.join("test_0.png"),
        &rgb,
        camera.width,
        camera.height,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(())
}
