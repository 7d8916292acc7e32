//! The page, in the binary: one HTML file with its style and script inline (no CDN, no build
//! step), served at `/`.

/// The operator's page.
pub const INDEX_HTML: &str = include_str!("../page/index.html");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_loads_nothing_from_elsewhere_and_keeps_the_estop_first() {
        for outside in ["http://", "https://", "//cdn", "<link ", "src=\""] {
            assert!(!INDEX_HTML.contains(outside), "{outside}");
        }
        let estop = INDEX_HTML.find("id=\"estop\"").expect("an E-STOP");
        let pad = INDEX_HTML.find("id=\"pad\"").expect("a pad");
        assert!(estop < pad, "the E-STOP comes first on the page");
    }
}
