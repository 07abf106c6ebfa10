//! The crate's layers, read from its source: no module of the rendering layer (what builds
//! without the feature `train`, all that `nbrdf-ffi` links) refers to a module of the training
//! layer (those declared under `#[cfg(feature = "train")]` in lib.rs), and no two top-level
//! modules depend on each other, directly or through others. Test code (`tests.rs` files and
//! `#[cfg(test)]` modules) and comments are not read: tests may reach anywhere.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

/// Top-level module -> (module it refers to -> first file that does).
type Graph = BTreeMap<String, BTreeMap<String, String>>;

fn source_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// The top-level modules lib.rs declares, each with whether it is gated on `train`.
fn declared_modules(lib_rs: &str) -> BTreeMap<String, bool> {
    let mut modules = BTreeMap::new();
    let mut gated = false;
    for line in lib_rs.lines().map(str::trim) {
        if line == "#[cfg(feature = \"train\")]" {
            gated = true;
            continue;
        }
        let declaration = line
            .strip_prefix("pub mod ")
            .or_else(|| line.strip_prefix("mod "))
            .and_then(|rest| rest.strip_suffix(';'));
        if let Some(name) = declaration {
            modules.insert(name.to_string(), gated);
        }
        gated = false;
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

/// The top-level modules `code` names through `crate::x` or `crate::{x, y::z}`.
fn crate_references(code: &str) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for (at, _) in code.match_indices("crate::") {
        if code[..at].ends_with(is_ident) {
            continue; // `nbrdf_crate::`, not a path from the crate root
        }
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let group = &group[..group.find('}').unwrap_or(group.len())];
            for item in group.split(',') {
                let name: String = item.trim().chars().take_while(|&c| is_ident(c)).collect();
                found.insert(name);
            }
        } else {
            found.insert(rest.chars().take_while(|&c| is_ident(c)).collect());
        }
    }
    found.retain(|name| !name.is_empty() && name != "self");
    found
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

/// The dependency graph between the declared top-level modules.
fn module_graph(src: &Path, modules: &BTreeMap<String, bool>) -> Graph {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut graph = Graph::new();
    for file in files {
        let relative = file.strip_prefix(src).expect("under src");
        let first = relative.components().next().expect("non-empty path");
        let top = first.as_os_str().to_string_lossy();
        let top = top.strip_suffix(".rs").unwrap_or(&top).to_string();
        if !modules.contains_key(&top) || file.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let text = fs::read_to_string(&file).expect("readable source file");
        for target in crate_references(&non_test_code(&text)) {
            if target != top && modules.contains_key(&target) {
                graph
                    .entry(top.clone())
                    .or_default()
                    .entry(target)
                    .or_insert_with(|| relative.display().to_string());
            }
        }
    }
    graph
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

fn crate_layers() -> (Graph, BTreeMap<String, bool>) {
    let src = source_dir();
    let lib = fs::read_to_string(src.join("lib.rs")).expect("lib.rs");
    let modules = declared_modules(&lib);
    (module_graph(&src, &modules), modules)
}

#[test]
fn the_rendering_layer_does_not_refer_to_the_training_layer() {
    let (graph, modules) = crate_layers();
    // The reading itself: both layers are found and the known arrows are seen.
    assert_eq!(modules.get("sampling"), Some(&false));
    assert_eq!(modules.get("train"), Some(&true));
    assert!(graph["network"].contains_key("sampling"), "{graph:?}");
    assert!(graph["ops"].contains_key("train"), "{graph:?}");
    let arrows = upward_arrows(&graph, &modules);
    assert!(arrows.is_empty(), "rendering -> training: {arrows:#?}");
}

#[test]
fn top_level_modules_have_no_cycle() {
    let (graph, _) = crate_layers();
    assert_eq!(find_cycle(&graph), None);
}

/// The checks catch what they are for, on made-up sources.
#[test]
fn the_checks_see_arrows_and_cycles() {
    let lib = "pub mod a;\n#[cfg(feature = \"train\")]\npub mod t;\nmod b;\n";
    let modules = declared_modules(lib);
    assert_eq!(
        modules,
        BTreeMap::from([("a".into(), false), ("b".into(), false), ("t".into(), true)])
    );
    let code = non_test_code(
        "use crate::{b, t::X};\n// crate::z in a comment\nfn f() { crate::b::g() }\n\
         #[cfg(test)]\nmod tests {\n    use crate::c;\n}\n",
    );
    assert_eq!(
        crate_references(&code),
        BTreeSet::from(["b".to_string(), "t".to_string()])
    );
    let edge = |to: &str| (to.to_string(), "f.rs".to_string());
    let mut graph = Graph::from([("a".into(), BTreeMap::from([edge("b"), edge("t")]))]);
    assert_eq!(upward_arrows(&graph, &modules), ["a -> t (f.rs)"]);
    assert_eq!(find_cycle(&graph), None);
    graph.insert("t".into(), BTreeMap::from([edge("b")]));
    graph.insert("b".into(), BTreeMap::from([edge("a")]));
    assert_eq!(find_cycle(&graph).as_deref(), Some("a -> b -> a"));
}
