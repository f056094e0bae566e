//! The compositing protocol on in-process ranks: the same bits for any number of ranks, the
//! right visibility order, empty bricks skipped exactly, and a failing rank reported by all.

use super::*;

const W: usize = 13;
const H: usize = 11;

/// A deterministic partial image for brick `b`: premultiplied RGBA with opacity in [0, 0.9],
/// or, for MIP/MinIP, NaN on about a fifth of the pixels; `None` for every fourth brick when
/// `empties` (a brick with nothing visible).
fn brick_image(b: usize, combine: Combine, empties: bool) -> Option<Pixels> {
    if empties && b % 4 == 3 {
        return None;
    }
    let mut seed = 0x9e37_79b9_7f4a_7c15u64 ^ (b as u64 + 1).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    Some(
        (0..W * H)
            .map(|_| {
                let a = 0.9 * next();
                let c = [next() * a, next() * a, next() * a, a];
                match combine {
                    Combine::Max | Combine::Min if next() < 0.2 => [f32::NAN; 4],
                    _ => c,
                }
            })
            .collect(),
    )
}

fn run(
    n: usize,
    tree: &BrickTree,
    eye: Eye,
    combine: Combine,
    empties: bool,
) -> Vec<Result<Option<Pixels>>> {
    FakeCluster { size: n }.run(|comm| {
        let (a, b) = tree.rank_leaves(comm.rank(), comm.size());
        let mine: Vec<usize> = tree.leaves[a..b].to_vec();
        composite_direct_send(comm, tree, eye, combine, (W, H), &mut |brick| {
            assert!(
                mine.contains(&brick),
                "rank {} rendered brick {brick}",
                comm.rank()
            );
            Ok(brick_image(brick, combine, empties))
        })
    })
}

fn bits(p: &Pixels) -> Vec<u32> {
    p.iter().flatten().map(|v| v.to_bits()).collect()
}

#[test]
fn the_image_is_the_same_bits_for_any_number_of_ranks() {
    let tree = BrickTree::new([3, 2, 2], 16).unwrap();
    let eyes = [
        Eye::Direction([0.3, -0.8, 0.5]),
        Eye::Direction([-1.0, 0.1, -0.2]),
        Eye::Point([20.0, 70.0, -30.0]),
        Eye::Point([40.0, 10.0, 20.0]),
    ];
    for combine in [Combine::Over, Combine::Max, Combine::Min, Combine::Sum] {
        for eye in eyes {
            for empties in [false, true] {
                let one = run(1, &tree, eye, combine, empties)
                    .remove(0)
                    .unwrap()
                    .unwrap();
                assert_eq!(one.len(), W * H);
                for n in 2..=5 {
                    let out = run(n, &tree, eye, combine, empties);
                    let (first, rest) = out.split_first().unwrap();
                    let image = first.as_ref().unwrap().as_ref().unwrap();
                    assert_eq!(bits(image), bits(&one), "{combine:?} {eye:?} n={n}");
                    for r in rest {
                        assert!(r.as_ref().unwrap().is_none(), "only rank 0 has the image");
                    }
                }
            }
        }
    }
}

