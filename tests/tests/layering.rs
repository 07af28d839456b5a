//! Every crate of the workspace layers its modules: no import circle between a crate's top-level
//! modules, and none between the sibling modules inside one top-level module. A circle means
//! neither side can be understood, tested or moved without the other; the code that both sides
//! need belongs in a module below them.
//!
//! Read from the sources (no compiler): the module tree is followed from `src/lib.rs` through its
//! `mod` declarations; comments, string and char literals and items under a `test` cfg are left
//! out. Every path (`use` trees, and `crate::`, `super::`, `self::` or child-module paths in
//! expressions) is resolved, through re-exports, to the module that defines what it names.
//! Reading the files is kept apart from the graphs, which are built from (module, text) pairs, so
//! the parser is also tested here on a small made-up crate with a known circle.

use std::collections::{BTreeMap, BTreeSet, HashSet};
use std::path::{Path, PathBuf};

/// The crates checked: folder below the workspace, fewest modules its tree must have, fewest
/// edges between its top-level modules. A walk or a parser that broke finds fewer, and fails.
const CRATES: &[(&str, usize, usize)] = &[
    ("rt", 30, 12),
    ("rt/model", 40, 45),
    ("actors", 14, 7),
    ("transport", 28, 12),
    ("tools", 22, 16),
    ("tests", 4, 1),
];

/// Edges (crate, from, to) tolerated in a circle; a module inside a top-level module `y` is named
/// `y::module`. An entry whose edge no longer exists fails, so the list only shrinks.
const ALLOWED: &[(&str, &str, &str)] = &[];

/// The name of the crate root in the top-level graph (when lib.rs itself uses a module).
const ROOT: &str = "<root>";

/// Words that name no item after an item keyword; the first nine define a named item.
const KEYWORDS: &[&str] = &[
    "fn", "struct", "enum", "union", "trait", "type", "const", "static", "mod", "mut", "unsafe",
    "extern", "async", "impl", "pub", "use", "where", "for", "in", "self", "super", "crate",
    "Self",
];

/// One source file: its module path below the crate root, the name shown for it, its text.
struct Source {
    module: Vec<String>,
    file: String,
    text: String,
}

// ----------------------------------------------------------------------------- reading files

/// The sources of the crate in `dir` (below `workspace`), from `src/lib.rs` down its `mod x;`.
fn read_crate(workspace: &Path, dir: &str) -> Vec<Source> {
    let mut out = Vec::new();
    let lib = workspace.join(dir).join("src").join("lib.rs");
    read_module(workspace, Vec::new(), &lib, &mut out);
    out
}

/// Reads `file` as `module`, then the files of the modules it declares with `mod x;`.
fn read_module(workspace: &Path, module: Vec<String>, file: &Path, out: &mut Vec<Source>) {
    let text = std::fs::read_to_string(file)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", file.display()));
    let prepared = prepare(&text);
    let (_, declared) = module_spans(&prepared, &module);
    let shown = file.strip_prefix(workspace).unwrap_or(file);
    out.push(Source {
        module: module.clone(),
        file: shown.display().to_string(),
        text,
    });
    // `mod x;` in lib.rs or a mod.rs looks beside the file, in `m.rs` into `m/`.
    let mut here = file.parent().expect("a file has a folder").to_path_buf();
    let stem = file.file_stem().expect("a file name").to_string_lossy();
    if stem != "lib" && stem != "mod" {
        here.push(stem.as_ref());
    }
    for child in declared {
        let mut at = here.clone();
        for inline in &child[module.len()..child.len() - 1] {
            at.push(inline);
        }
        let name = child.last().expect("a declared module has a name");
        let candidates: [PathBuf; 2] =
            [at.join(format!("{name}.rs")), at.join(name).join("mod.rs")];
        let target = candidates.iter().find(|c| c.exists()).unwrap_or_else(|| {
            panic!("{}: `mod {name};` has no file", shown.display());
        });
        read_module(workspace, child.clone(), target, out);
    }
}

// ----------------------------------------------------------------------------- lexing

/// True for the bytes of an identifier.
fn is_word(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_'
}

/// True when `code[i]` may start a word: at the start, or after a byte that is no word's.
fn word_start(code: &[u8], i: usize) -> bool {
    i == 0 || !is_word(code[i - 1])
}

