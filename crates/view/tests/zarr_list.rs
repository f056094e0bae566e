//! The viewer's volume list (`--data-dir`) offers OME-Zarr stores, folders named `.zarr`
//! (issue 31 item 6), beside volume files; other folders stay out.

#[test]
fn zarr_stores_are_listed_beside_volume_files() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("a.nrrd"), b"x").unwrap();
    std::fs::create_dir(dir.path().join("b.zarr")).unwrap();
    std::fs::create_dir(dir.path().join("c")).unwrap();
    std::fs::create_dir(dir.path().join("d.nrrd")).unwrap();
    assert_eq!(
        volsplat_view::list_volumes(dir.path()),
        ["a.nrrd", "b.zarr"]
    );
}
