use super::*;
use crate::volume::{Grid, Volume};

#[test]
fn every_preset_validates_with_ordered_points_and_unit_opacities() {
    for p in Preset::ALL {
        for range in [(0.0, 255.0), (-1024.0, 3071.0), (0.0, 1.0)] {
            let mut tf = p.transfer_function(range);
            tf.validate().unwrap_or_else(|e| panic!("{p}: {e}"));
            for w in tf.scalar_opacity.windows(2) {
                assert!(w[0][0] <= w[1][0], "{p}: {w:?}");
            }
            for w in tf.color.windows(2) {
                assert!(w[0][0] <= w[1][0], "{p}: {w:?}");
            }
            assert!(
                tf.scalar_opacity
                    .iter()
                    .all(|q| (0.0..=1.0).contains(&q[1]))
            );
            crate::CrioTables::from_transfer_function(&tf, 256).unwrap();
        }
        assert!(!p.description().is_empty() && !p.description().contains('\n'));
        assert!(!p.units().is_empty());
    }
    assert_eq!(Preset::ALL.len(), Preset::NAMES.len());
    assert_eq!(Preset::ALL.iter().filter(|p| p.is_slicer()).count(), 31);
}

#[test]
fn names_round_trip_in_any_case_and_aliases_keep_working() {
    for (n, p) in Preset::ALL.iter().enumerate() {
        assert_eq!(p.name(), Preset::NAMES[n]);
        assert_eq!(p.to_string().parse::<Preset>().unwrap(), *p);
        assert_eq!(p.name().to_uppercase().parse::<Preset>().unwrap(), *p);
        assert_eq!(p.name().to_lowercase().parse::<Preset>().unwrap(), *p);
    }
    assert_eq!(TransferFunction::PRESETS, &Preset::NAMES[..]);
    // The names of volsplat's first presets.
    assert_eq!("ct-bone".parse::<Preset>().unwrap(), Preset::CtBone);
    assert_eq!("ct-skin".parse::<Preset>().unwrap(), Preset::CtSkin);
    assert_eq!("mr".parse::<Preset>().unwrap(), Preset::MrDefault);
    assert_eq!("ramp".parse::<Preset>().unwrap(), Preset::Ramp);
    assert_eq!(
        "ct_chest_contrast".parse::<Preset>().unwrap(),
        Preset::CtChestContrastEnhanced
    );
    assert_eq!(" CT-X-RAY ".parse::<Preset>().unwrap(), Preset::CtXRay);
    let e = "ct-bonez".parse::<Preset>().unwrap_err().to_string();
    for name in Preset::NAMES {
        assert!(e.contains(name), "{name} missing from: {e}");
    }
    assert!(
        e.contains("ct-bonez") && e.contains("mr = MR-Default"),
        "{e}"
    );
}

/// The aliases give the same functions as volsplat's presets of the same name did before
/// Slicer's were added (values copied from the earlier `TransferFunction::preset`).
#[test]
fn old_preset_names_give_the_old_functions() {
    let range = (-500.0, 900.0);
    let bone = TransferFunction::preset("ct-bone", range).unwrap();
    assert_eq!(
        bone.scalar_opacity,
        [
            [-3024.0, 0.0],
            [-16.4458, 0.0],
            [641.385, 0.715686],
            [3071.0, 0.705882]
        ]
    );
    assert_eq!(bone.color[1], [-16.4458, 0.729412, 0.254902, 0.301961]);
    assert_eq!(
        (bone.shade, bone.ambient, bone.diffuse, bone.specular),
        (true, 0.1, 0.9, 0.2)
    );
    let mr = TransferFunction::preset("mr", range).unwrap();
    assert_eq!(
        mr.scalar_opacity,
        [
            [0.0, 0.0],
            [20.0, 0.0],
            [40.0, 0.15],
            [120.0, 0.3],
            [220.0, 0.375],
            [1024.0, 0.5]
        ]
    );
    assert_eq!(mr.color[3], [120.0, 0.780392, 0.607843, 0.380392]);
    assert_eq!(
        (mr.ambient, mr.diffuse, mr.specular, mr.specular_power),
        (0.2, 1.0, 0.0, 1.0)
    );
    let skin = TransferFunction::preset("ct-skin", range).unwrap();
    assert_eq!(skin.scalar_opacity[4], [500.0, 0.6]);
    assert_eq!(skin.specular_power, 15.0);
    assert_eq!(
        TransferFunction::preset("ramp", range).unwrap(),
        TransferFunction::ramp(-500.0, 900.0, 0.5)
    );
    for tf in [&bone, &mr, &skin] {
        assert_eq!(tf.gradient_opacity, None);
        assert_eq!(tf.scalar_opacity_unit_distance, 1.0);
    }
}

