//! At each discontinuity of the forward (training settings), which one-sided derivative the
//! crate's backward returns.
//!
//! Each test builds a tiny scene whose pixel of interest lies *exactly* on the discontinuity in
//! both the crate's f32 arithmetic and the f64 reference (identity camera, principal point on a
//! pixel centre, exactly representable geometry, texel values chosen so that the products are
//! exact; each test asserts the exactness it relies on), takes the left and right one-sided
//! differences of the f64 renderer along one parameter, and asserts which one the crate returns.
//! At a jump the jumping side's difference grows like `1/h`; at a kink both are finite.
//!
//! Found (training settings, `CompositeParams::default()`):
//! - alpha clamp `a = 0.99`: **left** derivative (the clamp is active only for `a > 0.99`);
//! - alpha cut-off `α = 1/255`: **right** (the entry is blended at equality; the left side jumps);
//! - transmittance stop `T·(1 − α) = 1e-4`: **left** in the alpha (blended at equality; the right
//!   side stops and jumps);
//! - near plane on the hit depth `= 0.2`: the **far** side (accepted at equality; the near side
//!   jumps);
//! - near plane on the centre depth `= 0.2`: the **near** side, i.e. zero (culled at equality; the
//!   far side jumps);
//! - texel centre line (integer texel coordinate): the **right** derivative in `u` (the cell
//!   `[⌊X⌋, ⌊X⌋ + 1)`), which is the left derivative in the billboard's x position (u decreases
//!   as the billboard moves right); half-integer texel coordinates are smooth;
//! - texture-support border (`X = −1`): both sides and the crate give 0 (the sampled alpha is
//!   below the 1/255 cut-off on both sides, which hides the kink).

use super::gradients::{Group, Loss, analytic, get, set};
use super::renderer::{Cam64, Fate, Scene64, Thresholds, Trace, render64};
use bbsplat::billboards::ActivatedBillboards;
use bbsplat::camera::Camera;
use bbsplat::raster::{RenderSettings, render};
use glam::{Mat3, Vec2, Vec3};

/// Relative tolerance for "the crate returns this one-sided derivative": 1e-6, measured worst
/// 3.2e-7 over the tests below (the row kink of the texel test; the f32 rounding of a few
/// products).
const SAME: f64 = 1e-6;

/// A tiny scene and the pixel of interest.
struct Tiny {
    b: ActivatedBillboards,
    cam: Camera,
    settings: RenderSettings,
    pixel: usize,
}

/// One-sided differences of the f64 loss and the crate's derivative.
#[derive(Debug)]
struct Sides {
    left: f64,
    right: f64,
    crate_value: f64,
}

impl Tiny {
    fn loss(&self) -> Loss {
        let n = self.cam.pixel_count();
        let mut l = Loss {
            rgb: vec![0.0; 3 * n],
            alpha: vec![0.0; n],
            depth: vec![0.0; n],
        };
        l.rgb[3 * self.pixel..3 * self.pixel + 3].copy_from_slice(&[0.7, -0.4, 0.5]);
        l.alpha[self.pixel] = 0.8;
        l.depth[self.pixel] = 0.3;
        l
    }

    fn th(&self) -> Thresholds {
        Thresholds::crate_values(&self.settings.composite)
    }

    /// The f64 trace at the point.
    fn trace(&self) -> Trace {
        let s = Scene64::of(&self.b, &self.settings);
        render64(&s, &Cam64::of(&self.cam), &self.th(), true).1.expect("traced")
    }