/// The end of the identifier starting at `i`, if one does.
fn ident_end(code: &[u8], i: usize) -> Option<usize> {
    let first = *code.get(i)?;
    if !(first.is_ascii_alphabetic() || first == b'_') {
        return None;
    }
    Some(i + code[i..].iter().take_while(|&&b| is_word(b)).count())
}

/// The first index at or after `i` that is not whitespace.
fn skip_ws(code: &[u8], i: usize) -> usize {
    i + code
        .get(i..)
        .map_or(0, |c| c.len() - c.trim_ascii_start().len())
}

/// Each identifier of `code` that starts a word: (start, end).
fn words(code: &[u8]) -> impl Iterator<Item = (usize, usize)> + '_ {
    let mut i = 0;
    std::iter::from_fn(move || {
        while i < code.len() {
            let start = i;
            match ident_end(code, i).filter(|_| word_start(code, start)) {
                Some(end) => {
                    i = end;
                    return Some((start, end));
                }
                None => i += 1,
            }
        }
        None
    })
}

/// Where `needle` next occurs in `hay` at or after `from`.
fn find(hay: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    let mut windows = hay.get(from..)?.windows(needle.len());
    windows.position(|w| w == needle).map(|p| p + from)
}

/// True when `code[i..]` starts with `s`.
fn at(code: &[u8], i: usize, s: &[u8]) -> bool {
    code.get(i..).is_some_and(|rest| rest.starts_with(s))
}

/// Spaces over `code[a..b]`, newlines kept (so lines keep their numbers).
fn wipe(code: &mut [u8], a: usize, b: usize) {
    for byte in code.iter_mut().take(b).skip(a).filter(|b| **b != b'\n') {
        *byte = b' ';
    }
}

/// At `i`, the opening of a raw string (`r#"`, `br"`): its length and its number of `#`.
fn raw_string_open(src: &[u8], i: usize) -> Option<(usize, usize)> {
    let j = i + usize::from(at(src, i, b"b"));
    let hashes = src.get(j + 1..)?.iter().take_while(|&&b| b == b'#').count();
    let open = at(src, j, b"r") && at(src, j + 1 + hashes, b"\"");
    open.then_some((j + hashes + 2 - i, hashes))
}

/// `text` with comments, string and char literals replaced by spaces.
fn blank(text: &str) -> Vec<u8> {
    let src = text.as_bytes();
    let mut out = src.to_vec();
    let n = src.len();
    let mut i = 0;
    while i < n {
        let c = src[i];
        let fresh = word_start(src, i);
        let end = if at(src, i, b"//") {
            Some(find(src, b"\n", i).unwrap_or(n))
        } else if at(src, i, b"/*") {
            let (mut depth, mut j) = (1, i + 2);
            while j < n && depth > 0 {
                let step = i32::from(at(src, j, b"/*")) - i32::from(at(src, j, b"*/"));
                depth += step;
                j += if step == 0 { 1 } else { 2 };
            }
            Some(j)
        } else if let (Some((open, hashes)), true) = (raw_string_open(src, i), fresh) {
            let close = [b"\"".to_vec(), vec![b'#'; hashes]].concat();
            Some(find(src, &close, i + open).map_or(n, |j| j + close.len()))
        } else if c == b'"' || (c == b'b' && at(src, i, b"b\"") && fresh) {
            let mut j = i + 1 + usize::from(c == b'b');
            while j < n && src[j] != b'"' {
                j += if src[j] == b'\\' { 2 } else { 1 };
            }
            Some(j + 1)
        } else if c == b'\'' {
            char_literal_end(src, i)
        } else {
            None
        };
        match end {
            Some(j) => {
                wipe(&mut out, i, j);
                i = j;
            }
            None => i += 1,
        }
    }
    out
}

/// At a `'`, the end of the char literal it opens; `None` for a lifetime.
fn char_literal_end(src: &[u8], i: usize) -> Option<usize> {
    if at(src, i + 1, b"\\") {
        return Some(find(src, b"'", i + 3).map_or(src.len(), |j| j + 1));
    }
    if at(src, i + 2, b"'") {
        return Some(i + 3);
    }
    // A character of several bytes.
    let j = find(src, b"'", i + 1).filter(|&j| src[i + 1] > 127 && j - i <= 5)?;
    Some(j + 1)
}

/// The index after the bracket closing the one at `i`.
fn match_close(code: &[u8], i: usize) -> usize {
    let open = code[i];
    let close = b"})]"[b"{([".iter().position(|&b| b == open).unwrap_or(2)];
    let mut depth = 0i64;
    for (j, &b) in code.iter().enumerate().skip(i) {
        depth += i64::from(b == open) - i64::from(b == close);
        if depth == 0 {
            return j + 1;
        }
    }
    code.len()
}