/// Spot checks against `presets.xml` (values typed from the file, not from the table).
#[test]
fn control_points_match_slicer_presets_xml() {
    let tf = |p: Preset| p.transfer_function((0.0, 1.0));
    // CT-AAA: scalarOpacity="12 -3024 0 143.556 0 166.222 0.686275 ..."
    let aaa = tf(Preset::CtAaa);
    assert_eq!(aaa.scalar_opacity.len(), 6);
    assert_eq!(aaa.scalar_opacity[2], [166.222, 0.686275]);
    assert_eq!(aaa.color[5], [3071.0, 0.827451, 0.658824, 1.0]);
    // CT-Lung: colorTransfer="24 ... -530 0.134704 0.781726 0.0724558 ...", steps at -600/-599.
    let lung = tf(Preset::CtLung);
    assert_eq!(lung.color[2], [-530.0, 0.134704, 0.781726, 0.0724558]);
    assert_eq!(&lung.scalar_opacity[1..3], &[[-600.0, 0.0], [-599.0, 0.15]]);
    assert_eq!((lung.ambient, lung.diffuse, lung.specular), (0.2, 1.0, 0.0));
    // CT-Fat: 7 opacity points, 9 colours, unshaded.
    let fat = tf(Preset::CtFat);
    assert_eq!((fat.scalar_opacity.len(), fat.color.len()), (7, 9));
    assert_eq!(fat.color[8], [2952.0, 1.0, 0.300267, 0.299886]);
    assert!(!fat.shade);
    // CT-Coronary-Arteries: unshaded, last opacity point 3661 → 1.
    let cor = tf(Preset::CtCoronaryArteries);
    assert!(!cor.shade);
    assert_eq!(cor.scalar_opacity[5], [3661.0, 1.0]);
    // CT-Air: opaque air, transparent above -500.
    let air = tf(Preset::CtAir);
    assert_eq!(air.scalar_opacity[1], [-900.0, 0.715686]);
    assert_eq!(air.opacity_at(0.0), 0.0);
    // MR-T2-Brain: specular 0.5, power 40, ambient 0.3, diffuse 0.6.
    let t2 = tf(Preset::MrT2Brain);
    assert_eq!(
        (t2.ambient, t2.diffuse, t2.specular, t2.specular_power),
        (0.3, 0.6, 0.5, 40.0)
    );
    assert_eq!(t2.color[2], [412.406, 0.0, 0.592157, 0.807843]);
    // DTI-FA-Brain: "16 0 0 0 0 0.3501 0.0158 ... 0.9920 1 0.9950 0 0.9950 0".
    let fa = tf(Preset::DtiFaBrain);
    assert_eq!(fa.scalar_opacity.len(), 8);
    assert_eq!(
        &fa.scalar_opacity[5..],
        &[[0.9920, 1.0], [0.9950, 0.0], [0.9950, 0.0]]
    );
    // uCT-Bone-16bit.
    let u16b = tf(Preset::UctBone16bit);
    assert_eq!(u16b.scalar_opacity[2], [59866.8515625, 1.0]);
    // Gradient opacity: only uCT-Skull's differs from 1 at magnitudes ≥ 0.
    for p in Preset::ALL {
        assert_eq!(
            tf(p).gradient_opacity.is_some(),
            p == Preset::UctSkull,
            "{p}"
        );
    }
    let skull = tf(Preset::UctSkull).gradient_opacity.unwrap();
    assert_eq!(skull.len(), 5);
    assert_eq!(skull[2], [46.9644546508789, 0.1]);
}