    /// Left and right differences with step `h` along coordinate `index` of `group`.
    fn sides(&self, group: Group, index: usize, h: f64) -> Sides {
        let loss = self.loss();
        let scene = Scene64::of(&self.b, &self.settings);
        let cam = Cam64::of(&self.cam);
        let x = get(&scene, group);
        let at = |dx: f64| {
            let mut s = scene.clone();
            let mut xs = x.clone();
            xs[index] += dx;
            set(&mut s, group, &xs);
            loss.value(&render64(&s, &cam, &self.th(), false).0)
        };
        let l0 = at(0.0);
        let g = loss.crate_gradients(&self.b, &self.cam, &self.settings);
        let sides = Sides {
            left: (l0 - at(-h)) / h,
            right: (at(h) - l0) / h,
            crate_value: analytic(&g, group)[index],
        };
        eprintln!("f64_reference one-sided {group:?}[{index}]: {sides:?}");
        sides
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= SAME * b.abs().max(1e-3)
}

/// Asserts that the crate returns `want` and not `other` (which differs clearly).
fn assert_returns(s: &Sides, want: f64, other: f64, what: &str) {
    assert!(
        close(s.crate_value, want),
        "{what}: crate {} vs expected side {want}",
        s.crate_value
    );
    assert!(
        (other - want).abs() > 1e-2 * want.abs().max(1e-2),
        "{what}: the two sides do not differ ({s:?}): not a discontinuity"
    );
}

/// The identity camera with the principal point on the centre of pixel (4, 4) of a 9×9 image.
fn centred_camera() -> Camera {
    Camera {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
        fx: 16.0,
        fy: 16.0,
        cx: 4.5,
        cy: 4.5,
        width: 9,
        height: 9,
    }
}

const CENTRE_PIXEL: usize = 4 * 9 + 4;

/// Appends a face-on billboard (identity rotation) at `(x, y, z)` with half sides 1, TS 3 and
/// the given texels (`[r, g, b, alpha]`, row-major), SH giving colour (0.3, 0.5, 0.7) at degree
/// 0.
fn push_face_on(b: &mut ActivatedBillboards, pos: Vec3, texels: [[f32; 4]; 9]) {
    b.positions.push(pos);
    b.quaternions.push([1.0, 0.0, 0.0, 0.0]);
    b.log_scales.push(Vec2::ZERO);
    let mut sh = [0.0f32; 48];
    for (ch, c) in [0.3f32, 0.5, 0.7].iter().enumerate() {
        sh[ch] = (c - 0.5) / 0.282_094_8;
    }
    b.sh.extend_from_slice(&sh);
    b.textures.extend_from_slice(&texels);
}

fn settings() -> RenderSettings {
    RenderSettings {
        background: Vec3::new(0.2, 0.9, 0.4),
        sh_degree: 0,
        ..RenderSettings::default()
    }
}

/// Texels with colour varying by texel and constant alpha `a`.
fn flat_alpha(a: f32) -> [[f32; 4]; 9] {
    std::array::from_fn(|k| [0.1 * k as f32, 0.9 - 0.08 * k as f32, 0.5, a])
}

/// Gradient index of texel `k` of billboard `b` (TS 3), channel `ch`, in the textures group.
fn texel_index(b: usize, k: usize, ch: usize) -> usize {
    4 * (9 * b + k) + ch
}

/// Alpha clamp: the centre pixel hits the centre texel exactly (`u = v = 0`, texel coordinate 1
/// with weight 1), whose alpha is exactly 0.99 (f32). Left of it the alpha follows the texel;
/// right of it the clamp holds it at 0.99 (right derivative of the alpha terms is 0). The crate
/// clamps only `a > 0.99`, so at equality its gradient is the **left** derivative.
#[test]
fn alpha_clamp_gives_the_left_derivative() {
    let mut b = ActivatedBillboards::empty(3);
    push_face_on(&mut b, Vec3::new(0.0, 0.0, 2.0), flat_alpha(0.99));
    let t = Tiny {
        b,
        cam: centred_camera(),
        settings: settings(),
        pixel: CENTRE_PIXEL,
    };
    let pair = t.trace().pairs[CENTRE_PIXEL];
    assert_eq!(
        (pair.tx, pair.ty, pair.a),
        (1.0, 1.0, t.th().max_alpha),
        "not exactly at the clamp"
    );
    let s = t.sides(Group::Textures, texel_index(0, 4, 3), 1e-6);
    assert_eq!(
        s.right, 0.0,
        "above the clamp the loss does not depend on the alpha texel"
    );
    assert_returns(&s, s.left, s.right, "alpha clamp");
}

/// Alpha cut-off: the centre texel's alpha is exactly f32 `1/255`; the crate skips only
/// `α < 1/255`, so the entry is blended. Left of it the entry is skipped (the loss jumps by the
/// entry's contribution: the left difference grows like 1/h); the crate returns the **right**
/// derivative.
#[test]
fn alpha_cut_off_gives_the_right_derivative() {
    let mut b = ActivatedBillboards::empty(3);
    push_face_on(&mut b, Vec3::new(0.0, 0.0, 2.0), flat_alpha(1.0 / 255.0));
    let t = Tiny {
        b,
        cam: centred_camera(),
        settings: settings(),
        pixel: CENTRE_PIXEL,
    };
    let pair = t.trace().pairs[CENTRE_PIXEL];
    assert_eq!(
        (pair.a, pair.fate),
        (t.th().min_alpha, Fate::Blend),
        "not exactly at the cut-off"
    );
    let out = render(&t.b.borrowed(), &t.cam, &t.settings);
    assert!(out.alpha[CENTRE_PIXEL] > 0.0, "the crate must blend at equality");
    let s = t.sides(Group::Textures, texel_index(0, 4, 3), 1e-6);
    assert!(s.left.abs() > 1e3 * s.right.abs(), "the left side must jump: {s:?}");
    assert_returns(&s, s.right, s.left, "alpha cut-off");
}

/// Transmittance stop: three face-on layers on the optical axis with alphas `1 − 2⁻¹`,
/// `1 − 225280·2⁻²⁴` and `1 − 249889·2⁻²⁴` (all exact in f32), so that the third one's
/// `T·(1 − α) = 2⁻¹·225280·249889·2⁻⁴⁸` equals f32 `1e-4` exactly, in f32 and in f64. The crate
/// stops only when `T·(1 − α) < 1e-4`, so the third layer is blended. Raising its alpha (right)
/// stops before it (a jump); the crate returns the **left** derivative.
#[test]
fn transmittance_stop_gives_the_left_derivative() {
    let alphas = [0.5f32, 1.0 - 225_280.0 / 16_777_216.0, 1.0 - 249_889.0 / 16_777_216.0];
    let mut b = ActivatedBillboards::empty(3);
    for (k, a) in alphas.iter().enumerate() {
        push_face_on(&mut b, Vec3::new(0.0, 0.0, 2.0 + k as f32), flat_alpha(*a));
    }
    let t = Tiny {
        b,
        cam: centred_camera(),
        settings: settings(),
        pixel: CENTRE_PIXEL,
    };
    let trace = t.trace();
    let third = trace.pairs[CENTRE_PIXEL * 3 + 2];
    assert_eq!(
        (third.test_t, third.fate),
        (t.th().min_transmittance, Fate::Blend),
        "not exactly at the stop"
    );
    // In f32: the same products, exact.
    let t2 = (1.0f32 - alphas[0]) * (1.0 - alphas[1]);
    assert_eq!(t2 * (1.0 - alphas[2]), 1e-4f32);
    let out = render(&t.b.borrowed(), &t.cam, &t.settings);
    assert!(out.impact[2] > 0.0, "the crate must blend the third layer at equality");
    let s = t.sides(Group::Textures, texel_index(2, 4, 3), 1e-7);
    assert!(s.right.abs() > 1e3 * s.left.abs(), "the right side must jump: {s:?}");
    assert_returns(&s, s.left, s.right, "transmittance stop");
}

/// Near plane on the hit depth: a horizontal plane `y = 0.2` (f32; normal (0, 1, 0) from the
/// exact quaternion `[0.5, −0.5, −0.5, −0.5]`, centre depth 0.25) seen by a camera with principal
/// point (0, 0) and `fy = 0.5`: the ray of pixel (0, 0) meets it at view depth exactly f32 `0.2`
/// (`u = 0.2 − 0.25` and `depth = u + 0.25` are exact in f32). The crate rejects only
/// `depth < 0.2`. Moving the plane up (right in `position.y`) moves the hit further; down, the
/// hit is rejected (a jump). The crate returns the **right** derivative (the accepted side).
#[test]
fn near_plane_on_the_hit_gives_the_far_side() {
    let d = 0.2f32;
    let mut b = ActivatedBillboards::empty(4);
    b.positions.push(Vec3::new(0.0, d, 0.25));
    b.quaternions.push([0.5, -0.5, -0.5, -0.5]);
    b.log_scales.push(Vec2::ZERO);
    b.sh.extend_from_slice(&[0.1f32; 48]);
    b.textures
        .extend((0..16).map(|k| [0.05 * k as f32, 0.3, 0.6, 0.3 + 0.03 * k as f32]));
    let cam = Camera {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
        fx: 0.5,
        fy: 0.5,
        cx: 0.0,
        cy: 0.0,
        width: 2,
        height: 2,
    };
    let t = Tiny {
        b,
        cam,
        settings: settings(),
        pixel: 0,
    };
    let pair = t.trace().pairs[0];
    assert_eq!(
        (pair.depth, pair.fate),
        (t.th().near, Fate::Blend),
        "not exactly at the near plane"
    );
    let out = render(&t.b.borrowed(), &t.cam, &t.settings);
    assert!(out.alpha[0] > 0.0, "the crate must accept the hit at equality");
    assert_eq!(
        out.depth[0],
        out.alpha[0] * d,
        "the crate's hit depth must be exactly 0.2"
    );
    let s = t.sides(Group::Positions, 1, 1e-7);
    assert!(s.left.abs() > 1e3 * s.right.abs(), "the near side must jump: {s:?}");
    assert_returns(&s, s.right, s.left, "near plane (hit)");
}

/// Near plane on the centre depth: a face-on billboard whose centre is at view depth exactly
/// f32 `0.2`. The crate culls `depth ≤ 0.2`, so its gradient is zero: the **left** (nearer)
/// side, where the billboard stays culled; the far side makes it appear (a jump).
#[test]
fn near_plane_on_the_centre_gives_the_near_side() {
    let mut b = ActivatedBillboards::empty(3);
    push_face_on(&mut b, Vec3::new(0.0, 0.0, 0.2), flat_alpha(0.6));
    b.log_scales[0] = Vec2::splat(0.05f32.ln());
    let t = Tiny {
        b,
        cam: centred_camera(),
        settings: settings(),
        pixel: CENTRE_PIXEL,
    };
    let trace = t.trace();
    assert!(
        !trace.visible[0] && trace.centre_depth[0] == t.th().near,
        "not exactly at the near plane"
    );
    let out = render(&t.b.borrowed(), &t.cam, &t.settings);
    assert!(!out.visible[0], "the crate must cull at equality");
    let s = t.sides(Group::Positions, 2, 1e-7);
    assert_eq!(s.left, 0.0);
    assert!(s.right.abs() > 1e3, "the far side must jump: {s:?}");
    assert_eq!(s.crate_value, 0.0);
    assert_returns(&s, s.left, s.right, "near plane (centre)");
}

/// Texel lines: alpha texels whose columns are (0.2, 0.6, 0.3) (a kink at column 1) and rows
/// (0.9, 1.0, 0.7)× (a kink at row 1). At the centre pixel `u = v = 0`, texel coordinates (1, 1)
/// exactly. The crate returns the derivative of the cell `[1, 2)` in `u` and `v`, the right
/// derivative in `u`; since `u = −x/s_u` (the pixel's ray stays put while the billboard moves),
/// that is the **left** derivative in `position.x` (and in `position.y`). At `u = 0.5` (texel
/// coordinate 1.5, the middle of a cell) both sides agree and the crate matches them.
#[test]
fn texel_centre_lines_give_the_right_derivative_in_u() {
    let texels = |k: usize| {
        let (row, col) = (k / 3, k % 3);
        let a = [0.2f32, 0.6, 0.3][col] * [0.9f32, 1.0, 0.7][row];
        [0.2 + 0.2 * col as f32, 0.7 - 0.3 * row as f32, 0.4, a]
    };
    let mut b = ActivatedBillboards::empty(3);
    push_face_on(&mut b, Vec3::new(0.0, 0.0, 2.0), std::array::from_fn(texels));
    let mut t = Tiny {
        b,
        cam: centred_camera(),
        settings: settings(),
        pixel: CENTRE_PIXEL,
    };
    let pair = t.trace().pairs[CENTRE_PIXEL];
    assert_eq!((pair.tx, pair.ty), (1.0, 1.0), "not exactly on the texel centre");
    for axis in [0, 1] {
        let s = t.sides(Group::Positions, axis, 1e-7);
        assert_returns(&s, s.left, s.right, "texel line");
    }
    // Mid-cell: smooth.
    t.b.positions[0].x = -0.5;
    let pair = t.trace().pairs[CENTRE_PIXEL];
    assert_eq!(pair.tx, 1.5, "not mid-cell");
    let s = t.sides(Group::Positions, 0, 1e-7);
    assert!(close(s.left, s.right) && close(s.crate_value, s.left), "{s:?}");
}

/// Texture-support border: the centre pixel hits `u = −2`, texel coordinate −1 (TS 3; support
/// `|u| < 1 + 2/(TS − 1) = 2`), exactly. The sampled alpha is 0 there and `0.8·(X + 1)` just
/// inside, below the 1/255 cut-off for any step under 4.9e-3: both one-sided derivatives are 0
/// and so is the crate's (it skips the pair).
#[test]
fn support_border_gives_zero_on_both_sides() {
    let mut b = ActivatedBillboards::empty(3);
    push_face_on(&mut b, Vec3::new(2.0, 0.0, 2.0), flat_alpha(0.8));
    let t = Tiny {
        b,
        cam: centred_camera(),
        settings: settings(),
        pixel: CENTRE_PIXEL,
    };
    let pair = t.trace().pairs[CENTRE_PIXEL];
    assert_eq!((pair.tx, pair.ty), (-1.0, 1.0), "not exactly on the border");
    let s = t.sides(Group::Positions, 0, 1e-7);
    assert_eq!((s.left, s.right, s.crate_value), (0.0, 0.0, 0.0));
    // Half a texel inside the border the pair is blended and has a gradient (the case is live).
    let mut inside = Tiny { b: t.b.clone(), ..t };
    inside.b.positions[0].x = 1.5;
    let s = inside.sides(Group::Positions, 0, 1e-7);
    assert!(
        s.crate_value != 0.0 && close(s.crate_value, s.left) && close(s.left, s.right),
        "{s:?}"
    );
}
