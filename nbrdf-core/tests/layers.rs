//! The workspace's layers, read from its source. In every crate of the workspace (each member of
//! the root `Cargo.toml`, each of its library and binary roots), no two top-level modules depend
//! on each other, directly or through others. In nbrdf-core's library, no module of the
//! rendering layer (what builds without the feature `train`, all that `nbrdf-ffi` links) refers
//! to a module of the training layer (those declared under `#[cfg(feature = "train")]`).
//!
//! A module refers to another through `crate::x`, `super::x` (from the crate root's children)
//! or a name the crate root imports from `x` (`pub use x::*` and the like). Test code
//! (`tests.rs` files and `#[cfg(test)]` modules) and comments are not read: tests may reach
//! anywhere.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

/// Top-level module -> (module it refers to -> first file that does).
type Graph = BTreeMap<String, BTreeMap<String, String>>;

/// One crate root (a library or a binary) and what its source says.
struct Crate {
    /// `member/src/lib.rs` and the like, from the workspace root.
    name: String,
    /// Declared top-level module -> whether it is gated on the feature `train`.
    modules: BTreeMap<String, bool>,
    graph: Graph,
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("nbrdf-core sits in the workspace")
        .to_path_buf()
}

/// The `members = [...]` of the workspace's `Cargo.toml`.
fn workspace_members(cargo_toml: &str) -> Vec<String> {
    let start = cargo_toml.find("members").expect("a members list");
    let list = &cargo_toml[start..];
    let list = &list[list.find('[').expect("[") + 1..list.find(']').expect("]")];
    list.split(',')
        .map(|m| m.trim().trim_matches('"').to_string())
        .filter(|m| !m.is_empty())
        .collect()
}

/// The crate roots of a member: `src/lib.rs`, `src/main.rs`, `src/bin/*.rs` and
/// `src/bin/*/main.rs`, those that exist.
fn crate_roots(member: &Path) -> Vec<PathBuf> {
    let src = member.join("src");
    let mut roots: Vec<PathBuf> = [src.join("lib.rs"), src.join("main.rs")]
        .into_iter()
        .filter(|p| p.is_file())
        .collect();
    if let Ok(entries) = fs::read_dir(src.join("bin")) {
        let mut bins: Vec<PathBuf> = entries
            .map(|e| e.expect("directory entry").path())
            .map(|p| if p.is_dir() { p.join("main.rs") } else { p })
            .filter(|p| p.is_file() && p.extension().is_some_and(|e| e == "rs"))
            .collect();
        bins.sort();
        roots.extend(bins);
    }
    roots
}

/// The top-level modules a crate root declares, each with whether it is gated on `train`.
fn declared_modules(root: &str) -> BTreeMap<String, bool> {
    let mut modules = BTreeMap::new();
    let mut gated = false;
    let mut test_only = false;
    for line in root.lines().map(str::trim) {
        if line == "#[cfg(feature = \"train\")]" {
            gated = true;
            continue;
        }
        if line == "#[cfg(test)]" {
            test_only = true;
            continue;
        }
        let declaration = line
            .strip_prefix("pub mod ")
            .or_else(|| line.strip_prefix("pub(crate) mod "))
            .or_else(|| line.strip_prefix("mod "))
            .and_then(|rest| rest.strip_suffix(';'));
        if let (Some(name), false) = (declaration, test_only) {
            modules.insert(name.to_string(), gated);
        }
        if !line.starts_with("#[") {
            (gated, test_only) = (false, false);
        }
    }
    modules
}

