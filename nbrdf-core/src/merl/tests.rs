//! The table's tests: file round trips and rejections, the grid's indices and angles, lookups
//! against closed forms, and the symmetries of the folds.

use super::*;
use crate::coords::{self, spherical_direction};
use crate::error::NbrdfError;
use proptest::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};

/// A table whose stored value is `f(channel, i_theta_h, i_theta_d, i_phi_d)`.
fn table_from(f: impl Fn(usize, usize, usize, usize) -> f64) -> MerlTable {
    let mut stored = vec![0.0; 3 * CELLS];
    for (k, s) in stored.iter_mut().enumerate() {
        let (h, d, p) = cell_coordinates(k % CELLS);
        *s = f(k / CELLS, h, d, p);
    }
    MerlTable::from_stored(stored).expect("test table is valid")
}

/// Irregular but deterministic values, so no interpolation can be right by accident.
fn hashed(c: usize, h: usize, d: usize, p: usize) -> f64 {
    let x = (c * 7919 + h * 104_729 + d * 1_299_709 + p * 15_485_863) as u64;
    ((x.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) % 1000) as f64 + 1.0
}

/// Stored value of a cell, scaled to reflectance.
fn refl(t: &MerlTable, c: usize, h: usize, d: usize, p: usize) -> f64 {
    t.stored()[c * CELLS + cell_index(h, d, p)] * SCALE[c]
}

fn temp_path(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("nbrdf-merl-test-{}-{name}", std::process::id()))
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()))
}

#[test]
fn cell_index_layout() {
    assert_eq!(cell_index(0, 0, 1), 1);
    assert_eq!(cell_index(0, 1, 0), 180);
    assert_eq!(cell_index(1, 0, 0), 16_200);
    assert_eq!(cell_index(89, 89, 179), CELLS - 1);
    assert_eq!(cell_coordinates(cell_index(12, 34, 56)), (12, 34, 56));
    assert_eq!(FILE_SIZE, 34_992_012);
}

#[test]
fn index_maps_match_the_format() {
    let a = RusinkiewiczAngles {
        theta_h: PI / 8.0,
        phi_h: 0.3,
        theta_d: PI / 4.0,
        phi_d: PI / 2.0,
    };
    let i = continuous_index(&a);
    // theta_h: 90 sqrt((pi/8) / (pi/2)) = 90 * 0.5.
    assert!(
        close(i[0], 45.0) && close(i[1], 45.0) && close(i[2], 90.0),
        "{i:?}"
    );
    let fold = |phi_d| continuous_index(&RusinkiewiczAngles { phi_d, ..a })[2];
    assert!(close(fold(-PI / 4.0), 135.0));
    assert_eq!(fold(0.0), 0.0);
    assert_eq!(fold(PI), 0.0);
    assert!(close(fold(1.5 * PI), 90.0));
    assert!(close(fold(-3.0 * PI + 0.1), 18.0 / PI * 0.1 * 10.0));
    let c = cell_centre_angles(0, 0, 0);
    assert!(close(c.theta_h, (0.5f64 / 90.0).powi(2) * FRAC_PI_2));
    assert!(close(c.theta_d, 0.5 / 90.0 * FRAC_PI_2));
    assert!(close(c.phi_d, 0.5 / 180.0 * PI));
    assert_eq!(c.phi_h, 0.0);
}

proptest! {
    #[test]
    fn centre_angles_invert_the_index_maps(h in 0usize..90, d in 0usize..90, p in 0usize..180) {
        let i = continuous_index(&cell_centre_angles(h, d, p));
        prop_assert!(close(i[0], h as f64 + 0.5) && close(i[1], d as f64 + 0.5));
        prop_assert!(close(i[2], p as f64 + 0.5), "{i:?}");
    }
}

