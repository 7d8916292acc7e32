//! The page's link as a QR code for a terminal, so a phone's camera opens it: two modules a
//! character (half blocks), dark on light in explicit colours whatever the terminal's own.

use qrcode::{Color, EcLevel, QrCode};

/// Light modules around the code, as the QR standard asks (ISO/IEC 18004: four).
const QUIET_ZONE: usize = 4;

/// Black on bright white (ANSI SGR 30 and 107), then back to the terminal's colours: a dark
/// terminal would otherwise show the code inverted, which not every phone reads.
const COLOURS: &str = "\x1b[30;107m";
const RESET: &str = "\x1b[0m";

/// The half blocks, indexed by (top dark) * 2 + (bottom dark).
const BLOCKS: [char; 4] = [' ', '▄', '▀', '█'];

/// `text` as a QR code (error correction M: a screen's glare), one string a terminal line
/// each, two rows of modules to a line, quiet zone included. `None` if `text` is longer than a
/// QR code holds (about 2,300 bytes at M; a link is far shorter).
pub fn terminal_lines(text: &str) -> Option<Vec<String>> {
    let code = QrCode::with_error_correction_level(text, EcLevel::M).ok()?;
    let width = code.width();
    let colors = code.to_colors();
    let side = width + 2 * QUIET_ZONE;
    let dark = |x: usize, y: usize| {
        let inside = QUIET_ZONE..QUIET_ZONE + width;
        inside.contains(&x)
            && inside.contains(&y)
            && colors[(y - QUIET_ZONE) * width + (x - QUIET_ZONE)] == Color::Dark
    };
    Some(
        (0..side)
            .step_by(2)
            .map(|y| {
                let row: String = (0..side)
                    .map(|x| BLOCKS[usize::from(dark(x, y)) * 2 + usize::from(dark(x, y + 1))])
                    .collect();
                format!("{COLOURS}{row}{RESET}")
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The modules a rendering shows (true: dark), read back from its characters.
    fn modules(lines: &[String]) -> Vec<Vec<bool>> {
        let mut rows = Vec::new();
        for line in lines {
            let line = line
                .strip_prefix(COLOURS)
                .and_then(|line| line.strip_suffix(RESET))
                .expect("every line in its colours");
            let blocks: Vec<usize> = line
                .chars()
                .map(|c| BLOCKS.iter().position(|&b| b == c).expect("a half block"))
                .collect();
            rows.push(blocks.iter().map(|b| b & 2 != 0).collect());
            rows.push(blocks.iter().map(|b| b & 1 != 0).collect());
        }
        rows
    }

    /// What an independent reader (rqrr) decodes from the rendering, drawn 4 pixels a module.
    fn decoded(lines: &[String]) -> String {
        let modules = modules(lines);
        let (width, height) = (modules[0].len() * 4, modules.len() * 4);
        let mut image = rqrr::PreparedImage::prepare_from_greyscale(width, height, |x, y| {
            if modules[y / 4][x / 4] { 0 } else { 255 }
        });
        let grids = image.detect_grids();
        assert_eq!(grids.len(), 1, "one code in the rendering");
        grids[0].decode().expect("a readable code").1
    }

    #[test]
    fn a_link_reads_back_from_what_the_terminal_shows() {
        for link in [
            "http://127.0.0.1:8090/#token=AbCdEfGhIjKlMnOpQrStUvWx",
            "https://192.168.1.23:8090/#token=0123456789-_abcdefghijkl",
            "https://[fd00::1234:5678]:65535/#token=zzzzzzzzzzzzzzzzzzzzzzzz",
        ] {
            let lines = terminal_lines(link).expect("a link fits");
            assert_eq!(decoded(&lines), link);
        }
    }

    #[test]
    fn the_quiet_zone_is_light_all_round() {
        let lines = terminal_lines("http://127.0.0.1:8090/#token=x").expect("fits");
        let modules = modules(&lines);
        let side = modules[0].len();
        for (y, row) in modules.iter().enumerate() {
            assert_eq!(row.len(), side, "every line as wide");
            for (x, &dark) in row.iter().enumerate() {
                let edge = x < QUIET_ZONE
                    || x >= side - QUIET_ZONE
                    || y < QUIET_ZONE
                    || y >= side - QUIET_ZONE;
                assert!(
                    !(edge && dark),
                    "module ({x}, {y}) of the quiet zone is dark"
                );
            }
        }
    }

    #[test]
    fn too_much_text_is_none_not_a_panic() {
        assert!(terminal_lines(&"x".repeat(5000)).is_none());
    }
}