/// True for a cfg predicate that holds only in a test build (`test`, `all(test, loom)`, but
/// not `not(test)`).
fn is_test_cfg(pred: &[u8]) -> bool {
    let word = |w: &'static [u8]| words(pred).filter(move |&(a, b)| &pred[a..b] == w);
    let negated = word(b"not").any(|(_, e)| {
        let j = skip_ws(pred, e + 1);
        at(pred, e, b"(") && at(pred, j, b"test") && at(pred, skip_ws(pred, j + 4), b")")
    });
    word(b"test").next().is_some() && !negated
}

/// Blanks every item gated on a test cfg: its attributes and the item, up to its `;` or its
/// `{...}`, whichever comes first outside brackets.
fn drop_test_items(code: &mut [u8]) {
    let mut pos = 0;
    while let Some(start) = find(code, b"#[cfg(", pos) {
        let inner = start + 6;
        let Some(close) = code[inner..].iter().position(|&b| b == b']') else {
            break;
        };
        let close = inner + close;
        if close == inner || code[close - 1] != b')' {
            pos = start + 1;
            continue;
        }
        if !is_test_cfg(&code[inner..close - 1]) {
            pos = close + 1;
            continue;
        }
        let mut j = skip_ws(code, close + 1);
        while at(code, j, b"#[") {
            j = skip_ws(code, match_close(code, j + 1));
        }
        let mut depth = 0i64;
        let mut end = code.len();
        while j < code.len() {
            match code[j] {
                b'(' | b'[' => depth += 1,
                b')' | b']' => depth -= 1,
                b';' if depth == 0 => {
                    end = j + 1;
                    break;
                }
                b'{' if depth == 0 => {
                    end = match_close(code, j);
                    break;
                }
                _ => {}
            }
            j += 1;
        }
        wipe(code, start, end);
        pos = end;
    }
}

/// A file's code as a build without tests reads it, with its brace depths and line starts.
struct Prepared {
    code: Vec<u8>,
    /// `depth[i]`: `{` minus `}` in `code[..i]`.
    depth: Vec<i64>,
    newlines: Vec<usize>,
}

/// Blanks comments, literals and test items of `text`, and indexes the result.
fn prepare(text: &str) -> Prepared {
    let mut code = blank(text);
    drop_test_items(&mut code);
    let depth = code.iter().scan(0, |d, &b| {
        *d += i64::from(b == b'{') - i64::from(b == b'}');
        Some(*d)
    });
    let depth = std::iter::once(0).chain(depth).collect();
    let newlines = (0..code.len()).filter(|&i| code[i] == b'\n').collect();
    Prepared {
        code,
        depth,
        newlines,
    }
}

impl Prepared {
    /// The line (from 1) of byte `i`.
    fn line(&self, i: usize) -> usize {
        self.newlines.partition_point(|&nl| nl < i) + 1
    }
}

// ----------------------------------------------------------------------------- module tree

/// A module's stretch of a file: the whole file, or an inline `mod x { ... }`.
struct Span {
    start: usize,
    end: usize,
    path: Vec<String>,
    depth: i64,
}

/// The spans of the modules in a file of module `base`, and the modules it declares with
/// `mod x;` (full paths, inline modules included).
fn module_spans(p: &Prepared, base: &[String]) -> (Vec<Span>, Vec<Vec<String>>) {
    let code = &p.code;
    let mut spans = vec![Span {
        start: 0,
        end: code.len(),
        path: base.to_vec(),
        depth: 0,
    }];
    let mut declared = Vec::new();
    for (i, after) in words(code).filter(|&(i, e)| &code[i..e] == b"mod") {
        let j = skip_ws(code, after);
        let Some(e) = ident_end(code, j).filter(|_| j > after) else {
            continue;
        };
        let k = skip_ws(code, e);
        let mut path = module_at(&spans, i).to_vec();
        path.push(String::from_utf8_lossy(&code[j..e]).into_owned());
        match code.get(k) {
            Some(b'{') => spans.push(Span {
                start: k,
                end: match_close(code, k),
                path,
                depth: p.depth[k] + 1,
            }),
            Some(b';') => declared.push(path),
            _ => {}
        }
    }
    (spans, declared)
}

