//! XML documents from untrusted text (URDF, MJCF, COLLADA): roxmltree's parse, after a linear scan that
//! refuses an element with more attributes than any real file has (roxmltree checks each attribute against
//! the element's others, so its time grows with the square of their number: 150,000 attributes took 15 s),
//! and a fallible reservation of the most memory the parse can take, freed before it starts: roxmltree
//! allocates infallibly, so a document too large for memory would abort the process.
//!
//! roxmltree's parse cannot be stopped once started; a cancelled load (`validate::cancellable`) stops in
//! the scan before it, or after it.

use roxmltree::Document;

use crate::{Error, Result};

/// The most attributes one element may have.
pub const MAX_ATTRIBUTES: usize = 1024;

/// roxmltree's peak heap per `<`, per `=` and per byte of text: a node and an attribute are 72 bytes each,
/// text between tags doubles the nodes, a vector that grows holds both copies, and text with references
/// is copied. Measured with a counting allocator over documents of 200,000 empty, text, escaped,
/// namespaced and nested elements: at most 312 B per `<` and 97 per `=`, plus the text's length.
const BYTES_PER_TAG: usize = 320;
const BYTES_PER_ATTRIBUTE: usize = 96;
const BYTES_PER_BYTE: usize = 2;

/// The document `text` holds, or (inner error) what is wrong with it; `Error::TooLarge` naming `argument`
/// when the memory its parse may take cannot be allocated.
pub fn parse<'a>(text: &'a str, argument: &'static str) -> Result<std::result::Result<Document<'a>, String>> {
    if let Some(line) = crowded_element(text) {
        return Ok(Err(format!("not valid XML: an element at line {line} has more than {MAX_ATTRIBUTES} attributes")));
    }
    crate::validate::check_cancelled("xml")?;
    // `<` and `=` signs bound roxmltree's nodes and attributes.
    let count = |sign: u8| text.bytes().filter(|&b| b == sign).count();
    let (tags, attributes) = (count(b'<'), count(b'='));
    let bytes = tags
        .checked_mul(BYTES_PER_TAG)
        .zip(attributes.checked_mul(BYTES_PER_ATTRIBUTE))
        .and_then(|(t, a)| t.checked_add(a)?.checked_add(text.len().checked_mul(BYTES_PER_BYTE)?))
        .unwrap_or(usize::MAX);
    if !crate::validate::headroom(bytes) {
        let reason = format!(
            "parsing {} bytes of XML ({tags} tags, {attributes} attributes) needs up to {bytes} bytes, which cannot be allocated",
            text.len()
        );
        return Err(Error::too_large(argument, reason));
    }
    Ok(Document::parse(text).map_err(|e| format!("not valid XML: {e}")))
}

/// The line of the first start tag with more than `MAX_ATTRIBUTES` attributes (counted as the `=` signs
/// outside quotes), skipping comments, CDATA sections, processing instructions and declarations. Malformed
/// text is left to the parser.
fn crowded_element(text: &str) -> Option<usize> {
    let bytes = text.as_bytes();
    let mut at = 0;
    let mut tags = 0usize;
    while let Some(offset) = bytes[at..].iter().position(|&b| b == b'<') {
        tags += 1;
        if tags.is_multiple_of(crate::validate::CANCEL_INTERVAL) && crate::validate::check_cancelled("xml").is_err() {
            // A cancelled load: the parse that follows is not wanted either (see `parse`).
            return None;
        }
        let start = at + offset;
        let rest = &text[start..];
        let skip_to = |end: &str| rest.find(end).map_or(bytes.len(), |i| start + i + end.len());
        if rest.starts_with("<!--") {
            at = skip_to("-->");
        } else if rest.starts_with("<![CDATA[") {
            at = skip_to("]]>");
        } else if rest.starts_with("<?") {
            at = skip_to("?>");
        } else {
            let (mut quote, mut attributes, mut end) = (None, 0, bytes.len());
            for (i, &b) in bytes.iter().enumerate().skip(start + 1) {
                match (quote, b) {
                    (Some(q), _) if b == q => quote = None,
                    (Some(_), _) => {}
                    (None, b'"' | b'\'') => quote = Some(b),
                    (None, b'=') => attributes += 1,
                    (None, b'>') => {
                        end = i + 1;
                        break;
                    }
                    _ => {}
                }
            }
            if attributes > MAX_ATTRIBUTES {
                return Some(text[..start].matches('\n').count() + 1);
            }
            at = end;
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_element_with_too_many_attributes_is_refused_with_its_line() {
        let crowded: String = (0..=MAX_ATTRIBUTES).map(|i| format!(" a{i}='>'")).collect();
        let text = format!("<r>\n<!-- <x {crowded}/> -->\n<e{crowded}/></r>");
        let error = parse(&text, "xml").unwrap().unwrap_err();
        assert!(error.contains("line 3") && error.contains("more than 1024 attributes"), "{error}");
        let fine: String = (0..MAX_ATTRIBUTES).map(|i| format!(" a{i}=\"=\"")).collect();
        assert!(parse(&format!("<r><e{fine}/></r>"), "xml").unwrap().is_ok());
    }
}
