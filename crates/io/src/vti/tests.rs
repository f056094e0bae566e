use super::*;
use base64::Engine;
use std::io::Write;
use std::path::PathBuf;
use volsplat_core::ScalarType;

const B64: base64::engine::GeneralPurpose = base64::engine::general_purpose::STANDARD;

fn zlib(data: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(data).unwrap();
    e.finish().unwrap()
}

fn word(v: usize, h64: bool) -> Vec<u8> {
    if h64 {
        (v as u64).to_le_bytes().to_vec()
    } else {
        (v as u32).to_le_bytes().to_vec()
    }
}

/// VTK's binary block for `data`: header + data, compressed in blocks of `bs` bytes or not.
fn block(data: &[u8], h64: bool, compress: Option<usize>) -> (Vec<u8>, Vec<u8>) {
    match compress {
        None => (word(data.len(), h64), data.to_vec()),
        Some(bs) => {
            let chunks: Vec<Vec<u8>> = data.chunks(bs).map(zlib).collect();
            let last = data.len() % bs;
            let mut h = word(chunks.len(), h64);
            h.extend(word(bs, h64));
            h.extend(word(last, h64));
            for c in &chunks {
                h.extend(word(c.len(), h64));
            }
            (h, chunks.concat())
        }
    }
}

fn doc(header: &str, image_attrs: &str, arrays: &str, appended: &[u8]) -> Vec<u8> {
    let mut s = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" \
         byte_order=\"LittleEndian\" {header}>\n  <ImageData {image_attrs}>\n    \
         <Piece Extent=\"0 2 0 1 0 1\">\n      <PointData Scalars=\"density\">\n{arrays}      \
         </PointData>\n      <CellData/>\n    </Piece>\n  </ImageData>\n"
    )
    .into_bytes();
    if !appended.is_empty() {
        s.extend_from_slice(appended);
    }
    s.extend_from_slice(b"</VTKFile>\n");
    s
}