/// The code of a file that is not test code nor a comment line: everything before its
/// `#[cfg(test)] mod ... {` block (by the crate's convention, the file's last item).
fn non_test_code(text: &str) -> String {
    let mut code = String::new();
    let mut after_cfg_test = false;
    for line in text.lines().map(str::trim) {
        if after_cfg_test && line.contains("mod ") && line.ends_with('{') {
            break;
        }
        after_cfg_test = line == "#[cfg(test)]";
        if !line.starts_with("//") {
            code.push_str(line);
            code.push('\n');
        }
    }
    code
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

fn leading_ident(text: &str) -> String {
    text.trim_start()
        .chars()
        .take_while(|&c| is_ident(c))
        .collect()
}

/// The first segments of the paths of a `use` tree's group `{a, b::c, d::{e, f}}`, `rest`
/// starting after its `{`.
fn group_heads(rest: &str) -> Vec<String> {
    let (mut depth, mut item_start, mut heads) = (0, 0, Vec::new());
    for (at, c) in rest.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                heads.push(leading_ident(&rest[item_start..at]));
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                heads.push(leading_ident(&rest[item_start..at]));
                item_start = at + 1;
            }
            _ => {}
        }
    }
    heads
}

/// The names of the crate root's namespace that a file at `module_path` (its module's path
/// from the root, `["ops", "fit_phong"]`) refers to: `x` of `crate::x`, of `super::x` from a
/// child of the root, of `super::super::x` from a grandchild, ...; each of a group.
fn root_references(code: &str, module_path: &[String]) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for prefix in ["crate::", "super::"] {
        for (at, _) in code.match_indices(prefix) {
            let before = &code[..at];
            if before.ends_with(is_ident) || before.ends_with("::") {
                continue; // `nbrdf_crate::`, or the second `super` of `super::super::`
            }
            let mut rest = &code[at + prefix.len()..];
            let mut depth = 0;
            if prefix == "super::" {
                depth = 1;
                while let Some(more) = rest.strip_prefix("super::") {
                    (depth, rest) = (depth + 1, more);
                }
            }
            if prefix == "super::" && depth != module_path.len() {
                continue; // climbs to a module inside this one (or past the root)
            }
            let heads = match rest.strip_prefix('{') {
                Some(group) => group_heads(group),
                None => vec![leading_ident(rest)],
            };
            found.extend(heads);
        }
    }
    found.retain(|name| !name.is_empty() && name != "self");
    found
}

/// The names a crate root imports from its modules (`pub use x::*`, `use x::{A, B}`,
/// `pub use x::A as B`): name -> module. A glob brings the `pub` items of the module's file.
fn root_imports(root_code: &str, modules: &BTreeMap<String, bool>, dir: &Path) -> Graph {
    let mut imports = Graph::new();
    let mut lines = root_code.lines();
    while let Some(line) = lines.next() {
        let Some(path) = ["use ", "pub use ", "pub(crate) use "]
            .iter()
            .find_map(|start| line.strip_prefix(start))
        else {
            continue;
        };
        let mut statement = path.to_string();
        while !statement.contains(';') {
            let Some(next) = lines.next() else { break };
            statement.push_str(next);
        }
        let path = statement.split(';').next().unwrap_or_default().trim();
        let path = path
            .strip_prefix("crate::")
            .or_else(|| path.strip_prefix("self::"))
            .unwrap_or(path);
        let module = leading_ident(path);
        if !modules.contains_key(&module) {
            continue;
        }
        let tail = path[module.len()..].trim_start_matches("::");
        let names: Vec<String> = if tail == "*" {
            pub_items(&fs::read_to_string(module_file(dir, &module)).expect("readable module"))
        } else if let Some(group) = tail.strip_prefix('{') {
            group[..group.rfind('}').unwrap_or(group.len())]
                .split(',')
                .map(imported_name)
                .collect()
        } else {
            vec![imported_name(tail)]
        };
        for name in names.into_iter().filter(|n| !n.is_empty()) {
            imports
                .entry(name)
                .or_default()
                .insert(module.clone(), String::new());
        }
    }
    imports
}

/// The name `a::b::C as D` brings into scope: `D`, else `C`.
fn imported_name(item: &str) -> String {
    let item = item.trim();
    match item.split_once(" as ") {
        Some((_, alias)) => leading_ident(alias),
        None => leading_ident(item.rsplit("::").next().unwrap_or(item)),
    }
}

