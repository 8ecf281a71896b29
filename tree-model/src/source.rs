//! Model text before it is parsed: reading a file with a size cap, line numbers of byte
//! offsets in one pass, and a linear scan that bounds an XML document's nesting and
//! attribute counts before any parser (some recurse, some are quadratic) sees it.

use std::io::Read;
use std::path::Path;

use crate::error::ModelError;

/// The largest model file read, in bytes (64 MiB; the biggest shipped model is 40 kB).
pub const MAX_FILE_BYTES: u64 = 64 << 20;

/// The deepest XML nesting accepted (URDF needs about 5 levels).
pub const MAX_XML_DEPTH: usize = 100;

/// The most attributes one XML element may have (URDF's have at most 6).
pub const MAX_XML_ATTRIBUTES: usize = 64;

/// Reads a model file as UTF-8, refusing one over [`MAX_FILE_BYTES`] (a device such as
/// `/dev/zero` included: it is read no further than the cap).
pub(crate) fn read_model_file(path: &Path) -> Result<String, ModelError> {
    let shown = path.display();
    let fail = |m: String| ModelError::single(None, m, None);
    let file = std::fs::File::open(path)
        .map_err(|e| fail(format!("cannot read model file `{shown}`: {e}")))?;
    let mut bytes = Vec::new();
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| fail(format!("cannot read model file `{shown}`: {e}")))?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(fail(format!(
            "model file `{shown}` is larger than the limit of {} MiB",
            MAX_FILE_BYTES >> 20
        )));
    }
    String::from_utf8(bytes)
        .map_err(|e| fail(format!("model file `{shown}` is not UTF-8 text: {e}")))
}

/// 1-based line numbers of byte offsets, from a table of the text's newlines built once
/// (looking each offset up costs a binary search, not a rescan of the text).
pub(crate) struct LineIndex(Vec<usize>);

impl LineIndex {
    pub(crate) fn new(text: &str) -> Self {
        LineIndex(
            text.bytes()
                .enumerate()
                .filter_map(|(i, b)| (b == b'\n').then_some(i))
                .collect(),
        )
    }

    /// The line of byte `offset`.
    pub(crate) fn of(&self, offset: usize) -> usize {
        self.0.partition_point(|&n| n < offset) + 1
    }
}

/// Scans XML text once, without building anything, and refuses nesting deeper than
/// [`MAX_XML_DEPTH`] or an element with more than [`MAX_XML_ATTRIBUTES`] attributes, with
/// the line. Comments, CDATA, processing instructions, declarations and quoted values are
/// skipped; whatever is malformed is left for the parser to name.
pub(crate) fn check_xml_shape(text: &str, lines: &LineIndex) -> Result<(), (String, usize)> {
    let b = text.as_bytes();
    let (mut i, mut depth) = (0usize, 0usize);
    let find = |from: usize, pat: &[u8]| {
        b[from..]
            .windows(pat.len())
            .position(|w| w == pat)
            .map_or(b.len(), |p| from + p + pat.len())
    };
    while i < b.len() {
        if b[i] != b'<' {
            i += 1;
            continue;
        }
        let start = i;
        if b[i..].starts_with(b"<!--") {
            i = find(i + 4, b"-->");
        } else if b[i..].starts_with(b"<![CDATA[") {
            i = find(i + 9, b"]]>");
        } else if b[i..].starts_with(b"<?") {
            i = find(i + 2, b"?>");
        } else if b[i..].starts_with(b"<!") {
            i = find(i + 2, b">");
        } else if b[i..].starts_with(b"</") {
            depth = depth.saturating_sub(1);
            i = find(i + 2, b">");
        } else {
            // A start tag: count `=` outside quotes up to its `>`.
            let (mut attributes, mut quote) = (0usize, None);
            i += 1;
            while i < b.len() {
                match (quote, b[i]) {
                    (Some(q), c) if c == q => quote = None,
                    (Some(_), _) => {}
                    (None, c @ (b'"' | b'\'')) => quote = Some(c),
                    (None, b'=') => attributes += 1,
                    (None, b'>') => break,
                    _ => {}
                }
                i += 1;
            }
            if attributes > MAX_XML_ATTRIBUTES {
                return Err((
                    format!(
                        "XML element has {attributes} attributes, more than the limit of {MAX_XML_ATTRIBUTES}"
                    ),
                    lines.of(start),
                ));
            }
            let self_closing = i > 0 && i < b.len() && b[i - 1] == b'/';
            if !self_closing {
                depth += 1;
                if depth > MAX_XML_DEPTH {
                    return Err((
                        format!("XML nesting is deeper than the limit of {MAX_XML_DEPTH} elements"),
                        lines.of(start),
                    ));
                }
            }
            i += 1;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape(text: &str) -> Result<(), (String, usize)> {
        check_xml_shape(text, &LineIndex::new(text))
    }

    #[test]
    fn lines_are_counted_from_one() {
        let lines = LineIndex::new("a\nbc\n\nd");
        assert_eq!([0, 1, 2, 4, 5, 6].map(|o| lines.of(o)), [1, 1, 2, 2, 3, 4]);
    }

    #[test]
    fn xml_nesting_and_attributes_are_bounded() {
        assert!(shape(r#"<robot name="r"><link name="a"><x a="1" b='>'/></link></robot>"#).is_ok());
        let deep = format!(
            "<r>\n{}{}</r>",
            "<x>".repeat(MAX_XML_DEPTH),
            "</x>".repeat(100)
        );
        let (msg, line) = shape(&deep).unwrap_err();
        assert!(msg.contains("deeper than the limit of 100"), "{msg}");
        assert_eq!(line, 2);
        // Closed elements do not add up, nor do comments, CDATA or quoted brackets.
        let flat = "<r><!-- <a><a> --><![CDATA[<a><a>]]><b x=\"<c>\"/>".to_string()
            + &"<x></x>".repeat(1000)
            + "</r>";
        assert!(shape(&flat).is_ok());
        let many = format!(
            "<r {}/>",
            (0..65).map(|k| format!("a{k}=\"1\" ")).collect::<String>()
        );
        let (msg, _) = shape(&many).unwrap_err();
        assert!(msg.contains("65 attributes"), "{msg}");
        // `=` inside a quoted value is not an attribute.
        assert!(shape(&format!("<r a=\"{}\"/>", "=".repeat(1000))).is_ok());
    }
}
