//! The embedded demo scene: determinism, its images, its points and its COLMAP export.

use bbsplat::demo::{DEMO_BACKGROUND, DemoConfig, export_colmap, generate};
use glam::Vec3;

#[test]
fn generation_is_deterministic() {
    let cfg = DemoConfig {
        resolution: 24,
        train_views: 4,
        test_views: 2,
        points: 50,
        seed: 3,
    };
    let a = generate(&cfg);
    let b = generate(&cfg);
    assert_eq!(a.train[2].rgb, b.train[2].rgb);
    assert_eq!(a.points, b.points);
    assert_eq!(a.test.len(), 2);
}

#[test]
fn images_show_objects_and_background() {
    let cfg = DemoConfig {
        resolution: 48,
        train_views: 2,
        test_views: 0,
        points: 10,
        seed: 0,
    };
    let s = generate(&cfg);
    let rgb = &s.train[0].rgb;
    let bg = rgb.chunks(3).filter(|p| p == &DEMO_BACKGROUND.as_slice()).count();
    let n = rgb.len() / 3;
    // Both background and objects are visible.
    assert!(bg > n / 20 && bg < n * 9 / 10, "background pixels {bg} of {n}");
    assert!(rgb.iter().all(|c| (0.0..=1.0).contains(c)));
}

#[test]
fn points_lie_on_surfaces() {
    // The scene's points are its surface samples; few small views keep the rendering cheap.
    let cfg = DemoConfig {
        resolution: 8,
        train_views: 1,
        test_views: 0,
        points: 200,
        seed: 5,
    };
    let pts = generate(&cfg).points;
    assert_eq!(pts.len(), 200);
    // The scene's two spheres (centre, radius) and its box, as `demo` builds them.
    let spheres = [(Vec3::new(-0.7, 0.55, 0.2), 0.55), (Vec3::new(0.75, 0.35, -0.45), 0.35)];
    for p in pts {
        let on_floor = p.y.abs() < 1e-3;
        let on_sphere = spheres
            .iter()
            .any(|&(centre, radius)| ((p - centre).length() - radius).abs() < 1e-3);
        let on_box = {
            let (min, max) = (Vec3::new(0.15, 0.0, 0.35), Vec3::new(0.85, 0.8, 1.05));
            let inside = p.cmpge(min - 1e-3).all() && p.cmple(max + 1e-3).all();
            let on_face = (p - min).abs().min_element() < 1e-3 || (p - max).abs().min_element() < 1e-3;
            inside && on_face
        };
        assert!(on_floor || on_sphere || on_box, "{p}");
    }
}

#[test]
fn exported_colmap_dataset_loads_back_with_the_same_cameras() {
    let cfg = DemoConfig {
        resolution: 16,
        train_views: 6,
        test_views: 2,
        points: 30,
        seed: 2,
    };
    let scene = generate(&cfg);
    let dir = std::env::temp_dir().join(format!("bbsplat-demo-export-{}", std::process::id()));
    export_colmap(&scene, &dir).unwrap();
    let options = bbsplat::scene::LoadOptions {
        test_every: 0,
        print_warnings: false,
        ..Default::default()
    };
    let loaded = bbsplat::scene::load(&dir, &options).unwrap();
    assert_eq!(loaded.train.len(), 8);
    assert_eq!(loaded.points.as_ref().unwrap().positions.len(), 30);
    // Every exported camera projects the origin where the original does.
    for v in &loaded.train {
        let original = scene
            .train
            .iter()
            .chain(&scene.test)
            .find(|o| o.camera.centre().distance(v.camera.centre()) < 1e-4)
            .expect("a matching original camera");
        let (a, b) = (
            original.camera.project(Vec3::ZERO).unwrap(),
            v.camera.project(Vec3::ZERO).unwrap(),
        );
        assert!((a.0 - b.0).abs() < 1e-3 && (a.1 - b.1).abs() < 1e-3, "{a:?} {b:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
