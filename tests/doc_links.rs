//! Every link into a heading of the README and docs/ names a heading that exists. The docs
//! cite each other's sections by anchor, and a heading retitled (a session's date range
//! widened) silently broke links to it twice.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// The anchor GitHub gives a heading: lower case, punctuation dropped (letters, digits,
/// `_`, `-` and spaces kept), spaces as hyphens.
fn slug(heading: &str) -> String {
    let kept: String = (heading.trim().to_lowercase().chars())
        .filter(|c| c.is_alphanumeric() || matches!(c, '_' | '-' | ' '))
        .collect();
    kept.replace(' ', "-")
}

/// The anchors of a Markdown file's headings (not counting lines in code blocks); a
/// repeated heading's anchors are numbered from its second (`-1`, `-2`, ...).
fn anchors(text: &str) -> HashSet<String> {
    let (mut found, mut repeats) = (HashSet::new(), HashMap::<String, usize>::new());
    let mut in_code = false;
    for line in text.lines() {
        if line.starts_with("```") {
            in_code = !in_code;
        }
        let heading = line.trim_start_matches('#');
        if in_code || heading.len() == line.len() || !heading.starts_with(' ') {
            continue;
        }
        let base = slug(heading);
        let seen = repeats.entry(base.clone()).or_insert(0);
        found.insert(match *seen {
            0 => base,
            n => format!("{base}-{n}"),
        });
        *seen += 1;
    }
    found
}

/// `(target file, anchor)` of each `](path#anchor)` link in `text` (an empty path: the file
/// itself).
fn heading_links(text: &str) -> Vec<(String, String)> {
    let mut links = Vec::new();
    for (at, _) in text.match_indices("](") {
        let rest = &text[at + 2..];
        let Some(end) = rest.find([')', ' ', '\n']) else {
            continue;
        };
        if let Some((path, anchor)) = rest[..end].split_once('#') {
            if !path.contains("://") {
                links.push((path.to_string(), anchor.to_string()));
            }
        }
    }
    links
}

fn markdown_files(root: &Path) -> Vec<PathBuf> {
    let mut files = vec![root.join("README.md")];
    let docs = std::fs::read_dir(root.join("docs")).expect("docs/ is read");
    files.extend(
        (docs.map(|entry| entry.expect("docs/ is listed").path()))
            .filter(|path| path.extension().is_some_and(|e| e == "md")),
    );
    files.sort();
    files
}

#[test]
fn slugs_follow_githubs_rule() {
    assert_eq!(
        slug("The label readers' pages, the ordered joins' queue (2026-11-30, third)"),
        "the-label-readers-pages-the-ordered-joins-queue-2026-11-30-third"
    );
    assert_eq!(
        slug("`--relabel` with one walk of the views"),
        "--relabel-with-one-walk-of-the-views"
    );
    let text = "# A\n```\n# not a heading\n```\n## A\n#no space\n";
    let expected: HashSet<String> = ["a", "a-1"].map(String::from).into();
    assert_eq!(anchors(text), expected);
    assert_eq!(
        heading_links("see [x](gpu.md#a-b) and [y](#c), [z](https://e.org/#d)"),
        [("gpu.md", "a-b"), ("", "c")].map(|(p, a)| (p.to_string(), a.to_string()))
    );
}

#[test]
fn every_heading_link_in_the_docs_resolves() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files = markdown_files(root);
    let read = |path: &Path| std::fs::read_to_string(path).expect("a Markdown file is read");
    let headings: HashMap<PathBuf, HashSet<String>> = (files.iter())
        .map(|path| (path.canonicalize().unwrap(), anchors(&read(path))))
        .collect();
    let mut broken = Vec::new();
    for file in &files {
        for (target, anchor) in heading_links(&read(file)) {
            let path = match target.is_empty() {
                true => file.clone(),
                false => file.parent().unwrap().join(&target),
            };
            let known = path.canonicalize().ok().and_then(|p| headings.get(&p));
            if !known.is_some_and(|anchors| anchors.contains(&anchor)) {
                broken.push(format!("{}: {target}#{anchor}", file.display()));
            }
        }
    }
    assert!(
        broken.is_empty(),
        "links to no heading:\n{}",
        broken.join("\n")
    );
}