/// The module whose code is at byte `i`: the innermost span holding it.
fn module_at(spans: &[Span], i: usize) -> &[String] {
    let mut best = &spans[0];
    for s in spans {
        if s.start <= i && i < s.end && s.depth >= best.depth {
            best = s;
        }
    }
    &best.path
}

/// What a module holds, as far as resolving paths goes.
#[derive(Default)]
struct Module {
    children: BTreeSet<String>,
    /// Names of the items it defines.
    items: BTreeSet<String>,
    /// Names a `use` brings in, with the path they stand for.
    imports: BTreeMap<String, Vec<String>>,
}

/// A path written in a module, where, and how.
struct Reference {
    owner: Vec<String>,
    file: String,
    line: usize,
    path: Vec<String>,
    /// In a `pub use` (a facade, not a user).
    facade: bool,
    is_use: bool,
}

/// A crate's modules and every path its code writes.
#[derive(Default)]
struct Crate {
    modules: BTreeMap<Vec<String>, Module>,
    refs: Vec<Reference>,
}

/// The crate made of `sources`.
fn parse_crate(sources: &[Source]) -> Crate {
    let mut krate = Crate::default();
    let mut files = Vec::new();
    for source in sources {
        let prepared = prepare(&source.text);
        let (spans, _) = module_spans(&prepared, &source.module);
        for span in &spans {
            krate.modules.entry(span.path.clone()).or_default();
            if let Some((name, parent)) = span.path.split_last() {
                let parent = krate.modules.entry(parent.to_vec()).or_default();
                parent.children.insert(name.clone());
            }
        }
        files.push((source, prepared, spans));
    }
    for (source, prepared, spans) in &files {
        krate.scan_items(prepared, spans);
        let uses = krate.scan_uses(&source.file, prepared, spans);
        krate.scan_paths(&source.file, prepared, spans, &uses);
    }
    krate
}

/// The `use` tree in `code[start..end]` as leaves: (path, name it brings in, byte of its last
/// segment). `*` ends a glob's path; `self` names the module before it.
fn parse_use(code: &[u8], start: usize, end: usize) -> Vec<(Vec<String>, Option<String>, usize)> {
    let mut toks: Vec<(String, usize)> = Vec::new();
    let mut i = start;
    while i < end {
        if at(&code[..end], i, b"::") {
            toks.push(("::".into(), i));
            i += 2;
        } else if let Some(e) = ident_end(&code[..end], i) {
            toks.push((String::from_utf8_lossy(&code[i..e]).into_owned(), i));
            i = e;
        } else {
            if matches!(code[i], b'{' | b'}' | b',' | b'*') {
                toks.push(((code[i] as char).to_string(), i));
            }
            i += 1;
        }
    }
    let mut leaves = Vec::new();
    let mut i = 0;
    while i < toks.len() {
        i = use_tree(&toks, i, &[], start, &mut leaves);
        if toks.get(i).is_some_and(|t| t.0 == ",") {
            i += 1;
        }
    }
    leaves
}

/// One use tree from token `i` below `prefix`, its leaves pushed; the token after it.
fn use_tree(
    toks: &[(String, usize)],
    mut i: usize,
    prefix: &[String],
    start: usize,
    leaves: &mut Vec<(Vec<String>, Option<String>, usize)>,
) -> usize {
    let mut segs = prefix.to_vec();
    let mut last_pos = toks.get(i).map_or(start, |t| t.1);
    while let Some((t, p)) = toks.get(i) {
        match t.as_str() {
            "::" => i += 1,
            "{" => {
                i += 1;
                while toks.get(i).is_some_and(|t| t.0 != "}") {
                    i = use_tree(toks, i, &segs, start, leaves);
                    if toks.get(i).is_some_and(|t| t.0 == ",") {
                        i += 1;
                    }
                }
                return i + 1;
            }
            "*" => {
                segs.push("*".into());
                leaves.push((segs, None, *p));
                return i + 1;
            }
            "," | "}" => break,
            "as" => {
                let alias = toks.get(i + 1).map(|t| t.0.clone());
                leaves.push((segs, alias, last_pos));
                return i + 2;
            }
            _ => {
                segs.push(t.clone());
                last_pos = *p;
                i += 1;
            }
        }
    }
    if !segs.is_empty() && segs != prefix {
        let mut name = segs.last().cloned();
        if name.as_deref() == Some("self") {
            segs.pop();
            name = segs.last().cloned();
        }
        leaves.push((segs, name, last_pos));
    }
    i
}