#[test]
fn range_warnings_say_when_a_preset_misses_the_data() {
    assert_eq!(
        Preset::CtBone.visible_range((0.0, 1.0)),
        Some((-16.4458, f64::INFINITY))
    );
    assert_eq!(
        Preset::CtLung.visible_range((0.0, 1.0)),
        Some((-600.0, -399.0))
    );
    assert_eq!(
        Preset::CtAir.visible_range((0.0, 1.0)),
        Some((f64::NEG_INFINITY, -500.0))
    );
    assert_eq!(Preset::CtBone.range_warning((-1024.0, 3071.0)), None);
    assert_eq!(Preset::MrDefault.range_warning((0.0, 255.0)), None);
    assert_eq!(Preset::Ramp.range_warning((3.0, 7.0)), None);
    // A CT lung preset on 8-bit MR data: nothing visible.
    let w = Preset::CtLung.range_warning((0.0, 255.0)).unwrap();
    assert!(w.contains("empty") && w.contains("HU"), "{w}");
    // MR-Default on data below its first visible value.
    assert!(Preset::MrDefault.range_warning((0.0, 10.0)).is_some());
    // Data beyond the last point: a uniform block.
    let w = Preset::CtBone.range_warning((4000.0, 5000.0)).unwrap();
    assert!(w.contains("same colour"), "{w}");
}

#[test]
fn histogram_bins_integers_exactly_and_clamps() {
    let mut h = Histogram::for_scalar_type(ScalarType::U8, (0.0, 255.0)).unwrap();
    assert_eq!(h.counts().len(), 256);
    assert_eq!(h.bin_width(), 1.0);
    for v in [0.0, 1.0, 1.0, 255.0, 300.0, -5.0, f64::NAN] {
        h.add(v);
    }
    assert_eq!(h.total(), 6);
    assert_eq!(h.counts()[0], 2);
    assert_eq!(h.counts()[1], 2);
    assert_eq!(h.counts()[255], 2);
    assert_eq!(h.bin_center(1), 1.0);
    assert_eq!(h.quantile(0.5), Some(1.0));
    assert_eq!(h.quantile(1.0), Some(255.0));
    let h = Histogram::for_scalar_type(ScalarType::I16, (-32768.0, 32767.0)).unwrap();
    assert_eq!(h.counts().len(), Histogram::MAX_BINS);
    assert_eq!(h.bin_center(0), -32768.0);
    let h = Histogram::for_scalar_type(ScalarType::F32, (-1.0, 1.0)).unwrap();
    assert_eq!(h.counts().len(), Histogram::FLOAT_BINS);
    assert!(Histogram::new(1.0, 0.0, 4).is_err());
    assert!(Histogram::new(0.0, f64::INFINITY, 4).is_err());
    assert!(Histogram::new(0.0, 1.0, 0).is_err());
    let mut one = Histogram::new(5.0, 5.0, 1).unwrap();
    one.add(7.0);
    assert_eq!((one.total(), one.quantile(0.5)), (1, Some(5.0)));
    let vol = AnyVolume::from(
        Volume::from_fn(Grid::with_dims([4, 3, 2]).unwrap(), |i, j, k| {
            (i + 4 * j + 12 * k) as i16 - 10
        })
        .unwrap(),
    );
    let h = Histogram::from_volume(&vol);
    assert_eq!(h.counts().len(), 24);
    assert!(h.counts().iter().all(|&c| c == 1));
}

/// A histogram of integer values from `(value, count)` pairs.
fn hist(pairs: &[(i32, u64)]) -> Histogram {
    let lo = pairs.iter().map(|p| p.0).min().unwrap_or(0) as f64;
    let hi = pairs.iter().map(|p| p.0).max().unwrap_or(0) as f64;
    let mut h = Histogram::for_scalar_type(ScalarType::I16, (lo, hi)).unwrap();
    for &(v, n) in pairs {
        for _ in 0..n {
            h.add(v as f64);
        }
    }
    h
}

/// A bell of counts `peak·exp(−((v−mean)/sd)²/2)` over mean ± 4 sd.
fn bell(mean: i32, sd: i32, peak: f64) -> Vec<(i32, u64)> {
    (mean - 4 * sd..=mean + 4 * sd)
        .map(|v| {
            let z = (v - mean) as f64 / sd as f64;
            (v, (peak * (-0.5 * z * z).exp()).round() as u64)
        })
        .collect()
}