const IMAGE: &str = "WholeExtent=\"0 2 0 1 0 1\" Origin=\"1 2 3\" Spacing=\"0.5 1 2\" \
                     Direction=\"0 -1 0 1 0 0 0 0 1\"";

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn values() -> Vec<f32> {
    (0..12).map(|i| i as f32 * 1.5 - 4.0).collect()
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn check(p: &Path) {
    let l = read_vti_with(p, &ReadOptions::default()).unwrap();
    let v = &l.volume;
    assert_eq!(v.scalar_type(), ScalarType::F32);
    assert_eq!(v.to_f32().data(), &values()[..]);
    let g = v.grid();
    assert_eq!(g.dims, [3, 2, 2]);
    assert_eq!(g.spacing, [0.5, 1.0, 2.0]);
    assert_eq!(g.origin, [1.0, 2.0, 3.0]);
    // Row-major "0 -1 0 1 0 0 0 0 1": column 0 (the i axis) is (0, 1, 0).
    assert_eq!(g.direction.col(0), DVec3::Y);
    assert_eq!(g.direction.col(1), -DVec3::X);
    assert_eq!(l.arrays, vec!["other".to_string(), "density".to_string()]);
}

/// `vtkLZ4DataCompressor`: the same header as zlib, raw LZ4 blocks; inline and appended;
/// a damaged block is an error naming it.
#[test]
fn lz4_compressed_blocks() {
    let dir = tempfile::tempdir().unwrap();
    let data = f32_bytes(&values());
    let other = "        <DataArray type=\"UInt8\" Name=\"other\" format=\"ascii\">1 2 3 4 5 6 7 8 9 10 11 12</DataArray>\n";
    for bs in [16usize, 1000] {
        let chunks: Vec<Vec<u8>> = data.chunks(bs).map(lz4_flex::block::compress).collect();
        let mut h = word(chunks.len(), false);
        h.extend(word(bs, false));
        h.extend(word(data.len() % bs, false));
        for c in &chunks {
            h.extend(word(c.len(), false));
        }
        let d = chunks.concat();
        let header = "header_type=\"UInt32\" compressor=\"vtkLZ4DataCompressor\"";
        let arrays = format!(
            "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">\n  {}{}\n</DataArray>\n",
            B64.encode(&h),
            B64.encode(&d)
        );
        check(&write(
            dir.path(),
            "l.vti",
            &doc(header, IMAGE, &arrays, b""),
        ));
        let mut app = b"  <AppendedData encoding=\"raw\">\n   _".to_vec();
        app.extend_from_slice(&h);
        app.extend_from_slice(&d);
        app.extend_from_slice(b"\n  </AppendedData>\n");
        let arrays = format!(
            "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"0\"/>\n"
        );
        check(&write(
            dir.path(),
            "m.vti",
            &doc(header, IMAGE, &arrays, &app),
        ));
        // Damage the first block: a clear error, never a panic.
        let mut bad = d.clone();
        bad[0] = 0xFF;
        bad.truncate(3);
        let arrays = format!(
            "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">\n  {}{}\n</DataArray>\n",
            B64.encode(&h),
            B64.encode(&bad)
        );
        let e = read_vti(write(
            dir.path(),
            "n.vti",
            &doc(header, IMAGE, &arrays, b""),
        ))
        .unwrap_err()
        .to_string();
        assert!(e.contains("n.vti"), "{e}");
    }
}

#[test]
fn every_encoding_and_header_type() {
    let dir = tempfile::tempdir().unwrap();
    let data = f32_bytes(&values());
    let other = "        <DataArray type=\"UInt8\" Name=\"other\" format=\"ascii\">1 2 3 4 5 6 7 8 9 10 11 12</DataArray>\n";
    // ascii
    let text: Vec<String> = values().iter().map(|v| v.to_string()).collect();
    let arrays = format!(
        "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"ascii\">\n{}\n</DataArray>\n",
        text.join(" ")
    );
    check(&write(dir.path(), "a.vti", &doc("", IMAGE, &arrays, b"")));
    for h64 in [false, true] {
        let ht = if h64 {
            "header_type=\"UInt64\""
        } else {
            "header_type=\"UInt32\""
        };
        for compress in [None, Some(16), Some(1000)] {
            let comp = if compress.is_some() {
                " compressor=\"vtkZLibDataCompressor\""
            } else {
                ""
            };
            let header = format!("{ht}{comp}");
            let (h, d) = block(&data, h64, compress);
            // inline base64: header and data encoded separately, and (uncompressed) together.
            let mut encodings = vec![format!("{}{}", B64.encode(&h), B64.encode(&d))];
            if compress.is_none() {
                encodings.push(B64.encode([h.clone(), d.clone()].concat()));
            }
            for enc in encodings {
                let arrays = format!(
                    "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">\n  {enc}\n</DataArray>\n"
                );
                check(&write(
                    dir.path(),
                    "b.vti",
                    &doc(&header, IMAGE, &arrays, b""),
                ));
            }
            // appended raw, after a dummy array at offset 0.
            let dummy = [0xABu8; 5];
            let mut app = b"  <AppendedData encoding=\"raw\">\n   _".to_vec();
            app.extend_from_slice(&dummy);
            app.extend_from_slice(&h);
            app.extend_from_slice(&d);
            app.extend_from_slice(b"\n  </AppendedData>\n");
            let arrays = format!(
                "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"{}\"/>\n",
                dummy.len()
            );
            check(&write(
                dir.path(),
                "c.vti",
                &doc(&header, IMAGE, &arrays, &app),
            ));
            // appended base64.
            let enc = format!("{}{}", B64.encode(&h), B64.encode(&d));
            let app =
                format!("  <AppendedData encoding=\"base64\">\n   _AAAA{enc}\n  </AppendedData>\n");
            let arrays = format!(
                "{other}        <DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"4\"/>\n"
            );
            check(&write(
                dir.path(),
                "d.vti",
                &doc(&header, IMAGE, &arrays, app.as_bytes()),
            ));
        }
    }
}

#[test]
fn array_choice_and_types() {
    let dir = tempfile::tempdir().unwrap();
    let arrays = "        <DataArray type=\"Int16\" Name=\"a\" format=\"ascii\">-1 2 3 4 5 6 7 8 9 10 11 -32768</DataArray>\n\
                  <DataArray type=\"Float64\" Name=\"b\" format=\"ascii\">0.5 2 3 4 5 6 7 8 9 10 11 1e30</DataArray>\n";
    let text = String::from_utf8(doc("", IMAGE, arrays, b"")).unwrap();
    // No Scalars attribute: the first array.
    let p = write(
        dir.path(),
        "t.vti",
        text.replace(" Scalars=\"density\"", "").as_bytes(),
    );
    let v = read_vti(&p).unwrap();
    assert_eq!(v.scalar_type(), ScalarType::I16);
    let o = ReadOptions {
        array: Some("b".into()),
        ..ReadOptions::default()
    };
    let l = read_vti_with(&p, &o).unwrap();
    assert_eq!(l.volume.scalar_type(), ScalarType::F32);
    assert_eq!(l.volume.to_f32().data()[0], 0.5);
    let o = ReadOptions {
        array: Some("c".into()),
        ..ReadOptions::default()
    };
    let e = read_vti_with(&p, &o).unwrap_err().to_string();
    assert!(e.contains("\"c\"") && e.contains("\"a\""), "{e}");
    // The active scalars name a missing array.
    let p = write(dir.path(), "t.vti", text.as_bytes());
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(e.contains("Scalars") && e.contains("density"), "{e}");
    // Through the dispatcher.
    let p = write(
        dir.path(),
        "u.vti",
        text.replace("Scalars=\"density\"", "Scalars=\"b\"")
            .as_bytes(),
    );
    let l = crate::read_volume_with(&p, &ReadOptions::default()).unwrap();
    assert_eq!(l.format, "VTK image data");
    assert_eq!(l.volume.scalar_type(), ScalarType::F32);
}

#[test]
fn extent_offset_and_negative_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let arrays = "        <DataArray type=\"UInt8\" Name=\"density\" format=\"ascii\">1 2 3 4 5 6 7 8 9 10 11 12</DataArray>\n";
    let text = String::from_utf8(doc(
        "",
        "WholeExtent=\"10 12 0 1 -1 0\" Origin=\"0 0 0\" Spacing=\"-2 1 1\"",
        arrays,
        b"",
    ))
    .unwrap()
    .replace("Extent=\"0 2 0 1 0 1\"", "Extent=\"10 12 0 1 -1 0\"");
    let p = write(dir.path(), "e.vti", text.as_bytes());
    let v = read_vti(&p).unwrap();
    let g = v.grid();
    assert_eq!(g.spacing, [2.0, 1.0, 1.0]);
    // Point (10, 0, -1) is at x = 10·(−2) = −20, z = −1.
    assert_eq!(g.origin, [-20.0, 0.0, -1.0]);
    assert_eq!(g.direction.col(0), -DVec3::X);
}