/// Along a row of bricks seen along ±x, the tree must composite in brick order (or reversed):
/// equal, to rounding, to folding the bricks front to back one by one, and far from the wrong
/// order.
#[test]
fn bricks_meet_in_visibility_order() {
    let tree = BrickTree::new([5, 1, 1], 8).unwrap();
    let fold = |order: &mut dyn Iterator<Item = usize>| {
        let mut acc = vec![[0.0f32; 4]; W * H];
        for b in order {
            let img = brick_image(b, Combine::Over, false).unwrap();
            for (a, p) in acc.iter_mut().zip(&img) {
                *a = Combine::Over.apply(*a, *p);
            }
        }
        acc
    };
    let max_diff = |a: &Pixels, b: &Pixels| {
        a.iter()
            .flatten()
            .zip(b.iter().flatten())
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    for (eye, order) in [
        (Eye::Direction([1.0, 0.2, 0.1]), (0..5).collect::<Vec<_>>()),
        (Eye::Direction([-1.0, 0.2, 0.1]), (0..5).rev().collect()),
        (Eye::Point([-10.0, 4.0, 4.0]), (0..5).collect()),
        (Eye::Point([100.0, 4.0, 4.0]), (0..5).rev().collect()),
    ] {
        for n in [1, 2, 3] {
            let img = run(n, &tree, eye, Combine::Over, false)
                .remove(0)
                .unwrap()
                .unwrap();
            let right = fold(&mut order.iter().copied());
            let wrong = fold(&mut order.iter().rev().copied());
            assert!(max_diff(&img, &right) < 1e-5, "{eye:?} n={n}");
            assert!(max_diff(&img, &wrong) > 1e-2, "{eye:?} n={n}");
        }
    }
}

/// An eye between the bricks: the bricks on each side are composited towards it, so neither
/// brick order alone is right (checked against a fold in the order the eye sees them).
#[test]
fn an_eye_inside_the_grid_sees_both_sides_towards_it() {
    let tree = BrickTree::new([4, 1, 1], 8).unwrap();
    // The eye at x = 12 (inside brick 1): brick 1, then 0 and 2 (either order between them
    // on one ray is impossible: they lie on opposite sides), then 3. Per the tree: the split at
    // 16 puts {0, 1} in front of {2, 3}; inside {0, 1}, the split at 8 puts 1 in front of 0.
    let img = run(2, &tree, Eye::Point([12.0, 4.0, 4.0]), Combine::Over, false)
        .remove(0)
        .unwrap()
        .unwrap();
    let mut acc = vec![[0.0f32; 4]; W * H];
    for b in [1, 0, 2, 3] {
        for (a, p) in acc
            .iter_mut()
            .zip(&brick_image(b, Combine::Over, false).unwrap())
        {
            *a = Combine::Over.apply(*a, *p);
        }
    }
    let d = img
        .iter()
        .flatten()
        .zip(acc.iter().flatten())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    assert!(d < 1e-5, "{d}");
}

/// Leaving an empty brick out is exact: the same bits as compositing a transparent image.
#[test]
fn empty_bricks_are_skipped_exactly() {
    let tree = BrickTree::new([2, 2, 2], 8).unwrap();
    let eye = Eye::Direction([0.4, 0.5, -0.7]);
    for combine in [Combine::Over, Combine::Max, Combine::Sum] {
        let skipped = run(3, &tree, eye, combine, true)
            .remove(0)
            .unwrap()
            .unwrap();
        let zeros = FakeCluster { size: 3 }
            .run(|comm| {
                composite_direct_send(comm, &tree, eye, combine, (W, H), &mut |b| {
                    Ok(Some(
                        brick_image(b, combine, true)
                            .unwrap_or_else(|| vec![combine.empty(); W * H]),
                    ))
                })
            })
            .remove(0)
            .unwrap()
            .unwrap();
        assert_eq!(bits(&skipped), bits(&zeros), "{combine:?}");
    }
    // Nothing visible anywhere: the empty image.
    let none = FakeCluster { size: 2 }
        .run(|comm| {
            composite_direct_send(comm, &tree, eye, Combine::Over, (W, H), &mut |_| Ok(None))
        })
        .remove(0)
        .unwrap()
        .unwrap();
    assert!(none.iter().all(|p| *p == [0.0; 4]));
}

/// A rank whose brick fails: every rank returns the error, naming that rank and brick, and
/// none waits for the others (the test would hang).
#[test]
fn a_failing_rank_stops_every_rank_with_its_error() {
    let tree = BrickTree::new([3, 3, 1], 8).unwrap();
    let bad = tree.leaves[5];
    for n in [1, 2, 4] {
        let out = FakeCluster { size: n }.run(|comm| {
            composite_direct_send(
                comm,
                &tree,
                Eye::Direction([0.0, 0.0, 1.0]),
                Combine::Over,
                (W, H),
                &mut |b| {
                    if b == bad {
                        Err(DistributedError::Brick {
                            brick: b,
                            why: "chunk 3/1/0: unexpected end of file".into(),
                        })
                    } else {
                        Ok(brick_image(b, Combine::Over, false))
                    }
                },
            )
        });
        let owner = (0..n)
            .find(|&r| {
                let (a, b) = tree.rank_leaves(r, n);
                tree.leaves[a..b].contains(&bad)
            })
            .unwrap();
        for r in out {
            let e = r.unwrap_err().to_string();
            assert!(
                e.contains(&format!("rank {owner} failed"))
                    && e.contains(&format!("brick {bad}"))
                    && e.contains("unexpected end of file"),
                "n={n}: {e}"
            );
        }
    }
}

#[test]
fn stripes_cover_the_rows_once() {
    for h in [1, 7, 64] {
        for n in 1..=9 {
            let mut rows = Vec::new();
            for s in 0..n {
                let (a, b) = stripe_rows(s, n, h);
                rows.extend(a..b);
            }
            assert_eq!(rows, (0..h).collect::<Vec<_>>());
        }
    }
}

/// End to end in one process: the image-aligned slabs render each brick's partial image from
/// the whole volume with only the brick's cells drawn ([`volsplat_splat::RenderSettings::owned_cells`]:
/// every sample at its global position), and the protocol composites them. The image must be
/// the same bits for 1–4 ranks and within 60 dB of the single-process render (f32 `over`
/// reassociated per brick), in both projections.
#[test]
fn slab_bricks_composite_to_the_whole_render() {
    use volsplat_core::glam::{DMat3, DVec3};
    use volsplat_core::{Camera, CrioTables, Grid, TransferFunction, Volume};
    use volsplat_splat::{Antialias, RenderMode, RenderSettings, Visibility, render_slabs};
    let n = 41;
    let grid = Grid::new(
        [n, n - 4, n + 3],
        [1.0, 1.2, 0.9],
        [-3.0, 2.0, 1.0],
        DMat3::IDENTITY,
    )
    .unwrap();
    let vol = Volume::from_fn(grid.clone(), |i, j, k| {
        let blob = |c: [f64; 3], s: f64| {
            let d2 =
                (i as f64 - c[0]).powi(2) + (j as f64 - c[1]).powi(2) + (k as f64 - c[2]).powi(2);
            (-d2 / (2.0 * s * s)).exp()
        };
        (blob([20.0, 18.0, 22.0], 9.0) + 0.7 * blob([28.0, 12.0, 30.0], 5.0)) as f32
    })
    .unwrap();
    let tf = TransferFunction {
        shade: true,
        ..TransferFunction::ramp(0.05, 1.2, 0.4)
    };
    let tables = CrioTables::from_transfer_function(&tf, 1024).unwrap();
    let (w, h) = (56, 48);
    let brick = 16;
    let cells = grid.dims.map(|d| d - 1);
    let tree = BrickTree::new(cells.map(|c| c.div_ceil(brick)), brick).unwrap();
    for parallel in [true, false] {
        let (lo, hi) = grid.bounds_world();
        let mut cam = Camera::reset_to_bounds(lo, hi, parallel);
        cam.azimuth(37.0);
        cam.elevation(-24.0);
        cam.orthogonalize_view_up();
        let mut s = RenderSettings::default();
        (s.width, s.height) = (w, h);
        s.mode = RenderMode::Composite;
        s.visibility = Visibility::ImageAligned;
        s.antialias = Antialias::None;
        s.slab = 1.0;
        let whole = render_slabs(&vol, &cam, &tables, &s, None, &mut |_| true).unwrap();
        let position = grid.index_from_world(DVec3::from(cam.position));
        let eye = if parallel {
            Eye::Direction((grid.index_from_world(DVec3::from(cam.focal_point)) - position).into())
        } else {
            Eye::Point(position.into())
        };
        let partial = |b: usize| -> Result<Option<Pixels>> {
            let at = [
                b % tree.dims[0],
                b / tree.dims[0] % tree.dims[1],
                b / (tree.dims[0] * tree.dims[1]),
            ];
            let mut s = s.clone();
            s.owned_cells = Some([at.map(|a| a * brick), at.map(|a| (a + 1) * brick)]);
            let r = render_slabs(&vol, &cam, &tables, &s, None, &mut |_| true).map_err(|e| {
                DistributedError::Brick {
                    brick: b,
                    why: e.to_string(),
                }
            })?;
            let p = r.image.pixels().to_vec();
            Ok(p.iter().any(|px| px[3] > 0.0).then_some(p))
        };
        let mut first: Option<Pixels> = None;
        for ranks in 1..=4 {
            let image = FakeCluster { size: ranks }
                .run(|comm| {
                    composite_direct_send(comm, &tree, eye, Combine::Over, (w, h), &mut |b| {
                        partial(b)
                    })
                })
                .remove(0)
                .unwrap()
                .unwrap();
            match &first {
                None => first = Some(image),
                Some(f) => assert_eq!(bits(f), bits(&image), "parallel={parallel} ranks={ranks}"),
            }
        }
        let image = first.unwrap();
        let mse = image
            .iter()
            .zip(whole.image.pixels())
            .flat_map(|(a, b)| (0..4).map(move |c| f64::from(a[c] - b[c]).powi(2)))
            .sum::<f64>()
            / (4 * w * h) as f64;
        let psnr = 10.0 * (1.0 / mse).log10();
        let peak = whole
            .image
            .pixels()
            .iter()
            .map(|p| p[3])
            .fold(0.0f32, f32::max);
        assert!(
            peak > 0.3,
            "parallel={parallel}: the volume is drawn ({peak})"
        );
        assert!(
            psnr >= 60.0,
            "parallel={parallel}: {psnr:.1} dB from the whole render"
        );
        eprintln!("parallel={parallel}: {psnr:.1} dB from the single-process render");
    }
}

/// The whole engine, sort-last: the demo MRI head (shaded, at the samples) in both projections,
/// rendered by 1–4 in-process ranks with bricks of 32 cells, each rank with its own renderer.
/// The same bits for every rank count, and within 60 dB of `Renderer::render` of the same
/// request with the early-termination cutoff off (`1 − 2⁻²⁰`), one point per slab and one ray
/// per pixel (the known differences, decision 0038).
#[test]
fn the_engine_renders_sort_last_as_one_process_does() {
    use crate::{RenderRequest, Renderer, Scene, request::PreintegrateChoice};
    for perspective in [false, true] {
        let mut req = RenderRequest::new(Scene::default(), 48, 40);
        req.quality.opacity_cutoff = 1.0 - 1.0 / (1u32 << 20) as f32;
        req.quality.preintegrate = PreintegrateChoice::Off;
        req.quality.antialias = crate::request::AntialiasChoice::None;
        if perspective {
            let cam = Renderer::new().camera(&req).unwrap();
            req.scene.camera = crate::CameraSpec::Explicit {
                camera: volsplat_core::Camera {
                    parallel_projection: false,
                    ..cam
                },
                orbit: Default::default(),
            };
        }
        let whole = Renderer::new().render(&req, &mut |_| true).unwrap().image;
        let mut first: Option<Vec<u32>> = None;
        for ranks in 1..=4 {
            let image = FakeCluster { size: ranks }
                .run(|comm| render_sort_last(comm, &mut Renderer::new(), &req, 32))
                .remove(0)
                .unwrap()
                .unwrap()
                .image;
            let b: Vec<u32> = image
                .pixels()
                .iter()
                .flatten()
                .map(|v| v.to_bits())
                .collect();
            match &first {
                None => {
                    let mse = image
                        .pixels()
                        .iter()
                        .zip(whole.pixels())
                        .flat_map(|(a, b)| (0..4).map(move |c| f64::from(a[c] - b[c]).powi(2)))
                        .sum::<f64>()
                        / (4 * 48 * 40) as f64;
                    let psnr = 10.0 * (1.0 / mse).log10();
                    eprintln!("perspective={perspective}: {psnr:.1} dB from one process");
                    assert!(psnr >= 60.0, "perspective={perspective}: {psnr:.1} dB");
                    assert!(whole.pixels().iter().any(|p| p[3] > 0.5));
                    first = Some(b);
                }
                Some(f) => assert!(f == &b, "perspective={perspective}: {ranks} ranks"),
            }
        }
    }
    // Composite not through the slabs (sheet-buffer visibility): refused by name on every rank.
    let mut req = RenderRequest::new(Scene::default(), 16, 16);
    req.quality.visibility = crate::request::VisibilityChoice::Sheet;
    let e = FakeCluster { size: 2 }
        .run(|comm| render_sort_last(comm, &mut Renderer::new(), &req, 32))
        .remove(0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("renderer") || e.contains("owned_cells"), "{e}");
    let e = FakeCluster { size: 1 }
        .run(|comm| render_sort_last(comm, &mut Renderer::new(), &req, 12))
        .remove(0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("brick size 12"), "{e}");
}

/// X-ray sort-last (sum): the demo head in both projections (the sheets orthographic, the splat
/// list perspective), with the request's defaults (anti-aliasing included), bricks of 16 cells.
/// The line integrals are the same bits for 1–4 ranks and within 60 dB (of their peak) of
/// `Renderer::render`; the grey picture is rebuilt from them as the renderer builds it.
#[test]
fn x_ray_bricks_sum_to_the_single_process_x_ray() {
    use crate::{Mode, RenderRequest, Renderer, Scene};
    for perspective in [false, true] {
        let mut req = RenderRequest::new(Scene::default(), 48, 40);
        req.mode = Mode::Xray;
        if perspective {
            let cam = Renderer::new().camera(&req).unwrap();
            req.scene.camera = crate::CameraSpec::Explicit {
                camera: volsplat_core::Camera {
                    parallel_projection: false,
                    ..cam
                },
                orbit: Default::default(),
            };
        }
        let whole = Renderer::new().render(&req, &mut |_| true).unwrap();
        let whole_values = whole.values.as_ref().unwrap().values().to_vec();
        let peak = whole_values.iter().fold(0.0f32, |m, v| m.max(*v));
        assert!(
            peak > 0.0,
            "perspective={perspective}: the X-ray sees the head"
        );
        let mut first: Option<Vec<u32>> = None;
        for ranks in 1..=4 {
            let out = FakeCluster { size: ranks }
                .run(|comm| render_sort_last(comm, &mut Renderer::new(), &req, 16))
                .remove(0)
                .unwrap()
                .unwrap();
            let values = out.values.as_ref().unwrap().values().to_vec();
            let b: Vec<u32> = values.iter().map(|v| v.to_bits()).collect();
            match &first {
                None => {
                    let mse = values
                        .iter()
                        .zip(&whole_values)
                        .map(|(a, b)| f64::from(a - b).powi(2))
                        .sum::<f64>()
                        / values.len() as f64;
                    let psnr = 10.0 * (f64::from(peak).powi(2) / mse).log10();
                    eprintln!("X-ray perspective={perspective}: {psnr:.1} dB from one process");
                    assert!(psnr >= 60.0, "perspective={perspective}: {psnr:.1} dB");
                    // The picture, from the values, as the renderer draws it.
                    let (grey, _) = volsplat_splat::xray_picture(48, 40, values.clone());
                    assert_eq!(out.image.pixels(), grey.pixels());
                    let d = out
                        .image
                        .pixels()
                        .iter()
                        .zip(whole.image.pixels())
                        .map(|(a, b)| (a[0] - b[0]).abs())
                        .fold(0.0f32, f32::max);
                    assert!(d < 1e-4, "perspective={perspective}: grey differs by {d}");
                    first = Some(b);
                }
                Some(f) => assert!(f == &b, "perspective={perspective}: {ranks} ranks"),
            }
        }
    }
}

/// A rank that cannot even load its volume (its request names a missing file; the others
/// render) still takes part in the exchange: every rank returns an error naming that rank and
/// the file, for 1–4 ranks, whichever rank fails (the test would hang otherwise).
#[test]
fn a_rank_that_cannot_read_its_volume_stops_every_rank() {
    use crate::{RenderRequest, Renderer, Scene};
    let good = RenderRequest::new(Scene::default(), 24, 20);
    let mut bad = good.clone();
    bad.scene.volume =
        serde_json::from_str(r#"{"file": {"path": "/nonexistent/volsplat-rank.nrrd"}}"#).unwrap();
    for n in 1..=4 {
        for failing in [0, n - 1] {
            let out = FakeCluster { size: n }.run(|comm| {
                let req = if comm.rank() == failing { &bad } else { &good };
                render_sort_last(comm, &mut Renderer::new(), req, 32)
            });
            for (r, o) in out.into_iter().enumerate() {
                let e = o.unwrap_err().to_string();
                assert!(
                    e.contains(&format!("rank {failing} failed"))
                        && e.contains("volsplat-rank.nrrd"),
                    "n={n} rank {r}: {e}"
                );
            }
        }
    }
}

/// MIP and MinIP sort-last (max, min): the demo head in both projections, bricks of 16 cells,
/// 1–4 ranks. Each brick draws the slabs' samples of its cells, so the extreme over the bricks
/// is `Renderer::render`'s projection bit for bit (one ray per pixel in both), values and
/// picture.
#[test]
fn mip_and_minip_bricks_are_the_single_process_projection_bit_for_bit() {
    use crate::{Mode, RenderRequest, Renderer, Scene};
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for mode in [Mode::Mip, Mode::Minip] {
        for perspective in [false, true] {
            let mut req = RenderRequest::new(Scene::default(), 48, 40);
            req.mode = mode;
            req.quality.antialias = crate::request::AntialiasChoice::None;
            if perspective {
                let cam = Renderer::new().camera(&req).unwrap();
                req.scene.camera = crate::CameraSpec::Explicit {
                    camera: volsplat_core::Camera {
                        parallel_projection: false,
                        ..cam
                    },
                    orbit: Default::default(),
                };
            }
            let whole = Renderer::new().render(&req, &mut |_| true).unwrap();
            let whole_values = whole.values.as_ref().unwrap().values().to_vec();
            let seen = whole_values.iter().filter(|v| !v.is_nan()).count();
            eprintln!(
                "{mode:?} perspective={perspective}: {seen} of {} pixels",
                whole_values.len()
            );
            assert!(seen > 300, "{seen}");
            for ranks in 1..=4 {
                let out = FakeCluster { size: ranks }
                    .run(|comm| render_sort_last(comm, &mut Renderer::new(), &req, 16))
                    .remove(0)
                    .unwrap()
                    .unwrap();
                let label = format!("{mode:?} perspective={perspective} ranks={ranks}");
                let values = out.values.as_ref().unwrap().values();
                assert_eq!(bits(values), bits(&whole_values), "{label}");
                let picture = |i: &volsplat_core::Image| {
                    i.pixels()
                        .iter()
                        .flatten()
                        .map(|v| v.to_bits())
                        .collect::<Vec<_>>()
                };
                assert_eq!(picture(&out.image), picture(&whole.image), "{label}");
            }
        }
    }
}