#[test]
fn auto_finds_background_fill_values_and_their_absence() {
    // CT-like: air around −1000, tissue around 40, some bone.
    let mut ct = bell(-1000, 20, 500.0);
    ct.extend(bell(40, 20, 400.0));
    ct.extend(bell(900, 150, 20.0));
    let a = AutoTransfer::from_histogram(&hist(&ct));
    assert_eq!((a.rule, a.fill_value), (BackgroundRule::Otsu, None));
    assert!(a.threshold > -950.0 && a.threshold < -100.0, "{a:?}");
    let tf = &a.transfer_function;
    assert_eq!(tf.opacity_at(-1000.0), 0.0);
    assert_eq!(tf.opacity_at(a.threshold), 0.0);
    assert!(tf.opacity_at(40.0) > 0.2, "{}", tf.opacity_at(40.0));
    // The same with padding at −3024 outside the field of view.
    let mut padded = ct.clone();
    padded.push((-3024, 200_000));
    let b = AutoTransfer::from_histogram(&hist(&padded));
    assert_eq!(
        (b.rule, b.fill_value),
        (BackgroundRule::Otsu, Some(-3024.0))
    );
    assert!((b.threshold - a.threshold).abs() < 50.0, "{a:?} {b:?}");
    assert_eq!(b.transfer_function.opacity_at(-1000.0), 0.0);
    // A masked object: fill value 0, then one tissue with no background of its own.
    let mut masked = bell(120, 25, 300.0);
    masked.push((0, 100_000));
    let c = AutoTransfer::from_histogram(&hist(&masked));
    assert_eq!(
        (c.rule, c.fill_value),
        (BackgroundRule::FillValue, Some(0.0)),
        "{c:?}"
    );
    assert_eq!(c.threshold, 0.5);
    assert!(c.transfer_function.opacity_at(60.0) > 0.1);
    // One tissue, no background at all: everything above the minimum is shown.
    let d = AutoTransfer::from_histogram(&hist(&bell(120, 25, 300.0)));
    assert_eq!((d.rule, d.fill_value), (BackgroundRule::None, None));
    // (the bell's lowest occupied value: counts below 31 round to zero)
    assert_eq!(d.threshold, 31.0);
    assert!(d.transfer_function.opacity_at(100.0) > 0.1);
    // A label image: 0 and one value.
    let e = AutoTransfer::from_histogram(&hist(&[(0, 1000), (7, 50)]));
    assert_eq!(e.rule, BackgroundRule::FillValue);
    assert_eq!(e.transfer_function.opacity_at(0.0), 0.0);
    assert!(e.transfer_function.opacity_at(7.0) > 0.3);
    // Degenerate: one value, or nothing.
    let f = AutoTransfer::from_histogram(&hist(&[(5, 10)]));
    assert_eq!(f.rule, BackgroundRule::Degenerate);
    let g = AutoTransfer::from_histogram(&Histogram::new(0.0, 1.0, 8).unwrap());
    assert_eq!(g.rule, BackgroundRule::Degenerate);
    for x in [&a, &b, &c, &d, &e, &f, &g] {
        x.transfer_function.clone().validate().unwrap();
        assert!(x.describe().starts_with("automatic transfer function"));
    }
    // Deterministic.
    assert_eq!(AutoTransfer::from_histogram(&hist(&padded)), b);
}