#[test]
fn malformed_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let data = f32_bytes(&values());
    let (h, d) = block(&data, false, Some(16));
    let ok_arrays = format!(
        "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}{}</DataArray>\n",
        B64.encode(&h),
        B64.encode(&d)
    );
    let comp = "compressor=\"vtkZLibDataCompressor\"";
    let ok = String::from_utf8(doc(comp, IMAGE, &ok_arrays, b"")).unwrap();
    read_vti(write(dir.path(), "ok.vti", ok.as_bytes())).unwrap();
    let cases: Vec<(String, &str)> = vec![
        (
            ok.replace("ImageData\" version", "PolyData\" version"),
            "VTKFile type",
        ),
        (
            ok.replace("WholeExtent=\"0 2", "WholeExtent=\"2 0"),
            "`WholeExtent`",
        ),
        (
            ok.replace(
                "WholeExtent=\"0 2 0 1 0 1\"",
                "WholeExtent=\"0 9223372036854775806 0 9223372036854775806 0 3\"",
            ),
            "`WholeExtent`",
        ),
        (ok.replace("Spacing=\"0.5", "Spacing=\"0"), "`Spacing`"),
        (
            ok.replace("Direction=\"0 -1 0", "Direction=\"1 1 0"),
            "`Direction`",
        ),
        (ok.replace("Float32", "Int64"), "type"),
        (ok.replace("vtkZLib", "vtkLZMA"), "`compressor`"),
        (
            ok.replace("UInt32", "UInt16")
                .replace("byte_order", "header_type=\"UInt16\" byte_order"),
            "`header_type`",
        ),
        (
            ok.replace("format=\"binary\">", "format=\"binary\">!!!!"),
            "base64",
        ),
        (
            ok.replace(
                "format=\"binary\">",
                "NumberOfComponents=\"3\" format=\"binary\">",
            ),
            "NumberOfComponents",
        ),
        (
            ok.replace("<Piece", "<Piece Foo=\"1\"")
                .replace("</ImageData>", "<Piece/></ImageData>"),
            "`Piece`",
        ),
        (ok.replace("</DataArray>", ""), "XML"),
        (
            ok.replace("format=\"binary\"", "format=\"appended\""),
            "AppendedData",
        ),
    ];
    for (text, want) in cases {
        let p = write(dir.path(), "bad.vti", text.as_bytes());
        let e = read_vti(&p).unwrap_err().to_string();
        assert!(
            e.contains(want) && e.contains("bad.vti"),
            "want {want}: {e}"
        );
    }
    // Truncated compressed data, a lying block count, raw appended data cut short.
    let cut = format!(
        "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}{}</DataArray>\n",
        B64.encode(&h),
        B64.encode(&d[..d.len() / 2])
    );
    let p = write(dir.path(), "cut.vti", &doc(comp, IMAGE, &cut, b""));
    assert!(read_vti(&p).is_err());
    let mut lying = h.clone();
    lying[0..4].copy_from_slice(&1000u32.to_le_bytes());
    let arrays = format!(
        "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}{}</DataArray>\n",
        B64.encode(&lying),
        B64.encode(&d)
    );
    let p = write(dir.path(), "lie.vti", &doc(comp, IMAGE, &arrays, b""));
    assert!(read_vti(&p).is_err());
    let (h, d) = block(&data, true, None);
    let mut app = b"<AppendedData encoding=\"raw\">_".to_vec();
    app.extend_from_slice(&h);
    app.extend_from_slice(&d[..20]);
    let arrays =
        "<DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"0\"/>\n";
    let p = write(
        dir.path(),
        "raw.vti",
        &doc("header_type=\"UInt64\"", IMAGE, arrays, &app),
    );
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(e.contains("truncated"), "{e}");
    let arrays =
        "<DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"99999\"/>\n";
    let p = write(
        dir.path(),
        "raw.vti",
        &doc("header_type=\"UInt64\"", IMAGE, arrays, &app),
    );
    assert!(read_vti(&p).is_err());
}

