//! The block partition's pieces (`bbsplat::blocks`): the ground frame, the balanced grid and
//! its margins, the views chosen by impact share, the merge.

use bbsplat::blocks::{GroundFrame, Partition, block_init, choose_views, impact_shares, merge, overlap_factor};
use bbsplat::camera::Camera;
use bbsplat::model::RawBillboards;
use bbsplat::raster::RenderSettings;
use glam::{Quat, Vec2, Vec3};
use proptest::prelude::*;

fn flat_frame() -> GroundFrame {
    GroundFrame {
        origin: Vec3::ZERO,
        up: Vec3::Y,
        along: Vec3::X,
        across: Vec3::NEG_Z,
    }
}

/// Cameras on a track along `direction` (horizontal) at height 1.5, 4 to its side, looking
/// across it down to height `look_at`; the whole set turned and moved by `turn` and `shift`.
fn pitched_track(direction: Vec3, count: usize, turn: Quat, shift: Vec3, look_at: f32) -> Vec<Camera> {
    let side = Vec3::Y.cross(direction);
    (0..count)
        .map(|i| {
            let x = direction * (i as f32 * 0.5);
            let eye = x + side * 4.0 + Vec3::Y * 1.5;
            let target = x + Vec3::Y * look_at;
            Camera::look_at(
                turn * eye + shift,
                turn * target + shift,
                turn * Vec3::Y,
                40.0,
                40.0,
                32,
                32,
            )
        })
        .collect()
}

/// [`pitched_track`] looking down to height 0.5.
fn track(direction: Vec3, count: usize, turn: Quat, shift: Vec3) -> Vec<Camera> {
    pitched_track(direction, count, turn, shift, 0.5)
}

/// The frame of a level track finds its up and its direction wherever the track is turned, to
/// 5e-7 (measured: 6.7e-8 worst over the cases, f32 vectors); so does that of two tracks facing each other,
/// both pitched down by 14° (their tilts cancel), while one pitched track alone tilts up by its
/// pitch, as the module says.
#[test]
fn the_ground_frame_of_a_track_is_its_up_and_its_direction() {
    let mut worst = 0.0f32;
    for (k, turn) in [
        Quat::IDENTITY,
        Quat::from_rotation_y(0.7),
        Quat::from_rotation_x(1.2),
        Quat::from_euler(glam::EulerRot::XYZ, 0.3, -2.0, 2.5),
    ]
    .into_iter()
    .enumerate()
    {
        let shift = Vec3::new(3.0, -2.0, 7.0);
        let level = pitched_track(Vec3::X, 20, turn, shift, 1.5);
        // Longer than the 8 between them, so that they spread most along the street.
        let mut facing = track(Vec3::X, 40, turn, shift);
        facing.extend(track(Vec3::NEG_X, 40, turn, shift + turn * Vec3::new(19.5, 0.0, 0.0)));
        for cams in [level, facing] {
            let f = GroundFrame::from_cameras(&cams).unwrap();
            let (up, along) = (turn * Vec3::Y, turn * Vec3::X);
            worst = worst
                .max((f.up - up).length())
                .max((f.along.dot(along).abs() - 1.0).abs());
            assert!((f.up - up).length() < 5e-7, "case {k}: up {:?} against {up:?}", f.up);
            assert!(
                (f.along.dot(along).abs() - 1.0).abs() < 5e-7,
                "case {k}: along {:?} against ±{along:?}",
                f.along
            );
            assert!((f.across - f.up.cross(f.along)).length() < 1e-6);
            assert!(f.along.dot(f.up).abs() < 1e-6);
        }
    }
    eprintln!("ground frame: worst up or along error {worst:e}");
    let pitched = GroundFrame::from_cameras(&track(Vec3::X, 20, Quat::IDENTITY, Vec3::ZERO)).unwrap();
    let tilt = pitched.up.angle_between(Vec3::Y).to_degrees();
    assert!((tilt - 1.0f32.atan2(4.0).to_degrees()).abs() < 1e-3, "tilt {tilt}°");
    assert!(GroundFrame::from_cameras(&[]).is_none());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Distinct points balance the columns to within one point of `n / columns`, and the rows of
    /// each column likewise; every point lies in one cell, which holds it with its margin.
    #[test]
    fn balanced_cells_hold_near_equal_shares(
        raw in prop::collection::vec((-50.0f32..50.0, -50.0f32..50.0), 12..80),
        columns in 1usize..4,
        rows in 1usize..3,
        margin in 0.0f32..0.5,
    ) {
        // Distinct coordinates on both axes (a tie can only go one way).
        let points: Vec<Vec2> = raw
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| Vec2::new(x + i as f32 * 1e-3, y - i as f32 * 1e-3))
            .collect();
        prop_assume!(points.len() >= columns * rows * 2);
        let p = Partition::balanced(flat_frame(), &points, columns, rows, margin).unwrap();
        prop_assert_eq!(p.cell_count(), columns * rows);
        let mut per_cell = vec![0usize; p.cell_count()];
        for &q in &points {
            let k = p.cell_of(q);
            per_cell[k] += 1;
            prop_assert!(p.in_cell_or_margin(k, q));
        }
        let n = points.len() as f64;
        for c in 0..columns {
            let column: usize = per_cell[c * rows..(c + 1) * rows].iter().sum();
            prop_assert!((column as f64 - n / columns as f64).abs() <= 1.0, "column {} holds {}", c, column);
            for r in 0..rows {
                let share = column as f64 / rows as f64;
                prop_assert!((per_cell[c * rows + r] as f64 - share).abs() <= 1.0);
            }
        }
    }
}