/// The names of a module file's `pub` items (what `use module::*` brings).
fn pub_items(text: &str) -> Vec<String> {
    const QUALIFIERS: [&str; 5] = ["unsafe", "extern", "\"C\"", "async", "mut"];
    const KINDS: [&str; 9] = [
        "fn", "struct", "enum", "union", "const", "static", "type", "trait", "mod",
    ];
    let mut names = Vec::new();
    for line in non_test_code(text).lines() {
        let Some(rest) = line.strip_prefix("pub ") else {
            continue;
        };
        let mut words = rest.split_whitespace().peekable();
        while let Some(word) = words.next() {
            let const_fn = word == "const" && words.peek() == Some(&"fn");
            if QUALIFIERS.contains(&word) || const_fn {
                continue;
            }
            if KINDS.contains(&word) {
                while words.peek().is_some_and(|w| QUALIFIERS.contains(w)) {
                    words.next();
                }
                names.extend(words.next().map(leading_ident));
            }
            break;
        }
    }
    names
}

/// `dir/x.rs`, else `dir/x/mod.rs`.
fn module_file(dir: &Path, module: &str) -> PathBuf {
    let flat = dir.join(format!("{module}.rs"));
    if flat.is_file() {
        flat
    } else {
        dir.join(module).join("mod.rs")
    }
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in fs::read_dir(dir).expect("readable source directory") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The path from the crate root of the module a file under `dir` defines.
fn module_path(relative: &Path) -> Vec<String> {
    let mut path: Vec<String> = relative
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if let Some(last) = path.last_mut() {
        *last = last.trim_end_matches(".rs").to_string();
    }
    if path.last().is_some_and(|last| last == "mod") {
        path.pop();
    }
    path
}

/// Reads the crate whose root file is `root` (its modules live beside it, in `dir`).
fn read_crate(root: &Path, dir: &Path, name: String) -> Crate {
    let root_code = non_test_code(&fs::read_to_string(root).expect("readable crate root"));
    let modules = declared_modules(&root_code);
    let imports = root_imports(&root_code, &modules, dir);
    let mut graph = Graph::new();
    for module in modules.keys() {
        let mut files = vec![module_file(dir, module)];
        if dir.join(module).is_dir() {
            rust_files(&dir.join(module), &mut files);
            files.sort();
            files.dedup();
        }
        for file in files {
            if file.file_name().is_some_and(|n| n == "tests.rs") {
                continue;
            }
            let relative = file.strip_prefix(dir).expect("under the crate's directory");
            let text = fs::read_to_string(&file).expect("readable source file");
            let names = root_references(&non_test_code(&text), &module_path(relative));
            let targets = names.iter().flat_map(|name| {
                let through_root = imports.get(name).into_iter().flat_map(|m| m.keys());
                std::iter::once(name)
                    .filter(|n| modules.contains_key(*n))
                    .chain(through_root)
            });
            for target in targets {
                if target != module {
                    graph
                        .entry(module.clone())
                        .or_default()
                        .entry(target.clone())
                        .or_insert_with(|| relative.display().to_string());
                }
            }
        }
    }
    Crate {
        name,
        modules,
        graph,
    }
}

/// Every crate root of the workspace, read.
fn workspace_crates() -> Vec<Crate> {
    let workspace = workspace_root();
    let cargo_toml = fs::read_to_string(workspace.join("Cargo.toml")).expect("Cargo.toml");
    let mut crates = Vec::new();
    for member in workspace_members(&cargo_toml) {
        for root in crate_roots(&workspace.join(&member)) {
            let named_dir = root
                .file_name()
                .is_some_and(|n| n == "lib.rs" || n == "main.rs");
            let dir = if named_dir {
                root.parent().expect("a directory").to_path_buf()
            } else {
                root.with_extension("")
            };
            let name = root
                .strip_prefix(&workspace)
                .expect("under the workspace")
                .display()
                .to_string();
            crates.push(read_crate(&root, &dir, name));
        }
    }
    crates
}

/// Each arrow from a rendering-layer module into a training-layer one, with the file.
fn upward_arrows(graph: &Graph, modules: &BTreeMap<String, bool>) -> Vec<String> {
    let mut arrows = Vec::new();
    for (from, targets) in graph {
        for (to, file) in targets {
            if !modules[from] && modules[to] {
                arrows.push(format!("{from} -> {to} ({file})"));
            }
        }
    }
    arrows
}

/// A cycle of the graph as `a -> b -> ... -> a`, if there is one (depth-first search).
fn find_cycle(graph: &Graph) -> Option<String> {
    fn visit<'a>(
        node: &'a str,
        graph: &'a Graph,
        path: &mut Vec<&'a str>,
        done: &mut BTreeSet<&'a str>,
    ) -> Option<String> {
        if let Some(start) = path.iter().position(|&n| n == node) {
            let mut cycle = path[start..].to_vec();
            cycle.push(node);
            return Some(cycle.join(" -> "));
        }
        if done.contains(node) {
            return None;
        }
        path.push(node);
        for next in graph.get(node).into_iter().flat_map(|t| t.keys()) {
            if let Some(cycle) = visit(next, graph, path, done) {
                return Some(cycle);
            }
        }
        path.pop();
        done.insert(node);
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|node| visit(node, graph, &mut Vec::new(), &mut done))
}