/// Rule step 4 (issue 28 §6): a binary mask's one foreground value and a label image's few
/// are opaque from halfway across the background–label step, each in its own colour; nine
/// distinct foreground values take the percentile ramp. Step 5: one value shows.
#[test]
fn masks_and_label_images_are_opaque_and_constant_data_shows() {
    let mask = AutoTransfer::from_histogram(&hist(&[(0, 50_000), (1, 4_000)]));
    assert_eq!(mask.rule, BackgroundRule::FillValue);
    assert_eq!(mask.labels, vec![1.0]);
    let tf = &mask.transfer_function;
    assert_eq!(tf.opacity_at(0.0), 0.0);
    assert_eq!(tf.opacity_at(0.5), 0.0);
    assert_eq!(tf.opacity_at(0.75), AutoTransfer::FEW_OPACITY);
    assert_eq!(tf.opacity_at(1.0), AutoTransfer::FEW_OPACITY);
    assert!(tf.opacity_at(0.6) > 0.2 && tf.opacity_at(0.6) < 0.5);
    let ivory = AutoTransfer::LABEL_COLORS[0];
    assert_eq!(tf.color_at(1.0), ivory);
    // The colour does not darken towards the background where the opacity rises.
    assert_eq!(tf.color_at(0.6), ivory);
    assert!(mask.describe().contains("1 foreground value (1) opaque"));
    // A label image: background 0 and labels 3, 5, 9 of different sizes.
    let labels = AutoTransfer::from_histogram(&hist(&[(0, 90_000), (3, 500), (5, 9_000), (9, 40)]));
    assert_eq!(labels.labels, vec![3.0, 5.0, 9.0]);
    let tf = &labels.transfer_function;
    for (n, v) in [3.0, 5.0, 9.0].into_iter().enumerate() {
        assert_eq!(tf.opacity_at(v), AutoTransfer::FEW_OPACITY);
        assert_eq!(tf.color_at(v), AutoTransfer::LABEL_COLORS[n]);
    }
    assert_eq!(tf.opacity_at(0.0), 0.0);
    // Nine foreground values: the percentile ramp, as before.
    let nine: Vec<(i32, u64)> = (0..10)
        .map(|v| (v * 10, if v == 0 { 9_000 } else { 100 }))
        .collect();
    let ramp = AutoTransfer::from_histogram(&hist(&nine));
    assert!(ramp.labels.is_empty());
    assert!(ramp.transfer_function.opacity_at(10.0) <= 0.15 + 1e-12);
    // Float masks: 4096 bins over [0, 1]; the value 1 lies beyond the last bin's centre.
    let mut h = Histogram::for_scalar_type(ScalarType::F32, (0.0, 1.0)).unwrap();
    for n in 0..10_000 {
        h.add(if n % 5 == 0 { 1.0 } else { 0.0 });
    }
    let f = AutoTransfer::from_histogram(&h);
    assert_eq!(f.labels.len(), 1);
    assert_eq!(
        f.transfer_function.opacity_at(1.0),
        AutoTransfer::FEW_OPACITY
    );
    assert_eq!(f.transfer_function.opacity_at(0.0), 0.0);
    // One value (constant data): opacity 0.5 at it, white; the empty histogram as before.
    let one = AutoTransfer::from_histogram(&hist(&[(40, 1000)]));
    assert_eq!(one.rule, BackgroundRule::Degenerate);
    assert_eq!(one.transfer_function.opacity_at(40.0), 0.5);
    assert_eq!(one.transfer_function.color_at(40.0), [1.0; 3]);
    let empty = AutoTransfer::from_histogram(&Histogram::new(0.0, 1.0, 8).unwrap());
    assert_eq!(
        empty.transfer_function,
        Preset::Ramp.transfer_function((0.0, 1.0))
    );
    for x in [&mask, &labels, &ramp, &f, &one, &empty] {
        x.transfer_function.clone().validate().unwrap();
    }
}

#[test]
fn auto_from_volume_uses_the_smallest_spacing_as_unit_distance() {
    let mut grid = Grid::with_dims([8, 8, 8]).unwrap();
    grid.spacing = [0.5, 0.25, 2.0];
    let vol = Volume::from_fn(grid, |i, j, k| {
        if (3..5).contains(&i) && (3..5).contains(&j) && (3..5).contains(&k) {
            200u8
        } else {
            (i + j + k) as u8 % 3
        }
    })
    .unwrap();
    let vol = AnyVolume::from(vol);
    let tf = TransferFunction::auto_from_volume(&vol);
    assert_eq!(tf.scalar_opacity_unit_distance, 0.25);
    assert_eq!(tf.opacity_at(2.0), 0.0);
    assert!(tf.opacity_at(200.0) > 0.3);
    let h = Histogram::from_volume(&vol);
    assert_eq!(
        TransferFunction::auto_from_histogram(&h).scalar_opacity,
        tf.scalar_opacity
    );
}
