//! The book (`docs/book`, mdBook): it builds with the pinned mdbook (installed by
//! `tools/setup.sh`; a missing or other mdbook fails, it does not skip), every page of
//! `docs/book/src` is in its table of contents, every internal link and anchor of the built HTML
//! leads somewhere (parsed with `scraper`), the command-line chapter is what the binary makes
//! now (`cli-markdown`, like the man page), and headless Chromium opens the built book, its
//! search finds a word, and every picture of every page loads (`naturalWidth > 0`). The shell
//! blocks of the book run in `readme_commands.rs`.

use crate::support::BIN;
use crate::support::child::root;
use crate::support::servers;
use scraper::{Html, Selector};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The mdbook version `tools/setup.sh` pins, read from it.
fn pinned_version() -> String {
    let setup = std::fs::read_to_string(root().join("tools/setup.sh")).expect("tools/setup.sh");
    setup
        .lines()
        .find_map(|l| l.strip_prefix("MDBOOK_VERSION="))
        .expect("tools/setup.sh pins MDBOOK_VERSION")
        .trim()
        .to_string()
}

/// The book built into a fresh folder by the pinned mdbook.
fn build() -> (tempfile::TempDir, PathBuf) {
    let want = pinned_version();
    let version = Command::new("mdbook").arg("--version").output();
    let said = match version {
        Ok(out) => String::from_utf8_lossy(&out.stdout).trim().to_string(),
        Err(e) => panic!("mdbook not found ({e}): `bash tools/setup.sh` installs mdbook {want}"),
    };
    assert_eq!(
        said,
        format!("mdbook v{want}"),
        "`bash tools/setup.sh` installs the pinned mdbook"
    );
    let dir = tempfile::tempdir().expect("a folder for the book");
    let out = dir.path().join("book");
    let built = Command::new("mdbook")
        .arg("build")
        .arg(root().join("docs/book"))
        .arg("--dest-dir")
        .arg(&out)
        .output()
        .expect("run mdbook");
    let stderr = String::from_utf8_lossy(&built.stderr);
    assert!(built.status.success(), "mdbook build failed:\n{stderr}");
    for bad in ["[ERROR]", "[WARN]"] {
        assert!(!stderr.contains(bad), "mdbook build says:\n{stderr}");
    }
    (dir, out)
}

/// Every `.html` file under `dir`.
fn html_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir)
        .expect("read the built book")
        .flatten()
    {
        let path = entry.path();
        if path.is_dir() {
            html_files(&path, out);
        } else if path.extension().is_some_and(|x| x == "html") {
            out.push(path);
        }
    }
}

/// A page's links (`href` and `src`), the ids it holds, and whether its `<base href="/">` makes
/// its links relative to the book's root (mdBook's 404 page, served at any path).
struct Page {
    links: Vec<String>,
    ids: BTreeSet<String>,
    from_root: bool,
}

fn parse(path: &Path) -> Page {
    let text = std::fs::read_to_string(path).expect("a built page");
    let doc = Html::parse_document(&text);
    let sel = |s: &str| Selector::parse(s).expect("a selector");
    let mut links = Vec::new();
    for el in doc.select(&sel("[href], [src]")) {
        for attr in ["href", "src"] {
            if let Some(v) = el.value().attr(attr) {
                links.push(v.to_string());
            }
        }
    }
    let mut ids = BTreeSet::new();
    for el in doc.select(&sel("[id], a[name]")) {
        for attr in ["id", "name"] {
            if let Some(v) = el.value().attr(attr) {
                ids.insert(v.to_string());
            }
        }
    }
    let from_root = doc
        .select(&sel("base[href]"))
        .any(|b| b.value().attr("href") == Some("/"));
    Page {
        links,
        ids,
        from_root,
    }
}