#[test]
fn write_read_round_trip_is_bit_exact() {
    let mut stored: Vec<f64> = (0..3 * CELLS)
        .map(|k| hashed(k % 3, k, k / 7, k / 13) / 3.0)
        .collect();
    // Markers and awkward values must survive too.
    stored[0] = NOT_MEASURED;
    stored[1] = -0.0;
    stored[2] = f64::MIN_POSITIVE / 4.0;
    // Large but still finite once scaled to the float32 range the table renders in.
    stored[3 * CELLS - 1] = 1e36;
    let table = MerlTable::from_stored(stored).unwrap();
    let bytes = table.to_bytes();
    assert_eq!(bytes.len(), FILE_SIZE);
    assert_eq!(&bytes[..12], &[90, 0, 0, 0, 90, 0, 0, 0, 180, 0, 0, 0]);
    assert_eq!(&bytes[12..20], &NOT_MEASURED.to_le_bytes());
    let path = temp_path("roundtrip.binary");
    table.write(&path).unwrap();
    let back = MerlTable::read(&path);
    let _ = std::fs::remove_file(&path);
    let back = back.unwrap();
    assert!(table
        .stored()
        .iter()
        .zip(back.stored())
        .all(|(a, b)| a.to_bits() == b.to_bits()));
}

/// Writes `bytes` to a temp file, reads it, returns the error message.
fn read_error(name: &str, bytes: &[u8]) -> String {
    let path = temp_path(name);
    std::fs::write(&path, bytes).unwrap();
    let result = MerlTable::read(&path);
    let _ = std::fs::remove_file(&path);
    let err = result.expect_err("must be rejected");
    assert!(matches!(err, NbrdfError::Format { .. }), "{err:?}");
    let message = err.to_string();
    assert!(
        message.contains(name),
        "message must name the file: {message}"
    );
    message
}

