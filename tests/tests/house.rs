//! The house rules a reader relies on, checked on the source text of every crate in the
//! workspace: no module over 700 lines of non-test code, no non-test function over 80
//! lines, and no import circles between a crate's files (two files that use each other,
//! directly or through others). A test module is the code from a column-0
//! `#[cfg(test)]` that opens a `mod`; the crate roots (`lib.rs`, `main.rs`) are left out
//! of the import graph because they only declare and re-export.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const MODULE_LINES: usize = 700;
const FUNCTION_LINES: usize = 80;

/// The `src` folders of the workspace's crates, relative to the workspace root.
const CRATES: &[&str] = &[
    "client/src",
    "client/receivers/src",
    "client/gnss/src",
    "client/ros2/src",
    "models/inference/src",
    "models/lab/src",
    "daemon/src",
    "tests/kit/src",
    "tests/tools/src",
    "examples/src",
];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().flatten().collect();
    entries.sort_by_key(|e| e.path());
    for e in entries {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The lines before the file's test module.
fn non_test(text: &str) -> Vec<&str> {
    let lines: Vec<&str> = text.lines().collect();
    for (i, l) in lines.iter().enumerate() {
        if l.trim_end() == "#[cfg(test)]" {
            let next = lines[i + 1..]
                .iter()
                .find(|n| !n.trim_start().starts_with("#["))
                .map(|n| n.trim_start());
            if next.is_some_and(|n| n.starts_with("mod ") || n.starts_with("pub mod ")) {
                return lines[..i].to_vec();
            }
        }
    }
    lines
}

/// A line without its `//` comment and the contents of its string and char literals,
/// so braces inside them are not counted.
fn code_of(line: &str) -> String {
    let mut out = String::new();
    let mut chars = line.chars().peekable();
    let mut in_str = false;
    while let Some(c) = chars.next() {
        if in_str {
            match c {
                '\\' => {
                    chars.next();
                }
                '"' => in_str = false,
                _ => {}
            }
            continue;
        }
        match c {
            '"' => in_str = true,
            '/' if chars.peek() == Some(&'/') => break,
            '\'' => {
                // A char literal such as '{' or '\''; a lifetime has no closing quote.
                let rest: String = chars.clone().take(3).collect();
                if let Some(escaped) = rest.strip_prefix('\\') {
                    let close = escaped.find('\'').map(|i| i + 2);
                    if let Some(n) = close {
                        for _ in 0..n {
                            chars.next();
                        }
                    }
                } else if rest.chars().nth(1) == Some('\'') {
                    chars.next();
                    chars.next();
                }
            }
            _ => out.push(c),
        }
    }
    out
}

fn is_fn_start(line: &str) -> Option<String> {
    let t = line.trim_start();
    let mut rest = t;
    for prefix in [
        "pub(crate) ",
        "pub(super) ",
        "pub ",
        "const ",
        "async ",
        "unsafe ",
        "extern \"C\" ",
    ] {
        if let Some(r) = rest.strip_prefix(prefix) {
            rest = r;
        }
    }
    let name = rest.strip_prefix("fn ")?;
    Some(
        name.chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect(),
    )
}

/// Every non-test function longer than the limit: (name, first line, lines).
fn long_functions(lines: &[&str]) -> Vec<(String, usize, usize)> {
    let mut found = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let Some(name) = is_fn_start(lines[i]) else {
            i += 1;
            continue;
        };
        let (mut depth, mut opened, mut end) = (0i64, false, None);
        for (j, l) in lines.iter().enumerate().skip(i) {
            for c in code_of(l).chars() {
                match c {
                    '{' => {
                        depth += 1;
                        opened = true;
                    }
                    '}' => depth -= 1,
                    ';' if !opened && depth == 0 => {
                        end = Some(j);
                    }
                    _ => {}
                }
                if end.is_some() || (opened && depth == 0) {
                    break;
                }
            }
            if end.is_some() {
                break;
            }
            if opened && depth == 0 {
                let n = j - i + 1;
                if n > FUNCTION_LINES {
                    found.push((name.clone(), i + 1, n));
                }
                break;
            }
        }
        i += 1;
    }
    found
}

/// A file's module path inside its crate (`a::b` for `a/b.rs` or `a/b/mod.rs`); empty for
/// the crate roots and binaries.
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap();
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    if (parts.len() == 1 && (parts[0] == "lib" || parts[0] == "main")) || parts[0] == "bin" {
        return Vec::new();
    }
    parts
}

