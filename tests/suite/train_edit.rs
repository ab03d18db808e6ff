//! The trainer's two forms of the billboard set stay in sync: `Trainer::activated` is, bit for
//! bit, what the raw parameters (`Trainer::model`, and in Gaussian mode the opacity logits) give,
//! after steps (optimiser, relocation, growth) and after an edit through `Trainer::edit_model`;
//! an edit that would change the set's shape is refused.

use bbsplat::billboards::ActivatedBillboards;
use bbsplat::demo::{DemoConfig, generate};
use bbsplat::model::RawBillboards;
use bbsplat::scene::split::camera_extent;
use bbsplat::train::{AdamMode, TextureMode, TrainConfig, TrainView, Trainer};
use glam::Vec3;
use std::path::Path;

fn setup(adam: AdamMode, texture_mode: TextureMode) -> (Trainer, Vec<TrainView>) {
    let scene = generate(&DemoConfig {
        resolution: 24,
        train_views: 4,
        test_views: 1,
        points: 120,
        seed: 3,
    });
    let views: Vec<TrainView> = scene.train.iter().map(TrainView::from_demo).collect();
    let mut model = RawBillboards::from_points(&scene.points, &scene.colours, 4, 3);
    // Dead billboards, so that relocation moves rows within the first steps.
    for d in [2, 30, 61] {
        model.alpha_logits[d * 16..(d + 1) * 16].fill(-12.0);
    }
    let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
    let config = TrainConfig {
        iterations: 128,
        seed: 3,
        background: Vec3::from_array(scene.background),
        extent: camera_extent(&cams),
        relocate_every: 3,
        growth_cap: 140,
        adam,
        texture_mode,
        ..TrainConfig::default()
    };
    (Trainer::new(model, config), views)
}

/// Every float of the set as bits, field by field.
fn bits(a: &ActivatedBillboards) -> Vec<u32> {
    let mut out: Vec<u32> = a
        .positions
        .iter()
        .flat_map(|p| p.to_array())
        .map(f32::to_bits)
        .collect();
    out.extend(a.quaternions.iter().flatten().map(|x| x.to_bits()));
    out.extend(a.log_scales.iter().flat_map(|s| s.to_array()).map(f32::to_bits));
    out.extend(a.sh.iter().map(|x| x.to_bits()));
    out.extend(a.textures.iter().flatten().map(|x| x.to_bits()));
    out.push(a.texture_size as u32);
    out
}

/// What the raw state gives: in full-texture mode `model().activate()`; in either mode the
/// activated copy a checkpoint of the trainer rebuilds from the raw parameters alone.
fn assert_in_sync(tr: &Trainer, tag: &str) {
    let rebuilt = Trainer::from_checkpoint_bytes(&tr.checkpoint_bytes(), Path::new("mem")).unwrap();
    assert!(
        bits(tr.activated()) == bits(rebuilt.activated()),
        "{tag}: activated copy out of sync"
    );
    if tr.config().texture_mode == TextureMode::Full {
        assert!(
            bits(tr.activated()) == bits(&tr.model().activate()),
            "{tag}: activated is not model().activate()"
        );
    }
}

/// An edit of several rows and every parameter group.
fn edit(m: &mut RawBillboards) {
    let t = m.texture_size * m.texture_size;
    m.positions[5] += Vec3::new(0.25, -0.5, 0.125);
    m.quaternions[9] = [0.5, 0.5, -0.5, 0.5];
    m.log_scales[11] *= 1.5;
    m.sh[17 * 48..18 * 48].iter_mut().for_each(|x| *x = -*x);
    m.alpha_logits[20 * t..21 * t].fill(2.5);
    m.colour_logits[33 * 3 * t..34 * 3 * t].fill(-1.0);
}

#[test]
fn the_activated_copy_follows_steps_and_edits() {
    for (adam, mode) in [
        (AdamMode::Dense, TextureMode::Full),
        (AdamMode::Sparse, TextureMode::Full),
        (AdamMode::Lazy, TextureMode::Full),
        (AdamMode::Dense, TextureMode::Gaussian),
    ] {
        let tag = format!("{adam:?}/{mode:?}");
        let (mut tr, views) = setup(adam, mode);
        let n0 = tr.model().len();
        let mut relocated = 0;
        for _ in 0..7 {
            relocated += tr.step(&views).unwrap().relocated;
        }
        assert!(
            relocated > 0 && tr.model().len() > n0,
            "{tag}: relocation and growth ran"
        );
        assert_in_sync(&tr, &format!("{tag} after steps"));

        let before = tr.model().clone();
        let answer = tr.edit_model(|m| {
            edit(m);
            42
        });
        assert_eq!(answer, 42);
        assert_in_sync(&tr, &format!("{tag} after the edit"));
        // The edit reached the activated copy (and only the edited rows of the model changed).
        let a = tr.activated();
        assert_eq!(a.positions[5], before.positions[5] + Vec3::new(0.25, -0.5, 0.125));
        assert_eq!(a.quaternions[9], [0.5, 0.5, -0.5, 0.5]);
        assert_eq!(a.sh[17 * 48], -before.sh[17 * 48]);
        let (m, t) = (tr.model(), 16);
        assert_eq!(m.positions[6], before.positions[6]);
        if mode == TextureMode::Full {
            // Texel 5 (not a masked corner).
            assert_eq!(a.textures[20 * t + 5][3], bbsplat::model::sigmoid(2.5));
            assert_eq!(m.alpha_logits[21 * t..], before.alpha_logits[21 * t..]);
        } else {
            // Gaussian mode: the alpha logits follow the opacity logits; the edit is overwritten.
            assert_eq!(m.alpha_logits, before.alpha_logits);
        }
        // Training goes on from the edited state, in sync.
        for _ in 0..3 {
            tr.step(&views).unwrap();
        }
        assert_in_sync(&tr, &format!("{tag} after more steps"));
    }
}

#[test]
fn an_edit_that_changes_the_shape_of_the_set_is_refused() {
    type Edit = fn(&mut RawBillboards);
    let edits: [(&str, Edit); 4] = [
        ("a row pushed", |m| m.positions.push(Vec3::ZERO)),
        ("SH shortened", |m| m.sh.truncate(m.sh.len() - 1)),
        ("texture size", |m| m.texture_size = 8),
        ("alpha mask", |m| m.alpha_mask[5] = !m.alpha_mask[5]),
    ];
    for (what, e) in edits {
        let (mut tr, _) = setup(AdamMode::Dense, TextureMode::Full);
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| tr.edit_model(e)));
        assert!(caught.is_err(), "{what}: the edit was accepted");
    }
}