fn find_crate<'a>(crates: &'a [Crate], name: &str) -> &'a Crate {
    crates
        .iter()
        .find(|c| c.name == name)
        .unwrap_or_else(|| panic!("{name} not read: {:?}", names(crates)))
}

fn names(crates: &[Crate]) -> Vec<&str> {
    crates.iter().map(|c| c.name.as_str()).collect()
}

#[test]
fn every_crate_of_the_workspace_is_read() {
    let crates = workspace_crates();
    for name in [
        "nbrdf-core/src/lib.rs",
        "nbrdf-core/src/bin/nbrdf/main.rs",
        "nbrdf-ffi/src/lib.rs",
        "nbrdf-ffi/common/src/lib.rs",
        "nbrdf-ffi/train/src/lib.rs",
    ] {
        find_crate(&crates, name);
    }
    // The reading itself: arrows of each kind are seen where the code has them.
    let core = find_crate(&crates, "nbrdf-core/src/lib.rs");
    assert!(
        core.graph["network"].contains_key("sampling"),
        "{:?}",
        core.graph
    );
    assert!(core.graph["ops"].contains_key("train"), "{:?}", core.graph);
    let ffi = find_crate(&crates, "nbrdf-ffi/src/lib.rs");
    assert!(
        ffi.graph["material"].contains_key("handles"),
        "{:?}",
        ffi.graph
    );
    assert!(
        ffi.graph["sampler"].contains_key("handles"),
        "{:?}",
        ffi.graph
    );
    let cli = find_crate(&crates, "nbrdf-core/src/bin/nbrdf/main.rs");
    assert!(
        cli.graph["ae_cmd"].contains_key("pretrained"),
        "{:?}",
        cli.graph
    );
    assert!(!cli.modules.contains_key("tests"), "{:?}", cli.modules);
}

#[test]
fn the_rendering_layer_does_not_refer_to_the_training_layer() {
    let crates = workspace_crates();
    let core = find_crate(&crates, "nbrdf-core/src/lib.rs");
    assert_eq!(core.modules.get("sampling"), Some(&false));
    assert_eq!(core.modules.get("train"), Some(&true));
    let arrows = upward_arrows(&core.graph, &core.modules);
    assert!(arrows.is_empty(), "rendering -> training: {arrows:#?}");
}

#[test]
fn top_level_modules_have_no_cycle_in_any_crate() {
    let cycles: Vec<String> = workspace_crates()
        .iter()
        .filter_map(|c| find_cycle(&c.graph).map(|cycle| format!("{}: {cycle}", c.name)))
        .collect();
    assert!(cycles.is_empty(), "{cycles:#?}");
}

