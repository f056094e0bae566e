//! The page, embedded in the binary: one HTML document with its style and script inlined
//! (`crates/view/assets/`), so nothing is fetched from a network at run time and every request
//! the page makes is the WebSocket.

/// The page's HTML template.
const INDEX: &str = include_str!("../assets/index.html");
/// Its style sheet.
const STYLE: &str = include_str!("../assets/style.css");
/// Its script.
const SCRIPT: &str = include_str!("../assets/app.js");

/// The page and the nonce its `<script>` carries (the Content-Security-Policy allows that
/// script and no other).
pub(crate) fn page() -> (Vec<u8>, String) {
    let mut bytes = [0u8; 16];
    // The operating system's random source does not fail on supported systems (the token
    // needed it already); should it, the time stands in: the nonce only has to differ from
    // what an injected script could know in advance, and the page itself needs the token.
    if getrandom::fill(&mut bytes).is_err() {
        let t = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        bytes = (t ^ std::process::id() as u128).to_le_bytes();
    }
    let nonce: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    let html = INDEX
        .replace("/*STYLE*/", STYLE)
        .replace("/*SCRIPT*/", SCRIPT)
        .replace("{{NONCE}}", &nonce);
    (html.into_bytes(), nonce)
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_page_inlines_its_assets_and_fetches_nothing() {
        let (page, nonce) = super::page();
        let page = String::from_utf8(page).unwrap();
        assert!(page.contains(&format!("<script nonce=\"{nonce}\">")));
        assert!(!page.contains("/*STYLE*/") && !page.contains("/*SCRIPT*/"));
        assert!(!page.contains("{{NONCE}}"));
        for remote in ["http://", "https://", "//cdn", "src=\"/", "href=\"/"] {
            assert!(!page.contains(remote), "the page refers to {remote}…");
        }
        let (_, other) = super::page();
        assert_ne!(nonce, other, "a fresh nonce per page");
    }
}