impl Crate {
    /// Records the names each module of a file defines (at the module's own brace depth).
    fn scan_items(&mut self, p: &Prepared, spans: &[Span]) {
        let code = &p.code;
        for (i, e) in words(code) {
            let item = KEYWORDS[..9].iter().any(|k| k.as_bytes() == &code[i..e]);
            let mut j = skip_ws(code, e);
            if !item || j == e || (i > 0 && code[i - 1] == b'\'') {
                continue;
            }
            if let Some(m) = ident_end(code, j).filter(|&m| &code[j..m] == b"mut") {
                let k = skip_ws(code, m);
                if k > m && ident_end(code, k).is_some() {
                    j = k;
                }
            }
            let Some(name_end) = ident_end(code, j) else {
                continue;
            };
            let name = String::from_utf8_lossy(&code[j..name_end]).into_owned();
            if KEYWORDS.contains(&name.as_str()) {
                continue; // `const fn f`: `fn f` comes next
            }
            let owner = module_at(spans, i);
            let own_depth = spans
                .iter()
                .filter(|s| s.path == owner)
                .map(|s| s.depth)
                .max();
            if p.depth[i] == own_depth.unwrap_or(0) {
                let module = self.modules.get_mut(owner).expect("a known module");
                module.items.insert(name);
            }
        }
    }

    /// Records the leaves of every `use` in a file (as references and as imported names);
    /// returns the byte ranges of the `use` statements.
    fn scan_uses(&mut self, file: &str, p: &Prepared, spans: &[Span]) -> Vec<(usize, usize)> {
        let code = &p.code;
        let mut ranges = Vec::new();
        for (at, e) in words(code) {
            if &code[at..e] != b"use" || !code.get(e).is_some_and(u8::is_ascii_whitespace) {
                continue;
            }
            let owner = module_at(spans, at).to_vec();
            let facade = ends_with_pub(&code[at.saturating_sub(40)..at]);
            let end = find(code, b";", at + 4).unwrap_or(code.len());
            ranges.push((at, end));
            for (leaf, alias, pos) in parse_use(code, at + 4, end) {
                self.refs.push(Reference {
                    owner: owner.clone(),
                    file: file.to_owned(),
                    line: p.line(pos),
                    path: leaf.clone(),
                    facade,
                    is_use: true,
                });
                if let Some(alias) = alias.filter(|a| a != "_") {
                    let module = self.modules.get_mut(&owner).expect("a known module");
                    module.imports.insert(alias, leaf);
                }
            }
        }
        ranges
    }

    /// Records every path outside a `use` that starts with `crate`, `super`, `self` or a
    /// child module's name (`pub(in crate::x)` aside).
    fn scan_paths(&mut self, file: &str, p: &Prepared, spans: &[Span], uses: &[(usize, usize)]) {
        let code = &p.code;
        let mut resume = 0;
        for (start, first_end) in words(code) {
            if start < resume || (start > 0 && matches!(code[start - 1], b':' | b'$')) {
                continue;
            }
            let mut segs = vec![String::from_utf8_lossy(&code[start..first_end]).into_owned()];
            let mut end = first_end;
            loop {
                let j = skip_ws(code, end);
                if !at(code, j, b"::") {
                    break;
                }
                let k = skip_ws(code, j + 2);
                let Some(e) = ident_end(code, k) else { break };
                segs.push(String::from_utf8_lossy(&code[k..e]).into_owned());
                end = e;
            }
            resume = end;
            if segs.len() < 2 || uses.iter().any(|&(a, b)| a <= start && start < b) {
                continue;
            }
            let owner = module_at(spans, start);
            let first = segs[0].as_str();
            let local = ["crate", "super", "self"].contains(&first)
                || self.modules[owner].children.contains(first);
            if !local || ends_with_word(&code[start.saturating_sub(5)..start], b"in") {
                continue;
            }
            self.refs.push(Reference {
                owner: owner.to_vec(),
                file: file.to_owned(),
                line: p.line(start),
                path: segs,
                facade: false,
                is_use: false,
            });
        }
    }