/// The checks catch what they are for, on made-up sources.
#[test]
fn the_checks_see_arrows_and_cycles() {
    let lib = "pub mod a;\n#[cfg(feature = \"train\")]\npub mod t;\nmod b;\n\
               #[cfg(test)]\nmod tests;\n#[cfg(feature = \"x\")]\n#[allow(unused)]\npub mod c;\n";
    let modules = declared_modules(lib);
    assert_eq!(
        modules,
        BTreeMap::from([
            ("a".into(), false),
            ("b".into(), false),
            ("c".into(), false),
            ("t".into(), true)
        ])
    );
    let code = non_test_code(
        "use crate::{b, t::X};\n// crate::z in a comment\nfn f() { crate::b::g() }\n\
         #[cfg(test)]\nmod tests {\n    use crate::c;\n}\n",
    );
    assert_eq!(
        root_references(&code, &["a".into()]),
        BTreeSet::from(["b".to_string(), "t".to_string()])
    );
    // `super::` reaches the root from the root's children only; nested groups count once.
    let code = "use super::{b::{X, Y}, c};\nuse super::super::d;\n";
    let child = root_references(code, &["a".into()]);
    assert_eq!(child, BTreeSet::from(["b".into(), "c".into()]));
    let grandchild = root_references(code, &["a".into(), "inner".into()]);
    assert_eq!(grandchild, BTreeSet::from(["d".to_string()]));
    let edge = |to: &str| (to.to_string(), "f.rs".to_string());
    let mut graph = Graph::from([("a".into(), BTreeMap::from([edge("b"), edge("t")]))]);
    assert_eq!(upward_arrows(&graph, &modules), ["a -> t (f.rs)"]);
    assert_eq!(find_cycle(&graph), None);
    // Through others: a -> b -> c -> a.
    graph.insert("b".into(), BTreeMap::from([edge("c")]));
    graph.insert("c".into(), BTreeMap::from([edge("a")]));
    assert_eq!(find_cycle(&graph).as_deref(), Some("a -> b -> c -> a"));
    graph.insert("c".into(), BTreeMap::new());
    assert_eq!(find_cycle(&graph), None);
    graph.insert("b".into(), BTreeMap::from([edge("a")]));
    assert_eq!(find_cycle(&graph).as_deref(), Some("a -> b -> a"));
}

/// A cycle planted in a crate on disk is reported, whichever way its modules reach each other:
/// a name the root re-exports (`pub use b::*`) and `super::`.
#[test]
fn a_planted_cycle_is_reported() {
    let dir = std::env::temp_dir().join(format!("nbrdf-layers-{}", std::process::id()));
    let src = dir.join("src");
    fs::create_dir_all(src.join("b")).unwrap();
    let files = [
        (
            "lib.rs",
            "pub mod a;\npub mod b;\nmod c;\n\npub use b::*;\n",
        ),
        (
            "a.rs",
            "use crate::Thing;\n\npub fn a() -> Thing {\n    Thing\n}\n",
        ),
        ("b/mod.rs", "mod inner;\n\npub struct Thing;\n"),
        ("b/inner.rs", "use super::super::c::helper;\n"),
        ("c.rs", "pub(crate) fn helper() {\n    super::a::a();\n}\n"),
    ];
    for (name, text) in files {
        fs::write(src.join(name), text).unwrap();
    }
    let planted = read_crate(&src.join("lib.rs"), &src, "planted".into());
    fs::remove_dir_all(&dir).unwrap();
    assert_eq!(
        planted.graph.keys().collect::<Vec<_>>(),
        ["a", "b", "c"],
        "{:?}",
        planted.graph
    );
    assert_eq!(
        find_cycle(&planted.graph).as_deref(),
        Some("a -> b -> c -> a")
    );
}
