//! PNG figures: the SVGs drawn by [`super::plot`], rasterised with `resvg` (pure Rust). Text
//! is set in the DejaVu Sans shipped in `assets/fonts/` (its licence beside it) and no system
//! font is looked up, so a figure is the same on any machine.
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use resvg::{tiny_skia, usvg};

use super::{ReportError, Result};

static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

fn options() -> &'static usvg::Options<'static> {
    static OPTIONS: OnceLock<usvg::Options<'static>> = OnceLock::new();
    OPTIONS.get_or_init(|| {
        let mut db = usvg::fontdb::Database::new();
        db.load_font_data(FONT.to_vec());
        // plotters writes `font-family="sans-serif"`; every generic family is our one font.
        for set in [
            usvg::fontdb::Database::set_sans_serif_family,
            usvg::fontdb::Database::set_serif_family,
            usvg::fontdb::Database::set_monospace_family,
        ] {
            set(&mut db, "DejaVu Sans");
        }
        usvg::Options {
            font_family: "DejaVu Sans".into(),
            fontdb: Arc::new(db),
            ..usvg::Options::default()
        }
    })
}

/// An SVG document as PNG bytes, `scale` pixels per SVG unit, on a white background.
pub fn svg_to_png(svg: &str, scale: f32) -> std::result::Result<Vec<u8>, String> {
    let tree = usvg::Tree::from_str(svg, options()).map_err(|e| format!("SVG: {e}"))?;
    let size = tree
        .size()
        .to_int_size()
        .scale_by(scale)
        .ok_or("empty SVG")?;
    let mut pixmap = tiny_skia::Pixmap::new(size.width(), size.height())
        .ok_or_else(|| format!("a {}x{} image is too large", size.width(), size.height()))?;
    pixmap.fill(tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(scale, scale),
        &mut pixmap.as_mut(),
    );
    pixmap.encode_png().map_err(|e| format!("PNG: {e}"))
}

/// Writes `<svg path with .png>` from the SVG file at `svg_path`; returns its path.
pub fn png_beside(svg_path: &Path) -> Result<PathBuf> {
    let out = svg_path.with_extension("png");
    let fail = |message: String| ReportError::Write {
        path: out.clone(),
        message,
    };
    let svg = std::fs::read_to_string(svg_path).map_err(|e| fail(e.to_string()))?;
    let png = svg_to_png(&svg, 1.0).map_err(fail)?;
    std::fs::write(&out, png).map_err(|e| fail(e.to_string()))?;
    Ok(out)
}