    /// `segs`, written in `owner`, as a path from the crate root; `None` when it names
    /// another crate's item.
    fn absolute(&self, owner: &[String], segs: &[String]) -> Option<Vec<String>> {
        let first = segs.first().map(String::as_str);
        if first == Some("crate") {
            return Some(segs[1..].to_vec());
        }
        let mut base = owner.to_vec();
        if first == Some("self") {
            base.extend_from_slice(&segs[1..]);
            return Some(base);
        }
        if first == Some("super") {
            let ups = segs.iter().take_while(|s| *s == "super").count();
            base.truncate(base.len().saturating_sub(ups));
            base.extend_from_slice(&segs[ups..]);
            return Some(base);
        }
        let module = &self.modules[owner];
        let first = first?;
        let imported = module.imports.get(first).and_then(|to| to.first());
        if !module.children.contains(first) && imported.is_some_and(|f| f == first) {
            return None; // `use anyhow::anyhow;`: the name is the other crate's
        }
        if module.children.contains(first)
            || module.items.contains(first)
            || module.imports.contains_key(first)
        {
            base.extend_from_slice(segs);
            return Some(base);
        }
        None
    }

    /// The module defining what the absolute `path` names, following imports; `None` for
    /// another crate's item.
    fn resolve(&self, path: &[String], seen: &mut HashSet<Vec<String>>) -> Option<Vec<String>> {
        if seen.len() > 50 || !seen.insert(path.to_vec()) {
            return None;
        }
        let mut base: Vec<String> = Vec::new();
        for (k, s) in path.iter().enumerate() {
            let Some(module) = self.modules.get(&base) else {
                return Some(base);
            };
            if module.children.contains(s) {
                base.push(s.clone());
                continue;
            }
            if let (false, Some(target)) = (module.items.contains(s), module.imports.get(s)) {
                let mut to = self.absolute(&base, target)?;
                to.extend_from_slice(&path[k + 1..]);
                return self.resolve(&to, seen);
            }
            return Some(base);
        }
        Some(base)
    }
}

/// True when `before` (the text ahead of a `use`) ends with `pub` or `pub(...)`.
fn ends_with_pub(before: &[u8]) -> bool {
    let mut s = before.trim_ascii_end();
    if let Some(inside) = s.strip_suffix(b")") {
        let Some(open) = inside.iter().rposition(|&b| b == b'(' || b == b')') else {
            return false;
        };
        if inside[open] == b')' {
            return false;
        }
        s = &inside[..open];
    }
    ends_with_word(s, b"pub")
}

/// True when `s`, trailing whitespace aside, ends with the whole word `word`.
fn ends_with_word(s: &[u8], word: &[u8]) -> bool {
    let s = s.trim_ascii_end();
    s.ends_with(word) && word_start(s, s.len() - word.len())
}

// ----------------------------------------------------------------------------- graphs

/// Module → the modules it uses.
type Graph = BTreeMap<String, BTreeSet<String>>;

/// (from, to) → where the code makes that edge: (file, line, what is written there).
type Evidence = BTreeMap<(String, String), BTreeSet<(String, usize, String)>>;

/// A crate's two levels of module graph.
#[derive(Default)]
struct Layers {
    /// Between top-level modules (and the root, when lib.rs itself uses one).
    top: Graph,
    /// Inside each top-level module `y`, between its children (named `y::child`).
    inner: BTreeMap<String, Graph>,
    evidence: Evidence,
}

/// The edges of `krate`'s top-level graph and of its level-2 graphs, with their evidence.
fn layers(krate: &Crate) -> Layers {
    let mut out = Layers::default();
    for r in &krate.refs {
        let Some(abs) = krate.absolute(&r.owner, &r.path) else {
            continue;
        };
        let Some(target) = krate.resolve(&abs, &mut HashSet::new()) else {
            continue;
        };
        let kind = match (r.is_use, r.facade) {
            (true, true) => "pub use",
            (true, false) => "use",
            (false, _) => "path",
        };
        let shown = if target.is_empty() {
            "crate".to_owned()
        } else {
            target.join("::")
        };
        let what = format!("{kind} {}  (=> {shown})", r.path.join("::"));
        let from = r.owner.first().map_or(ROOT, String::as_str);
        let to = target.first().map_or(ROOT, String::as_str);
        let mut edge = |graph: &mut Graph, a: String, b: String| {
            graph.entry(a.clone()).or_default().insert(b.clone());
            let at = (r.file.clone(), r.line, what.clone());
            out.evidence.entry((a, b)).or_default().insert(at);
        };
        if from != to && !(from == ROOT && r.facade) {
            edge(&mut out.top, from.to_owned(), to.to_owned());
        }
        if r.owner.len() > 1 && target.len() > 1 && from == to && r.owner[1] != target[1] {
            let graph = out.inner.entry(from.to_owned()).or_default();
            let a = format!("{from}::{}", r.owner[1]);
            edge(graph, a, format!("{from}::{}", target[1]));
        }
    }
    out
}