#[test]
fn a_grid_that_cannot_be_balanced_is_refused() {
    let points: Vec<Vec2> = (0..5).map(|i| Vec2::new(i as f32, 0.0)).collect();
    for (columns, rows, margin, says) in [
        (0, 1, 0.1, "has no cell"),
        (3, 2, 0.1, "at least one per cell"),
        (2, 1, -0.1, "margin"),
        (2, 1, f32::NAN, "margin"),
    ] {
        let e = Partition::balanced(flat_frame(), &points, columns, rows, margin).unwrap_err();
        assert!(e.to_string().contains(says), "{e}");
    }
    // Ties: every point at one place goes to one column, which leaves the other empty.
    let e = Partition::balanced(flat_frame(), &[Vec2::ZERO; 6], 2, 2, 0.1).unwrap_err();
    assert!(e.to_string().contains("too few for 2 rows"), "{e}");
    let e = Partition::balanced(flat_frame(), &[Vec2::new(f32::NAN, 0.0), Vec2::ZERO], 1, 1, 0.1).unwrap_err();
    assert!(e.to_string().contains("not finite"), "{e}");
}

/// A street of billboards along x seen by cameras along it: with no margin every billboard
/// counts for one cell, so a view's shares sum to 1 (to 1e-12, f64 sums of f32 impacts); a view sees
/// mostly the cell in front of it; every view goes to some block, and a wider margin only adds
/// views.
#[test]
fn a_views_shares_follow_what_it_sees() {
    let points: Vec<Vec3> = (0..200)
        .map(|i| Vec3::new(i as f32 * 0.05, 0.2 + (i % 7) as f32 * 0.1, (i % 5) as f32 * 0.1 - 0.2))
        .collect();
    let model = RawBillboards::from_points(&points, &vec![[0.6, 0.4, 0.3]; points.len()], 4, 0);
    let cameras = track(Vec3::X, 21, Quat::IDENTITY, Vec3::ZERO);
    let frame = GroundFrame::from_cameras(&cameras).unwrap();
    let centres: Vec<Vec2> = cameras.iter().map(|c| frame.project(c.centre())).collect();
    let settings = RenderSettings::default();
    let tight = Partition::balanced(frame, &centres, 3, 1, 0.0).unwrap();
    let shares = impact_shares(&model, &cameras, &settings, &tight);
    for (v, s) in shares.iter().enumerate() {
        let total: f64 = s.iter().sum();
        assert!((total - 1.0).abs() < 1e-12, "view {v}: shares {s:?} sum to {total}");
        let own = tight.cell_of_point(cameras[v].centre());
        let best = (0..3).max_by(|&a, &b| s[a].total_cmp(&s[b])).unwrap();
        assert_eq!(best, own, "view {v}: shares {s:?}");
    }
    let tight_blocks = choose_views(&shares, &cameras, &tight, 0.1);
    let wide = Partition::balanced(frame, &centres, 3, 1, 0.5).unwrap();
    let wide_blocks = choose_views(&impact_shares(&model, &cameras, &settings, &wide), &cameras, &wide, 0.1);
    for blocks in [&tight_blocks, &wide_blocks] {
        for v in 0..cameras.len() {
            assert!(
                blocks.iter().any(|b| b.contains(&v)),
                "view {v} is in no block: {blocks:?}"
            );
        }
    }
    for k in 0..3 {
        assert!(
            tight_blocks[k].iter().all(|v| wide_blocks[k].contains(v)),
            "block {k}: {:?} against {:?}",
            tight_blocks[k],
            wide_blocks[k]
        );
    }
    let (a, b) = (overlap_factor(&tight_blocks, 21), overlap_factor(&wide_blocks, 21));
    assert!((1.0..=3.0).contains(&a) && a <= b, "overlap {a} then {b}");
}