/// `%20` and the like in a link, as the browser reads them.
fn unescape(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while let Some(&b) = bytes.get(i) {
        let hex = bytes
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match (b, hex) {
            (b'%', Some(v)) => {
                out.push(v);
                i += 3;
            }
            _ => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The broken internal links of the built book at `book`: `page: link (why)`.
fn broken_links(book: &Path) -> Vec<String> {
    let mut files = Vec::new();
    html_files(book, &mut files);
    let pages: BTreeMap<PathBuf, Page> = files.iter().map(|f| (f.clone(), parse(f))).collect();
    let mut broken = Vec::new();
    for (file, page) in &pages {
        let name = file
            .strip_prefix(book)
            .unwrap_or(file)
            .display()
            .to_string();
        for link in &page.links {
            let external = ["http:", "https:", "mailto:", "javascript:", "data:"]
                .iter()
                .any(|s| link.starts_with(s));
            if external {
                continue;
            }
            let (path, fragment) = link.split_once('#').unwrap_or((link, ""));
            let path = path.split('?').next().unwrap_or_default();
            let target = if path.is_empty() {
                file.clone()
            } else {
                // An absolute path, or any path under `<base href="/">`, starts at the root.
                let parent = if page.from_root || path.starts_with('/') {
                    book
                } else {
                    file.parent().unwrap_or(book)
                };
                let joined = parent.join(unescape(path.trim_start_matches('/')));
                match joined.canonicalize() {
                    Ok(t) => t,
                    Err(_) => {
                        broken.push(format!("{name}: {link} (no such file)"));
                        continue;
                    }
                }
            };
            if !target.starts_with(book) {
                broken.push(format!("{name}: {link} (leaves the book)"));
                continue;
            }
            if fragment.is_empty() {
                continue;
            }
            match pages.get(&target) {
                Some(p) if p.ids.contains(&unescape(fragment)) => {}
                Some(_) => broken.push(format!("{name}: {link} (no such anchor)")),
                None => {}
            }
        }
    }
    broken
}

#[test]
fn the_book_builds_and_no_internal_link_or_anchor_is_broken() {
    let (_dir, out) = build();
    let book = out.canonicalize().expect("the built book");
    for page in [
        "index.html",
        "getting-started.html",
        "cli.html",
        "benchmarks.html",
    ] {
        assert!(book.join(page).is_file(), "{page} is built");
    }
    let broken = broken_links(&book);
    assert!(
        broken.is_empty(),
        "broken links in the book:\n{}",
        broken.join("\n")
    );
    // Every page of docs/book/src is in the table of contents (else mdBook leaves it out).
    let src = root().join("docs/book/src");
    let summary = std::fs::read_to_string(src.join("SUMMARY.md")).expect("SUMMARY.md");
    for entry in std::fs::read_dir(&src).expect("docs/book/src").flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.ends_with(".md") && name != "SUMMARY.md" {
            assert!(
                summary.contains(&format!("]({name})")),
                "{name} is not in SUMMARY.md"
            );
        }
    }
}

#[test]
fn the_link_check_finds_a_broken_link_and_a_missing_anchor() {
    let dir = tempfile::tempdir().expect("a folder");
    let book = dir.path().canonicalize().expect("the folder");
    std::fs::write(
        book.join("a.html"),
        "<html><body><h1 id=\"top\">A</h1><a href=\"b.html#there\">b</a>\
         <a href=\"gone.html\">gone</a><a href=\"#top\">top</a><a href=\"#nowhere\">x</a>\
         <a href=\"https://example.org/\">out</a><img src=\"../outside.png\"></body></html>",
    )
    .expect("write a.html");
    std::fs::write(
        dir.path().join("b.html"),
        "<html><body><p id=\"here\">b</p></body></html>",
    )
    .expect("write b.html");
    let broken = broken_links(&book);
    assert_eq!(
        broken,
        vec![
            "a.html: b.html#there (no such anchor)".to_string(),
            "a.html: gone.html (no such file)".to_string(),
            "a.html: #nowhere (no such anchor)".to_string(),
            "a.html: ../outside.png (no such file)".to_string(),
        ]
    );
}

#[test]
fn the_command_line_chapter_is_what_the_binary_makes() {
    let out = Command::new(BIN)
        .arg("cli-markdown")
        .output()
        .expect("run cli-markdown");
    assert!(out.status.success());
    let made = String::from_utf8_lossy(&out.stdout);
    let page = std::fs::read_to_string(root().join("docs/book/src/cli.md")).expect("cli.md");
    assert!(
        made == page,
        "docs/book/src/cli.md is out of date: `make cli-md` writes it"
    );
    for sub in [
        "run",
        "check",
        "trace",
        "report",
        "simulate",
        "spec publish",
    ] {
        assert!(
            page.contains(&format!("## `tessla-telegraf {sub}`")),
            "cli.md has `{sub}`"
        );
    }
    assert!(
        !page.contains("## `tessla-telegraf cli-markdown`"),
        "the hidden subcommand has no section"
    );
}

/// Chromium's DOM of `url` after its scripts ran (virtual time), from a profile of its own.
fn dump_dom(chromium: &Path, url: &str) -> String {
    let profile = tempfile::tempdir().expect("a profile folder");
    let out_path = profile.path().join("dom.html");
    let mut child = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--virtual-time-budget=10000",
            "--dump-dom",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(url)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out_path).expect("dom file"))
        .stderr(Stdio::null())
        .spawn()
        .expect("start chromium");
    let deadline = Instant::now() + Duration::from_secs(120);
    let status = loop {
        if let Ok(Some(status)) = child.try_wait() {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("chromium on {url} did not end in 120 s");
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(status.success(), "chromium on {url}: {status}");
    std::fs::read_to_string(&out_path).unwrap_or_default()
}

/// Put into each page with pictures (in the test's copy of the book): once loaded, the page lists
/// each picture's `src` and `naturalWidth` in `<pre id="img-check">`.
const IMAGE_PROBE: &str = "<script>window.addEventListener('load', function () {\
    var p = document.createElement('pre'); p.id = 'img-check';\
    p.textContent = Array.prototype.map.call(document.images, function (i) {\
      return i.getAttribute('src') + ' ' + i.naturalWidth; }).join('\\n');\
    document.body.appendChild(p); });</script>";

#[test]
fn headless_chromium_opens_the_book_finds_a_word_and_loads_every_picture() {
    let Some(chromium) = servers::require("chromium", "chromium") else {
        return;
    };
    let (_dir, out) = build();
    let book = out.canonicalize().expect("the built book");
    // Opens: the introduction with the table of contents.
    let dom = dump_dom(&chromium, &format!("file://{}/index.html", book.display()));
    assert!(
        dom.contains("Runtime verification for digital twins"),
        "{dom}"
    );
    assert!(
        dom.contains("getting-started.html"),
        "the table of contents"
    );
    // Search (mdBook runs `?search=` on load): a word of the fleet chapter.
    let dom = dump_dom(
        &chromium,
        &format!("file://{}/index.html?search=takeover", book.display()),
    );
    let doc = Html::parse_document(&dom);
    let results = Selector::parse("#searchresults li a").expect("selector");
    let hits: Vec<String> = doc
        .select(&results)
        .filter_map(|a| a.value().attr("href").map(str::to_string))
        .collect();
    assert!(
        hits.iter().any(|h| h.starts_with("fleet.html")),
        "search for `takeover` finds the fleet chapter: {hits:?}"
    );
    // Pictures: every <img> of every page loads.
    let mut files = Vec::new();
    html_files(&book, &mut files);
    let mut checked = 0;
    for file in files {
        if file.file_name().is_some_and(|n| n == "print.html") {
            continue;
        }
        let text = std::fs::read_to_string(&file).expect("a page");
        if !text.contains("<img") {
            continue;
        }
        let probed = text.replace("</body>", &format!("{IMAGE_PROBE}</body>"));
        std::fs::write(&file, probed).expect("write the probe");
        let dom = dump_dom(&chromium, &format!("file://{}", file.display()));
        let doc = Html::parse_document(&dom);
        let pre = Selector::parse("pre#img-check").expect("selector");
        let list = doc
            .select(&pre)
            .next()
            .map(|p| p.text().collect::<String>())
            .unwrap_or_else(|| panic!("{}: the probe did not run", file.display()));
        for line in list.lines() {
            let (src, width) = line.rsplit_once(' ').unwrap_or((line, "0"));
            assert!(
                width.parse::<u32>().is_ok_and(|w| w > 0),
                "{}: picture {src} did not load (naturalWidth {width})",
                file.display()
            );
            checked += 1;
        }
    }
    // The report's page and its plot, the report example and the reproduction's four plots.
    assert!(checked >= 7, "only {checked} pictures checked");
}
