//! The documentation stays true to the tree: every relative link of the README, the guides in
//! `docs/`, ARCHITECTURE.md and BENCHMARKS.md leads to a file that exists (and a heading that
//! exists, for an anchor), and every path and symbol ARCHITECTURE.md names exists: a symbol
//! written after a path (`path` `Type::function`) is a word of that file.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the repository")
        .to_path_buf()
}

/// The Markdown files that are documentation.
fn documents() -> Vec<PathBuf> {
    let root = repository();
    let mut files: Vec<PathBuf> = ["README.md", "ARCHITECTURE.md", "BENCHMARKS.md"]
        .iter()
        .map(|name| root.join(name))
        .collect();
    let mut guides: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/")
        .flatten()
        .map(|entry| entry.path())
        .filter(|path| path.extension().is_some_and(|e| e == "md"))
        .collect();
    guides.sort();
    files.extend(guides);
    files
}

/// A heading's anchor as GitHub makes it: lower case, punctuation but `-` and `_` dropped,
/// spaces as `-`.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// A Markdown text's lines outside code blocks.
fn prose(text: &str) -> impl Iterator<Item = &str> {
    let mut fenced = false;
    text.lines().filter(move |line| {
        if line.starts_with("```") {
            fenced = !fenced;
            return false;
        }
        !fenced
    })
}

/// The anchors of a Markdown text's headings (outside code blocks).
fn anchors(text: &str) -> BTreeSet<String> {
    prose(text)
        .filter(|line| line.starts_with('#'))
        .map(|line| slug(line.trim_start_matches('#')))
        .collect()
}

/// The targets of a text's Markdown links `[text](target)`, outside code blocks.
fn links(text: &str) -> Vec<String> {
    let mut found = Vec::new();
    for line in prose(text) {
        let mut rest = line;
        while let Some(at) = rest.find("](") {
            rest = &rest[at + 2..];
            if let Some(end) = rest.find(')') {
                found.push(rest[..end].to_owned());
                rest = &rest[end..];
            }
        }
    }
    found
}

#[test]
fn every_relative_link_leads_to_a_file_and_heading_that_exist() {
    let mut broken = Vec::new();
    for document in documents() {
        let text = std::fs::read_to_string(&document).expect("read");
        let dir = document.parent().expect("a directory");
        for target in links(&text) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (path, anchor) = target.split_once('#').unwrap_or((&target, ""));
            let file = if path.is_empty() {
                document.clone()
            } else {
                dir.join(path)
            };
            if !file.exists() {
                broken.push(format!("{}: {target} (no such file)", document.display()));
                continue;
            }
            if !anchor.is_empty() && file.extension().is_some_and(|e| e == "md") {
                let headings = anchors(&std::fs::read_to_string(&file).expect("read"));
                if !headings.contains(anchor) {
                    broken.push(format!(
                        "{}: {target} (no such heading)",
                        document.display()
                    ));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

/// Whether a backticked token is a path of the tree (it has a `/` and no spaces).
fn is_path(token: &str) -> bool {
    token.contains('/') && !token.contains(' ') && !token.starts_with('-')
}

/// Whether a backticked token is a symbol: `Type`, `function`, `Type::function`, `CONSTANT`,
/// maybe with `()`.
fn is_symbol(token: &str) -> bool {
    let token = token.trim_end_matches("()");
    !token.is_empty()
        && token
            .split("::")
            .all(|part| !part.is_empty() && part.chars().all(|c| c.is_alphanumeric() || c == '_'))
        && token
            .chars()
            .next()
            .is_some_and(|c| c.is_alphabetic() || c == '_')
}

fn is_word_of(word: &str, text: &str) -> bool {
    text.match_indices(word).any(|(at, _)| {
        let before = text[..at].chars().next_back();
        let after = text[at + word.len()..].chars().next();
        let boundary = |c: Option<char>| !c.is_some_and(|c| c.is_alphanumeric() || c == '_');
        boundary(before) && boundary(after)
    })
}

#[test]
fn every_path_and_symbol_architecture_md_names_exists() {
    let root = repository();
    let text = std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let mut missing = Vec::new();
    let mut checked = 0;
    for line in prose(&text) {
        // Each table cell or line names its own paths; a symbol belongs to the path before it.
        for cell in line.split('|') {
            let mut current: Option<PathBuf> = None;
            for (i, token) in cell.split('`').enumerate() {
                if i % 2 == 0 {
                    continue;
                }
                if is_path(token) {
                    let path = root.join(token.trim_end_matches('/'));
                    checked += 1;
                    if path.exists() {
                        current = path.is_file().then_some(path);
                    } else {
                        missing.push(format!("path `{token}`"));
                        current = None;
                    }
                } else if let (true, Some(file)) = (is_symbol(token), &current) {
                    let source = std::fs::read_to_string(file).unwrap_or_default();
                    let word = token
                        .trim_end_matches("()")
                        .rsplit("::")
                        .next()
                        .unwrap_or("");
                    checked += 1;
                    if !is_word_of(word, &source) {
                        missing.push(format!(
                            "symbol `{token}` in {}",
                            file.strip_prefix(&root).unwrap_or(file).display()
                        ));
                    }
                }
            }
        }
    }
    assert!(
        checked > 50,
        "ARCHITECTURE.md names only {checked} paths and symbols"
    );
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md names what no longer exists:\n{}",
        missing.join("\n")
    );
}

#[test]
fn the_checks_read_what_they_should() {
    assert_eq!(
        slug("`scout echo` and the state schema"),
        "scout-echo-and-the-state-schema"
    );
    assert_eq!(
        slug("Status schema (`scout status --json`)"),
        "status-schema-scout-status---json"
    );
    assert_eq!(links("a [b](c.md#d) e [f](g)"), ["c.md#d", "g"]);
    assert!(is_path("gateway/src/core.rs") && !is_path("a b/c"));
    assert!(is_symbol("Core::handle_rx") && is_symbol("poll_transmit()") && !is_symbol("a b"));
    assert!(is_word_of("handle_rx", "fn handle_rx(") && !is_word_of("handle", "fn handle_rx("));
}