/// The strongly connected components of `graph` with more than one module (Tarjan), each
/// sorted.
fn circles(graph: &Graph) -> Vec<Vec<String>> {
    /// Tarjan's walk state.
    #[derive(Default)]
    struct Walk<'g> {
        index: BTreeMap<&'g str, usize>,
        low: BTreeMap<&'g str, usize>,
        on_stack: BTreeSet<&'g str>,
        stack: Vec<&'g str>,
        found: Vec<Vec<String>>,
    }
    /// Visits `v`, closing its component when `v` is its root.
    fn strong<'g>(v: &'g str, graph: &'g Graph, w: &mut Walk<'g>) {
        let n = w.index.len();
        w.index.insert(v, n);
        w.low.insert(v, n);
        w.stack.push(v);
        w.on_stack.insert(v);
        for u in graph.get(v).into_iter().flatten() {
            let u = u.as_str();
            if !w.index.contains_key(u) {
                strong(u, graph, w);
                let low = w.low[v].min(w.low[u]);
                w.low.insert(v, low);
            } else if w.on_stack.contains(u) {
                let low = w.low[v].min(w.index[u]);
                w.low.insert(v, low);
            }
        }
        if w.low[v] == w.index[v] {
            let mut component = Vec::new();
            while let Some(u) = w.stack.pop() {
                w.on_stack.remove(u);
                component.push(u.to_owned());
                if u == v {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                w.found.push(component);
            }
        }
    }
    let nodes: BTreeSet<&str> = graph
        .iter()
        .flat_map(|(a, bs)| std::iter::once(a).chain(bs))
        .map(String::as_str)
        .collect();
    let mut walk = Walk::default();
    for v in nodes {
        if !walk.index.contains_key(v) {
            strong(v, graph, &mut walk);
        }
    }
    walk.found
}

/// The problems of crate `name`: each circle left once the `allowed` edges are taken out
/// (with every edge of it and where the code makes it), and each allowed edge that is gone.
fn check(name: &str, layers: &Layers, allowed: &[(&str, &str, &str)]) -> Vec<String> {
    let mut graphs: Vec<(String, Graph)> = vec![("top-level".to_owned(), layers.top.clone())];
    for (y, graph) in &layers.inner {
        graphs.push((format!("inside {y}"), graph.clone()));
    }
    let mut problems = Vec::new();
    for &(_, from, to) in allowed.iter().filter(|a| a.0 == name) {
        let edge = graphs
            .iter_mut()
            .find_map(|(_, g)| g.get_mut(from).filter(|tos| tos.contains(to)));
        match edge {
            Some(tos) => {
                tos.remove(to);
            }
            None => problems.push(format!(
                "{name}: the allowed edge {from} -> {to} no longer exists: take it out of ALLOWED"
            )),
        }
    }
    for (title, graph) in &graphs {
        for circle in circles(graph) {
            let mut text = format!("{name}: import circle [{title}]: {{{}}}", circle.join(", "));
            for a in &circle {
                for b in graph[a].iter().filter(|b| circle.contains(b)) {
                    text.push_str(&format!("\n    {a} -> {b}"));
                    let key = (a.clone(), b.clone());
                    for (file, line, what) in layers.evidence.get(&key).into_iter().flatten() {
                        text.push_str(&format!("\n        {file}:{line}  {what}"));
                    }
                }
            }
            problems.push(text);
        }
    }
    problems
}

// ----------------------------------------------------------------------------- tests

/// Every crate of `CRATES`, read from its files: enough modules found, no circle left.
#[test]
fn no_crate_has_an_import_circle_between_its_modules() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("coop-tests sits in the workspace");
    let mut problems = Vec::new();
    for &(dir, min_modules, min_edges) in CRATES {
        let krate = parse_crate(&read_crate(workspace, dir));
        let graphs = layers(&krate);
        let modules = krate.modules.len();
        let edges: usize = graphs.top.values().map(BTreeSet::len).sum();
        if modules < min_modules || edges < min_edges {
            problems.push(format!(
                "{dir}: read {modules} modules and {edges} top-level edges, expected at least \
                 {min_modules} and {min_edges}: is the walk or the parser broken?"
            ));
        }
        problems.extend(check(dir, &graphs, ALLOWED));
    }
    for &(dir, from, to) in ALLOWED {
        if !CRATES.iter().any(|c| c.0 == dir) {
            problems.push(format!(
                "ALLOWED names {dir} ({from} -> {to}), not a checked crate"
            ));
        }
    }
    assert!(problems.is_empty(), "\n{}\n", problems.join("\n\n"));
}

