//! A minimal writer for Mitsuba 3's XML scene format: nested elements with attributes, escaped, indented.

use std::fmt::Write as _;

/// An XML element.
#[derive(Debug, Clone, PartialEq)]
pub struct Element {
    name: String,
    attrs: Vec<(String, String)>,
    children: Vec<Element>,
    comment: Option<String>,
}

impl Element {
    /// `<name>` without attributes.
    pub fn new(name: &str) -> Element {
        Element { name: name.into(), attrs: Vec::new(), children: Vec::new(), comment: None }
    }

    /// Adds an attribute.
    pub fn attr(mut self, key: &str, value: impl Into<String>) -> Element {
        self.attrs.push((key.into(), value.into()));
        self
    }

    /// Adds a child.
    pub fn child(mut self, c: Element) -> Element {
        self.children.push(c);
        self
    }

    /// Adds a child in place.
    pub fn push(&mut self, c: Element) {
        self.children.push(c);
    }

    /// A comment written before the element.
    pub fn comment(mut self, text: impl Into<String>) -> Element {
        self.comment = Some(text.into());
        self
    }

    /// `<float name=… value=…/>`.
    pub fn float(name: &str, v: f64) -> Element {
        Element::new("float").attr("name", name).attr("value", num(v))
    }

    /// `<integer name=… value=…/>`.
    pub fn integer(name: &str, v: i64) -> Element {
        Element::new("integer").attr("name", name).attr("value", v.to_string())
    }

    /// `<string name=… value=…/>`.
    pub fn string(name: &str, v: &str) -> Element {
        Element::new("string").attr("name", name).attr("value", v)
    }

    /// `<boolean name=… value=…/>`.
    pub fn boolean(name: &str, v: bool) -> Element {
        Element::new("boolean").attr("name", name).attr("value", v.to_string())
    }

    /// `<rgb name=… value="r, g, b"/>`.
    pub fn rgb(name: &str, v: [f64; 3]) -> Element {
        Element::new("rgb").attr("name", name).attr("value", format!("{}, {}, {}", num(v[0]), num(v[1]), num(v[2])))
    }

    /// A `point` or `vector` element (`tag`) with x, y, z.
    pub fn xyz(tag: &str, name: &str, v: [f64; 3]) -> Element {
        Element::new(tag).attr("name", name).attr("x", num(v[0])).attr("y", num(v[1])).attr("z", num(v[2]))
    }

    /// `<ref id=…/>`, named when `name` is given (`interior`, `exterior`, `medium`).
    pub fn reference(name: Option<&str>, id: &str) -> Element {
        let e = Element::new("ref");
        let e = if let Some(n) = name { e.attr("name", n) } else { e };
        e.attr("id", id)
    }

    /// `<transform name="to_world"><matrix value="…"/></transform>` from a row-major 4×4 matrix.
    pub fn to_world_matrix(rows: [[f64; 4]; 4]) -> Element {
        let v: Vec<String> = rows.iter().flatten().map(|&x| num(x)).collect();
        Element::new("transform").attr("name", "to_world").child(Element::new("matrix").attr("value", v.join(" ")))
    }

    /// The document text (with the XML declaration).
    pub fn document(&self) -> String {
        let mut s = String::from("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
        self.write(&mut s, 0);
        s
    }

    fn write(&self, s: &mut String, depth: usize) {
        let pad = "    ".repeat(depth);
        if let Some(c) = &self.comment {
            let _ = writeln!(s, "{pad}<!-- {} -->", c.replace("--", "- -"));
        }
        let _ = write!(s, "{pad}<{}", self.name);
        for (k, v) in &self.attrs {
            let _ = write!(s, " {k}=\"{}\"", escape(v));
        }
        if self.children.is_empty() {
            s.push_str("/>\n");
            return;
        }
        s.push_str(">\n");
        for c in &self.children {
            c.write(s, depth + 1);
        }
        let _ = writeln!(s, "{pad}</{}>", self.name);
    }
}

/// A number with full round-trip precision (shortest representation of the f64).
pub fn num(v: f64) -> String {
    if v == 0.0 { "0".into() } else { format!("{v:?}") }
}

fn escape(v: &str) -> String {
    v.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

#[cfg(test)]
mod tests;
