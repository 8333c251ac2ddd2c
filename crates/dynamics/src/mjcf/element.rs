//! The MJCF's elements read into one owned tree: included files spliced in place, tag and attribute names shared,
//! each element's file and line kept for messages; the memory that building a model takes reserved first.

use std::path::{Path, PathBuf};
use std::rc::Rc;

use roxmltree::Node;

use super::{invalid, BYTES_PER_ELEMENT, MAX_DEPTH, MAX_ELEMENTS, MAX_INCLUDE_DEPTH};
use crate::mesh::cancel_point;
use crate::{Error, Result};

pub(super) fn read_text(path: &Path, argument: &'static str) -> Result<String> {
    let bytes = crate::validate::read_regular_file(argument, path)?;
    let text = String::from_utf8(bytes).map_err(|e| Error::invalid(argument, format!("{}: not UTF-8 text: {e}", path.display())))?;
    Ok(text.strip_prefix('\u{feff}').map(str::to_owned).unwrap_or(text))
}

/// An element, owned, so that included files splice into one tree. Its tag and attribute names are shared
/// (`Source::name`) and its place holds the file's label by reference: an element owns only its values and lists,
/// so a tree of a million elements is built, and freed when a load is cancelled, in fewer allocations.
#[derive(Debug, Clone)]
pub(super) struct El {
    pub(super) tag: Name,
    pub(super) attrs: Vec<(Name, String)>,
    pub(super) children: Vec<El>,
    pub(super) at: At,
}

/// A tag or attribute name, shared by every element that has it.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(super) struct Name(Rc<str>);

impl Name {
    pub(super) fn as_str(&self) -> &str {
        &self.0
    }
}

impl std::ops::Deref for Name {
    type Target = str;
    fn deref(&self) -> &str {
        &self.0
    }
}

impl PartialEq<str> for Name {
    fn eq(&self, other: &str) -> bool {
        &*self.0 == other
    }
}

impl PartialEq<&str> for Name {
    fn eq(&self, other: &&str) -> bool {
        &*self.0 == *other
    }
}

impl From<&str> for Name {
    fn from(name: &str) -> Self {
        Name(Rc::from(name))
    }
}

impl std::fmt::Display for Name {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// Where an element is, for messages: "file:line".
#[derive(Debug, Clone)]
pub(super) struct At {
    pub(super) label: Rc<str>,
    pub(super) line: usize,
}

impl std::fmt::Display for At {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "{}:{}", self.label, self.line)
    }
}

impl El {
    pub(super) fn attr(&self, key: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }
    pub(super) fn elements<'a>(&'a self, tag: &'a str) -> impl Iterator<Item = &'a El> + 'a {
        self.children.iter().filter(move |c| c.tag == tag)
    }
    pub(super) fn what(&self) -> String {
        match self.attr("name") {
            Some(name) => format!("<{} name={name:?}> ({})", self.tag, self.at),
            None => format!("<{}> ({})", self.tag, self.at),
        }
    }
}

pub(super) struct Source<'a> {
    /// "path" or "xml": what a size that cannot be allocated is reported against.
    pub(super) argument: &'static str,
    pub(super) folder: Option<&'a Path>,
    pub(super) elements: usize,
    pub(super) stack: Vec<PathBuf>,
    /// The tag and attribute names read so far.
    pub(super) names: std::collections::HashSet<Rc<str>>,
}

impl Source<'_> {
    fn name(&mut self, name: &str) -> Name {
        if let Some(shared) = self.names.get(name) {
            return Name(Rc::clone(shared));
        }
        let shared: Rc<str> = Rc::from(name);
        self.names.insert(Rc::clone(&shared));
        Name(shared)
    }
}

/// The byte offsets of the line breaks of `text`, to find an element's line by bisection (roxmltree's
/// `text_pos_at` scans from the start: quadratic over a file).
pub(super) fn line_breaks(text: &str) -> Vec<usize> {
    text.bytes().enumerate().filter(|(_, b)| *b == b'\n').map(|(i, _)| i).collect()
}

/// `node` owned, at `depth` in the tree (the root at 0), with its includes spliced in.
pub(super) fn own(node: Node, label: &Rc<str>, breaks: &[usize], source: &mut Source, depth: usize) -> Result<El> {
    let row = breaks.partition_point(|&b| b < node.range().start) + 1;
    if depth > MAX_DEPTH {
        return Err(invalid(format!("elements nest deeper than {MAX_DEPTH} levels ({label}:{row})")));
    }
    let mut el = El {
        tag: source.name(node.tag_name().name()),
        attrs: node.attributes().map(|a| (source.name(a.name()), a.value().to_owned())).collect(),
        children: Vec::new(),
        at: At { label: Rc::clone(label), line: row },
    };
    for child in node.children().filter(Node::is_element) {
        source.elements += 1;
        cancel_point("from_mjcf", source.elements)?;
        if source.elements > MAX_ELEMENTS {
            return Err(Error::too_large("mjcf", format!("more than {MAX_ELEMENTS} elements")));
        }
        if child.tag_name().name() == "include" {
            let file = child.attribute("file").ok_or_else(|| invalid(format!("<include> has no file attribute ({label}:{row})")))?;
            let path = source.folder.map_or_else(|| PathBuf::from(file), |f| f.join(file));
            if source.stack.len() >= MAX_INCLUDE_DEPTH || source.stack.contains(&path) {
                return Err(invalid(format!("<include file={file:?}>: includes nest too deep or include themselves ({label})")));
            }
            let text = read_text(&path, "mjcf").map_err(|e| invalid(format!("<include file={file:?}> ({label}:{row}): {}", e.reason())))?;
            let doc = crate::xml::parse(&text, source.argument)?.map_err(|e| invalid(format!("{file}: {e}")))?;
            reserve_build(&doc, source.argument)?;
            if doc.root_element().tag_name().name() != "mujoco" {
                return Err(invalid(format!("{file}: an included file's root must be <mujoco>")));
            }
            source.stack.push(path);
            let included = own(doc.root_element(), &Rc::from(file), &line_breaks(&text), source, depth)?;
            source.stack.pop();
            el.children.extend(included.children);
        } else {
            el.children.push(own(child, label, breaks, source, depth + 1)?);
        }
    }
    Ok(el)
}

/// Whitespace-separated finite numbers.
pub(super) fn numbers(text: &str, what: &dyn Fn() -> String) -> Result<Vec<f64>> {
    text.split_whitespace()
        .map(|t| match t.parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            _ => Err(invalid(format!("{}: {t:?} is not a finite number", what()))),
        })
        .collect()
}

/// Fails with `Error::TooLarge` naming `argument` when the memory that building a model from `doc` may take
/// cannot be allocated: the element tree, the bodies and the model grow infallibly.
pub(super) fn reserve_build(doc: &roxmltree::Document, argument: &'static str) -> Result<()> {
    let elements = doc.descendants().filter(Node::is_element).count();
    let bytes = elements.saturating_mul(BYTES_PER_ELEMENT);
    if crate::validate::headroom(bytes) {
        Ok(())
    } else {
        Err(Error::too_large(argument, format!("building a model of {elements} elements needs up to {bytes} bytes, which cannot be allocated")))
    }
}