/// A `<DataArray>` of `values()` in appended raw data; `block` is its header and samples.
fn appended_doc(header: &str, block: &[u8]) -> Vec<u8> {
    let mut app = b"  <AppendedData encoding=\"raw\">\n   _".to_vec();
    app.extend_from_slice(block);
    app.extend_from_slice(b"\n  </AppendedData>\n");
    let arrays = "        <DataArray type=\"Float32\" Name=\"density\" format=\"appended\" \
                  offset=\"0\"/>\n";
    doc(header, IMAGE, arrays, &app)
}

/// Issue 28 §2: an LZ4 block header declaring 2⁴⁰-byte blocks for a 2³³-voxel float grid
/// (32 GiB of samples) from a few compressed bytes is an error naming the block, raised before
/// anything is allocated (it used to allocate the 32 GiB up front).
#[test]
fn lz4_block_larger_than_its_compressed_bytes_can_hold() {
    let dir = tempfile::tempdir().unwrap();
    let payload = lz4_flex::block::compress(&[7u8; 64]);
    let mut h = word(1, true);
    h.extend(word(1 << 40, true));
    h.extend(word(0, true));
    h.extend(word(payload.len(), true));
    let arrays = format!(
        "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}{}</DataArray>\n",
        B64.encode(&h),
        B64.encode(&payload)
    );
    let big = "WholeExtent=\"0 2047 0 2047 0 2047\" Origin=\"0 0 0\" Spacing=\"1 1 1\"";
    let text = String::from_utf8(doc(
        "header_type=\"UInt64\" compressor=\"vtkLZ4DataCompressor\"",
        big,
        &arrays,
        b"",
    ))
    .unwrap()
    .replace("Extent=\"0 2 0 1 0 1\"", "Extent=\"0 2047 0 2047 0 2047\"");
    let p = write(dir.path(), "lz4big.vti", text.as_bytes());
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(
        e.contains("lz4big.vti")
            && e.contains("LZ4 block 0 must decode to 34359738368 bytes")
            && e.contains("block size 1099511627776"),
        "{e}"
    );
    // The same with zlib: its ratio bound (1032:1) applies.
    let text = text.replace("vtkLZ4DataCompressor", "vtkZLibDataCompressor");
    let p = write(dir.path(), "zbig.vti", text.as_bytes());
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(e.contains("zlib block 0 must decode to"), "{e}");
}