/// The module paths a file names through `crate::…`, `super::…` or `self::…`.
fn references(module: &[String], lines: &[&str]) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    // `self` of `a/b.rs` or `a/b/mod.rs` is `a::b`; `super` is `a`.
    let here: Vec<String> = module.to_vec();
    for l in lines {
        let code = code_of(l);
        for (start, anchor) in [("crate::", None), ("super::", Some(1)), ("self::", Some(0))] {
            let mut from = 0;
            while let Some(pos) = code[from..].find(start) {
                let at = from + pos;
                from = at + start.len();
                let before = code[..at].chars().last();
                if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                    continue;
                }
                let mut base: Vec<String> = match anchor {
                    None => Vec::new(),
                    Some(up) => {
                        if here.len() < up {
                            continue;
                        }
                        here[..here.len() - up].to_vec()
                    }
                };
                let mut tail = &code[from..];
                while tail.starts_with("super::") {
                    base.pop();
                    tail = &tail["super::".len()..];
                }
                let path: Vec<String> = tail
                    .split("::")
                    .map(|s| {
                        s.chars()
                            .take_while(|c| c.is_alphanumeric() || *c == '_')
                            .collect::<String>()
                    })
                    .take_while(|s| !s.is_empty())
                    .collect();
                base.extend(path);
                out.push(base);
            }
        }
    }
    out
}

/// Strongly connected groups of more than one file (Tarjan).
fn circles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct T<'a> {
        edges: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<String, usize>,
        low: BTreeMap<String, usize>,
        stack: Vec<String>,
        on: BTreeSet<String>,
        next: usize,
        out: Vec<Vec<String>>,
    }
    fn visit(t: &mut T, v: &str) {
        t.index.insert(v.to_string(), t.next);
        t.low.insert(v.to_string(), t.next);
        t.next += 1;
        t.stack.push(v.to_string());
        t.on.insert(v.to_string());
        let next: Vec<String> = t.edges.get(v).into_iter().flatten().cloned().collect();
        for w in next {
            if !t.index.contains_key(&w) {
                visit(t, &w);
                let lw = t.low[&w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if t.on.contains(&w) {
                let iw = t.index[&w];
                let lv = t.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if t.low[v] == t.index[v] {
            let mut group = Vec::new();
            while let Some(w) = t.stack.pop() {
                t.on.remove(&w);
                let done = w == v;
                group.push(w);
                if done {
                    break;
                }
            }
            if group.len() > 1 {
                group.sort();
                t.out.push(group);
            }
        }
    }
    let mut t = T {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in edges.keys() {
        if !t.index.contains_key(v) {
            visit(&mut t, v);
        }
    }
    t.out
}

#[test]
fn modules_functions_and_imports_keep_the_house_rules() {
    let root = root();
    let mut problems = Vec::new();
    for krate in CRATES {
        let src = root.join(krate);
        let mut files = Vec::new();
        rust_files(&src, &mut files);
        let modules: BTreeMap<Vec<String>, String> = files
            .iter()
            .map(|f| (module_of(&src, f), f.display().to_string()))
            .filter(|(m, _)| !m.is_empty())
            .collect();
        let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for f in &files {
            let text = std::fs::read_to_string(f).unwrap();
            let lines = non_test(&text);
            let name = f.strip_prefix(&root).unwrap().display().to_string();
            if lines.len() > MODULE_LINES {
                problems.push(format!("{name}: {} non-test lines", lines.len()));
            }
            for (func, line, n) in long_functions(&lines) {
                problems.push(format!("{name}:{line}: fn {func} has {n} lines"));
            }
            let module = module_of(&src, f);
            if module.is_empty() {
                continue;
            }
            for mut path in references(&module, &lines) {
                while !path.is_empty() && !modules.contains_key(&path) {
                    path.pop();
                }
                if path.is_empty() || path == module {
                    continue;
                }
                edges
                    .entry(f.display().to_string())
                    .or_default()
                    .insert(modules[&path].clone());
            }
        }
        for group in circles(&edges) {
            let names: Vec<String> = group
                .iter()
                .map(|g| {
                    Path::new(g)
                        .strip_prefix(&root)
                        .unwrap()
                        .display()
                        .to_string()
                })
                .collect();
            problems.push(format!("import circle: {}", names.join(" <-> ")));
        }
    }
    assert!(
        problems.is_empty(),
        "house rules broken:\n{}",
        problems.join("\n")
    );
}
