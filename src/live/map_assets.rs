//! The live map's files, built from `web/` (`npm run build`, see
//! `web/build.mjs`) into `web/dist/` and embedded here, so the binary serves
//! its map without npm, the network or files beside it. `.ci/run` rebuilds
//! `web/dist/` and fails if it differs from the commit.

/// A file of the map: its path under `/`, its content type and its bytes.
pub struct Asset {
    pub path: &'static str,
    pub content_type: &'static str,
    pub bytes: &'static [u8],
}

macro_rules! asset {
    ($path:literal, $kind:literal) => {
        Asset { path: $path, content_type: $kind, bytes: include_bytes!(concat!("../../web/dist", $path)) }
    };
}

/// Every file; the first is the page itself, served at `/`.
pub static ASSETS: &[Asset] = &[
    asset!("/index.html", "text/html; charset=utf-8"),
    asset!("/app.js", "text/javascript; charset=utf-8"),
    asset!("/style.css", "text/css; charset=utf-8"),
    asset!("/leaflet.js", "text/javascript; charset=utf-8"),
    asset!("/leaflet.css", "text/css; charset=utf-8"),
    asset!("/world.json", "application/json"),
    asset!("/LICENSES.txt", "text/plain; charset=utf-8"),
];

/// The file served at `path` (`/` is the page).
pub fn find(path: &str) -> Option<&'static Asset> {
    let path = if path == "/" { "/index.html" } else { path };
    ASSETS.iter().find(|a| a.path == path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_and_every_file_it_names_are_served() {
        let page = std::str::from_utf8(find("/").unwrap().bytes).unwrap();
        for name in ["leaflet.css", "style.css", "leaflet.js", "app.js"] {
            assert!(page.contains(&format!("\"{name}\"")), "{name} not in the page");
            assert!(find(&format!("/{name}")).is_some_and(|a| !a.bytes.is_empty()), "{name} not served");
        }
        let app = std::str::from_utf8(find("/app.js").unwrap().bytes).unwrap();
        assert!(app.contains("'world.json'") && find("/world.json").is_some());
        assert!(find("/../Cargo.toml").is_none() && find("/data/aircraft.json").is_none());
    }
}