/// A made-up crate, file by file (`@@ module file`): `a` and `b` use each other, `c` uses `a`,
/// and inside `d`, `x` and `y` use each other (`y` through `d`'s `pub use`). `a` names `c` only
/// where no build without tests sees it.
const FAKE_CRATE: &str = r##"@@ crate lib.rs
mod a;
mod b;
mod c;
pub mod d;
pub use a::A;
@@ a a.rs
use crate::b::B;
pub struct A(pub B);
// crate::c::C in a line comment
/* crate::c::C in a /* nested */ block comment, crate::c::C */
pub const NOTE: &str = "crate::c::C \" still a string crate::c::C";
pub const RAW: &str = r#"a "quoted" crate::c::C"#;
pub const QUOTE: char = '"';
pub fn id<'a>(s: &'a str) -> &'a str { s }
#[cfg(test)]
mod tests {
    use crate::c::C;
    fn f() -> C { crate::c::C }
}
#[cfg(all(test, loom))]
use crate::c::C as Loom;
@@ b b.rs
pub struct B;
pub fn make() -> crate::a::A {
    crate::a::A(B)
}
@@ c c.rs
use crate::a::A;
pub struct C;
pub fn keep(a: A) -> A { a }
@@ d d/mod.rs
mod x;
mod y;
pub use x::X;
@@ d::x d/x.rs
pub struct X;
pub fn y() -> super::y::Y {
    super::y::Y(X)
}
@@ d::y d/y.rs
pub struct Y(pub super::X);
"##;

/// The sources of `FAKE_CRATE`.
fn fake_sources() -> Vec<Source> {
    let mut out = Vec::new();
    for chunk in FAKE_CRATE.split("@@ ").skip(1) {
        let (header, text) = chunk.split_once('\n').expect("a header line");
        let (module, file) = header.split_once(' ').expect("`module file`");
        let module = module.split("::").filter(|&s| s != "crate");
        out.push(Source {
            module: module.map(String::from).collect(),
            file: file.to_owned(),
            text: text.to_owned(),
        });
    }
    out
}

/// A made-up crate with two circles: both found, with where each edge is written; what is in a
/// comment, a literal or a test module makes no edge; allowed edges break circles, stale ones fail.
#[test]
fn the_parser_finds_a_circle_and_ignores_comments_strings_and_tests() {
    let krate = parse_crate(&fake_sources());
    assert_eq!(krate.modules.len(), 7);
    let graphs = layers(&krate);
    let edge = |a: &str, b: &str| -> (String, BTreeSet<String>) { (a.into(), [b.into()].into()) };
    let top: Graph = [edge("a", "b"), edge("b", "a"), edge("c", "a")].into();
    assert_eq!(graphs.top, top, "comments, literals, tests make no edge");
    let inner: Graph = [edge("d::x", "d::y"), edge("d::y", "d::x")].into();
    assert_eq!(graphs.inner.get("d"), Some(&inner), "through d's pub use");

    let problems = check("fake", &graphs, &[]);
    assert_eq!(problems.len(), 2, "{problems:#?}");
    let expected = [
        (0, "fake: import circle [top-level]: {a, b}"),
        (0, "\n    a -> b\n        a.rs:1  use crate::b::B  (=> b)"),
        (0, "\n    b -> a\n        b.rs:2  path crate::a::A  (=> a)"),
        (0, "\n        b.rs:3  path crate::a::A  (=> a)"),
        (1, "fake: import circle [inside d]: {d::x, d::y}"),
        (1, "\n    d::x -> d::y\n        d/x.rs:2  path super::y::Y"),
        (
            1,
            "\n    d::y -> d::x\n        d/y.rs:1  path super::X  (=> d::x)",
        ),
    ];
    for (k, text) in expected {
        assert!(problems[k].contains(text), "{}", problems[k]);
    }

    let allowed = [("fake", "b", "a"), ("fake", "d::y", "d::x")];
    assert_eq!(check("fake", &graphs, &allowed), Vec::<String>::new());
    let stale = [("fake", "c", "b")];
    let problems = check("fake", &graphs, &stale);
    assert_eq!(problems.len(), 3, "{problems:#?}");
    assert!(
        problems[0].contains("c -> b no longer exists"),
        "{}",
        problems[0]
    );
}