/// Issue 28 §3: `header_type="UInt64"` with blocks written with 4-byte counts decoded shifted
/// by one sample, the last taken from the closing tags' text (VTK 9.7.2 reads it so too); a
/// count of 4.6e18 was accepted. Now an error saying the counts look 4 bytes wide.
#[test]
fn uint64_header_with_4_byte_counts_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let mut v = values();
    let mut four = word(48, false);
    four.extend(f32_bytes(&v));
    let want = "written with header_type=\"UInt32\" although the file declares \"UInt64\"";
    let u64h = "header_type=\"UInt64\"";
    // Appended raw: the count reads 48 + (first sample << 32) ≈ 1.4e19.
    let p = write(dir.path(), "a.vti", &appended_doc(u64h, &four));
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(e.contains(want) && e.contains("byte count"), "{e}");
    // The first sample 0: the count reads exactly 48, but the block is 4 bytes short.
    v[0] = 0.0;
    let mut four0 = word(48, false);
    four0.extend(f32_bytes(&v));
    let p = write(dir.path(), "b.vti", &appended_doc(u64h, &four0));
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(e.contains(want), "{e}");
    // Inline base64, header and data together.
    let arrays = format!(
        "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}</DataArray>\n",
        B64.encode(&four)
    );
    let p = write(dir.path(), "c.vti", &doc(u64h, IMAGE, &arrays, b""));
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(e.contains(want), "{e}");
    // The count of 4.6e18 of the issue, no width mix-up: more than the block holds.
    let mut huge = 4_600_000_000_000_000_000u64.to_le_bytes().to_vec();
    huge.extend(f32_bytes(&values()));
    let p = write(dir.path(), "d.vti", &appended_doc(u64h, &huge));
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(
        e.contains("4600000000000000000") && e.contains("more than the"),
        "{e}"
    );
    // Compressed, UInt64 declared, 4-byte words written.
    let (h, d) = block(&f32_bytes(&values()), false, Some(16));
    let arrays = format!(
        "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}{}</DataArray>\n",
        B64.encode(&h),
        B64.encode(&d)
    );
    let header = "header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\"";
    let p = write(dir.path(), "e.vti", &doc(header, IMAGE, &arrays, b""));
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(e.contains(want) && e.contains("compression header"), "{e}");
    // The right header type reads them all.
    let mut right = word(48, false);
    right.extend(f32_bytes(&values()));
    let v = read_vti(write(dir.path(), "f.vti", &appended_doc("", &right))).unwrap();
    assert_eq!(v.to_f32().data(), &values()[..]);
}