/// A view that sees nothing of the model goes to the cell under its camera; one below
/// `min_share` everywhere to its largest share.
#[test]
fn views_below_the_share_still_go_to_a_block() {
    let cameras = track(Vec3::X, 8, Quat::IDENTITY, Vec3::ZERO);
    let frame = GroundFrame::from_cameras(&cameras).unwrap();
    let centres: Vec<Vec2> = cameras.iter().map(|c| frame.project(c.centre())).collect();
    let p = Partition::balanced(frame, &centres, 2, 1, 0.0).unwrap();
    let shares = vec![vec![0.0, 0.0], vec![0.05, 0.07], vec![0.6, 0.4]];
    let blocks = choose_views(&shares, &cameras[5..8], &p, 0.5);
    assert_eq!(blocks, vec![vec![2], vec![0, 1]]);
}

/// Each block keeps what lies in its own cell: the merge of the blocks' initial models (the
/// coarse model's billboards in each cell and margin) is the coarse model, row for row, in cell
/// order; a block model of another texture size is refused.
#[test]
fn merging_the_initial_blocks_gives_back_the_coarse_model() {
    let points: Vec<Vec3> = (0..120)
        .map(|i| Vec3::new((i * 37 % 120) as f32 * 0.1, 0.3, (i % 9) as f32 * 0.2 - 0.8))
        .collect();
    let coarse = RawBillboards::from_points(&points, &vec![[0.5; 3]; points.len()], 4, 7);
    let centres: Vec<Vec2> = points.iter().map(|&p| flat_frame().project(p)).collect();
    let p = Partition::balanced(flat_frame(), &centres, 3, 2, 0.3).unwrap();
    let blocks: Vec<RawBillboards> = (0..p.cell_count()).map(|k| block_init(&p, &coarse, k)).collect();
    let with_margins: usize = blocks.iter().map(RawBillboards::len).sum();
    assert!(with_margins > coarse.len(), "the margins overlap: {with_margins}");
    let (merged, kept) = merge(&p, &blocks).unwrap();
    assert_eq!(kept.iter().sum::<usize>(), coarse.len());
    // Row for row: the coarse rows sorted by cell (stable).
    let mut order: Vec<usize> = (0..coarse.len()).collect();
    order.sort_by_key(|&i| p.cell_of_point(coarse.positions[i]));
    assert_eq!(
        merged.positions,
        order.iter().map(|&i| coarse.positions[i]).collect::<Vec<_>>()
    );
    let t = 16;
    for (row, &i) in order.iter().enumerate() {
        assert_eq!(
            merged.alpha_logits[row * t..(row + 1) * t],
            coarse.alpha_logits[i * t..(i + 1) * t]
        );
        assert_eq!(merged.sh[row * 48..(row + 1) * 48], coarse.sh[i * 48..(i + 1) * 48]);
    }
    let mut odd = blocks.clone();
    odd[1] = RawBillboards::from_points(&points[..3], &[[0.5; 3]; 3], 8, 0);
    let e = merge(&p, &odd).unwrap_err();
    assert!(e.to_string().contains("texture size"), "{e}");
    let e = merge(&p, &blocks[..2]).unwrap_err();
    assert!(e.to_string().contains("2 block models for 6 cells"), "{e}");
}

/// A 3×2 grid balanced by a lattice of ground points spread 0..12 along and 0..6 across.
fn lattice_grid() -> Partition {
    let points: Vec<Vec2> = (0..12)
        .flat_map(|i| (0..6).map(move |j| Vec2::new(i as f32 + 0.5, j as f32 + 0.5)))
        .collect();
    Partition::balanced(flat_frame(), &points, 3, 2, 0.1).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    /// A point's distance to a seam is how far it can move without leaving its cell: moves
    /// shorter than it along either axis keep the cell, and one move a little longer changes it
    /// (no seam beyond the grid's outer sides: there the distance may be infinite).
    #[test]
    fn the_distance_to_a_seam_is_how_far_a_point_stays_in_its_cell(x in -4.0f32..16.0, y in -3.0f32..9.0) {
        let grid = lattice_grid();
        let q = Vec2::new(x, y);
        let d = bbsplat::blocks::distance_to_seam(&grid, q);
        prop_assert!(d >= 0.0);
        let cell = grid.cell_of(q);
        let steps = [Vec2::X, Vec2::NEG_X, Vec2::Y, Vec2::NEG_Y];
        for s in steps {
            prop_assert_eq!(grid.cell_of(q + s * (0.99 * d).min(100.0)), cell, "{:?} by {}", s, d);
        }
        prop_assert!(d.is_finite(), "every cell of a 3×2 grid has a seam");
        let beyond = 1.01 * d + 1e-4;
        prop_assert!(steps.iter().any(|&s| grid.cell_of(q + s * beyond) != cell), "no move of {} leaves the cell", beyond);
    }
}

