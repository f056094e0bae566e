//! Runs the texture-bench evaluation and prints the Markdown report.
//!
//! `cargo run --release -p volsplat-studies --example texture_bench [-- WIDTH HEIGHT]`

use volsplat_studies::texture_bench::{TextureBenchSettings, run_texture_bench};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let mut settings = TextureBenchSettings::default();
    if let [w, h, ..] = args[..] {
        settings.width = w;
        settings.height = h;
    }
    let report = run_texture_bench(&settings)?;
    println!("{}", report.to_markdown());
    // Optional: write the images as binary PGM files into $TEXTURE_BENCH_OUT.
    if let Ok(dir) = std::env::var("TEXTURE_BENCH_OUT") {
        std::fs::create_dir_all(&dir)?;
        for img in &report.images {
            let (w, h) = (img.image.width(), img.image.height());
            let mut bytes = format!("P5\n{w} {h}\n255\n").into_bytes();
            bytes.extend(
                img.image
                    .values()
                    .iter()
                    .map(|v| volsplat_studies::metrics::to_8bit(*v)),
            );
            std::fs::write(format!("{dir}/{}.pgm", img.name), bytes)?;
        }
    }
    Ok(())
}