/// The mirror case: 8-byte counts under the default `UInt32` would read the count's zero high
/// half as the first sample.
#[test]
fn uint32_header_with_8_byte_counts_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let mut eight = word(48, true);
    eight.extend(f32_bytes(&values()));
    let p = write(dir.path(), "a.vti", &appended_doc("", &eight));
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(
        e.contains("written as an 8-byte word") && e.contains("a.vti"),
        "{e}"
    );
    let arrays = format!(
        "        <DataArray type=\"Float32\" Name=\"density\" format=\"binary\">{}</DataArray>\n",
        B64.encode(&eight)
    );
    let p = write(dir.path(), "b.vti", &doc("", IMAGE, &arrays, b""));
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(e.contains("written as an 8-byte word"), "{e}");
}

/// An appended array's block ends at the next array's offset: a byte count reaching into the
/// next array is an error, and two arrays back to back read as written.
#[test]
fn appended_blocks_end_at_the_next_array() {
    let dir = tempfile::tempdir().unwrap();
    let mut first = word(12, false);
    first.extend(1u8..=12);
    let mut second = word(48, false);
    second.extend(f32_bytes(&values()));
    let mut app = b"  <AppendedData encoding=\"raw\">\n   _".to_vec();
    app.extend_from_slice(&first);
    app.extend_from_slice(&second);
    app.extend_from_slice(b"\n  </AppendedData>\n");
    let arrays = format!(
        "        <DataArray type=\"UInt8\" Name=\"other\" format=\"appended\" offset=\"0\"/>\n        \
         <DataArray type=\"Float32\" Name=\"density\" format=\"appended\" offset=\"{}\"/>\n",
        first.len()
    );
    let p = write(dir.path(), "ok.vti", &doc("", IMAGE, &arrays, &app));
    check(&p);
    let o = ReadOptions {
        array: Some("other".into()),
        ..ReadOptions::default()
    };
    let l = read_vti_with(&p, &o).unwrap();
    assert_eq!(l.volume.to_f32().data()[11], 12.0);
    // The first array's count claims 16 bytes: 4 of them would be the next array's header.
    let mut bad = app.clone();
    let at = bad.iter().position(|&b| b == b'_').unwrap() + 1;
    bad[at..at + 4].copy_from_slice(&16u32.to_le_bytes());
    let p = write(dir.path(), "bad.vti", &doc("", IMAGE, &arrays, &bad));
    let e = read_vti_with(&p, &o).unwrap_err().to_string();
    assert!(e.contains("more than the 12 bytes"), "{e}");
}

/// Decision 0030: NaN and infinities in a float array are read (the volume's finite extremes,
/// with a note); a finite double beyond float32 is an error naming the sample.
#[test]
fn ascii_nan_is_read_and_float32_overflow_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let array = |values: &str| {
        let a = format!(
            "        <DataArray type=\"Float64\" Name=\"density\" format=\"ascii\">{values}</DataArray>\n"
        );
        String::from_utf8(doc("", IMAGE, &a, b"")).unwrap()
    };
    let p = write(
        dir.path(),
        "n.vti",
        array("nan 2 3 4 5 6 7 8 9 10 11 inf").as_bytes(),
    );
    let l = crate::read_volume_with(&p, &ReadOptions::default()).unwrap();
    let d = l.volume.to_f32();
    assert_eq!((d.data()[0], d.data()[11]), (2.0, 11.0));
    assert!(
        l.notes.iter().any(|n| n.contains("1 sample was NaN")
            && n.contains("1 sample was +inf, taken as the highest finite value 11")),
        "{:?}",
        l.notes
    );
    let p = write(
        dir.path(),
        "o.vti",
        array("1 2 3 4 5 1e300 7 8 9 10 11 12").as_bytes(),
    );
    let e = read_vti(&p).unwrap_err().to_string();
    assert!(
        e.contains("sample #5") && e.contains("float32 range"),
        "{e}"
    );
}