#[test]
fn a_single_cell_has_no_seam() {
    let points: Vec<Vec2> = (0..4).map(|i| Vec2::new(i as f32, 0.0)).collect();
    let one = Partition::balanced(flat_frame(), &points, 1, 1, 0.2).unwrap();
    assert_eq!(
        bbsplat::blocks::distance_to_seam(&one, Vec2::new(1.0, 2.0)),
        f32::INFINITY
    );
}

/// A camera 5 above the ground plane y = 0 looking straight down at it, the grid's column cuts
/// (x = 4 and 8) in view: the band mask marks exactly the pixels whose ground point, found by
/// intersecting the pixel's ray with the plane, lies within the width of a cut (pixels within
/// 1e-3 of the band's edge are not compared: rounding may put them either side).
#[test]
fn the_seam_band_holds_the_pixels_whose_surface_lies_near_a_cut() {
    let grid = lattice_grid();
    assert_eq!(grid.along_cuts, vec![4.0, 8.0]);
    let camera = Camera::look_at(
        Vec3::new(6.0, 5.0, -3.0),
        Vec3::new(6.0, 0.0, -3.0),
        Vec3::Z,
        30.0,
        30.0,
        48,
        40,
    );
    let (w, h) = (48usize, 40usize);
    let centre = camera.centre();
    let mut alpha = vec![1.0f32; w * h];
    let mut depth = vec![0.0f32; w * h];
    let mut ground = vec![Vec3::ZERO; w * h];
    for row in 0..h {
        for column in 0..w {
            let k = row * w + column;
            // The pixel's ray in the world, hit with the plane y = 0.
            let view_dir = Vec3::new(
                (column as f32 + 0.5 - camera.cx) / camera.fx,
                (row as f32 + 0.5 - camera.cy) / camera.fy,
                1.0,
            );
            let dir = camera.rotation.transpose() * view_dir;
            let p = centre + dir * (-centre.y / dir.y);
            ground[k] = p;
            // Opacity 0.8: the expected depth is depth / alpha.
            alpha[k] = 0.8;
            depth[k] = 0.8 * camera.world_to_view(p).z;
        }
    }
    // The left quarter of the image has no surface.
    for row in 0..h {
        for column in 0..w / 4 {
            alpha[row * w + column] = 0.3;
        }
    }
    let width = 0.7;
    let mask = bbsplat::blocks::seam_band_mask(&grid, &camera, &alpha, &depth, width);
    let (mut inside, mut compared) = (0, 0);
    for k in 0..w * h {
        let q = grid.frame.project(ground[k]);
        // Distance to the nearest seam of this grid: the column cuts, and the row cut of q's column.
        let column = grid.along_cuts.iter().filter(|&&c| c <= q.x).count();
        let mut d = grid
            .along_cuts
            .iter()
            .map(|&c| (q.x - c).abs())
            .fold(f32::INFINITY, f32::min);
        d = grid.across_cuts[column]
            .iter()
            .map(|&c| (q.y - c).abs())
            .fold(d, f32::min);
        if (d - width).abs() < 1e-3 {
            continue;
        }
        compared += 1;
        let want = alpha[k] >= 0.5 && d < width;
        assert_eq!(mask[k] == 255, want, "pixel {k}: ground {q:?}, distance {d}");
        inside += want as usize;
    }
    assert!(
        compared > w * h * 9 / 10 && inside > 100 && inside < compared / 2,
        "{inside} of {compared}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]
    /// A turned frame keeps up and the origin, stays orthonormal and right-handed
    /// (`across = up × along`), turns `along` by the angle, and turning back gives the frame again
    /// (tolerance 1e-6: f32 vectors turned in f64; measured worst 1.8e-7).
    #[test]
    fn a_turned_frame_is_the_frame_turned_about_up(degrees in -360.0f32..360.0) {
        let frame = flat_frame();
        let t = frame.turned(degrees);
        prop_assert_eq!((t.up, t.origin), (frame.up, frame.origin));
        prop_assert!((t.along.length() - 1.0).abs() < 1e-6 && t.along.dot(t.up).abs() < 1e-6);
        prop_assert!((t.across - t.up.cross(t.along)).length() < 1e-6);
        let angle = (t.along.dot(frame.across)).atan2(t.along.dot(frame.along)).to_degrees();
        let wrapped = (angle - degrees).rem_euclid(360.0);
        prop_assert!(wrapped.min(360.0 - wrapped) < 1e-3, "turned by {} for {}", angle, degrees);
        let back = t.turned(-degrees);
        prop_assert!((back.along - frame.along).length() < 1e-6 && (back.across - frame.across).length() < 1e-6);
    }
}