#[test]
fn malformed_files_are_rejected_with_the_file_named() {
    let good = shared_table().to_bytes();
    let m = read_error("truncated.binary", &good[..1234]);
    assert!(
        m.contains("truncated: 1234 bytes, a MERL table has 34992012"),
        "{m}"
    );
    let m = read_error("tiny.binary", &good[..5]);
    assert!(m.contains("truncated: 5 bytes"), "{m}");
    let m = read_error("short-by-one.binary", &good[..FILE_SIZE - 1]);
    assert!(m.contains("truncated: 34992011 bytes"), "{m}");
    let mut long = good.clone();
    long.extend_from_slice(&[0; 8]);
    let m = read_error("long.binary", &long);
    assert!(
        m.contains("34992020 bytes") && m.contains("exactly 34992012"),
        "{m}"
    );
    let mut header = good.clone();
    header[8..12].copy_from_slice(&360i32.to_le_bytes());
    let m = read_error("header.binary", &header);
    assert!(m.contains("header is (90, 90, 360)"), "{m}");
    let mut nan = good.clone();
    let at = 12 + 8 * (CELLS + cell_index(1, 2, 3));
    nan[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    let m = read_error("nan.binary", &nan);
    assert!(
        m.contains("NaN") && m.contains("green") && m.contains("theta_h 1, theta_d 2, phi_d 3"),
        "{m}"
    );
    let mut inf = good;
    inf[12..20].copy_from_slice(&f64::NEG_INFINITY.to_le_bytes());
    assert!(read_error("inf.binary", &inf).contains("-inf"));
}

#[test]
fn missing_file_is_an_io_error_naming_it() {
    let path = temp_path("does-not-exist.binary");
    let err = MerlTable::read(&path).unwrap_err();
    assert!(matches!(err, NbrdfError::Io { .. }));
    assert!(err.to_string().contains("does-not-exist.binary"));
}

#[test]
fn from_stored_validates() {
    assert!(MerlTable::from_stored(vec![0.0; 10]).is_err());
    let mut v = vec![0.0; 3 * CELLS];
    v[17] = f64::NAN;
    assert!(matches!(
        MerlTable::from_stored(v),
        Err(NbrdfError::InvalidArgument(_))
    ));
}

#[test]
fn lookups_at_cell_centres_return_stored_values() {
    let t = shared_table();
    for (h, d, p) in [
        (0, 0, 0),
        (89, 89, 179),
        (0, 89, 90),
        (45, 12, 179),
        (17, 60, 1),
        (89, 0, 0),
    ] {
        let a = cell_centre_angles(h, d, p);
        let expect: [f64; 3] = std::array::from_fn(|c| refl(t, c, h, d, p));
        assert_eq!(t.lookup(&a, Interpolation::Nearest), expect);
        let tri = t.lookup(&a, Interpolation::Trilinear);
        assert!(
            (0..3).all(|c| close(tri[c], expect[c])),
            "{h} {d} {p}: {tri:?} vs {expect:?}"
        );
    }
}

#[test]
fn nearest_floors_the_continuous_index() {
    let t = shared_table();
    let a = angles_at_index([10.99, 20.01, 30.7]);
    assert_eq!(
        t.lookup(&a, Interpolation::Nearest)[1],
        refl(t, 1, 10, 20, 30)
    );
    // Beyond the theta range: clamped to the last cell.
    let a = RusinkiewiczAngles {
        theta_h: 2.0,
        phi_h: 0.0,
        theta_d: 3.0,
        phi_d: 0.1,
    };
    assert_eq!(
        t.lookup(&a, Interpolation::Nearest)[0],
        refl(t, 0, 89, 89, 5)
    );
}

#[test]
fn trilinear_blends_linearly_between_centres() {
    let t = shared_table();
    // Along phi_d: continuous index 30.75 is a quarter of the way from centre 30 to 31.
    let a = angles_at_index([10.5, 20.5, 30.75]);
    let expect = 0.75 * refl(t, 2, 10, 20, 30) + 0.25 * refl(t, 2, 10, 20, 31);
    assert!(close(t.lookup(&a, Interpolation::Trilinear)[2], expect));
    // Along all three axes at once: the full trilinear formula, written out.
    let a = angles_at_index([10.8, 20.6, 30.9]);
    let (wh, wd, wp) = (0.3, 0.1, 0.4);
    let mut expect = 0.0;
    for (h, fh) in [(10, 1.0 - wh), (11, wh)] {
        for (d, fd) in [(20, 1.0 - wd), (21, wd)] {
            for (p, fp) in [(30, 1.0 - wp), (31, wp)] {
                expect += fh * fd * fp * refl(t, 0, h, d, p);
            }
        }
    }
    assert!(close(t.lookup(&a, Interpolation::Trilinear)[0], expect));
}

#[test]
fn trilinear_reproduces_a_linear_field() {
    // A field linear in the cell indices is reproduced exactly away from the borders.
    let t =
        &table_from(|c, h, d, p| 1.0 + c as f64 + 2.0 * h as f64 + 3.0 * d as f64 + 0.5 * p as f64);
    for idx in [[3.2, 4.7, 5.9], [70.1, 0.6, 178.2], [88.4, 88.9, 1.0]] {
        let got = t.lookup(&angles_at_index(idx), Interpolation::Trilinear)[1];
        let t_idx = idx.map(|x| x - 0.5);
        let expect = (2.0 + 2.0 * t_idx[0] + 3.0 * t_idx[1] + 0.5 * t_idx[2]) * SCALE[1];
        assert!(close(got, expect), "{idx:?}: {got} vs {expect}");
    }
}

#[test]
fn trilinear_clamps_at_theta_borders() {
    let t = shared_table();
    // theta_h index 0.2 is before the first centre: clamped onto it.
    let got = t.lookup(
        &angles_at_index([0.2, 89.9, 40.5]),
        Interpolation::Trilinear,
    );
    assert!(close(got[0], refl(t, 0, 0, 89, 40)));
    let a = RusinkiewiczAngles {
        theta_h: 1.7,
        phi_h: 0.0,
        theta_d: 1.6,
        phi_d: PI * 40.5 / 180.0,
    };
    assert!(close(
        t.lookup(&a, Interpolation::Trilinear)[2],
        refl(t, 2, 89, 89, 40)
    ));
}

#[test]
fn trilinear_wraps_in_phi_d() {
    let t = shared_table();
    // Continuous index 0.2 (t = -0.3): 0.3 of centre 179 and 0.7 of centre 0.
    let expect = 0.3 * refl(t, 0, 5, 6, 179) + 0.7 * refl(t, 0, 5, 6, 0);
    let got = t.lookup(&angles_at_index([5.5, 6.5, 0.2]), Interpolation::Trilinear)[0];
    assert!(close(got, expect), "{got} vs {expect}");
    // Continuous index 179.8 (t = 179.3): 0.7 of centre 179 and 0.3 of centre 0.
    let expect = 0.7 * refl(t, 0, 5, 6, 179) + 0.3 * refl(t, 0, 5, 6, 0);
    let got = t.lookup(
        &angles_at_index([5.5, 6.5, 179.8]),
        Interpolation::Trilinear,
    )[0];
    assert!(close(got, expect));
    // phi_d just below 0 folds to just below pi: the same point as index 179.8.
    let mut a = angles_at_index([5.5, 6.5, 179.8]);
    a.phi_d -= PI;
    assert!(close(t.lookup(&a, Interpolation::Trilinear)[0], expect));
}

#[test]
fn mirror_fold_reflects_phi_d_and_clamps() {
    let t = shared_table().clone().with_phi_fold(PhiFold::Mirror);
    assert_eq!(t.phi_fold(), PhiFold::Mirror);
    // Stored centres come back as they are, whatever the fold.
    let centre = cell_centre_angles(5, 6, 40);
    assert!(close(
        t.lookup(&centre, Interpolation::Trilinear)[1],
        refl(&t, 1, 5, 6, 40)
    ));
    // phi_d + pi is the mirror image of pi - phi_d (cell 139), not cell 40 as by reciprocity.
    let swapped = RusinkiewiczAngles {
        phi_d: centre.phi_d + PI,
        ..centre
    };
    for interpolation in [Interpolation::Nearest, Interpolation::Trilinear] {
        let got = t.lookup(&swapped, interpolation)[1];
        assert!(close(got, refl(&t, 1, 5, 6, 139)), "{got}");
        let negative = RusinkiewiczAngles {
            phi_d: -centre.phi_d,
            ..centre
        };
        assert!(close(
            t.lookup(&negative, interpolation)[1],
            refl(&t, 1, 5, 6, 40)
        ));
    }
    // Near the mirror planes 0 and pi the lookup clamps instead of wrapping around.
    for (index, cell) in [(0.2, 0), (179.8, 179)] {
        let got = t.lookup(
            &angles_at_index([5.5, 6.5, index]),
            Interpolation::Trilinear,
        )[0];
        assert!(close(got, refl(&t, 0, 5, 6, cell)), "{index}: {got}");
    }
    let i = continuous_index_folded(
        &RusinkiewiczAngles {
            phi_d: 1.5 * PI,
            ..centre
        },
        PhiFold::Mirror,
    );
    assert!(close(i[2], 90.0), "{i:?}");
    // lookup_valid folds the same way.
    assert_eq!(
        t.lookup_valid(&swapped),
        Some(t.lookup(&swapped, Interpolation::Trilinear))
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn mirror_fold_is_mirror_symmetric_and_rotation_invariant(
        tl in 0.0..FRAC_PI_2, pl in -PI..PI, tv in 0.0..FRAC_PI_2, pv in -PI..PI
    ) {
        let t = shared_table().clone().with_phi_fold(PhiFold::Mirror);
        let (l, v) = (spherical_direction(tl, pl), spherical_direction(tv, pv));
        let flip = DVec3::new(1.0, -1.0, 1.0);
        let a = t.eval_f64(v, l, Interpolation::Trilinear);
        let b = t.eval_f64(v * flip, l * flip, Interpolation::Trilinear);
        let rot = glam::DMat3::from_rotation_z(0.77);
        let c = t.eval_f64(rot * v, rot * l, Interpolation::Trilinear);
        prop_assert!((0..3).all(|k| (a[k] - b[k]).abs() <= 1e-6 * (1.0 + a[k])), "{a:?} vs {b:?}");
        prop_assert!((0..3).all(|k| (a[k] - c[k]).abs() <= 1e-6 * (1.0 + a[k])), "{a:?} vs {c:?}");
    }
}

#[test]
fn invalid_neighbours_are_left_out() {
    let t = &table_from(|c, h, d, p| match (h, d, p) {
        (10, 20, 31) => NOT_MEASURED,
        (10, 21, 30) if c == 2 => NOT_MEASURED, // one channel is enough to invalidate
        (40, _, _) => NOT_MEASURED,
        _ => hashed(c, h, d, p),
    });
    assert_eq!(t.cell(cell_index(10, 20, 31)), None);
    assert_eq!(t.cell(cell_index(10, 21, 30)), None);
    assert_eq!(t.cell(CELLS), None);
    // Two corners along phi_d, one of them invalid: the valid one alone.
    let got = t.lookup(
        &angles_at_index([10.5, 20.5, 30.75]),
        Interpolation::Trilinear,
    );
    assert!(close(got[0], refl(t, 0, 10, 20, 30)));
    // Four corners in (theta_d, phi_d), two invalid: the other two, renormalised.
    let got = t.lookup(
        &angles_at_index([10.5, 20.75, 30.6]),
        Interpolation::Trilinear,
    )[1];
    let (w_a, w_b) = (0.75 * 0.9, 0.25 * 0.1); // (20, 30) and (21, 31)
    let expect = (w_a * refl(t, 1, 10, 20, 30) + w_b * refl(t, 1, 10, 21, 31)) / (w_a + w_b);
    assert!(close(got, expect), "{got} vs {expect}");
    // Every weighted corner invalid: 0; nearest on an invalid cell: 0.
    assert_eq!(
        t.lookup(&angles_at_index([40.5, 3.3, 7.7]), Interpolation::Trilinear),
        [0.0; 3]
    );
    assert_eq!(
        t.lookup(&angles_at_index([10.5, 20.5, 31.2]), Interpolation::Nearest),
        [0.0; 3]
    );
    // Exactly on an invalid centre: zero-weight valid neighbours do not count.
    assert_eq!(
        t.lookup(
            &angles_at_index([40.5, 20.5, 31.5]),
            Interpolation::Trilinear
        ),
        [0.0; 3]
    );
}

#[test]
fn eval_is_zero_below_the_horizon_and_total() {
    let t = shared_table();
    let up = spherical_direction(0.4, 0.3);
    let cases = [
        (DVec3::new(1.0, 0.0, 0.0), up),
        (up, DVec3::new(0.3, 0.1, -0.2)),
        (DVec3::new(0.0, 0.0, -1.0), up),
        (DVec3::ZERO, up),
        (up, DVec3::new(f64::NAN, 0.0, 1.0)),
        (DVec3::new(f64::INFINITY, 0.0, 1.0), up),
    ];
    for (l, v) in cases {
        assert_eq!(
            t.eval_f64(v, l, Interpolation::Trilinear),
            [0.0; 3],
            "{l} {v}"
        );
        assert_eq!(t.eval_f64(v, l, Interpolation::Nearest), [0.0; 3]);
        assert_eq!(t.eval(v.as_vec3(), l.as_vec3()), [0.0; 3]);
    }
    // Grazing but above, and l = v (phi_d undefined): finite.
    for (l, v) in [
        (DVec3::new(1.0, 0.0, 1e-12), up),
        (up, up),
        (DVec3::Z, DVec3::Z),
    ] {
        let f = t.eval_f64(v, l, Interpolation::Trilinear);
        assert!(f.iter().all(|x| x.is_finite() && *x >= 0.0));
    }
    // Non-unit input: the same as unit input.
    for (l, v) in [
        (DVec3::new(1.0, 0.0, 1e-3), up),
        (up, spherical_direction(1.0, -2.0)),
    ] {
        let (a, b) = (
            t.eval_f64(0.5 * v, 3.0 * l, Interpolation::Trilinear),
            t.eval_f64(v, l, Interpolation::Trilinear),
        );
        assert!((0..3).all(|c| close(a[c], b[c])), "{a:?} vs {b:?}");
    }
}

#[test]
fn eval_matches_lookup_of_the_angles() {
    let t = shared_table();
    let (l, v) = (spherical_direction(0.5, 0.2), spherical_direction(1.1, 2.9));
    let a = coords::to_rusinkiewicz(v, l);
    for mode in [Interpolation::Nearest, Interpolation::Trilinear] {
        assert_eq!(t.eval_f64(v, l, mode), t.lookup(&a, mode));
    }
    // Rotating both directions about the normal changes nothing for an isotropic table.
    let rot = glam::DMat3::from_rotation_z(1.234);
    let a = t.eval_f64(v, l, Interpolation::Trilinear);
    let b = t.eval_f64(rot * v, rot * l, Interpolation::Trilinear);
    assert!((0..3).all(|c| close(a[c], b[c])));
}

#[test]
fn nearest_is_reciprocal_on_generic_directions() {
    let t = shared_table();
    for (tl, pl, tv, pv) in [
        (0.3, 0.1, 1.2, 2.0),
        (1.4, -2.0, 0.2, 0.5),
        (0.9, 3.0, 0.7, -1.0),
    ] {
        let (l, v) = (spherical_direction(tl, pl), spherical_direction(tv, pv));
        assert_eq!(
            t.eval_f64(v, l, Interpolation::Nearest),
            t.eval_f64(l, v, Interpolation::Nearest)
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn trilinear_is_reciprocal_and_finite(
        tl in 0.0..FRAC_PI_2, pl in -PI..PI, tv in 0.0..FRAC_PI_2, pv in -PI..PI
    ) {
        let t = shared_table();
        let (l, v) = (spherical_direction(tl, pl), spherical_direction(tv, pv));
        let a = t.eval_f64(v, l, Interpolation::Trilinear);
        let b = t.eval_f64(l, v, Interpolation::Trilinear);
        prop_assert!((0..3).all(|c| close(a[c], b[c])), "{a:?} vs {b:?}");
        prop_assert!(a.iter().all(|x| x.is_finite() && *x >= 0.0));
    }
}

/// One table for the property tests, built once.
fn shared_table() -> &'static MerlTable {
    static TABLE: std::sync::OnceLock<MerlTable> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| table_from(hashed))
}

#[test]
fn batch_matches_single_evaluation() {
    let t = shared_table();
    let n = 3000;
    let mut light = vec![0.0f32; 3 * n];
    let mut view = vec![0.0f32; 3 * n];
    for i in 0..n {
        let l = spherical_direction(1.7 * (i as f64 / n as f64) - 0.05, i as f64);
        let v = spherical_direction(1.5 * ((i * 7 % n) as f64 / n as f64), -(i as f64) * 0.3);
        for k in 0..3 {
            light[k * n + i] = l[k] as f32;
            view[k * n + i] = v[k] as f32;
        }
    }
    let mut out = vec![-1.0f32; 3 * n];
    t.eval_cos_batch(
        Directions::from_planar(&view).unwrap(),
        Directions::from_planar(&light).unwrap(),
        RgbMut::from_planar(&mut out).unwrap(),
    );
    for i in 0..n {
        let (l, v) = (
            Vec3::new(light[i], light[n + i], light[2 * n + i]),
            Vec3::new(view[i], view[n + i], view[2 * n + i]),
        );
        let f = t.eval(v, l);
        let cos = crate::brdf::cos_theta_light(l);
        for c in 0..3 {
            let expect = f[c] * cos;
            assert!(
                (out[c * n + i] - expect).abs() <= 1e-6 * (1.0 + expect.abs()),
                "{i} {c}"
            );
        }
    }
    // Mismatched lengths: the common prefix only, no panic.
    let mut short = vec![7.0f32; 3 * 10];
    let before = short.clone();
    let out = RgbMut::from_planar(&mut short).unwrap();
    t.eval_cos_batch(
        Directions::from_planar(&view).unwrap(),
        Directions::from_planar(&light[..3 * 4]).unwrap(),
        out,
    );
    assert_eq!(&short[4..10], &before[4..10]);
}

#[test]
fn tabulate_stores_scaled_values_at_cell_centres() {
    let t = MerlTable::tabulate(|a| {
        if a.theta_d > 1.5 {
            [f64::NAN, 1.0, -2.0]
        } else {
            [a.theta_h, a.theta_d, a.phi_d]
        }
    });
    for (h, d, p) in [(0, 0, 0), (89, 10, 179), (33, 44, 55)] {
        let a = cell_centre_angles(h, d, p);
        let i = cell_index(h, d, p);
        assert_eq!(t.stored()[i], a.theta_h / SCALE[0]);
        assert_eq!(t.stored()[CELLS + i], a.theta_d / SCALE[1]);
        assert_eq!(t.stored()[2 * CELLS + i], a.phi_d / SCALE[2]);
    }
    // theta_d index 86 is the first centre past 1.5 rad.
    let i = cell_index(3, 86, 4);
    assert_eq!(
        [
            t.stored()[i],
            t.stored()[CELLS + i],
            t.stored()[2 * CELLS + i]
        ],
        [NOT_MEASURED, 1.0 / SCALE[1], 0.0]
    );
    let stats = t.stats();
    assert_eq!(stats.invalid_cells, 90 * 4 * 180);
    assert_eq!(stats.valid_cells, CELLS - 90 * 4 * 180);
}

#[test]
fn stats_of_a_known_table() {
    let t = &table_from(|c, h, _, _| {
        if h == 0 {
            NOT_MEASURED
        } else {
            (c + 1) as f64 * if h == 1 { 2.0 } else { 1.0 }
        }
    });
    let s = t.stats();
    assert_eq!(s.invalid_cells, 90 * 180);
    assert_eq!(s.valid_cells, 89 * 90 * 180);
    assert!(close(s.min[2], 3.0 * SCALE[2]) && close(s.max[2], 6.0 * SCALE[2]));
    assert!(close(s.mean[0], (88.0 + 2.0) / 89.0 * SCALE[0]));
}
